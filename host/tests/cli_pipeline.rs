//! The paths between commands: `fit --params-out` → `export` / `flash` (to the simulated board),
//! and the same input checks in `fit`, `report` and `analyze`.

use std::path::PathBuf;
use std::process::{Command, Output};

use imucal::device::ParamsFile;
use imucal_hil_sim::board::PersonSchedule;
use imucal_hil_sim::serve::{SimOptions, SimServer};

fn imucal(args: &[&str]) -> Output {
    // The history goes to a database of this test process, never the user's.
    let db =
        std::env::temp_dir().join(format!("imucal-cli-pipeline-{}.sqlite", std::process::id()));
    Command::new(env!("CARGO_BIN_EXE_imucal"))
        .env("IMUCAL_DB", db)
        .args(args)
        .output()
        .expect("the imucal binary runs")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn real(name: &str) -> String {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../data/real")
        .join(name)
        .display()
        .to_string()
}

fn temp_file(name: &str) -> String {
    std::env::temp_dir()
        .join(format!("imucal-cli-pipeline-{}-{name}", std::process::id()))
        .display()
        .to_string()
}

/// Every recording in `data/real` with its unit flags (INDEX.md) and the sensors it can
/// calibrate (the full-sphere set has only five accelerometer directions).
const FITTABLE: [(&str, &[&str], &[&str]); 5] = [
    (
        "imucal_nilspod_ferraris.csv",
        &["--gyro-unit", "dps"],
        &["accel", "gyro"],
    ),
    (
        "imutk_xsens_multipos.csv",
        &["--accel-unit", "counts", "--gyro-unit", "counts"],
        &["accel"],
    ),
    (
        "tsi_mpu6050_multipos.csv",
        &["--accel-unit", "counts", "--gyro-unit", "counts"],
        &["accel"],
    ),
    (
        "sf_mpu6050_hmc5883l_full_sphere.csv",
        &[
            "--accel-unit",
            "g",
            "--gyro-unit",
            "dps",
            "--mag-unit",
            "gauss",
            "--location",
            "46.05,14.51",
            "--sensor",
            "mag",
        ],
        &["mag"],
    ),
    (
        "tsm_qmc5883l_mag_rotation.csv",
        &["--mag-unit", "counts"],
        &["mag"],
    ),
];

/// `fit --params-out` and the parameter file it wrote (which must parse as `flash` reads it).
fn fit_params(name: &str, flags: &[&str]) -> (String, ParamsFile) {
    // One file per call: tests fitting the same recording run in parallel, and `fit` refuses
    // to replace an existing file.
    static CALLS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let call = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let path = temp_file(&format!("{name}-{call}.json"));
    let recording = real(name);
    let out = imucal(
        &[
            &["fit", recording.as_str()],
            flags,
            &["--params-out", &path],
        ]
        .concat(),
    );
    assert!(out.status.success(), "{name}: {}", text(&out.stderr));
    let file = ParamsFile::load(path.as_ref()).expect("fit writes a readable parameter file");
    file.to_calibration_set(&path)
        .expect("every number fits the board's f32");
    (path, file)
}

#[test]
fn fit_params_out_then_export_c_header_works_for_every_fittable_real_recording() {
    for (name, flags, fitted) in FITTABLE {
        let (path, file) = fit_params(name, flags);
        let provenance = file.provenance.as_ref().expect("provenance is written");
        for sensor in ["accel", "gyro", "mag"] {
            // A sensor is either fitted (with its method in the provenance) or listed as not
            // fitted with a reason; never silently identity.
            assert_ne!(
                provenance.methods.contains_key(sensor) && fitted.contains(&sensor),
                file.not_fitted.contains_key(sensor),
                "{name}: {sensor}: {:?} / {:?}",
                provenance.methods,
                file.not_fitted
            );
        }
        let out = imucal(&["export", &path, "--format", "c-header"]);
        let header = text(&out.stdout);
        let _ = std::fs::remove_file(&path);
        assert!(out.status.success(), "{name}: {}", text(&out.stderr));
        for sensor in fitted {
            assert!(
                header.contains(&format!("imucal_{sensor}_A[3][3]")),
                "{name}"
            );
        }
        let lower = header.to_lowercase();
        assert!(!lower.contains("nan") && !lower.contains("inf"), "{name}");
    }
}

#[test]
fn the_parameter_file_takes_nominal_units_so_a_degrees_per_second_fit_becomes_rad_per_s() {
    let (path, file) = fit_params("imucal_nilspod_ferraris.csv", &["--gyro-unit", "dps"]);
    let _ = std::fs::remove_file(&path);
    // The gyroscope was read in °/s; the board feeds rad/s, so A is the identity and b the
    // zero-rate offset in rad/s (|b| of this NilsPod ≈ 0.7 °/s = 0.012 rad/s).
    for (r, row) in file.gyro.a.iter().enumerate() {
        for (c, v) in row.iter().enumerate() {
            let want = if r == c { 1.0 } else { 0.0 };
            assert!((v - want).abs() < 1e-12, "gyro A[{r}][{c}] = {v}");
        }
    }
    let b = file.gyro.b.map(f64::abs);
    assert!(
        b.iter().all(|v| *v < 0.02) && b.iter().any(|v| *v > 1e-3),
        "{b:?}"
    );
    assert_eq!(file.gyro.input_unit, None);
    assert!(file.not_fitted.contains_key("mag"));
}

#[test]
fn a_parameter_file_fitted_from_a_recording_flashes_to_the_simulated_board_and_verifies() {
    let (path, file) = fit_params("imucal_nilspod_ferraris.csv", &["--gyro-unit", "dps"]);
    let mut options = SimOptions::new(21);
    options.schedule = PersonSchedule::Rest;
    let sim = SimServer::start(options).expect("the simulator starts");
    let port = sim.port_path().to_string();
    let out = imucal(&["flash", &path, "--port", &port]);
    let _ = std::fs::remove_file(&path);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(
        text(&out.stdout).contains("verified"),
        "{}",
        text(&out.stdout)
    );
    assert!(
        text(&out.stderr).contains("no mag calibration"),
        "{}",
        text(&out.stderr)
    );
    assert_eq!(file.accel.input_unit, None);
}

#[test]
fn fit_writes_no_parameter_file_and_fails_when_no_requested_sensor_can_go_into_it() {
    // The magnetometer fits, but without a field reference its output is normalised to 1: a
    // board would read the field as 1 µT. A file of identities would only overwrite a board.
    let path = temp_file("nothing.json");
    let recording = real("sf_mpu6050_hmc5883l_full_sphere.csv");
    let out = imucal(&[
        "fit",
        &recording,
        "--sensor",
        "mag",
        "--mag-unit",
        "gauss",
        "--params-out",
        &path,
    ]);
    let stderr = text(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(!std::path::Path::new(&path).exists(), "{stderr}");
    assert!(
        stderr.contains("was not written") && stderr.contains("--field-ut or --location"),
        "{stderr}"
    );
}

#[test]
fn export_and_flash_refuse_a_parameter_file_that_calibrates_no_sensor() {
    let (path, _) = fit_params("imucal_nilspod_ferraris.csv", &["--gyro-unit", "dps"]);
    let mut json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).expect("the file")).expect("JSON");
    for sensor in ["accel", "gyro", "mag"] {
        json["not_fitted"][sensor] = "not fitted in this test".into();
    }
    std::fs::write(&path, json.to_string()).expect("rewrite");
    let exported = imucal(&["export", &path, "--format", "c-header"]);
    // No port is opened: the refusal comes first.
    let flashed = imucal(&["flash", &path, "--port", "/nonexistent/port"]);
    let _ = std::fs::remove_file(&path);
    for (command, out) in [("export", exported), ("flash", flashed)] {
        let stderr = text(&out.stderr);
        assert!(!out.status.success(), "{command}: {stderr}");
        assert!(
            stderr.contains("holds no calibration"),
            "{command}: {stderr}"
        );
        assert!(
            out.stdout.is_empty(),
            "{command} wrote {}",
            text(&out.stdout)
        );
    }
}

#[test]
fn a_parameter_file_fitted_for_one_board_is_refused_by_another() {
    let (path, file) = fit_params(
        "imucal_nilspod_ferraris.csv",
        &["--gyro-unit", "dps", "--device", "another-board"],
    );
    let provenance = file.provenance.as_ref().expect("provenance");
    assert_eq!(provenance.device_id.as_deref(), Some("another-board"));
    let mut options = SimOptions::new(22);
    options.schedule = PersonSchedule::Rest;
    let sim = SimServer::start(options).expect("the simulator starts");
    let port = sim.port_path().to_string();
    let out = imucal(&["flash", &path, "--port", &port]);
    let _ = std::fs::remove_file(&path);
    let stderr = text(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(
        stderr.contains("not for this board") && stderr.contains("another-board"),
        "{stderr}"
    );
}

#[test]
fn flash_refuses_a_parameter_file_fitted_from_raw_counts() {
    let (path, file) = fit_params(
        "tsi_mpu6050_multipos.csv",
        &["--accel-unit", "counts", "--gyro-unit", "counts"],
    );
    assert_eq!(file.accel.input_unit.as_deref(), Some("counts"));
    // No port is opened: the refusal comes first.
    let out = imucal(&["flash", &path, "--port", "/nonexistent/port"]);
    let _ = std::fs::remove_file(&path);
    assert!(!out.status.success());
    let stderr = text(&out.stderr);
    assert!(
        stderr.contains("accel (counts)") && stderr.contains("--accel-unit"),
        "{stderr}"
    );
}

/// One unit mix-up per class: the recording, the wrong flags, and the flag the fix names.
const MIX_UPS: [(&str, &[&str], &str); 4] = [
    // Accelerometer in g declared m/s².
    (
        "sf_mpu6050_hmc5883l_full_sphere.csv",
        &["--gyro-unit", "dps", "--mag-unit", "gauss"],
        "--accel-unit g",
    ),
    // Accelerometer in counts declared m/s².
    (
        "imutk_xsens_multipos.csv",
        &["--gyro-unit", "counts"],
        "--accel-unit counts",
    ),
    // Gyroscope in °/s declared rad/s.
    ("imucal_nilspod_ferraris.csv", &[], "°/s"),
    // Magnetometer in gauss declared µT.
    (
        "sf_mpu6050_hmc5883l_full_sphere.csv",
        &["--accel-unit", "g", "--gyro-unit", "dps"],
        "--mag-unit gauss",
    ),
];

fn refused_by(command: &str, name: &str, flags: &[&str], fix: &str) {
    let recording = real(name);
    let report_dir = temp_file(&format!("{command}-report"));
    // The page of an earlier mix-up (written for the sensors it could fit) is not this one's.
    let _ = std::fs::remove_dir_all(&report_dir);
    let extra: &[&str] = if command == "report" {
        &["-o", &report_dir]
    } else {
        &[]
    };
    let out = imucal(&[&[command, recording.as_str()], flags, extra].concat());
    let stderr = text(&out.stderr);
    assert!(!out.status.success(), "{command} {name} {flags:?} exited 0");
    assert!(stderr.contains(fix), "{command} {name}: {stderr}");
    // The report of what could be fitted may be written; the refused sensor is not in it as
    // fitted, and the page says why.
    let page = std::path::Path::new(&report_dir).join("report.html");
    if let Ok(html) = std::fs::read_to_string(&page) {
        assert!(
            html.contains("not fitted"),
            "{command} {name}: the page hides the refusal"
        );
    }
}

#[test]
fn fit_refuses_every_class_of_unit_mix_up() {
    for (name, flags, fix) in MIX_UPS {
        refused_by("fit", name, flags, fix);
    }
}

#[test]
fn report_refuses_every_class_of_unit_mix_up_that_fit_refuses() {
    for (name, flags, fix) in MIX_UPS {
        refused_by("report", name, flags, fix);
    }
}

#[test]
fn analyze_refuses_every_class_of_unit_mix_up_that_fit_refuses() {
    for (name, flags, fix) in MIX_UPS {
        refused_by("analyze", name, flags, fix);
    }
}

#[test]
fn absurd_reference_values_are_refused_by_every_command_with_a_sentence() {
    let recording = real("imucal_nilspod_ferraris.csv");
    for command in ["fit", "report", "analyze"] {
        let out = imucal(&[
            command,
            &recording,
            "--gyro-unit",
            "dps",
            "--gravity",
            "1e300",
        ]);
        let stderr = text(&out.stderr);
        assert!(!out.status.success(), "{command}");
        assert!(
            stderr.contains("--gravity 1e300 is outside"),
            "{command}: {stderr}"
        );
    }
}

#[test]
fn analyze_labels_a_gyroscope_without_a_scale_in_counts_not_rad_per_s() {
    let recording = real("imutk_xsens_multipos.csv");
    let out = imucal(&[
        "analyze",
        &recording,
        "--accel-unit",
        "counts",
        "--gyro-unit",
        "counts",
    ]);
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let gyro = stdout
        .split("gyro — ")
        .nth(1)
        .expect("the gyroscope is analysed");
    assert!(gyro.contains("counts"), "{gyro}");
    assert!(!gyro.contains("rad/s"), "{gyro}");
}

#[test]
fn a_magnetometer_sample_cap_below_an_ellipsoids_needs_is_refused_at_the_flag() {
    // A cap of 5 would refuse every fit with "record longer": the flag itself is the cause.
    let recording = real("sf_mpu6050_hmc5883l_full_sphere_mag.csv");
    for command in ["fit", "report", "analyze"] {
        let out = imucal(&[command, &recording, "--max-mag-samples", "5"]);
        let stderr = text(&out.stderr);
        assert!(!out.status.success(), "{command}");
        assert!(
            stderr.contains("--max-mag-samples") && stderr.contains("at least 12"),
            "{command}: {stderr}"
        );
        assert!(!stderr.contains("record longer"), "{command}: {stderr}");
    }
}

#[test]
fn magnetometer_columns_replaced_by_a_mag_file_are_said_to_be_unread() {
    let recording = real("tsm_qmc5883l_mag_rotation.csv");
    let mag = real("sf_mpu6050_hmc5883l_full_sphere_mag.csv");
    let out = imucal(&[
        "fit",
        &recording,
        "--sensor",
        "mag",
        "--mag-unit",
        "gauss",
        "--mag-file",
        &mag,
    ]);
    let stderr = text(&out.stderr);
    assert!(
        stderr.contains("not read from") && stderr.contains("replaced by --mag-file"),
        "{stderr}"
    );
}

#[test]
fn a_report_of_standard_input_goes_to_a_named_directory_not_a_dash() {
    let dir = PathBuf::from(temp_file("stdin-report"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch directory");
    let recording = std::fs::File::open(real("tsi_mpu6050_multipos.csv")).expect("recording");
    let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .current_dir(&dir)
        .args([
            "report",
            "-",
            "--accel-unit",
            "counts",
            "--gyro-unit",
            "counts",
        ])
        .stdin(recording)
        .output()
        .expect("the imucal binary runs");
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(dir.join("recording_report/report.html").is_file());
    assert!(!dir.join("-_report").exists());
}

#[test]
fn analyze_studies_the_accelerometer_in_a_model_that_fit_does_not_refuse() {
    // On these eleven poses `fit` refuses the full norm model (its scales would be uncertain
    // by 4 %); the analysis must not build its findings on that model.
    let recording = real("tsi_mpu6050_multipos.csv");
    let units = ["--accel-unit", "counts", "--gyro-unit", "counts"];
    let fit = imucal(&[&["fit", &recording, "--sensor", "accel"][..], &units].concat());
    assert!(
        text(&fit.stdout).contains("lm: refused"),
        "{}",
        text(&fit.stdout)
    );
    let analyze = imucal(&[&["analyze", &recording][..], &units].concat());
    let stdout = text(&analyze.stdout);
    assert!(analyze.status.success(), "{}", text(&analyze.stderr));
    assert!(
        stdout.contains("accel — base model axis-aligned"),
        "{stdout}"
    );
}

#[test]
fn analyze_holds_out_on_six_faces_only_the_poses_the_model_can_spare_and_says_so() {
    let recording = real("imucal_nilspod_ferraris.csv");
    let out = imucal(&["analyze", &recording, "--gyro-unit", "dps"]);
    let stdout = text(&out.stdout);
    assert!(
        stdout.contains("accel — base model minmax+axis-aligned — 13 observations"),
        "{stdout}"
    );
    let held_out = stdout
        .lines()
        .find(|l| l.trim_start().starts_with("held out:"))
        .unwrap_or_else(|| panic!("no note of the poses held out: {stdout}"));
    assert!(
        held_out.contains("each of the 10 observations") && held_out.contains("other 3"),
        "{held_out}"
    );
}

#[test]
fn a_fit_of_raw_counts_is_exported_with_its_input_unit_and_never_in_adafruits_forms() {
    // The Adafruit library subtracts its offsets from m/s²: offsets of ≈ 700 counts there
    // would ruin every reading.
    let (path, _) = fit_params(
        "tsi_mpu6050_multipos.csv",
        &["--accel-unit", "counts", "--gyro-unit", "counts"],
    );
    for format in ["adafruit-json", "motioncal"] {
        let out_file = temp_file(&format!("counts-{format}.out"));
        let out = imucal(&["export", &path, "--format", format, "-o", &out_file]);
        let stderr = text(&out.stderr);
        assert!(!out.status.success(), "{format}");
        assert!(
            stderr.contains("accel in counts") && stderr.contains("m/s²"),
            "{format}: {stderr}"
        );
        assert!(!std::path::Path::new(&out_file).exists(), "{format}");
    }
    let header = imucal(&["export", &path, "--format", "c-header"]);
    assert!(header.status.success(), "{}", text(&header.stderr));
    assert!(
        text(&header.stdout).contains("Except: accel inputs x are raw readings in counts"),
        "{}",
        text(&header.stdout)
    );
    let json = imucal(&["export", &path, "--format", "json"]);
    let document: serde_json::Value =
        serde_json::from_slice(&json.stdout).expect("the export is JSON");
    assert_eq!(document["accel"]["input_unit"], "counts");
    assert_eq!(document["gyro"]["input_unit"], "rad/s");
}

#[test]
fn a_rate_is_said_to_be_ignored_only_when_the_file_has_its_own_time_stamps() {
    let with_time = real("imucal_nilspod_ferraris.csv");
    // The same rows without the `t_s` column: then the rate is what times them.
    let without: String = std::fs::read_to_string(&with_time)
        .expect("recording")
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| l.split_once(',').map_or(l, |(_, rest)| rest).to_string() + "\n")
        .collect();
    let without_time = temp_file("no-time.csv");
    std::fs::write(&without_time, without).expect("scratch file");
    let flags = ["--gyro-unit", "dps", "--sensor", "gyro", "--rate", "102.4"];
    let moot = imucal(&[&["fit", with_time.as_str()][..], &flags].concat());
    assert!(text(&moot.stderr).contains("--rate is ignored"));
    let used = imucal(&[&["fit", without_time.as_str()][..], &flags].concat());
    assert!(used.status.success(), "{}", text(&used.stderr));
    assert!(!text(&used.stderr).contains("--rate is ignored"));
}

#[test]
fn a_gyroscope_scale_given_for_data_in_a_physical_unit_is_said_to_be_unused() {
    let recording = real("imucal_nilspod_ferraris.csv");
    let out = imucal(&[
        "fit",
        &recording,
        "--gyro-unit",
        "dps",
        "--gyro-scale",
        "0.001",
        "--sensor",
        "gyro",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(
        text(&out.stdout).contains("--gyro-scale 0.001 was not used"),
        "{}",
        text(&out.stdout)
    );
}

#[test]
fn a_sensor_left_out_of_the_parameter_file_has_no_residual_in_it() {
    // The gyroscope in counts without --gyro-scale is fitted but not written: its RMS, in
    // counts, must not stand in the file's rad/s field.
    let (_, file) = fit_params(
        "tsi_mpu6050_multipos.csv",
        &["--accel-unit", "counts", "--gyro-unit", "counts"],
    );
    assert!(file.not_fitted.contains_key("gyro"));
    assert_eq!(file.residuals.gyro_rms, 0.0);
    assert!(file.residuals.accel_rms > 0.0);
}

#[test]
fn a_fit_of_standard_input_is_not_recorded_as_a_board_without_a_device_id() {
    let recording = std::fs::File::open(real("tsi_mpu6050_multipos.csv")).expect("recording");
    let params = temp_file("stdin-params.json");
    let db = temp_file("stdin-history.sqlite");
    let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .env("IMUCAL_DB", format!("sqlite://{db}"))
        .args([
            "fit",
            "-",
            "--accel-unit",
            "counts",
            "--gyro-unit",
            "counts",
            "--params-out",
            &params,
        ])
        .stdin(recording)
        .output()
        .expect("the imucal binary runs");
    let stderr = text(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains("not recorded in the calibration history") && stderr.contains("--device"),
        "{stderr}"
    );
    assert!(
        !std::path::Path::new(&db).exists(),
        "no history was written"
    );
}

#[test]
fn analyze_write_params_keeps_the_sessions_board_binding_and_provenance() {
    // A session of one simulated board: its parameter file names that board.
    let dir = temp_file("bound-session");
    let _ = std::fs::remove_dir_all(&dir);
    let out = imucal(&["calibrate", "--sim", "--yes", "--sim-seed", "3", "-o", &dir]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let base = ParamsFile::load(&PathBuf::from(&dir).join("params.json")).expect("base file");
    assert!(base.device.is_some(), "a session's file names its board");

    let written = temp_file("bound-extended.json");
    let out = imucal(&["analyze", &dir, "--write-params", &written]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let extended = ParamsFile::load(&PathBuf::from(&written)).expect("written file");
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_file(&written);
    // Without the binding, `flash` would write this board's set to any other board.
    assert_eq!(extended.device, base.device);
    assert_eq!(extended.provenance, base.provenance);
    assert_eq!(extended.not_fitted, base.not_fitted);
    assert_eq!(extended.absent_sensors, base.absent_sensors);
    for (e, b) in [
        (&extended.accel, &base.accel),
        (&extended.gyro, &base.gyro),
        (&extended.mag, &base.mag),
    ] {
        assert_eq!(e.input_unit, b.input_unit);
    }
}

#[test]
fn analyze_write_params_of_a_recording_is_a_usage_error_with_exit_status_2() {
    // A recording has no parameter set to extend: only a session directory has one.
    let written = temp_file("not-written.json");
    let out = imucal(&[
        "analyze",
        &real("imucal_nilspod_ferraris.csv"),
        "--gyro-unit",
        "dps",
        "--write-params",
        &written,
    ]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("--write-params needs a session directory"),
        "{stderr}"
    );
    assert!(!std::path::Path::new(&written).exists());
}

/// The lines of the block that starts with `start` and runs to the next empty line.
fn block<'a>(stdout: &'a str, start: &str) -> Vec<&'a str> {
    stdout
        .lines()
        .skip_while(|l| !l.starts_with(start))
        .take_while(|l| !l.is_empty())
        .collect()
}

#[test]
fn analyze_prints_the_base_fits_fit_gives_for_the_same_recording_and_options() {
    let recording = real("imucal_nilspod_ferraris.csv");
    let units = ["--gyro-unit", "dps"];
    let fit = imucal(&[&["fit", &recording, "--json"][..], &units].concat());
    assert!(fit.status.success(), "{}", text(&fit.stderr));
    let analyze = imucal(&[&["analyze", &recording, "--json"][..], &units].concat());
    let fit: serde_json::Value = serde_json::from_slice(&fit.stdout).expect("fit JSON");
    let analyze: serde_json::Value = serde_json::from_slice(&analyze.stdout).expect("analyze JSON");
    for sensor in ["accel", "gyro"] {
        // One pipeline, the same arithmetic on the same samples: equal to the last bit, not
        // within a tolerance (the gyroscope's bias RMS once came out 1.706e-4 and 1.776e-4).
        assert_eq!(
            analyze["sensors"][sensor]["base_fit"], fit[sensor],
            "{sensor}"
        );
    }
    assert_eq!(fit["accel"]["method"], "minmax+axis-aligned");

    // The text: each sensor's base-fit block as `fit` prints it, line for line.
    let fit = text(&imucal(&[&["fit", &recording][..], &units].concat()).stdout);
    let analyze = text(&imucal(&[&["analyze", &recording][..], &units].concat()).stdout);
    for start in ["accel — method", "gyro — method"] {
        let printed = block(&fit, start);
        assert!(printed.len() > 4, "{start}: {fit}");
        assert_eq!(block(&analyze, start), printed, "{start}");
    }
    // The analysis builds on the model `fit` chose, not on one it chose again.
    assert!(
        analyze.contains("accel — base model minmax+axis-aligned"),
        "{analyze}"
    );
}

#[test]
fn analyze_fails_naming_the_sensor_it_could_not_analyse_after_reporting_the_others() {
    // Raw gyroscope counts read as rad/s: `fit` leaves the gyroscope out, so it cannot be
    // analysed; the accelerometer's analysis is still done.
    let recording = real("tsi_mpu6050_multipos.csv");
    let dir = temp_file("partial-analysis-report");
    let _ = std::fs::remove_dir_all(&dir);
    let out = imucal(&[
        "analyze",
        &recording,
        "--accel-unit",
        "counts",
        "--report",
        &dir,
    ]);
    let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
    let written = PathBuf::from(&dir).join("analysis.json").is_file();
    let _ = std::fs::remove_dir_all(&dir);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stdout.contains("accel — base model"), "{stdout}");
    assert!(written, "the report of what could be analysed is written");
    let last = stderr.lines().last().unwrap_or_default();
    assert!(
        last.starts_with("imucal: gyro not analysed") && last.contains("not fitted"),
        "{stderr}"
    );
    assert!(!last.contains("accel"), "{stderr}");
    for command in ["fit", "analyze"] {
        let help = text(&imucal(&[command, "--help"]).stdout);
        assert!(
            help.contains("Exit status: 0 when every") && help.contains("1 when any"),
            "{command}: {help}"
        );
    }
}

#[test]
fn fit_of_gyroscope_counts_with_a_scale_prints_the_calibration_the_parameter_file_holds() {
    // The NilsPod's gyroscope in its raw counts (±2000 °/s over 16 bits), read back with the
    // scale that makes them rad/s.
    let step_dps = 2000.0 / 32768.0;
    let source = std::fs::read_to_string(real("imucal_nilspod_ferraris.csv")).expect("recording");
    let mut lines = source.lines();
    let header = lines.next().expect("header");
    let columns: Vec<&str> = header.split(',').collect();
    let gyro: Vec<usize> = ["gx", "gy", "gz"]
        .map(|c| columns.iter().position(|h| *h == c).expect("gyro column"))
        .to_vec();
    let mut counts = format!("{header}\n");
    for line in lines {
        let fields: Vec<String> = line
            .split(',')
            .enumerate()
            .map(|(i, v)| match gyro.contains(&i) {
                true => format!("{}", (v.parse::<f64>().expect("number") / step_dps).round()),
                false => v.to_string(),
            })
            .collect();
        counts.push_str(&fields.join(","));
        counts.push('\n');
    }
    let csv = temp_file("gyro-counts.csv");
    std::fs::write(&csv, counts).expect("scratch recording");
    let params = temp_file("gyro-counts-params.json");
    let _ = std::fs::remove_file(&params);
    let scale = format!("{}", step_dps.to_radians());
    let out = imucal(&[
        "fit",
        &csv,
        "--sensor",
        "gyro",
        "--gyro-unit",
        "counts",
        "--gyro-scale",
        &scale,
        "--params-out",
        &params,
    ]);
    let stdout = text(&out.stdout);
    let file = ParamsFile::load(params.as_ref());
    let _ = std::fs::remove_file(&csv);
    let _ = std::fs::remove_file(&params);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let file = file.expect("the parameter file");
    assert_eq!(file.gyro.input_unit, None, "the file holds rad/s input");
    // The table's rows for the file: `A[r] a a a   b[r] b`.
    let rows: Vec<Vec<f64>> = stdout
        .lines()
        .skip_while(|l| !l.contains("as the parameter file holds it, for input in rad/s"))
        .skip(1)
        .take(3)
        .map(|l| {
            l.split_whitespace()
                .filter_map(|w| w.parse::<f64>().ok())
                .collect()
        })
        .collect();
    assert_eq!(rows.len(), 3, "{stdout}");
    for (r, row) in rows.iter().enumerate() {
        assert_eq!(row.len(), 4, "{stdout}");
        // Printed with 6 decimals (or 7 significant digits below 0.01): agreement to half a
        // unit of the sixth decimal, far below the factor of 939 (1/scale) a count differs by.
        let close =
            |printed: f64, written: f64| (printed - written).abs() <= 5e-7 * written.abs().max(1.0);
        for (c, (printed, written)) in row.iter().zip(file.gyro.a[r]).enumerate() {
            assert!(close(*printed, written), "A[{r}][{c}]: {stdout}");
        }
        assert!(close(row[3], file.gyro.b[r]), "b[{r}]: {stdout}");
    }
}
