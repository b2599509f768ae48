//! `imucal fit` across sensors: each sensor judged on its own, the axis-aligned fallback when
//! the poses cannot determine the cross-axis terms, the magnetometer rotated into the
//! accelerometer frame (synthetic recordings with a known rotation, written by the test), and
//! the field reference from `--location`.

use std::f64::consts::PI;
use std::path::{Path, PathBuf};
use std::process::Command;

use imucal::fit::validate::face_directions;
use imucal::fit::{Mat3, Vec3};
use nalgebra::{Rotation3, Unit};
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal, UnitSphere};
use serde_json::Value;

const G: f64 = 9.80665;

fn imucal(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .args(args)
        .output()
        .expect("binary runs");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("imucal-sensors-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temporary directory is writable");
    dir
}

fn real(name: &str) -> String {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../data/real")
        .join(name)
        .display()
        .to_string()
}

fn numbers(v: &Value) -> Vec<f64> {
    v.as_array()
        .expect("array")
        .iter()
        .map(|x| x.as_f64().expect("number"))
        .collect()
}

/// `A` as printed by `fit --json`: three rows, the parameter file's layout.
fn matrix(v: &Value) -> Mat3 {
    let rows: Vec<f64> = v
        .as_array()
        .expect("rows")
        .iter()
        .flat_map(numbers)
        .collect();
    Mat3::from_row_slice(&rows)
}

fn json(stdout: &str) -> Value {
    serde_json::from_str(stdout).expect("valid JSON")
}

#[test]
fn a_refused_sensor_does_not_stop_the_others_but_fails_the_run() {
    // Full-sphere set, turned by hand throughout: no window is at rest (the gyroscope varies by
    // more than sensor noise everywhere), so accelerometer and gyroscope are refused; the
    // magnetometer sphere is fine.
    let (ok, stdout, stderr) = imucal(&[
        "fit",
        &real("sf_mpu6050_hmc5883l_full_sphere.csv"),
        "--accel-unit",
        "g",
        "--gyro-unit",
        "dps",
        "--mag-unit",
        "gauss",
        "--json",
    ]);
    assert!(!ok, "a refused sensor makes the exit code non-zero");
    let out = json(&stdout);
    let accel_error = out["accel"]["error"].as_str().expect("accel refused");
    assert!(accel_error.contains("never rests"), "{accel_error}");
    let gyro_error = out["gyro"]["error"].as_str().expect("gyro refused");
    assert!(gyro_error.contains("never rests"), "{gyro_error}");
    assert_eq!(out["mag"]["method"], "lm");
    // Without an accelerometer fit there is no gravity to align the magnetometer to.
    assert_eq!(out["mag"]["alignment"]["applied"], false);
    assert_eq!(
        out["mag"]["alignment"]["error"],
        "the accelerometer was not fitted"
    );
    // Both refused for one reason, said once.
    assert!(stderr.contains("accel and gyro not fitted"), "{stderr}");
    assert_eq!(stderr.matches("never rests").count(), 1, "{stderr}");
}

#[test]
fn poses_that_cannot_determine_cross_axis_terms_get_the_axis_aligned_model_and_say_why() {
    let path = real("tsi_mpu6050_multipos.csv");
    let args = ["fit", &path, "--accel-unit", "counts", "--sensor", "accel"];
    let (ok, stdout, stderr) = imucal(&[&args[..], &["--json"]].concat());
    assert!(ok, "{stderr}");
    let accel = &json(&stdout)["accel"];
    assert_eq!(accel["method"], "axis-aligned");
    let note = accel["note"].as_str().expect("note says why");
    for phrase in [
        "axis-aligned (6 unknowns) chosen by leave-one-pose-out error",
        "lm: refused",
        // 4 %, not 6 %: the knocks in these hand-held holds are screened out of the pose
        // variances (median/MAD bound), which sets the noise the covariance is scaled by.
        "uncertain by 4 %",
        "six-position: refused",
    ] {
        assert!(note.contains(phrase), "missing `{phrase}` in {note}");
    }
    // MPU-6050 at ±2 g: 16384 counts per g nominal, sensitivity tolerance ±3 % (datasheet).
    let a = matrix(&accel["A"]);
    for k in 0..3 {
        let nominal = G / 16384.0;
        assert!(
            (a[(k, k)] / nominal - 1.0).abs() < 0.03,
            "A[{k}{k}] {} vs {nominal}",
            a[(k, k)]
        );
    }
    // Asked for explicitly, lm keeps its refusal.
    let (ok, _, stderr) = imucal(&[&args[..], &["--method", "lm"]].concat());
    assert!(!ok);
    assert!(stderr.contains("uncertain by"), "{stderr}");
}

/// Known truth of the synthetic accelerometer + magnetometer recording.
struct Truth {
    /// Accelerometer: raw m/s² → calibrated, upper-triangular (the fit's gauge).
    accel_a: Mat3,
    accel_b: Vec3,
    /// Magnetometer: raw µT → magnetometer frame, upper-triangular (the fit's gauge).
    mag_a: Mat3,
    mag_b: Vec3,
    /// Magnetometer frame → accelerometer frame.
    rotation: Rotation3<f64>,
    field_ut: f64,
    dip_deg: f64,
}

fn truth() -> Truth {
    Truth {
        accel_a: Mat3::new(1.02, 0.004, -0.003, 0.0, 0.98, 0.005, 0.0, 0.0, 1.01),
        accel_b: Vec3::new(0.15, -0.22, 0.31),
        mag_a: Mat3::new(1.08, 0.03, -0.02, 0.0, 0.93, 0.04, 0.0, 0.0, 1.05),
        mag_b: Vec3::new(12.0, -25.0, 8.0),
        rotation: Rotation3::from_axis_angle(
            &Unit::new_normalize(Vec3::new(0.3, -0.5, 0.8)),
            7.0_f64.to_radians(),
        ),
        field_ut: 50.0,
        dip_deg: 60.0,
    }
}

/// Writes `<dir>/rec.csv` (accelerometer, 100 Hz) and `<dir>/rec_mag.csv` (magnetometer on its
/// own 75 Hz clock): 14 holds of 2 s in distinct directions and headings joined by 1 s of
/// tumbling, then 40 s of tumbling for the magnetometer's sphere. Magnetometer samples inside
/// the holds whose index is not in `mag_holds` are left out. Returns the accelerometer path.
fn write_accel_mag(dir: &Path, truth: &Truth, mag_holds: &[usize]) -> String {
    let mut rng = rand::rngs::StdRng::seed_from_u64(11);
    let accel_noise = Normal::new(0.0, 0.02).expect("sigma"); // m/s²
    let mag_noise = Normal::new(0.0, 0.2).expect("sigma"); // µT
    let mut dirs = face_directions().to_vec();
    for s in [-1.0, 1.0] {
        for t in [-1.0, 1.0] {
            dirs.push(Vec3::new(s, t, 1.0).normalize());
            dirs.push(Vec3::new(t, 1.0, s).normalize());
        }
    }
    // World → body for each hold: gravity's "up" onto the hold's direction, then a heading.
    let holds: Vec<Rotation3<f64>> = dirs
        .iter()
        .enumerate()
        .map(|(k, d)| {
            let tilt = Rotation3::rotation_between(&Vec3::z(), d)
                .unwrap_or_else(|| Rotation3::from_axis_angle(&Vec3::x_axis(), PI));
            tilt * Rotation3::from_axis_angle(&Vec3::z_axis(), 0.9 * k as f64)
        })
        .collect();
    let dip = truth.dip_deg.to_radians();
    let field_world = Vec3::new(dip.cos(), 0.0, -dip.sin()) * truth.field_ut;
    let hold_s = 2.0;
    let period = 3.0;
    let duration = holds.len() as f64 * period + 40.0;
    let orientation = |t: f64, rng: &mut rand::rngs::StdRng| -> (Rotation3<f64>, Option<usize>) {
        let k = (t / period) as usize;
        if k < holds.len() && t - k as f64 * period < hold_s {
            (holds[k], Some(k))
        } else {
            let axis: [f64; 3] = UnitSphere.sample(rng);
            let angle = rng.gen_range(0.0..PI);
            (
                Rotation3::from_axis_angle(&Unit::new_normalize(Vec3::from(axis)), angle),
                None,
            )
        }
    };
    let accel_inv = truth.accel_a.try_inverse().expect("invertible");
    let mag_inv = truth.mag_a.try_inverse().expect("invertible");
    let mut accel_text = String::from("t_s,ax,ay,az\n");
    for i in 0..(duration * 100.0) as usize {
        let t = i as f64 / 100.0;
        let (q, _) = orientation(t, &mut rng);
        let raw = accel_inv * (q * Vec3::z() * G)
            + truth.accel_b
            + Vec3::from_fn(|_, _| accel_noise.sample(&mut rng));
        accel_text += &format!("{t:.4},{:.5},{:.5},{:.5}\n", raw.x, raw.y, raw.z);
    }
    let mut mag_text = String::from("t_s,mx,my,mz\n");
    for j in 0..(duration * 75.0) as usize {
        // Offset clock: the magnetometer's samples fall between the accelerometer's.
        let t = j as f64 / 75.0 + 0.003;
        let (q, hold) = orientation(t, &mut rng);
        if hold.is_some_and(|k| !mag_holds.contains(&k)) {
            continue;
        }
        let in_mag_frame = truth.rotation.inverse() * (q * field_world);
        let raw =
            mag_inv * in_mag_frame + truth.mag_b + Vec3::from_fn(|_, _| mag_noise.sample(&mut rng));
        mag_text += &format!("{t:.4},{:.4},{:.4},{:.4}\n", raw.x, raw.y, raw.z);
    }
    let accel_path = dir.join("rec.csv");
    std::fs::write(&accel_path, accel_text).expect("writable");
    std::fs::write(dir.join("rec_mag.csv"), mag_text).expect("writable");
    accel_path.display().to_string()
}

#[test]
fn magnetometer_is_rotated_into_the_accelerometer_frame_by_the_known_rotation() {
    let truth = truth();
    let dir = scratch("aligned");
    let path = write_accel_mag(&dir, &truth, &(0..14).collect::<Vec<_>>());
    let (ok, stdout, stderr) = imucal(&["fit", &path, "--field-ut", "50", "--json"]);
    assert!(ok, "{stderr}");
    let out = json(&stdout);
    assert_eq!(out["accel"]["method"], "lm");
    let mag = &out["mag"];
    let alignment = &mag["alignment"];
    assert_eq!(alignment["applied"], true, "{alignment}");
    // Error budget: the magnetometer fit's parameters are uncertain by about
    // 0.2 µT/50 µT·√(9/2000) ≈ 3e-4 (0.015°), the hold means by 0.2/√150/50 ≈ 3e-4 rad each over
    // 14 holds; 0.1° is several times both.
    let angle = alignment["angle_deg"].as_f64().expect("angle");
    assert!((angle - 7.0).abs() < 0.1, "angle {angle}°");
    let dip = alignment["dip_deg"].as_f64().expect("dip");
    assert!((dip - truth.dip_deg).abs() < 0.1, "dip {dip}°");
    let axis = Vec3::from_row_slice(&numbers(&alignment["axis"]));
    let want_axis = Vec3::new(0.3, -0.5, 0.8).normalize();
    // An axis error of 0.1° on a 7° rotation moves the axis by up to 0.1/7 rad ≈ 0.014.
    assert!((axis - want_axis).norm() < 0.03, "axis {axis}");
    // The stated σ of angle and dip are those of the alignment's own residual: positive and
    // below the 0.1° bound.
    for key in ["angle_std_deg", "dip_std_deg"] {
        let s = alignment[key].as_f64().expect("σ");
        assert!(s > 0.0 && s < 0.1, "{key} {s}");
    }
    let rows: Vec<Vec<f64>> = alignment["rotation"]
        .as_array()
        .expect("rows")
        .iter()
        .map(numbers)
        .collect();
    assert_eq!(rows.len(), 3);
    // The rotated A maps raw readings into the accelerometer frame: R·A_mag. Entries ~1, each
    // uncertain by ~3e-4 from the fit plus the rotation's ~2e-3 rad × |A| (the 0.1° above).
    let a = matrix(&mag["A"]);
    let want = truth.rotation.matrix() * truth.mag_a * (50.0 / truth.field_ut);
    assert!((a - want).abs().max() < 3e-3, "A\n{a}\nvs\n{want}");
}

#[test]
fn too_few_holds_with_magnetometer_data_leave_it_unrotated_say_so_and_fail_the_run() {
    let truth = truth();
    let dir = scratch("unaligned");
    let path = write_accel_mag(&dir, &truth, &[0, 2, 4]);
    let (ok, stdout, stderr) = imucal(&["fit", &path, "--field-ut", "50", "--json"]);
    assert!(!ok, "a failed alignment fails the run");
    assert!(
        stderr.contains("not aligned to the accelerometer") && stderr.contains("--sensor mag"),
        "{stderr}"
    );
    let mag = &json(&stdout)["mag"];
    assert_eq!(mag["alignment"]["applied"], false);
    let error = mag["alignment"]["error"]
        .as_str()
        .expect("refusal sentence");
    assert!(error.contains("only 3 poses"), "{error}");
    // Unrotated: the fit's upper-triangular gauge survives.
    let a = matrix(&mag["A"]);
    for (r, c) in [(1, 0), (2, 0), (2, 1)] {
        assert_eq!(a[(r, c)], 0.0, "A[{r}{c}]");
    }
    let (_, table, _) = imucal(&["fit", &path, "--field-ut", "50"]);
    assert!(
        table.contains("A is left in the magnetometer's own frame"),
        "{table}"
    );
}

#[test]
fn a_magnetometer_spike_inside_a_hold_is_dropped_named_and_leaves_the_alignment_exact() {
    let truth = truth();
    let dir = scratch("spike");
    let path = write_accel_mag(&dir, &truth, &(0..14).collect::<Vec<_>>());
    // One corrupted read of 10⁵ µT in the middle of hold 5 (15–17 s).
    let mag_path = dir.join("rec_mag.csv");
    let text = std::fs::read_to_string(&mag_path).expect("written above");
    let mut spiked = false;
    let lines: Vec<String> = text
        .lines()
        .map(|line| {
            let t: f64 = line
                .split(',')
                .next()
                .and_then(|t| t.parse().ok())
                .unwrap_or(-1.0);
            if !spiked && (16.0..16.1).contains(&t) {
                spiked = true;
                let rest: Vec<&str> = line.split(',').skip(2).collect();
                format!("{t:.4},100000.0,{}", rest.join(","))
            } else {
                line.to_string()
            }
        })
        .collect();
    assert!(spiked);
    std::fs::write(&mag_path, lines.join("\n") + "\n").expect("writable");
    let (ok, stdout, stderr) = imucal(&["fit", &path, "--field-ut", "50", "--json"]);
    assert!(ok, "{stderr}");
    assert!(
        stderr.contains("outliers dropped from its statistics: 1 of ")
            && stderr.contains(" mag samples"),
        "{stderr}"
    );
    assert!(
        stderr.contains("hold #") && stderr.contains(" at 15."),
        "the warning names the hold: {stderr}"
    );
    let alignment = &json(&stdout)["mag"]["alignment"];
    assert_eq!(alignment["applied"], true, "{alignment}");
    // The same 0.1° budget as without the spike (see the test above): unscreened, the spike
    // moves that hold's field mean by ~700 µT and the rotation by tens of degrees.
    let angle = alignment["angle_deg"].as_f64().expect("angle");
    assert!((angle - 7.0).abs() < 0.1, "angle {angle}°");
    let dip = alignment["dip_deg"].as_f64().expect("dip");
    assert!((dip - truth.dip_deg).abs() < 0.1, "dip {dip}°");
}

/// A magnetometer-only CSV in µT over the whole sphere with radius `radius_ut`.
fn write_mag_sphere(path: &Path, radius_ut: f64) -> String {
    let mut rng = rand::rngs::StdRng::seed_from_u64(5);
    let noise = Normal::new(0.0, 0.2).expect("sigma");
    let mut text = String::from("t_s,mx,my,mz\n");
    for i in 0..2000 {
        let u: [f64; 3] = UnitSphere.sample(&mut rng);
        let m = Vec3::from(u) * radius_ut
            + Vec3::new(10.0, -4.0, 6.0)
            + Vec3::from_fn(|_, _| noise.sample(&mut rng));
        text += &format!("{:.3},{:.4},{:.4},{:.4}\n", i as f64 * 0.02, m.x, m.y, m.z);
    }
    std::fs::write(path, text).expect("writable");
    path.display().to_string()
}

#[test]
fn location_supplies_the_field_reference_and_checks_the_radius() {
    let location: imucal::geomag::Location = "46.05,14.51,295".parse().expect("location");
    let model = imucal::geomag::local_field_today(&location).expect("date within the model");
    let dir = scratch("location");
    let path = write_mag_sphere(&dir.join("sphere.csv"), model.total_ut);
    let (ok, stdout, stderr) = imucal(&["fit", &path, "--location", "46.05,14.51,295", "--json"]);
    assert!(ok, "{stderr}");
    let mag = &json(&stdout)["mag"];
    // The reference is the model's field exactly (passed through, not re-estimated).
    let reference = mag["reference"].as_f64().expect("reference");
    assert!((reference - model.total_ut).abs() < 1e-9, "{reference}");
    assert_eq!(mag["output_unit"], "µT");
    // Readings on a sphere of the model's radius with 0.2 µT noise: the fitted radius is within
    // 0.1 % of it (noise/√2000 is 0.005 µT; the radial bias of isotropic noise σ²/r is 1e-3 µT).
    let deviation = mag["radius_check"]["deviation_pct"]
        .as_f64()
        .expect("deviation");
    assert!(deviation.abs() < 0.1, "deviation {deviation} %");
    assert_eq!(mag["radius_check"]["plausible"], true);

    // A sensor reading 1.5× the field (e.g. wrong unit): the check says so, the fit still runs.
    let path = write_mag_sphere(&dir.join("strong.csv"), 1.5 * model.total_ut);
    let (ok, stdout, stderr) = imucal(&["fit", &path, "--location", "46.05,14.51"]);
    assert!(ok, "{stderr}");
    assert!(
        stdout.contains("+50 %: check the magnetometer unit"),
        "{stdout}"
    );

    // --field-ut wins over the model; the radius is still checked against the model.
    let (ok, stdout, stderr) = imucal(&[
        "fit",
        &path,
        "--location",
        "46.05,14.51",
        "--field-ut",
        "70",
        "--json",
    ]);
    assert!(ok, "{stderr}");
    let mag = &json(&stdout)["mag"];
    assert_eq!(mag["reference"].as_f64(), Some(70.0));
    assert_eq!(mag["radius_check"]["plausible"], false);

    let (ok, _, stderr) = imucal(&["fit", &path, "--location", "95,14"]);
    assert!(!ok);
    assert!(stderr.contains("latitude 95° is outside"), "{stderr}");
}

#[test]
fn still_names_the_unit_problem_that_fit_refuses_the_sensor_for() {
    // Raw counts read as m/s² and rad/s: `fit` refuses both sensors, `still` lists the holds
    // and says the same.
    let path = real("tsi_mpu6050_multipos.csv");
    let (fit_ok, _, fit_err) = imucal(&["fit", &path]);
    assert!(!fit_ok);
    let (ok, stdout, stderr) = imucal(&["still", &path]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("still intervals detected"), "{stdout}");
    for phrase in ["pass --accel-unit counts", "pass --gyro-unit counts"] {
        assert!(fit_err.contains(phrase), "fit: {fit_err}");
        assert!(stderr.contains(phrase), "still: {stderr}");
    }
    // With the right units there is nothing to say.
    let (_, _, stderr) = imucal(&[
        "still",
        &path,
        "--accel-unit",
        "counts",
        "--gyro-unit",
        "counts",
    ]);
    assert!(!stderr.contains("refuse the sensor"), "{stderr}");
}

#[test]
fn a_parameter_file_names_the_methods_and_units_of_the_sensors_it_holds_only() {
    let path = real("tsi_mpu6050_multipos.csv");
    let out = scratch("provenance").join("params.json");
    let _ = std::fs::remove_file(&out);
    let out_text = out.display().to_string();
    let (_, _, stderr) = imucal(&[
        "fit",
        &path,
        "--accel-unit",
        "counts",
        "--gyro-unit",
        "counts",
        "--no-history",
        "--params-out",
        &out_text,
    ]);
    let file = json(&std::fs::read_to_string(&out).unwrap_or_else(|e| panic!("{e}: {stderr}")));
    let not_fitted = file["not_fitted"].as_object().expect("not_fitted");
    assert!(not_fitted.contains_key("gyro"), "{file}");
    let provenance = &file["provenance"];
    for key in ["methods", "input_units"] {
        let listed = provenance[key].as_object().expect("a map");
        assert!(listed.contains_key("accel"), "{provenance}");
        for left_out in not_fitted.keys() {
            assert!(
                !listed.contains_key(left_out),
                "{key} names {left_out}: {provenance}"
            );
        }
    }
}

#[test]
fn a_gyroscope_bias_from_a_single_hold_says_nothing_was_held_out() {
    // One 20 s hold at 100 Hz: the bias is that hold's mean and its residual is zero by
    // construction, which must not read as a clean bill of health.
    let dir = scratch("one-hold");
    let path = dir.join("one_hold.csv");
    let mut rng = rand::rngs::StdRng::seed_from_u64(17);
    let noise = Normal::new(0.0, 0.05).expect("valid normal");
    let mut text = String::from("t_s,ax,ay,az,gx,gy,gz\n");
    for i in 0..2000 {
        let g = [0.4, -0.2, 0.1].map(|b: f64| b + noise.sample(&mut rng));
        text.push_str(&format!(
            "{:.2},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5}\n",
            i as f64 * 0.01,
            0.002 * noise.sample(&mut rng),
            0.002 * noise.sample(&mut rng),
            1.0 + 0.002 * noise.sample(&mut rng),
            g[0],
            g[1],
            g[2]
        ));
    }
    std::fs::write(&path, text).expect("recording written");
    let path = path.display().to_string();
    let (_, out, err) = imucal(&[
        "fit",
        &path,
        "--accel-unit",
        "g",
        "--gyro-unit",
        "dps",
        "--sensor",
        "gyro",
    ]);
    assert!(
        out.contains("one hold: the bias is its mean"),
        "{out}\n{err}"
    );
    assert!(!out.contains("verdict: fitted\n"), "{out}");
    let _ = std::fs::remove_dir_all(&dir);
}
