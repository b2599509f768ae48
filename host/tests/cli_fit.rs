//! The `imucal fit` command end to end: on a synthetic recording with known calibration (written
//! by the test), on a copied real recording, and on bad input.

use std::path::{Path, PathBuf};
use std::process::Command;

use imucal::fit::validate::face_directions;
use imucal::fit::{Mat3, Vec3};
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
    let dir = std::env::temp_dir().join(format!("imucal-cli-{}-{name}", std::process::id()));
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

/// `A` as printed by `fit --json`: three rows, the parameter file's layout.
fn matrix(v: &Value) -> Mat3 {
    let e: Vec<f64> = v
        .as_array()
        .expect("rows")
        .iter()
        .flat_map(|row| row.as_array().expect("row of 3").clone())
        .map(|x| x.as_f64().expect("number"))
        .collect();
    Mat3::from_row_slice(&e)
}

fn vector(v: &Value) -> Vec3 {
    let e: Vec<f64> = v
        .as_array()
        .expect("array")
        .iter()
        .map(|x| x.as_f64().expect("number"))
        .collect();
    Vec3::from_row_slice(&e)
}

/// The accelerometer truth: counts → m/s², upper-triangular with positive diagonal (the gauge
/// of the norm-model fit), offsets of a few hundred counts.
fn accel_truth() -> (Mat3, Vec3) {
    let a = Mat3::new(
        1.0 / 1640.0,
        2.0e-6,
        -1.5e-6,
        0.0,
        1.0 / 1655.0,
        3.0e-6,
        0.0,
        0.0,
        1.0 / 1620.0,
    ) * 1.0;
    (a, Vec3::new(120.0, -340.0, 75.0))
}

/// A CSV with 14 still holds (2 s at 100 Hz) in distinct directions joined by 1 s of motion;
/// accelerometer in counts, gyroscope in rad/s with a constant bias.
fn write_synthetic_imu(path: &Path, sigma_counts: f64, sigma_gyro: f64, gyro_bias: Vec3) {
    let (a, b) = accel_truth();
    let a_inv = a.try_inverse().expect("invertible truth");
    let mut rng = rand::rngs::StdRng::seed_from_u64(42);
    let na = Normal::new(0.0, sigma_counts).expect("sigma");
    let ng = Normal::new(0.0, sigma_gyro).expect("sigma");
    let mut dirs: Vec<Vec3> = face_directions().to_vec();
    for s in [-1.0, 1.0] {
        for t in [-1.0, 1.0] {
            dirs.push(Vec3::new(s, t, 1.0).normalize());
            dirs.push(Vec3::new(t, 1.0, s).normalize());
        }
    }
    let mut text = String::from("t_s,ax,ay,az,gx,gy,gz\n");
    let mut t = 0.0;
    for k in 0..dirs.len() {
        let raw = a_inv * (dirs[k] * G) + b;
        for _ in 0..200 {
            let x = raw + Vec3::from_fn(|_, _| na.sample(&mut rng));
            let w = gyro_bias + Vec3::from_fn(|_, _| ng.sample(&mut rng));
            text += &format!(
                "{t:.2},{:.3},{:.3},{:.3},{:.6},{:.6},{:.6}\n",
                x.x, x.y, x.z, w.x, w.y, w.z
            );
            t += 0.01;
        }
        let next = dirs[(k + 1) % dirs.len()];
        for i in 0..100 {
            let s = i as f64 / 100.0;
            let d = (dirs[k] * (1.0 - s)
                + next * s
                + Vec3::new(0.3, -0.2, 0.25) * (s * std::f64::consts::PI).sin())
            .normalize();
            let x = a_inv * (d * G) + b + Vec3::from_fn(|_, _| rng.gen_range(-40.0..40.0));
            let w =
                gyro_bias + Vec3::new(0.8, -0.5, 0.6) + Vec3::from_fn(|_, _| ng.sample(&mut rng));
            text += &format!(
                "{t:.2},{:.3},{:.3},{:.3},{:.6},{:.6},{:.6}\n",
                x.x, x.y, x.z, w.x, w.y, w.z
            );
            t += 0.01;
        }
    }
    std::fs::write(path, text).expect("temporary file is writable");
}

#[test]
fn synthetic_accelerometer_and_gyroscope_recover_the_truth_within_their_stated_uncertainty() {
    let dir = scratch("synthetic");
    let path = dir.join("imu.csv");
    let gyro_bias = Vec3::new(0.012, -0.034, 0.005);
    let (sigma_counts, sigma_gyro) = (4.0, 0.003);
    write_synthetic_imu(&path, sigma_counts, sigma_gyro, gyro_bias);
    let path = path.display().to_string();
    let (ok, stdout, stderr) = imucal(&["fit", &path, "--accel-unit", "counts", "--json"]);
    assert!(ok, "{stderr}");
    let json: Value = serde_json::from_str(&stdout).expect("valid JSON");

    let accel = &json["accel"];
    assert_eq!(accel["method"], "lm");
    assert_eq!(accel["n_poses"], 14, "{stdout}");
    let (a_true, b_true) = accel_truth();
    let (a, b) = (matrix(&accel["A"]), vector(&accel["b"]));
    let (a_std, b_std) = (
        matrix(&accel["param_std"]["A"]),
        vector(&accel["param_std"]["b"]),
    );
    // Each estimate within 5 of its own stated standard deviations (a 6e-7 two-sided chance per
    // entry if the uncertainty is right) plus a floor for entries fixed by the gauge.
    for k in 0..3 {
        assert!(
            (b[k] - b_true[k]).abs() <= 5.0 * b_std[k] + 1e-9,
            "b[{k}] {} vs {} ± {}",
            b[k],
            b_true[k],
            b_std[k]
        );
        // The stated σ of b must itself match the noise: pose means of 200 samples with σ = 4
        // counts have standard error 0.28 counts; 14 poses spread it over 3 offsets, so σ_b is
        // of that order (between 0.05 and 1 count).
        assert!(b_std[k] > 0.05 && b_std[k] < 1.0, "σ_b[{k}] = {}", b_std[k]);
    }
    for r in 0..3 {
        for c in r..3 {
            let tol = 5.0 * a_std[(r, c)] + 1e-12;
            assert!(
                (a[(r, c)] - a_true[(r, c)]).abs() <= tol,
                "A[{r}{c}] {} vs {}",
                a[(r, c)],
                a_true[(r, c)]
            );
        }
    }
    // Relative residual: the noise of a pose mean (4/√200 = 0.28 counts) over the radius
    // (~1600 counts) is 1.8e-4; with 9 of 14 degrees of freedom used the RMS is below that.
    let rms = accel["rms"].as_f64().expect("rms");
    assert!(rms < 3.0e-4, "rms {rms}");
    assert!(accel["loo_rms"].as_f64().expect("loo") >= rms);

    let gyro = &json["gyro"];
    assert_eq!(gyro["method"], "gyro-bias");
    let gb = vector(&gyro["b"]);
    // 14 holds of ≥ 150 still samples each: standard error σ/√2100 = 6.5e-5 rad/s; 5 of them.
    for k in 0..3 {
        assert!(
            (gb[k] - gyro_bias[k]).abs() < 5.0 * sigma_gyro / 2100f64.sqrt(),
            "gyro b[{k}] {}",
            gb[k]
        );
    }
    assert!(
        json.get("mag").is_none(),
        "no magnetometer columns, no mag entry"
    );
}

#[test]
fn synthetic_magnetometer_in_counts_is_fitted_to_the_given_field() {
    let dir = scratch("mag");
    let path = dir.join("mag.csv");
    let a_true = Mat3::new(0.16, 0.004, -0.002, 0.0, 0.15, 0.003, 0.0, 0.0, 0.17); // counts → µT
    let b_true = Vec3::new(210.0, -95.0, 40.0);
    let field = 48.0;
    let sigma = 1.5; // counts
    let a_inv = a_true.try_inverse().expect("invertible");
    let mut rng = rand::rngs::StdRng::seed_from_u64(9);
    let noise = Normal::new(0.0, sigma).expect("sigma");
    let mut text = String::from("t_s,mx,my,mz\n");
    for i in 0..3000 {
        let u: [f64; 3] = UnitSphere.sample(&mut rng);
        let m =
            a_inv * (Vec3::from(u) * field) + b_true + Vec3::from_fn(|_, _| noise.sample(&mut rng));
        text += &format!("{:.3},{:.3},{:.3},{:.3}\n", i as f64 * 0.02, m.x, m.y, m.z);
    }
    std::fs::write(&path, text).expect("writable");
    let path = path.display().to_string();
    let (ok, stdout, stderr) = imucal(&[
        "fit",
        &path,
        "--mag-unit",
        "counts",
        "--field-ut",
        "48",
        "--json",
    ]);
    assert!(ok, "{stderr}");
    let mag = &serde_json::from_str::<Value>(&stdout).expect("valid JSON")["mag"];
    assert_eq!(mag["n_samples"], 3000, "every sample is fitted by default");
    let b = vector(&mag["b"]);
    // 3000 samples of σ = 1.5 counts on a ~300-count radius: σ_b ≈ 1.5·√(3/3000) ≈ 0.05 counts;
    // allow 0.5 counts (8 σ) as the stated σ is checked separately.
    for k in 0..3 {
        assert!(
            (b[k] - b_true[k]).abs() < 0.5,
            "b[{k}] {} vs {}",
            b[k],
            b_true[k]
        );
    }
    // Relative residual = σ·|A|/H ≈ 1.5·0.16/48 = 5e-3.
    let rms = mag["rms"].as_f64().expect("rms");
    assert!((rms / 5.0e-3 - 1.0).abs() < 0.2, "rms {rms}");
}

#[test]
fn xsens_recording_in_counts_fits_offsets_near_the_per_axis_reference() {
    let (ok, stdout, stderr) = imucal(&[
        "fit",
        &real("imutk_xsens_multipos.csv"),
        "--accel-unit",
        "counts",
        "--gyro-unit",
        "counts",
        "--sensor",
        "accel",
        "--json",
    ]);
    assert!(ok, "{stderr}");
    let accel = &serde_json::from_str::<Value>(&stdout).expect("valid JSON")["accel"];
    assert_eq!(accel["method"], "lm");
    assert!((36..=40).contains(&accel["n_poses"].as_u64().expect("count")));
    // The provenance note's per-axis fit (no cross-axis terms) puts the offsets at
    // 32768 + [354.35, 510.24, −396.56] counts. The cross-axis terms of this fit (up to 2% here)
    // move them by a few counts; 10 counts is 0.25% of the ~4000-count radius.
    let b = vector(&accel["b"]);
    for (k, want) in [354.35, 510.24, -396.56].into_iter().enumerate() {
        assert!(
            (b[k] - 32768.0 - want).abs() < 10.0,
            "b[{k}] {} vs {want}",
            b[k] - 32768.0
        );
    }
    // Scale: ~414 counts per m/s² on each axis in the note, so A diagonal ≈ 1/414 within 1%.
    let a = matrix(&accel["A"]);
    for k in 0..3 {
        assert!(
            (a[(k, k)] * 414.0 - 1.0).abs() < 0.01,
            "A[{k}{k}] {}",
            a[(k, k)]
        );
    }
    // With 38 holds the held-out error is close to the fit error: the model is not overfitted.
    let (rms, loo) = (
        accel["rms"].as_f64().expect("rms"),
        accel["loo_rms"].as_f64().expect("loo"),
    );
    assert!(rms < 3.0e-4 && loo < 2.0 * rms, "rms {rms}, loo {loo}");
    // The solver says why it stopped, and it is one of the convergence tests.
    let termination = accel["termination"].as_str().expect("termination");
    assert!(
        [
            "exact_fit",
            "cost_converged",
            "step_converged",
            "cost_and_step_converged",
            "gradient_converged"
        ]
        .contains(&termination),
        "{termination}"
    );
}

#[test]
fn six_face_recording_gets_the_model_with_the_best_held_out_error_and_says_why() {
    let (ok, stdout, stderr) = imucal(&[
        "fit",
        &real("imucal_nilspod_ferraris.csv"),
        "--gyro-unit",
        "dps",
        "--sensor",
        "accel",
        "--json",
    ]);
    assert!(ok, "{stderr}");
    let accel = &serde_json::from_str::<Value>(&stdout).expect("valid JSON")["accel"];
    // Six faces: lm is refused (6 directions for 9 unknowns); six-position's 6 extra unknowns
    // predict held-out holds worse; a paired t test does not tell min/max and the axis-aligned
    // ellipsoid (6 unknowns each) apart, and their mean is within one standard error of the
    // best, so the mean is used.
    assert_eq!(accel["method"], "minmax+axis-aligned");
    let chain = &accel["default_chain"];
    assert_eq!(chain["chosen"], "minmax+axis-aligned");
    let p = chain["pair_test"]["p_value"]
        .as_f64()
        .expect("paired test reported");
    assert!((0.05..=1.0).contains(&p), "p = {p}");
    let note = accel["note"].as_str().expect("note");
    assert!(
        note.contains("lm: refused")
            && note.contains("six-position: held-out error")
            && note.contains("paired t test")
            && note.contains("cannot tell them apart"),
        "{note}"
    );
    assert_eq!(accel["n_poses"], 13);
    // Offsets of the provenance note's per-axis fit of the six faces: [0.537, −0.616, 0.399]
    // m/s²; the same model on the same holds, up to hold detection (0.005 m/s² ≈ 0.5 mg).
    let b = vector(&accel["b"]);
    for (k, want) in [0.53667, -0.61626, 0.39856].into_iter().enumerate() {
        assert!((b[k] - want).abs() < 0.005, "b[{k}] {} vs {want}", b[k]);
    }
    // Norm residual of a six-face fit: table tilt and temperature leave ~1e-3 of g.
    assert!(accel["rms"].as_f64().expect("rms") < 2.0e-3);
}

#[test]
fn table_output_names_method_uncertainty_and_verdict() {
    let (ok, stdout, stderr) = imucal(&[
        "fit",
        &real("imucal_nilspod_ferraris.csv"),
        "--gyro-unit",
        "dps",
    ]);
    assert!(ok, "{stderr}");
    for needle in [
        "accel — method minmax+axis-aligned",
        "gyro — method gyro-bias",
        "±",
        "leave-one-out RMS",
        "verdict:",
    ] {
        assert!(stdout.contains(needle), "missing `{needle}` in\n{stdout}");
    }
}

#[test]
fn errors_are_sentences_with_a_failing_exit_code() {
    let (ok, _, stderr) = imucal(&["fit", "/nonexistent/rec.csv"]);
    assert!(!ok);
    assert!(
        stderr.contains("cannot read `/nonexistent/rec.csv`"),
        "{stderr}"
    );

    let dir = scratch("errors");
    let bad = dir.join("bad.csv");
    std::fs::write(&bad, "t_s,ax,ay,az\n0,1,2,3\n0.01,1,x,3\n").expect("writable");
    let (ok, _, stderr) = imucal(&["fit", &bad.display().to_string()]);
    assert!(!ok);
    assert!(
        stderr.contains("line 3, column `ay`: `x` is not a finite number"),
        "{stderr}"
    );

    let (ok, _, stderr) = imucal(&[
        "fit",
        &real("tsm_qmc5883l_mag_rotation.csv"),
        "--method",
        "six-position",
        "--sensor",
        "mag",
    ]);
    assert!(!ok);
    assert!(stderr.contains("does not apply to the mag"), "{stderr}");

    let (ok, _, stderr) = imucal(&[
        "fit",
        &real("tsm_qmc5883l_mag_rotation.csv"),
        "--sensor",
        "accel",
    ]);
    assert!(!ok);
    assert!(stderr.contains("has no accel data"), "{stderr}");
}

#[test]
fn still_on_a_magnetometer_only_recording_lists_the_field_means() {
    let (ok, stdout, stderr) = imucal(&["still", &real("tsm_qmc5883l_mag_rotation.csv")]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("mag mean ("), "{stdout}");
    assert!(!stdout.contains("accel mean"), "{stdout}");
    // Every hold row shows a mean triple, not "-".
    let rows: Vec<&str> = stdout.lines().filter(|l| l.contains(" [")).collect();
    assert!(rows.len() >= 10, "{stdout}");
}

#[test]
fn help_of_every_command_has_an_example() {
    for command in ["fit", "still"] {
        let (ok, stdout, _) = imucal(&[command, "--help"]);
        assert!(ok);
        assert!(stdout.contains("Example"), "{command} --help:\n{stdout}");
    }
}

#[test]
fn a_method_given_without_sensor_is_fitted_to_the_sensors_it_is_a_method_for() {
    // NilsPod: accelerometer and gyroscope; six-position is an accelerometer method.
    let nilspod = real("imucal_nilspod_ferraris.csv");
    let (ok, stdout, stderr) = imucal(&[
        "fit",
        &nilspod,
        "--gyro-unit",
        "dps",
        "--method",
        "six-position",
        "--json",
    ]);
    assert!(ok, "{stderr}");
    let json: Value = serde_json::from_str(&stdout).expect("JSON");
    assert_eq!(json["accel"]["method"], "six-position", "{stdout}");
    assert_eq!(json["gyro"]["method"], "gyro-bias", "{stdout}");
    assert!(
        stderr.contains("--method six-position is fitted to the accel; the gyro keeps the default"),
        "{stderr}"
    );
    // Named with --sensor, the gyroscope must take the method asked for.
    let (ok, _, stderr) = imucal(&[
        "fit",
        &nilspod,
        "--gyro-unit",
        "dps",
        "--method",
        "six-position",
        "--sensor",
        "gyro",
    ]);
    assert!(!ok);
    assert!(stderr.contains("does not apply to the gyro"), "{stderr}");
}

#[test]
fn still_lists_the_holds_fit_uses_with_the_same_screening_and_label_names() {
    // The NilsPod session with its segment column read as poses: some labelled rows span a
    // move, and both commands leave those holds out alike.
    let text = std::fs::read_to_string(real("imucal_nilspod_ferraris.csv")).expect("reads");
    let (header, rows) = text.split_once('\n').expect("a header");
    let dir = scratch("posecol");
    let path = dir.join("posecol.csv");
    std::fs::write(
        &path,
        format!("{}\n{rows}", header.replace("segment", "pose")),
    )
    .expect("writable");
    let path = path.display().to_string();
    let (ok, stdout, stderr) = imucal(&["still", &path, "--gyro-unit", "dps", "--json"]);
    assert!(ok, "{stderr}");
    let still: Value = serde_json::from_str(&stdout).expect("JSON");
    let intervals = still["intervals"].as_array().expect("intervals");
    let (ok, stdout, stderr) = imucal(&["fit", &path, "--gyro-unit", "dps", "--json"]);
    assert!(ok, "{stderr}");
    let fit: Value = serde_json::from_str(&stdout).expect("JSON");
    assert_eq!(
        fit["gyro"]["n_poses"].as_u64(),
        Some(intervals.len() as u64),
        "{stdout}"
    );
    assert!(
        intervals
            .iter()
            .all(|i| i["label_name"].as_str().is_some_and(|n| n.contains('_'))),
        "{intervals:?}"
    );
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn a_still_detection_flag_out_of_range_is_a_usage_error_naming_the_flag() {
    let nilspod = real("imucal_nilspod_ferraris.csv");
    for (flag, value) in [
        ("--window", "0"),
        ("--min-hold", "-1"),
        ("--still-margin", "0.5"),
        ("--direction-angle", "nan"),
    ] {
        let given = format!("{flag}={value}");
        let (ok, _, stderr) = imucal(&["fit", &nilspod, "--gyro-unit", "dps", &given]);
        assert!(!ok, "{flag} {value}");
        assert!(stderr.contains(&format!("for '{flag} ")), "{stderr}");
    }
}

#[test]
fn a_rate_no_sensor_samples_at_is_a_usage_error_with_exit_status_2() {
    let nilspod = real("imucal_nilspod_ferraris.csv");
    for command in ["fit", "still", "analyze"] {
        for rate in ["0", "-100", "inf", "1e-300", "1e12"] {
            let given = format!("--rate={rate}");
            let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
                .args([command, &nilspod, "--gyro-unit", "dps", &given])
                .output()
                .expect("binary runs");
            let stderr = String::from_utf8_lossy(&out.stderr);
            assert_eq!(out.status.code(), Some(2), "{command} {given}: {stderr}");
            assert!(stderr.contains("for '--rate "), "{stderr}");
        }
    }
}

#[test]
fn still_says_what_fit_refuses_a_sensor_for_and_lists_the_holds_all_the_same() {
    let dir = scratch("still-one-pose");
    let path = dir.join("one_pose.csv");
    // Five seconds lying flat: one hold, one gravity direction.
    let mut rng = rand::rngs::StdRng::seed_from_u64(11);
    let noise = Normal::new(0.0, 0.01).expect("valid");
    let mut text = String::from("t_s,ax,ay,az,gx,gy,gz\n");
    for i in 0..500 {
        let mut value = |mean: f64, scale: f64| mean + scale * noise.sample(&mut rng);
        text.push_str(&format!(
            "{:.2},{:.5},{:.5},{:.5},{:.6},{:.6},{:.6}\n",
            i as f64 * 0.01,
            value(0.0, 1.0),
            value(0.0, 1.0),
            value(9.81, 1.0),
            value(0.0, 0.1),
            value(0.0, 0.1),
            value(0.0, 0.1)
        ));
    }
    std::fs::write(&path, text).expect("written");
    let path = path.display().to_string();
    let (fit_ok, _, fit_err) = imucal(&["fit", &path]);
    assert!(
        !fit_ok && fit_err.contains("only 1 distinct gravity direction among 1 hold"),
        "{fit_err}"
    );
    let (ok, stdout, stderr) = imucal(&["still", &path]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("1 still interval detected"), "{stdout}");
    assert!(
        stderr.contains("only 1 distinct gravity direction among 1 hold")
            && stderr.contains("fit, analyze and report refuse the sensor for this"),
        "{stderr}"
    );
}

#[test]
fn a_negative_option_value_written_with_a_space_reaches_the_option_check() {
    let nilspod = real("imucal_nilspod_ferraris.csv");
    // `--min-hold -1` is the option's value, refused by its own range check, not an unknown
    // flag with a tip to write `-- -1` (which would pass `-1` as the recording's name).
    let (ok, _, stderr) = imucal(&["fit", &nilspod, "--gyro-unit", "dps", "--min-hold", "-1"]);
    assert!(!ok);
    assert!(
        stderr.contains("for '--min-hold ") && stderr.contains("not zero or a positive number"),
        "{stderr}"
    );
    assert!(!stderr.contains("-- -1"), "{stderr}");
    // A negative value where one makes sense is read as a number.
    let (_, _, stderr) = imucal(&["fit", &nilspod, "--gyro-unit", "dps", "--field-ut", "-3"]);
    assert!(stderr.contains("--field-ut -3 is outside"), "{stderr}");
    // Numbers clap does not take for negative (`-.5`, `-inf`) and a choice from a list reach
    // their own checks too.
    for (args, expected) in [
        (["--window", "-.5"], "-.5 is not a positive number"),
        (["--gravity", "-inf"], "--gravity -inf is outside"),
        (["--sensor", "-x"], "possible values: accel, gyro, mag, all"),
    ] {
        let mut all = vec!["fit", nilspod.as_str(), "--gyro-unit", "dps"];
        all.extend(args);
        let (ok, _, stderr) = imucal(&all);
        assert!(!ok, "{args:?}");
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
        assert!(!stderr.contains("use '-- "), "{args:?}: {stderr}");
    }
    // Counts and seeds say what they take, not the integer parser's "invalid digit".
    for (args, expected) in [
        (
            vec!["calibrate", "--sim", "--sim-seed", "-1"],
            "`-1` is not a whole number of 0 or more",
        ),
        (
            vec!["history", "--changes", "-2"],
            "`-2` is not a whole number of 0 or more",
        ),
        (
            vec!["fleet", "--min-spread-values", "99999999999999999999999"],
            "is larger than the largest value allowed",
        ),
    ] {
        let (ok, _, stderr) = imucal(&args);
        assert!(!ok, "{args:?}");
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
        assert!(!stderr.contains("invalid digit"), "{args:?}: {stderr}");
    }
}

#[test]
fn a_gyroscope_bias_from_one_wandering_hold_states_the_wander_in_its_uncertainty() {
    // Five minutes still at 100 Hz; the x bias random-walks (as a MEMS gyroscope's does over
    // minutes), y and z carry white noise only. σ/√n would claim the x bias to a tenth of what
    // its batch means show.
    let mut rng = rand::rngs::StdRng::seed_from_u64(21);
    let noise = Normal::new(0.0, 0.002).expect("σ > 0");
    let n = 30_000;
    let mut walk = 0.0;
    let mut csv = String::from("t_s,gx,gy,gz\n");
    for i in 0..n {
        walk += rng.gen_range(-1.5e-4..1.5e-4);
        let g = [
            0.01 + walk + noise.sample(&mut rng),
            -0.02 + noise.sample(&mut rng),
            0.005 + noise.sample(&mut rng),
        ];
        csv.push_str(&format!(
            "{:.2},{:.7},{:.7},{:.7}\n",
            i as f64 / 100.0,
            g[0],
            g[1],
            g[2]
        ));
    }
    let path = scratch("wandering_gyro").join("rec.csv");
    std::fs::write(&path, csv).expect("scratch file");
    let (ok, stdout, stderr) = imucal(&["fit", path.to_str().expect("utf-8"), "--json"]);
    assert!(ok, "{stderr}");
    let json: Value = serde_json::from_str(&stdout).expect("JSON");
    let std = vector(&json["gyro"]["param_std"]["b"]);
    // White noise: σ/√n = 0.002/√30000 ≈ 1.15e-5 rad/s (kept within the fit's ±20 %).
    let white = 0.002 / (n as f64).sqrt();
    for axis in [1, 2] {
        assert!((std[axis] / white - 1.0).abs() < 0.2, "{std:?}");
    }
    assert!(std[0] > 3.0 * white, "the wander is not in σ: {std:?}");
}
