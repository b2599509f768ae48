//! Options and paths every command treats alike: an option that would have no effect in the
//! session the others choose is refused before a board is opened, a session directory reads as
//! its recording, and a refusal names the option or path that causes it.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn imucal_in(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_imucal"))
        .current_dir(dir)
        .env("IMUCAL_DB", dir.join("history.sqlite"))
        .args(args)
        .output()
        .expect("the imucal binary runs")
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("imucal-coherence-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temporary directory");
    dir
}

fn real(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../data/real")
        .join(name)
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn calibrate_refuses_an_option_that_would_have_no_effect_before_any_board_starts() {
    let cases: [(&[&str], &str); 5] = [
        (&["--sim", "--sim-faulty", "2"], "--sim-boards"),
        (
            &["--sim-boards", "2", "--sim-protocol", "motioncal"],
            "a batch needs boards running imucal's firmware",
        ),
        (
            &["--sim", "--sketch-rate", "50"],
            "--sim-protocol motioncal",
        ),
        (
            &["--sim", "--no-history", "--db", "sqlite://x.sqlite"],
            "--db",
        ),
        (&["--sim", "--rounds", "0"], "--rounds"),
    ];
    for (options, named) in cases {
        let dir = scratch("calibrate");
        let out = imucal_in(&dir, &[&["calibrate", "--yes"], options].concat());
        let message = stderr(&out);
        assert!(!out.status.success(), "{options:?} was accepted: {message}");
        assert!(message.contains(named), "{options:?}: {message}");
        // Refused before the simulated board started: no session directory was begun.
        let left: Vec<_> = std::fs::read_dir(&dir)
            .expect("the scratch directory")
            .flatten()
            .map(|e| e.file_name())
            .collect();
        assert!(left.is_empty(), "{options:?} left {left:?}");
    }
}

#[test]
fn fit_and_still_read_a_session_directory_as_its_recording() {
    let dir = scratch("session");
    let session = dir.join("imucal-session-1");
    std::fs::create_dir(&session).expect("session directory");
    let recording = real("imucal_nilspod_ferraris.csv");
    std::fs::copy(&recording, session.join("recording.csv")).expect("copy the recording");
    let session = session.display().to_string();
    let recording = recording.display().to_string();
    for command in ["fit", "still"] {
        let of_dir = imucal_in(&dir, &[command, &session, "--gyro-unit", "dps", "--json"]);
        let of_file = imucal_in(&dir, &[command, &recording, "--gyro-unit", "dps", "--json"]);
        assert!(of_dir.status.success(), "{command}: {}", stderr(&of_dir));
        assert_eq!(of_dir.stdout, of_file.stdout, "{command}");
    }
    let empty = dir.join("empty");
    std::fs::create_dir(&empty).expect("an empty directory");
    let out = imucal_in(&dir, &["fit", &empty.display().to_string()]);
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("is a directory without a recording.csv"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn fit_and_still_on_a_session_without_its_recording_point_to_analyze_and_report() {
    let dir = scratch("pose-session");
    // What `calibrate` leaves: the poses it averaged and its parameters, no recording.
    let session = dir.join("S");
    std::fs::create_dir(&session).expect("session directory");
    std::fs::write(session.join("poses.json"), "[]").expect("poses");
    std::fs::write(session.join("params.json"), "{}").expect("params");
    for command in ["fit", "still"] {
        let out = imucal_in(&dir, &[command, "S"]);
        let message = stderr(&out);
        assert!(!out.status.success(), "{command}: {message}");
        assert!(
            message.contains("`S` is a session directory of `imucal calibrate`")
                && message.contains("no recording (recording.csv)")
                && message.contains("`imucal analyze S`")
                && message.contains("`imucal report S`"),
            "{command}: {message}"
        );
        assert!(
            !message.contains("pass a recording file, or a session"),
            "{message}"
        );
    }
}

#[test]
fn an_option_value_or_combination_the_command_cannot_take_exits_with_the_usage_status() {
    let dir = scratch("usage");
    let recording = real("imucal_nilspod_ferraris.csv").display().to_string();
    for (options, named) in [
        (
            &["--method", "bogus"][..],
            "unknown method `bogus`; choose one of",
        ),
        (&["--gravity", "0"], "--gravity 0 is outside 9.7–9.9 m/s²"),
        (&["--field-ut", "-5"], "--field-ut -5 is outside 1–5000 µT"),
        (&["--gyro-scale", "-1"], "--gyro-scale -1 is outside"),
        (
            &["--sensor", "gyro", "--method", "chen"],
            "method `chen` does not apply to the gyro",
        ),
    ] {
        let out = imucal_in(
            &dir,
            &[&["fit", &recording, "--gyro-unit", "dps"], options].concat(),
        );
        let message = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{options:?}: {message}");
        assert!(message.contains(named), "{options:?}: {message}");
    }
    // Said before the recording is read: a missing file does not hide it.
    let out = imucal_in(
        &dir,
        &[
            "fit",
            "none.csv",
            "--sensor",
            "mag",
            "--method",
            "six-position",
        ],
    );
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("does not apply to the mag"),
        "{}",
        stderr(&out)
    );
    let out = imucal_in(&dir, &["calibrate", "--sim", "--yes", "--sim-faulty", "2"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    // Session values checked as they are parsed, before a board is opened.
    for (options, named) in [
        (&["--hold", "-1"][..], "--hold"),
        (&["--speed", "0"], "--speed"),
        (&["--pose-timeout", "0"], "--pose-timeout"),
        (&["--sim-temperature", "bogus"], "sweep:10:40:90"),
        (
            &["--sim-protocol", "motioncal", "--sketch-rate", "50"],
            "the simulated sketch prints 100 readings/s",
        ),
    ] {
        let out = imucal_in(
            &dir,
            &[&["calibrate", "--sim", "--yes"][..], options].concat(),
        );
        let message = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{options:?}: {message}");
        assert!(message.contains(named), "{options:?}: {message}");
    }
    // The binary MotionCal packet needs a file to go to.
    let params = dir.join("p.json").display().to_string();
    let fitted = imucal_in(
        &dir,
        &[
            "fit",
            &recording,
            "--gyro-unit",
            "dps",
            "--params-out",
            &params,
            "--no-history",
        ],
    );
    assert!(fitted.status.success(), "{}", stderr(&fitted));
    let out = imucal_in(&dir, &["export", &params, "--format", "motioncal"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(stderr(&out).contains("-o cal.bin"), "{}", stderr(&out));
}

#[test]
fn a_direction_angle_of_90_degrees_or_more_is_refused_with_its_range() {
    let dir = scratch("direction-angle");
    let recording = real("imucal_nilspod_ferraris.csv").display().to_string();
    // The angle is compared through its cosine: 400° used to act as 40°.
    for command in ["fit", "still"] {
        for angle in ["400", "90", "-10"] {
            let out = imucal_in(
                &dir,
                &[
                    command,
                    &recording,
                    "--gyro-unit",
                    "dps",
                    "--direction-angle",
                    angle,
                ],
            );
            let message = stderr(&out);
            assert_eq!(out.status.code(), Some(2), "{command} {angle}: {message}");
            assert!(
                message.contains("more than 0 and less than 90"),
                "{command} {angle}: {message}"
            );
        }
    }
    let out = imucal_in(
        &dir,
        &[
            "still",
            &recording,
            "--gyro-unit",
            "dps",
            "--direction-angle",
            "45",
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
}

#[test]
fn an_input_option_the_recording_makes_moot_is_said_to_be_ignored() {
    let dir = scratch("moot");
    let recording = real("imucal_nilspod_ferraris.csv").display().to_string();
    let accel_only = "--columns=t_s=t_s,ax=ax,ay=ay,az=az";
    let cases: [(&[&str], &str); 4] = [
        (
            &[
                "fit",
                "--gyro-unit",
                "dps",
                "--gyro-scale",
                "0.001",
                "--sensor",
                "accel",
            ],
            "--gyro-scale 0.001 is ignored: it converts counts to rad/s, and the gyroscope \
             data are in °/s",
        ),
        (
            &["still", "--gyro-unit", "dps", "--imutk-time-unit", "ms"],
            "--imutk-time-unit ms is ignored",
        ),
        (
            &["fit", accel_only, "--gyro-unit", "dps"],
            "--gyro-unit dps is ignored: --columns maps no gyro columns",
        ),
        (
            &["still", "--gyro-unit", "dps", "--mag-unit", "gauss"],
            "--mag-unit gauss is ignored: `",
        ),
    ];
    for (options, expected) in cases {
        let args = [&options[..1], &[recording.as_str()], &options[1..]].concat();
        let out = imucal_in(&dir, &args);
        let message = stderr(&out);
        assert!(out.status.success(), "{args:?}: {message}");
        assert!(message.contains(expected), "{args:?}: {message}");
    }
    // Where the option acts, nothing is said: IMU-TK text with its time unit, and units of
    // sensors the recording has.
    let imutk = dir.join("accel.txt");
    let rows: String = (0..400)
        .map(|i| format!("{} 0.01 0.02 9.81\n", i * 10))
        .collect();
    std::fs::write(&imutk, rows).expect("an IMU-TK file");
    let out = imucal_in(
        &dir,
        &[
            "still",
            &imutk.display().to_string(),
            "--imutk-time-unit",
            "ms",
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(!stderr(&out).contains("is ignored"), "{}", stderr(&out));
    let out = imucal_in(
        &dir,
        &[
            "still",
            &recording,
            "--gyro-unit",
            "dps",
            "--accel-unit",
            "mps2",
        ],
    );
    assert!(!stderr(&out).contains("is ignored"), "{}", stderr(&out));
}

#[test]
fn report_refuses_a_report_directory_saying_what_it_is() {
    let dir = scratch("report");
    let recording = real("imucal_nilspod_ferraris.csv").display().to_string();
    let first = imucal_in(
        &dir,
        &["report", &recording, "--gyro-unit", "dps", "-o", "rep"],
    );
    assert!(first.status.success(), "{}", stderr(&first));
    let out = imucal_in(&dir, &["report", "rep"]);
    assert!(!out.status.success());
    let message = stderr(&out);
    assert!(message.contains("is not a session directory"), "{message}");
    assert!(message.contains("output of `imucal report`"), "{message}");
}

#[test]
fn a_stillness_window_longer_than_the_recording_is_named_as_the_cause() {
    let dir = scratch("window");
    let recording = real("imucal_nilspod_ferraris.csv").display().to_string();
    let out = imucal_in(
        &dir,
        &["fit", &recording, "--gyro-unit", "dps", "--window", "1e9"],
    );
    let message = stderr(&out);
    assert!(!out.status.success());
    assert!(
        message.contains("--window 1000000000 s) is longer than the whole recording"),
        "{message}"
    );
    assert!(!message.contains("--min-hold"), "{message}");
}

#[test]
fn a_report_with_nothing_fitted_names_why_each_sensor_was_not() {
    let dir = scratch("nothing");
    let mut csv = String::from("t_s,ax,ay,az,gx,gy,gz\n");
    for i in 0..1000 {
        csv.push_str(&format!(
            "{:.2},0.1,0.2,9.8,0.5,-0.25,0.125\n",
            f64::from(i) / 100.0
        ));
    }
    let path = dir.join("stuck.csv");
    std::fs::write(&path, csv).expect("write the recording");
    let out = imucal_in(&dir, &["report", &path.display().to_string(), "-o", "rep"]);
    let message = stderr(&out);
    assert!(!out.status.success());
    assert!(
        message.contains("no accelerometer or gyroscope poses"),
        "{message}"
    );
    assert!(
        message.contains("accel reads (0.1, 0.2, 9.8)")
            && message.contains("gyro reads (0.5, -0.25, 0.125)"),
        "{message}"
    );
}

#[test]
fn a_session_directorys_magnetometer_file_is_an_input_no_output_may_replace() {
    let dir = scratch("mag-input");
    let session = dir.join("session");
    std::fs::create_dir(&session).expect("session directory");
    std::fs::copy(
        real("sf_mpu6050_hmc5883l_full_sphere.csv"),
        session.join("recording.csv"),
    )
    .expect("copy the recording");
    let mag = session.join("recording_mag.csv");
    std::fs::copy(real("sf_mpu6050_hmc5883l_full_sphere_mag.csv"), &mag)
        .expect("copy its magnetometer file");
    let before = std::fs::read(&mag).expect("the magnetometer file");
    let out = imucal_in(
        &dir,
        &[
            "fit",
            "session",
            "--sensor",
            "mag",
            "--mag-unit",
            "gauss",
            "--params-out",
            "session/recording_mag.csv",
            "--force",
        ],
    );
    assert!(!out.status.success(), "the input was replaced");
    assert!(
        stderr(&out).contains("is also the input"),
        "{}",
        stderr(&out)
    );
    assert_eq!(std::fs::read(&mag).expect("still there"), before);
}

#[test]
fn a_stillness_window_longer_than_the_holds_is_named_when_moves_pass_as_one_hold() {
    // tsi_mpu6050_multipos holds each face for a few seconds in raw counts (no gyroscope rest
    // bound applies): a 60 s window takes in a move in every window, so the whole recording
    // passes as one "hold" whose samples scatter over several faces.
    let dir = scratch("long-window");
    let csv = real("tsi_mpu6050_multipos.csv");
    let csv = csv.to_str().expect("UTF-8 path");
    let args = ["--accel-unit", "counts", "--gyro-unit", "counts"];
    let long = imucal_in(
        &dir,
        &[&["still", csv, "--window", "60"][..], &args[..]].concat(),
    );
    let err = stderr(&long);
    assert!(
        err.contains("it is not one pose") && err.contains("--window"),
        "{err}"
    );
    assert!(!err.contains("a knock during the hold"), "{err}");
    // With the default window the holds are real poses: no such sentence.
    let default = imucal_in(&dir, &[&["still", csv][..], &args[..]].concat());
    assert!(default.status.success(), "{}", stderr(&default));
    assert!(
        !stderr(&default).contains("not one pose"),
        "{}",
        stderr(&default)
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn resuming_a_finished_session_or_another_directory_is_refused_before_a_board_is_opened() {
    let dir = scratch("resume-finished");
    std::fs::create_dir_all(dir.join("done")).expect("session directory");
    std::fs::write(dir.join("done/summary.json"), "{}").expect("summary");
    std::fs::create_dir_all(dir.join("other")).expect("directory");
    for (target, expected) in [
        ("done", "is a finished session"),
        ("other", "holds no progress.json"),
    ] {
        let out = imucal_in(
            &dir,
            &[
                "calibrate",
                "--resume",
                target,
                "--sim",
                "--yes",
                "--no-history",
            ],
        );
        let text = stderr(&out);
        assert_eq!(out.status.code(), Some(1), "{text}");
        assert!(text.contains(expected), "{text}");
        assert!(
            !text.contains("Simulated board"),
            "a board was opened: {text}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn still_json_names_the_unit_of_its_means_and_noise() {
    let dir = scratch("still-units");
    let recording = real("imucal_nilspod_ferraris.csv").display().to_string();
    let out = imucal_in(&dir, &["still", &recording, "--gyro-unit", "dps", "--json"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    assert_eq!(json["units"]["accel_mean"], "m/s²", "{}", json["units"]);
    assert_eq!(json["units"]["gyro_mean"], "°/s", "{}", json["units"]);
    let noise = json["noise"].as_array().expect("noise");
    assert!(noise.iter().all(|n| n["unit"].is_string()), "{noise:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_stillness_window_or_margin_outside_what_the_detector_uses_is_said() {
    let dir = scratch("still-window");
    let recording = real("imucal_nilspod_ferraris.csv").display().to_string();
    let out = imucal_in(
        &dir,
        &[
            "still",
            &recording,
            "--gyro-unit",
            "dps",
            "--window",
            "0.001",
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("is shorter than 5 rows at 102.4 Hz"),
        "{}",
        stderr(&out)
    );
    let out = imucal_in(
        &dir,
        &[
            "still",
            &recording,
            "--gyro-unit",
            "dps",
            "--still-margin",
            "1e300",
        ],
    );
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("1e300 is not from 1 to 256"),
        "{}",
        stderr(&out)
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn analyze_and_report_go_on_with_the_sensors_fit_fits_when_one_is_refused() {
    let dir = scratch("per-sensor");
    // The gyroscope in counts read as rad/s: fit leaves it out and fits the accelerometer.
    let tsi = real("tsi_mpu6050_multipos.csv").display().to_string();
    let out = imucal_in(&dir, &["analyze", &tsi, "--accel-unit", "counts", "--json"]);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    assert!(
        json["sensors"]["accel"]["chi2_before"]["chi2"].is_number(),
        "{json}"
    );
    assert!(
        stderr(&out).contains("gyro not analysed: not fitted"),
        "{}",
        stderr(&out)
    );
    let out = imucal_in(
        &dir,
        &["report", &tsi, "--accel-unit", "counts", "-o", "rep"],
    );
    // Written, and failing as fit does, naming the sensor left out.
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("the report leaves out what was refused: gyro"),
        "{}",
        stderr(&out)
    );
    let page = std::fs::read_to_string(dir.join("rep/report.html")).expect("the report");
    assert!(
        page.contains("gyroscope not fitted"),
        "the refusal is in the report"
    );
    // A tumble with no still holds: the magnetometer is analysed on windows of its stream.
    let sphere = real("sf_mpu6050_hmc5883l_full_sphere.csv")
        .display()
        .to_string();
    let out = imucal_in(
        &dir,
        &[
            "analyze",
            &sphere,
            "--accel-unit",
            "g",
            "--gyro-unit",
            "dps",
            "--mag-unit",
            "gauss",
            "--field-ut",
            "48.5",
        ],
    );
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("mag — base model"), "{text}");
    assert!(text.contains("accel: not analysed"), "{text}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn analyze_writes_the_document_and_text_it_prints() {
    let dir = scratch("analyze-report");
    let recording = real("tsi_mpu6050_multipos.csv").display().to_string();
    let flags = ["--accel-unit", "counts", "--gyro-unit", "counts"];
    let printed = imucal_in(
        &dir,
        &[&["analyze", &recording, "--json"][..], &flags].concat(),
    );
    let written = imucal_in(
        &dir,
        &[&["analyze", &recording, "--report", "rep"][..], &flags].concat(),
    );
    let printed: serde_json::Value = serde_json::from_slice(&printed.stdout).expect("JSON");
    let saved: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join("rep/analysis.json")).expect("analysis.json"),
    )
    .expect("analysis.json parses");
    assert_eq!(saved, printed);
    assert!(saved["sensors"]["accel"]["base_fit"].is_object());
    let text = std::fs::read_to_string(dir.join("rep/analysis.txt")).expect("analysis.txt");
    let shown = String::from_utf8_lossy(&written.stdout);
    assert!(
        shown.starts_with(&text),
        "the text file is what was printed"
    );
    assert!(text.contains("verdict:"), "{text}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_report_whose_fits_have_findings_says_so_in_its_headline() {
    let dir = scratch("report-findings");
    let tsi = real("tsi_mpu6050_multipos.csv").display().to_string();
    let out = imucal_in(
        &dir,
        &[
            "report",
            &tsi,
            "--accel-unit",
            "counts",
            "--gyro-unit",
            "counts",
            "-o",
            "rep",
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let page = std::fs::read_to_string(dir.join("rep/report.html")).expect("the report");
    // Both fits' residuals are above their noise (fit says so too): not a plain "fitted".
    assert!(
        page.contains("Verdict: fitted, with findings"),
        "the headline hides the findings"
    );
    assert!(page.contains("the model misses something"));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_stopped_session_directory_points_to_resume_and_force_says_what_it_replaces() {
    let dir = scratch("stopped");
    let session = dir.join("s");
    std::fs::create_dir(&session).expect("session directory");
    let progress = serde_json::json!({
        "device_id": "01000000004d49530000000000000000",
        "stage": "stopped",
        "stopped_because": "the session was stopped by the user (during stage `positions`)",
        "board_holds": "its earlier calibration",
        "poses": 11,
        "mag_samples": 0,
        "params_crc": null
    });
    std::fs::write(session.join("progress.json"), progress.to_string()).expect("progress");
    let out = imucal_in(
        &dir,
        &["calibrate", "--sim", "--yes", "--no-history", "-o", "s"],
    );
    let message = stderr(&out);
    assert!(!out.status.success(), "{message}");
    assert!(
        message.contains("holds a stopped session (11 positions measured")
            && message.contains("calibrate --resume s"),
        "{message}"
    );
    // Nothing was started: the stopped session is as it was.
    assert!(session.join("progress.json").is_file());
    assert!(!session.join("poses.json").exists());
}

#[test]
fn analyze_tests_held_out_the_accelerometer_model_fit_chose_on_six_faces() {
    let dir = scratch("six-faces");
    // 13 holds on the six faces, three faces held once: fit scores its models on the 10 poses
    // they can be refit without; analyze used to refuse the model fit chose.
    let recording = real("imucal_nilspod_ferraris.csv").display().to_string();
    let args = ["--gyro-unit", "dps", "--json"];
    let out = imucal_in(&dir, &[&["fit", recording.as_str()][..], &args].concat());
    let fit: serde_json::Value = serde_json::from_slice(&out.stdout).expect("fit JSON");
    let fit_loo = fit["accel"]["loo_rms"]
        .as_f64()
        .expect("fit's held-out RMS");
    let out = imucal_in(
        &dir,
        &[&["analyze", recording.as_str()][..], &args].concat(),
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("analyze JSON");
    let accel = &json["sensors"]["accel"];
    assert_eq!(accel["heldout_always_trained"], 3, "{accel}");
    // Same poses held out, but analyze's holds lose a detection window at either end and are
    // weighed by their own noise: the two held-out RMS agree to within a factor of 1.5.
    let heldout = accel["heldout_rms_before"].as_f64().expect("held-out RMS");
    assert!(
        heldout < 1.5 * fit_loo && heldout > fit_loo / 1.5,
        "analyze {heldout:.3e}, fit {fit_loo:.3e}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_history_database_that_cannot_be_used_stops_calibrate_before_a_board_is_written() {
    let dir = scratch("bad-db");
    // A database "inside" a regular file cannot be created.
    std::fs::write(dir.join("a-file"), "not a directory").expect("scratch file");
    for (how, args) in [
        ("env", vec![]),
        ("flag", vec!["--db", "sqlite://a-file/history.sqlite"]),
    ] {
        let mut command = Command::new(env!("CARGO_BIN_EXE_imucal"));
        command
            .current_dir(&dir)
            .args(["calibrate", "--sim", "--yes", "-o", how])
            .args(&args);
        if how == "env" {
            command.env("IMUCAL_DB", "mysql://station/history");
        } else {
            command.env_remove("IMUCAL_DB");
        }
        let out = command.output().expect("the imucal binary runs");
        assert_eq!(out.status.code(), Some(1), "{how}: {}", stderr(&out));
        assert!(
            stderr(&out).contains("nothing was started") && stderr(&out).contains("--no-history"),
            "{how}: {}",
            stderr(&out)
        );
        assert!(!dir.join(how).exists(), "{how}: no session was started");
    }
    // A plain path names a SQLite file: `fit --params-out` records into it.
    let recording = real("imucal_nilspod_ferraris.csv").display().to_string();
    let db = dir.join("plain.sqlite");
    let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .current_dir(&dir)
        .env("IMUCAL_DB", &db)
        .args([
            "fit",
            &recording,
            "--gyro-unit",
            "dps",
            "--params-out",
            "p.json",
        ])
        .output()
        .expect("the imucal binary runs");
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("Recorded as calibration 1"),
        "{}",
        stderr(&out)
    );
    assert!(db.exists());
    let _ = std::fs::remove_dir_all(&dir);
}

/// Seven holds at 100 Hz, 2 s each, labelled `P1` … `P7` in a `pose` column: the six faces, then
/// one tilted 45° between +X and +Z, which no face is within 30° of.
fn six_faces_and_a_tilt() -> String {
    let g = 9.81;
    let h = g / 2f64.sqrt();
    let holds = [
        [0.0, 0.0, g],
        [0.0, 0.0, -g],
        [g, 0.0, 0.0],
        [-g, 0.0, 0.0],
        [0.0, g, 0.0],
        [0.0, -g, 0.0],
        [h, 0.0, h],
    ];
    let mut text = String::from("t_s,ax,ay,az,pose\n");
    for (k, mean) in holds.iter().enumerate() {
        for i in 0..200 {
            let row = (k * 200 + i) as f64;
            let noise = |axis: f64| 0.01 * (row * (1.7 + axis)).sin();
            text += &format!(
                "{:.2},{:.5},{:.5},{:.5},P{}\n",
                row / 100.0,
                mean[0] + noise(0.0),
                mean[1] + noise(1.0),
                mean[2] + noise(2.0),
                k + 1
            );
        }
    }
    text
}

#[test]
fn a_refused_fit_names_the_hold_by_the_number_and_span_the_still_table_shows() {
    let dir = scratch("hold-names");
    std::fs::write(dir.join("rec.csv"), six_faces_and_a_tilt()).expect("writable");
    let table = imucal_in(&dir, &["still", "rec.csv"]);
    assert!(table.status.success(), "{}", stderr(&table));
    let table = String::from_utf8_lossy(&table.stdout).into_owned();
    // The row of the tilted hold: `#`, t_start, t_end, dur, label.
    let row: Vec<&str> = table
        .lines()
        .map(str::split_whitespace)
        .map(Iterator::collect)
        .find(|fields: &Vec<&str>| fields.get(4) == Some(&"P7"))
        .unwrap_or_else(|| panic!("a row labelled P7: {table}"));
    assert_eq!(row[0], "7", "holds are numbered from 1: {table}");
    let (start, end): (f64, f64) = (row[1].parse().unwrap(), row[2].parse().unwrap());
    let json = imucal_in(&dir, &["still", "rec.csv", "--json"]);
    let json: serde_json::Value = serde_json::from_slice(&json.stdout).expect("JSON");
    assert_eq!(json["intervals"][6]["number"], 7, "{json}");

    let out = imucal_in(
        &dir,
        &[
            "fit",
            "rec.csv",
            "--sensor",
            "accel",
            "--method",
            "six-position",
        ],
    );
    let message = stderr(&out);
    assert!(!out.status.success(), "{message}");
    let named =
        format!("hold #7 at {start:.1}–{end:.1} s (pose P7) is more than 30° from every axis");
    assert!(message.contains(&named), "{named}: {message}");
    assert!(!message.contains("pose 6"), "{message}");
}

#[test]
fn a_unit_option_the_header_contradicts_exits_with_the_usage_status_naming_the_fix() {
    let dir = scratch("unit-conflict");
    let mut text = String::from("t_s,ax [m/s2],ay [m/s2],az [m/s2]\n");
    for i in 0..10 {
        text += &format!("{:.2},0,0,9.81\n", f64::from(i) / 100.0);
    }
    std::fs::write(dir.join("rec.csv"), &text).expect("writable");
    std::fs::write(
        dir.join("mapped.csv"),
        text.replace(" [m/s2]", "_ms2 [m/s2]"),
    )
    .expect("writable");
    for args in [
        &["fit", "rec.csv", "--accel-unit", "g"][..],
        &["still", "rec.csv", "--accel-unit", "g"],
        &["report", "rec.csv", "--accel-unit", "g", "-o", "r.html"],
        &[
            "fit",
            "mapped.csv",
            "--accel-unit",
            "g",
            "--columns",
            "t_s=t_s,ax=ax_ms2 [m/s2],ay=ay_ms2 [m/s2],az=az_ms2 [m/s2]",
        ],
    ] {
        let out = imucal_in(&dir, args);
        let message = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {message}");
        assert!(
            message.contains("but --accel-unit says g")
                && message.contains("leave --accel-unit out"),
            "{args:?}: {message}"
        );
    }
}

#[test]
fn calibrate_option_values_it_cannot_run_with_exit_2_naming_the_cause_and_the_fix() {
    let dir = scratch("sim-values");
    for (args, words) in [
        (
            &[
                "calibrate",
                "--sim",
                "--sim-effect",
                "foo",
                "--yes",
                "-o",
                "a",
            ][..],
            "use one of",
        ),
        (
            &[
                "calibrate",
                "--sim-boards",
                "2",
                "--sim-faulty",
                "3",
                "--yes",
                "-o",
                "b",
            ][..],
            "give --sim-faulty 2 or less",
        ),
    ] {
        let out = imucal_in(&dir, args);
        let text = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {text}");
        assert!(text.contains(words), "{args:?}: {text}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_written_set_that_misses_its_target_at_rest_is_named_in_the_verdict_and_history_and_fails() {
    let dir = scratch("missed-target");
    let out = imucal_in(
        &dir,
        &[
            "calibrate",
            "--sim",
            "--sim-seed",
            "50",
            "--sim-effect",
            "bias_step",
            "--yes",
            "-o",
            "s",
        ],
    );
    let text = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{text}");
    assert!(
        text.contains("written and verified on the board, but misses its targets at rest"),
        "{text}"
    );
    let summary: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join("s/summary.json")).expect("summary.json"),
    )
    .expect("JSON");
    assert_eq!(summary["written"], true);
    assert_ne!(summary["verdict"]["level"], "good");
    let reasons = summary["verdict"]["reasons"].to_string();
    assert!(reasons.contains("misses its target at rest"), "{reasons}");
    let location = imucal::history::DbLocation::Sqlite(dir.join("history.sqlite"));
    let mut store = imucal::history::HistoryStore::open(&location).expect("history");
    let records = store.records(None).expect("records");
    let verdict = records
        .last()
        .and_then(|r| r.record.verdict.clone())
        .expect("a recorded verdict");
    assert!(
        verdict
            .reasons
            .iter()
            .any(|r| r.contains("misses its target at rest")),
        "{verdict:?}"
    );
    std::fs::remove_dir_all(&dir).ok();
}
