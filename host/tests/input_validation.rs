//! Bad input to `imucal fit` and `imucal still`, run through the real binary on small files
//! written here: each class is refused (exit code ≠ 0, no panic) with a sentence naming the
//! cause and the fix, or, where the data is still usable, a hold is left out with a warning.

use std::path::PathBuf;
use std::process::Command;

use imucal::fit::Vec3;
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

const G: f64 = 9.80665;
const RATE_HZ: f64 = 100.0;
/// Accelerometer noise per sample in g and gyroscope noise in rad/s (MEMS-like).
const ACCEL_SIGMA_G: f64 = 0.003;
const GYRO_SIGMA_RADS: f64 = 0.002;

struct Outcome {
    success: bool,
    stdout: String,
    stderr: String,
}

fn imucal(args: &[&str]) -> Outcome {
    let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .args(args)
        .output()
        .expect("the binary runs");
    Outcome {
        success: out.status.success(),
        stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
    }
}

/// A file in a per-process scratch directory.
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("imucal-input-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temporary directory is writable");
    dir.join(name)
}

fn write(name: &str, bytes: &[u8]) -> String {
    let path = scratch(name);
    std::fs::write(&path, bytes).expect("scratch file is writable");
    path.display().to_string()
}

/// Assert a refusal: failing exit code, no panic, and every phrase in the message.
fn assert_refused(outcome: &Outcome, phrases: &[&str]) {
    assert!(
        !outcome.success,
        "expected a failure; stdout: {}",
        outcome.stdout
    );
    assert!(
        !outcome.stderr.contains("panicked"),
        "panicked: {}",
        outcome.stderr
    );
    for phrase in phrases {
        assert!(
            outcome.stderr.contains(phrase),
            "missing `{phrase}` in: {}",
            outcome.stderr
        );
    }
}

/// How a synthetic recording is written.
struct Synthetic {
    /// Gravity directions of the holds (need not be unit length).
    directions: Vec<Vec3>,
    /// Numbers per g in the file (1 for g, 9.80665 for m/s², 16384 for counts).
    accel_per_g: f64,
    /// Numbers per rad/s in the file (1 for rad/s, 180/π for °/s).
    gyro_per_rads: f64,
    /// Hold length and move length in seconds.
    hold_s: f64,
    move_s: f64,
    /// Write a `pose` column labelling the holds (moves unlabelled).
    pose_column: bool,
    /// Index of a hold during which the board shakes (accelerometer noise × 30), if any.
    shaking_hold: Option<usize>,
    /// Clip each accelerometer axis to ± this many g (the sensor's full-scale range per axis).
    clip_g: Option<Vec3>,
    /// Decimals the accelerometer is written with (6 unless set).
    accel_decimals: Option<usize>,
}

impl Synthetic {
    fn new(directions: Vec<Vec3>) -> Self {
        Self {
            directions,
            accel_per_g: G,
            gyro_per_rads: 1.0,
            hold_s: 2.0,
            move_s: 1.0,
            pose_column: false,
            shaking_hold: None,
            clip_g: None,
            accel_decimals: None,
        }
    }

    /// Holds joined by great-circle moves at constant rate; the gyroscope reads that rate
    /// plus a bias of 0.01 rad/s on x.
    fn csv(&self) -> String {
        let mut rng = StdRng::seed_from_u64(7);
        let accel_noise = Normal::new(0.0, ACCEL_SIGMA_G).expect("valid sigma");
        let gyro_noise = Normal::new(0.0, GYRO_SIGMA_RADS).expect("valid sigma");
        let bias = Vec3::new(0.01, 0.0, 0.0);
        let mut out = String::from("t_s,ax,ay,az,gx,gy,gz");
        if self.pose_column {
            out.push_str(",pose");
        }
        out.push('\n');
        let mut t = 0.0;
        let mut row = |out: &mut String, g: Vec3, rate: Vec3, shake: f64, label: Option<usize>| {
            let mut a = g + shake * Vec3::from_fn(|_, _| accel_noise.sample(&mut rng));
            if let Some(clip) = self.clip_g {
                a = Vec3::from_fn(|k, _| a[k].clamp(-clip[k], clip[k]));
            }
            let a = a * self.accel_per_g;
            let w = (rate + bias + Vec3::from_fn(|_, _| gyro_noise.sample(&mut rng)))
                * self.gyro_per_rads;
            let d = self.accel_decimals.unwrap_or(6);
            out.push_str(&format!(
                "{t:.3},{:.d$},{:.d$},{:.d$},{:.6},{:.6},{:.6}",
                a.x, a.y, a.z, w.x, w.y, w.z
            ));
            if self.pose_column {
                out.push_str(&label.map_or(",-".to_string(), |l| format!(",{l}")));
            }
            out.push('\n');
            t += 1.0 / RATE_HZ;
        };
        let hold_rows = (self.hold_s * RATE_HZ) as usize;
        let move_rows = (self.move_s * RATE_HZ) as usize;
        for (i, d) in self.directions.iter().enumerate() {
            let d = d.normalize();
            let shake = if self.shaking_hold == Some(i) {
                30.0
            } else {
                1.0
            };
            for _ in 0..hold_rows {
                row(&mut out, d, Vec3::zeros(), shake, Some(i));
            }
            let Some(next) = self.directions.get(i + 1).map(|n| n.normalize()) else {
                continue;
            };
            let angle = d.dot(&next).clamp(-1.0, 1.0).acos();
            let axis = d.cross(&next).try_normalize(1e-9).unwrap_or_else(Vec3::z);
            let rate = axis * angle / self.move_s;
            for k in 0..move_rows {
                let turned = nalgebra::Rotation3::new(axis * angle * k as f64 / move_rows as f64);
                row(&mut out, turned * d, rate, 1.0, None);
            }
        }
        out
    }

    fn write(&self, name: &str) -> String {
        write(name, self.csv().as_bytes())
    }
}

/// `imucal fit PATH --sensor accel --accel-unit g --json`.
fn fit_accel_in_g_as_json(path: &str) -> Outcome {
    imucal(&[
        "fit",
        path,
        "--sensor",
        "accel",
        "--accel-unit",
        "g",
        "--json",
    ])
}

/// Twelve well-spread gravity directions: the six faces and six diagonals.
fn twelve_directions() -> Vec<Vec3> {
    vec![
        Vec3::new(0.0, 0.0, 1.0),
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(0.0, 1.0, 0.0),
        Vec3::new(0.0, 0.0, -1.0),
        Vec3::new(-1.0, 0.0, 0.0),
        Vec3::new(0.0, -1.0, 0.0),
        Vec3::new(1.0, 1.0, 1.0),
        Vec3::new(-1.0, 1.0, -1.0),
        Vec3::new(1.0, -1.0, -1.0),
        Vec3::new(-1.0, -1.0, 1.0),
        Vec3::new(1.0, 0.0, 1.0),
        Vec3::new(0.0, 1.0, -1.0),
    ]
}

fn six_faces() -> Vec<Vec3> {
    twelve_directions().into_iter().take(6).collect()
}

#[test]
fn a_clean_synthetic_recording_is_accepted_without_warnings() {
    // The control for every refusal below: the same generator with nothing wrong passes.
    let path = Synthetic::new(twelve_directions()).write("clean.csv");
    let outcome = imucal(&["fit", &path, "--json"]);
    assert!(outcome.success, "{}", outcome.stderr);
    assert!(!outcome.stderr.contains("warning"), "{}", outcome.stderr);
}

#[test]
fn rows_repeating_the_time_stamp_before_them_are_counted_in_a_warning_and_the_fit_goes_on() {
    // Every fourth row carries the time stamp of the row before (a clock coarser than the rate).
    let clean = Synthetic::new(twelve_directions()).csv();
    let mut lines: Vec<String> = clean.lines().map(str::to_string).collect();
    let mut repeated = 0;
    for i in (4..lines.len()).step_by(4) {
        let previous_time = lines[i - 1].split(',').next().expect("a time").to_string();
        let rest = lines[i].split_once(',').expect("fields").1.to_string();
        lines[i] = format!("{previous_time},{rest}");
        repeated += 1;
    }
    let rows = lines.len() - 1;
    let path = write("repeated_times.csv", (lines.join("\n") + "\n").as_bytes());
    let outcome = imucal(&["fit", &path, "--json"]);
    assert!(outcome.success, "{}", outcome.stderr);
    let expected = format!("{repeated} of {rows} rows repeat the time stamp of the row before");
    assert!(outcome.stderr.contains(&expected), "{}", outcome.stderr);
    assert_eq!(outcome.stderr.matches("repeat the time stamp").count(), 1);
}

#[test]
fn milliseconds_in_the_seconds_column_are_named_before_the_detection_finds_no_hold() {
    // The clean recording with its time written in milliseconds under `t_s`.
    let clean = Synthetic::new(twelve_directions()).csv();
    let mut lines = clean.lines();
    let mut text = format!("{}\n", lines.next().expect("header"));
    for line in lines {
        let (t, rest) = line.split_once(',').expect("fields");
        let ms = t.parse::<f64>().expect("a time") * 1000.0;
        text += &format!("{ms:.0},{rest}\n");
    }
    let path = write("milliseconds.csv", text.as_bytes());
    for command in ["fit", "still"] {
        let outcome = imucal(&[command, &path]);
        assert!(!outcome.success, "{command}: {}", outcome.stdout);
        assert!(
            outcome
                .stderr
                .contains("the time column advances 10.0000 s per row (0.1000 Hz)"),
            "{command}: {}",
            outcome.stderr
        );
        assert!(outcome.stderr.contains("`t_ms=t_s`"), "{}", outcome.stderr);
        // The refusal names the clock too, not holds that are too short.
        assert!(
            outcome
                .stderr
                .contains("the time is most likely in milliseconds or microseconds"),
            "{command}: {}",
            outcome.stderr
        );
        assert!(
            !outcome.stderr.contains("lower --min-hold"),
            "{command}: {}",
            outcome.stderr
        );
    }
    // Read as milliseconds, the same file fits.
    let columns = "t_ms=t_s,ax=ax,ay=ay,az=az,gx=gx,gy=gy,gz=gz";
    let outcome = imucal(&["fit", &path, "--columns", columns, "--json"]);
    assert!(outcome.success, "{}", outcome.stderr);
    assert!(!outcome.stderr.contains("advances"), "{}", outcome.stderr);
}

#[test]
fn too_few_directions_are_refused_and_the_missing_faces_asked_for() {
    let path = Synthetic::new(six_faces().into_iter().take(3).collect()).write("three.csv");
    let outcome = imucal(&["fit", &path, "--sensor", "accel"]);
    assert_refused(
        &outcome,
        &[
            "only 3 distinct gravity directions among 3 holds",
            "add holds with other faces up",
        ],
    );
}

#[test]
fn repeated_directions_do_not_count_and_the_repeats_are_named() {
    // Eight holds alternating between two faces: two directions, six repeats.
    let directions: Vec<Vec3> = (0..8)
        .map(|i| if i % 2 == 0 { Vec3::z() } else { Vec3::x() })
        .collect();
    let path = Synthetic::new(directions).write("repeats.csv");
    let outcome = imucal(&["fit", &path, "--sensor", "accel"]);
    assert_refused(
        &outcome,
        &[
            "only 2 distinct gravity directions among 8 holds",
            "6 of them repeat a direction",
        ],
    );
}

#[test]
fn directions_all_near_one_plane_are_refused_and_the_missing_axis_named() {
    // Eight directions around the horizon tilted 8° out of the x–y plane: the RMS
    // out-of-plane angle is 8°, below the 20° limit; Z is the axis to add.
    let tilt = 8f64.to_radians();
    let directions: Vec<Vec3> = (0..8)
        .map(|i| {
            let phi = i as f64 * std::f64::consts::FRAC_PI_4;
            let up = if i % 2 == 0 { tilt } else { -tilt };
            Vec3::new(phi.cos() * up.cos(), phi.sin() * up.cos(), up.sin())
        })
        .collect();
    let path = Synthetic::new(directions).write("planar.csv");
    let outcome = imucal(&["fit", &path, "--sensor", "accel"]);
    assert_refused(
        &outcome,
        &["within 20° of a plane", "Z axis pointing up or down"],
    );
}

#[test]
fn a_recording_with_no_still_interval_is_refused_by_fit_and_still() {
    // Only moves: 0.05 s holds are far below the 1 s minimum hold.
    let mut synthetic = Synthetic::new(twelve_directions());
    synthetic.hold_s = 0.05;
    let path = synthetic.write("moving.csv");
    for command in ["fit", "still"] {
        let outcome = imucal(&[command, &path]);
        assert_refused(
            &outcome,
            &[
                "no still interval",
                "hold it still for 2–3 s in each orientation",
            ],
        );
    }
}

#[test]
fn a_hold_with_motion_is_left_out_with_a_sentence_and_the_fit_goes_on() {
    // Pose 7 shakes with 30× the noise: variance 900× the median hold's, far above the
    // factor 10 at which a hold counts as moving.
    let mut synthetic = Synthetic::new(twelve_directions());
    synthetic.pose_column = true;
    synthetic.shaking_hold = Some(7);
    let path = synthetic.write("shaking.csv");
    let outcome = imucal(&["fit", &path, "--sensor", "accel", "--json"]);
    assert!(outcome.success, "{}", outcome.stderr);
    assert!(
        outcome.stderr.contains("(pose 7) is left out")
            && outcome
                .stderr
                .contains("the board moved during the capture"),
        "{}",
        outcome.stderr
    );
    let json: serde_json::Value = serde_json::from_str(&outcome.stdout).expect("JSON output");
    assert_eq!(json["accel"]["n_poses"], 11, "{json}");
}

#[test]
fn a_saturated_hold_is_left_out_and_all_saturated_holds_are_refused() {
    // Clipping z at ±0.99 g (3.3 noise sigmas below 1 g) pins it in nearly every sample of
    // the +Z and −Z holds; every other hold has |z| ≤ 0.71 g, so two holds are left out and
    // ten remain.
    let mut synthetic = Synthetic::new(twelve_directions());
    synthetic.clip_g = Some(Vec3::new(2.0, 2.0, 0.99));
    synthetic.accel_per_g = 1.0;
    let path = synthetic.write("clipped.csv");
    let outcome = fit_accel_in_g_as_json(&path);
    assert!(outcome.success, "{}", outcome.stderr);
    assert_eq!(
        outcome.stderr.matches("is left out").count(),
        2,
        "{}",
        outcome.stderr
    );
    assert!(
        outcome.stderr.contains("saturated at the end of its range")
            && outcome.stderr.contains("larger full-scale range"),
        "{}",
        outcome.stderr
    );
    let json: serde_json::Value = serde_json::from_str(&outcome.stdout).expect("JSON output");
    assert_eq!(json["accel"]["n_poses"], 10, "{json}");
    // Six faces all pinned: every hold is left out.
    let mut faces = Synthetic::new(six_faces());
    faces.clip_g = Some(Vec3::repeat(0.99));
    faces.accel_per_g = 1.0;
    let path = faces.write("clipped_faces.csv");
    let outcome = imucal(&["fit", &path, "--sensor", "accel", "--accel-unit", "g"]);
    assert_refused(
        &outcome,
        &["every hold", "all saturated", "within the sensor's range"],
    );
}

#[test]
fn readings_quantised_coarser_than_their_noise_are_not_taken_for_a_saturated_axis() {
    // g to one decimal: the noise (ACCEL_SIGMA_G) is far below the 0.1 g step, so a face-down
    // hold reads −1.0 in every sample, the recording's smallest value, with no rail near.
    let mut synthetic = Synthetic::new(twelve_directions());
    synthetic.accel_per_g = 1.0;
    synthetic.accel_decimals = Some(1);
    let path = synthetic.write("one_decimal.csv");
    let outcome = fit_accel_in_g_as_json(&path);
    assert!(outcome.success, "{}", outcome.stderr);
    assert!(!outcome.stderr.contains("saturated"), "{}", outcome.stderr);
    let json: serde_json::Value = serde_json::from_str(&outcome.stdout).expect("JSON output");
    assert_eq!(json["accel"]["n_poses"], 12, "{json}");
    // Each hold reads one value: its mean carries the rounding (± 0.1 g/√12), not the
    // hidden noise averaged over 200 samples, so the model is not blamed for it.
    let verdict = json["accel"]["verdict"].as_str().unwrap_or_default();
    assert!(!verdict.contains("misses something"), "{verdict}");
}

#[test]
fn a_gyroscope_that_turns_too_far_under_a_given_rate_names_the_rate_first() {
    // The clean recording without its time column, read at a tenth of its 100 Hz: every move
    // lasts ten times as long, so the gyroscope seems to turn ten times too far.
    let csv = Synthetic::new(twelve_directions()).csv();
    let untimed: String = csv
        .lines()
        .map(|line| {
            line.split_once(',')
                .map_or(line, |(_, rest)| rest)
                .to_string()
                + "\n"
        })
        .collect();
    let path = write("untimed.csv", untimed.as_bytes());
    let outcome = imucal(&["fit", &path, "--sensor", "gyro", "--rate", "10"]);
    assert!(
        outcome.stderr.contains("the times come from --rate")
            && outcome.stderr.contains("check --rate first"),
        "{}",
        outcome.stderr
    );
}

#[test]
fn accelerometer_units_contradicted_by_the_rest_magnitude_are_refused_with_the_right_flag() {
    let cases: [(f64, &str, &str); 3] = [
        (
            1.0,
            "mps2",
            "which looks like g, but it is read as mps2 (--accel-unit, else a unit written in the header, else mps2); pass --accel-unit g",
        ),
        (
            G,
            "g",
            "which looks like m/s², but it is read as g (--accel-unit, else a unit written in the header, else mps2); pass --accel-unit mps2",
        ),
        (
            16384.0,
            "mps2",
            "looks like raw counts, but it is read as mps2 (--accel-unit, else a unit written in the header, else mps2); pass --accel-unit counts",
        ),
    ];
    for (per_g, declared, sentence) in cases {
        let mut synthetic = Synthetic::new(twelve_directions());
        synthetic.accel_per_g = per_g;
        let path = synthetic.write(&format!("accel_{declared}_{per_g}.csv"));
        let outcome = imucal(&["fit", &path, "--sensor", "accel", "--accel-unit", declared]);
        assert_refused(&outcome, &[sentence]);
    }
}

#[test]
fn gyroscope_in_degrees_declared_as_radians_is_found_from_the_turn_between_holds() {
    // Moves turn the gravity direction by 45–180°; in °/s the gyroscope integrates to 57×
    // that angle, far above the factor 10 allowed in the right unit.
    let mut synthetic = Synthetic::new(twelve_directions());
    synthetic.gyro_per_rads = 180.0 / std::f64::consts::PI;
    let path = synthetic.write("gyro_dps.csv");
    let outcome = imucal(&["fit", &path, "--sensor", "gyro"]);
    assert_refused(&outcome, &["not in rad/s", "pass --gyro-unit dps"]);
    // Declared correctly, the same file is accepted.
    let outcome = imucal(&["fit", &path, "--sensor", "gyro", "--gyro-unit", "dps"]);
    assert!(outcome.success, "{}", outcome.stderr);
}

#[test]
fn gyroscope_in_radians_declared_as_degrees_is_refused() {
    let path = Synthetic::new(twelve_directions()).write("gyro_rads.csv");
    let outcome = imucal(&["fit", &path, "--sensor", "gyro", "--gyro-unit", "dps"]);
    assert_refused(&outcome, &["not in °/s", "pass --gyro-unit rads"]);
}

/// Magnetometer samples on an ellipsoid (radius `field` per axis within ±10 %, offset) over
/// the whole sphere (`flat` = turned about Z only), in file units.
fn write_mag(name: &str, field: f64, flat: bool) -> String {
    let mut rng = StdRng::seed_from_u64(11);
    let noise = Normal::new(0.0, field * 0.005).expect("valid sigma");
    let offset = Vec3::new(0.3, -0.2, 0.1) * field;
    let scale = Vec3::new(1.1, 0.95, 1.0);
    let mut out = String::from("t_s,mx,my,mz\n");
    for i in 0..1500 {
        let z = if flat {
            0.5
        } else {
            -1.0 + 2.0 * (i as f64 + 0.5) / 1500.0
        };
        let phi = i as f64 * 2.399963;
        let r = (1.0 - z * z).sqrt();
        let m = Vec3::new(r * phi.cos(), r * phi.sin(), z).component_mul(&scale) * field
            + offset
            + Vec3::from_fn(|_, _| noise.sample(&mut rng));
        out.push_str(&format!(
            "{:.2},{:.6},{:.6},{:.6}\n",
            i as f64 / 50.0,
            m.x,
            m.y,
            m.z
        ));
    }
    write(name, out.as_bytes())
}

#[test]
fn magnetometer_units_contradicted_by_the_field_radius_are_refused() {
    let gauss = write_mag("mag_gauss.csv", 0.485, false);
    let outcome = imucal(&["fit", &gauss, "--sensor", "mag"]);
    assert_refused(&outcome, &["looks like gauss", "pass --mag-unit gauss"]);
    let microtesla = write_mag("mag_ut.csv", 48.5, false);
    let outcome = imucal(&["fit", &microtesla, "--sensor", "mag", "--mag-unit", "gauss"]);
    assert_refused(&outcome, &["looks like µT", "pass --mag-unit ut"]);
    let counts = write_mag("mag_counts.csv", 530.0, false);
    let outcome = imucal(&["fit", &counts, "--sensor", "mag"]);
    assert_refused(
        &outcome,
        &["looks like raw counts", "pass --mag-unit counts"],
    );
}

#[test]
fn a_field_magnitude_far_from_the_data_is_refused_and_a_near_one_warned() {
    // Data radius ≈ 48.5 µT (axes 0.95–1.1 of it). 485 is a factor ~10 off: refused.
    let path = write_mag("mag_field.csv", 48.5, false);
    let outcome = imucal(&["fit", &path, "--sensor", "mag", "--field-ut", "485"]);
    assert_refused(&outcome, &["a factor", "check --field-ut"]);
    // 35 µT is ~40 % below the data: fitted, with a warning.
    let outcome = imucal(&[
        "fit",
        &path,
        "--sensor",
        "mag",
        "--field-ut",
        "35",
        "--json",
    ]);
    assert!(outcome.success, "{}", outcome.stderr);
    assert!(
        outcome.stderr.contains("warning") && outcome.stderr.contains("from --field-ut 35"),
        "{}",
        outcome.stderr
    );
    // 48.5 µT agrees: no warning.
    let outcome = imucal(&[
        "fit",
        &path,
        "--sensor",
        "mag",
        "--field-ut",
        "48.5",
        "--json",
    ]);
    assert!(
        outcome.success && !outcome.stderr.contains("warning"),
        "{}",
        outcome.stderr
    );
}

#[test]
fn a_magnetometer_turned_only_flat_is_refused_as_planar() {
    let path = write_mag("mag_flat.csv", 48.5, true);
    let outcome = imucal(&["fit", &path, "--sensor", "mag"]);
    assert_refused(
        &outcome,
        &[
            "within 20° of a plane",
            "turn the board through all orientations",
        ],
    );
}

#[test]
fn a_magnetometer_that_was_never_turned_is_refused_as_such_not_as_a_unit_mix_up() {
    // Five minutes on a table in gauss: the samples are the field plus noise in one spot. A
    // sphere fitted to them has the noise's radius, which read as "far below the Earth's field
    // in gauss, pass --mag-unit counts" before.
    let mut rng = StdRng::seed_from_u64(5);
    let noise = Normal::new(0.0, 0.002).expect("valid sigma");
    let field = Vec3::new(0.21, -0.05, 0.43);
    let mut out = String::from("t_s,mx,my,mz\n");
    for i in 0..3000 {
        let m = field + Vec3::from_fn(|_, _| noise.sample(&mut rng));
        out.push_str(&format!(
            "{:.2},{:.6},{:.6},{:.6}\n",
            i as f64 / 10.0,
            m.x,
            m.y,
            m.z
        ));
    }
    let path = write("mag_still.csv", out.as_bytes());
    let outcome = imucal(&["fit", &path, "--sensor", "mag", "--mag-unit", "gauss"]);
    assert_refused(&outcome, &["was not turned", "turn it slowly"]);
    assert!(
        !outcome.stderr.contains("--mag-unit counts"),
        "{}",
        outcome.stderr
    );
}

/// A file name, which rows hold no number, and the phrases of the refusal.
type BadRows = (&'static str, fn(usize) -> bool, &'static [&'static str]);

/// A recording of `rows` rows whose `ax` field is `ax(i)` in row `i`.
fn with_ax(name: &str, rows: usize, ax: impl Fn(usize) -> String) -> String {
    let mut text = String::from("t_s,ax,ay,az\n");
    for i in 0..rows {
        text += &format!("{:.2},{},0.01,9.81\n", i as f64 * 0.01, ax(i));
    }
    write(name, text.as_bytes())
}

#[test]
fn a_value_that_is_not_a_number_gets_advice_from_how_much_of_its_column_is_like_it() {
    // Every row: the sensor was not recorded. The file is longer than one read block, so the
    // count goes on past the block the first value was in.
    let empty = with_ax("empty_column.csv", 60_000, |_| "NaN".into());
    assert_refused(
        &imucal(&["fit", &empty]),
        &[
            "line 2, column `ax`: `NaN` is not a finite number",
            "no row holds a number there (all 60000 rows from there to the end)",
            "the column holds no readings",
        ],
    );
    // Which rows of 500 hold `x`: from row 200 on (the sensor stopped), three rows (mend
    // them), one row (mend it).
    let cases: [BadRows; 3] = [
        (
            "stopped.csv",
            |i| i >= 200,
            &[
                "line 202",
                "from line 202 on (all 300 rows",
                "cut the file before line 202",
            ],
        ),
        (
            "few.csv",
            |i| [100, 300, 301].contains(&i),
            &[
                "line 102",
                "3 of the 400 rows from there on",
                "correct or delete those rows",
            ],
        ),
        (
            "one.csv",
            |i| i == 100,
            &[
                "line 102",
                "is not a finite number; correct or delete that row",
            ],
        ),
    ];
    for (name, bad, phrases) in cases {
        let path = with_ax(
            name,
            500,
            |i| if bad(i) { "x".into() } else { "0.1".into() },
        );
        assert_refused(&imucal(&["fit", &path]), phrases);
    }
}

#[test]
fn a_gyroscope_that_reads_one_constant_is_refused_as_not_measuring_and_the_accelerometer_still_fits(
) {
    // A stuck gyroscope fits a bias with zero noise and RMS 0: a perfect-looking calibration of
    // a dead sensor. Its columns become one constant; the accelerometer's are left as they are.
    let clean = Synthetic::new(twelve_directions()).csv();
    let mut lines = clean.lines();
    let mut stuck = format!("{}\n", lines.next().expect("a header"));
    for line in lines {
        let fields: Vec<&str> = line.split(',').collect();
        stuck.push_str(&format!("{},0.5,-0.25,0.125\n", fields[..4].join(",")));
    }
    let path = write("stuck-gyro.csv", stuck.as_bytes());
    let outcome = imucal(&["fit", &path, "--json"]);
    assert_refused(
        &outcome,
        &[
            "the gyro reads (0.5, -0.25, 0.125) in every one of its",
            "not measuring",
        ],
    );
    // The symptom the unit check would report instead is not given as the cause.
    assert!(!outcome.stderr.contains("turns"), "{}", outcome.stderr);
    let json: serde_json::Value = serde_json::from_str(&outcome.stdout).expect("JSON on stdout");
    assert!(json["accel"]["A"].is_array(), "{}", json["accel"]);
    assert!(json["gyro"]["error"]
        .as_str()
        .is_some_and(|e| e.contains("not measuring")));
}
