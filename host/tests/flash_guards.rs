//! What `imucal flash` lets reach a board: misspelled sensors, sensors the file leaves out,
//! and files made for another board, against a fake board on a pseudo-terminal.

mod device_fake;

use std::path::PathBuf;
use std::process::{Command, Output};

use device_fake::{FakeConfig, FakeDevice};
use imucal::device::params_json::{DeviceJson, RangesJson};
use imucal::device::ParamsFile;
use imucal_protocol::{CalibrationSet, SensorCalibration};

/// A file path unique to this test process.
fn temp_file(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("imucal-flash-guards-{}-{name}", std::process::id()))
}

/// Runs `imucal flash FILE --port PORT extra…` with the history in a temporary database.
fn flash(file: &PathBuf, port: &str, extra: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_imucal"))
        .env("IMUCAL_DB", temp_file("history.sqlite"))
        .arg("flash")
        .arg(file)
        .args(["--port", port])
        .args(extra)
        .output()
        .expect("the imucal binary runs")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn calibrated_set() -> CalibrationSet {
    let mut set = CalibrationSet::identity();
    set.accel.b = [0.25, -0.125, 0.0625];
    set.gyro.b = [0.01, 0.02, -0.03];
    set.mag.a[0][1] = 0.015;
    set.mag.b = [12.0, -3.5, 40.0];
    set
}

/// The JSON of `set` with the `drop` sensor key removed.
fn file_without(set: &CalibrationSet, drop: &str) -> String {
    let mut value: serde_json::Value =
        serde_json::from_str(&ParamsFile::from(set).to_json()).expect("own output is JSON");
    value
        .as_object_mut()
        .expect("an object")
        .remove(drop)
        .expect("the key was there");
    value.to_string()
}

#[test]
fn a_misspelled_sensor_key_is_refused_naming_it_and_the_valid_keys() {
    let fake = FakeDevice::start(FakeConfig::default());
    let path = temp_file("acel.json");
    let json = ParamsFile::from(&calibrated_set())
        .to_json()
        .replace("\"accel\"", "\"acel\"");
    std::fs::write(&path, json).expect("temp dir writable");
    let out = flash(&path, &fake.path, &[]);
    let _ = std::fs::remove_file(&path);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("`acel` is not a parameter file key"),
        "{stderr}"
    );
    assert!(stderr.contains("accel, gyro, mag"), "{stderr}");
    assert!(
        fake.state().requests.is_empty(),
        "the board was not touched"
    );
}

#[test]
fn a_sensor_the_file_leaves_out_keeps_the_boards_calibration() {
    let fake = FakeDevice::start(FakeConfig::default());
    let full = calibrated_set();
    let path = temp_file("full.json");
    std::fs::write(&path, ParamsFile::from(&full).to_json()).expect("temp dir writable");
    assert!(flash(&path, &fake.path, &[]).status.success());

    let mut update = CalibrationSet::identity();
    update.accel.b = [0.5, 0.5, 0.5];
    std::fs::write(&path, file_without(&update, "mag")).expect("temp dir writable");
    let out = flash(&path, &fake.path, &[]);
    let stderr = text(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("keeps its current calibration"), "{stderr}");
    let active = fake.state().active;
    assert_eq!(active.accel.b, [0.5, 0.5, 0.5], "the file's accelerometer");
    assert_eq!(active.mag, full.mag, "the board's magnetometer is kept");

    let out = flash(&path, &fake.path, &["--reset", "mag"]);
    let _ = std::fs::remove_file(&path);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert_eq!(fake.state().active.mag, SensorCalibration::identity());
}

#[test]
fn reset_of_a_sensor_the_file_calibrates_is_refused() {
    let fake = FakeDevice::start(FakeConfig::default());
    let path = temp_file("reset-conflict.json");
    std::fs::write(&path, ParamsFile::from(&calibrated_set()).to_json())
        .expect("temp dir writable");
    let out = flash(&path, &fake.path, &["--reset", "accel"]);
    let _ = std::fs::remove_file(&path);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("--reset accel conflicts"), "{stderr}");
    assert_eq!(fake.state().commits, 0);
}

fn foreign_file(path: &PathBuf) {
    let mut file = ParamsFile::from(&calibrated_set());
    file.device = Some(DeviceJson {
        id: "00000000000000000000000000001234".to_string(),
        sensors: vec!["accel".into(), "gyro".into(), "mag".into(), "temp".into()],
        ranges: RangesJson {
            accel_mps2: 39.2,
            gyro_rads: 34.9,
            mag_ut: 400.0,
        },
        firmware: "0.3.1".to_string(),
    });
    std::fs::write(path, file.to_json()).expect("temp dir writable");
}

#[test]
fn a_file_made_for_another_board_is_refused_unless_forced() {
    let fake = FakeDevice::start(FakeConfig::default());
    let path = temp_file("foreign.json");
    foreign_file(&path);
    let out = flash(&path, &fake.path, &[]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("is not for this board"), "{stderr}");
    assert!(
        stderr.contains("made for device 00000000000000000000000000001234"),
        "{stderr}"
    );
    assert!(stderr.contains("--force-other-device"), "{stderr}");
    assert_eq!(fake.state().commits, 0, "nothing written");

    let out = flash(&path, &fake.path, &["--force-other-device"]);
    let _ = std::fs::remove_file(&path);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert_eq!(fake.state().active, calibrated_set());
}

#[test]
fn a_file_that_names_no_board_is_written_with_a_note() {
    let fake = FakeDevice::start(FakeConfig::default());
    let path = temp_file("offline.json");
    std::fs::write(&path, ParamsFile::from(&calibrated_set()).to_json())
        .expect("temp dir writable");
    let out = flash(&path, &fake.path, &[]);
    let _ = std::fs::remove_file(&path);
    let stderr = text(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("names no board"), "{stderr}");
    assert!(
        stderr.contains("fits the board's sensors and ranges"),
        "{stderr}"
    );
    assert!(
        !stderr.contains("recording"),
        "the file does not say where it came from: {stderr}"
    );
    assert_eq!(fake.state().active, calibrated_set());
}

/// A change that makes one metadata value implausible.
type Spoil = fn(&mut ParamsFile);

#[test]
fn implausible_metadata_is_refused_naming_the_field() {
    let fake = FakeDevice::start(FakeConfig::default());
    let path = temp_file("metadata.json");
    let good = ParamsFile::from(&calibrated_set());
    let cases: [(&str, Spoil); 3] = [
        ("residuals.accel_rms", |f| f.residuals.accel_rms = -1e30),
        ("reference.gravity_mps2", |f| {
            f.reference.gravity_mps2 = -1.0
        }),
        ("reference.field_ut", |f| f.reference.field_ut = 0.0),
    ];
    for (field, spoil) in cases {
        let mut file = good.clone();
        spoil(&mut file);
        std::fs::write(&path, file.to_json()).expect("temp dir writable");
        let out = flash(&path, &fake.path, &[]);
        let stderr = text(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{field}: {stderr}");
        assert!(stderr.contains(field), "{field}: {stderr}");
    }
    let _ = std::fs::remove_file(&path);
    assert!(
        fake.state().requests.is_empty(),
        "the board was not touched"
    );
}

#[test]
fn a_file_of_another_board_written_by_force_is_recorded_as_from_that_boards_session() {
    let fake = FakeDevice::start(FakeConfig::default());
    let path = temp_file("foreign-recorded.json");
    foreign_file(&path);
    let db = temp_file("forced-history.sqlite");
    let _ = std::fs::remove_file(&db);
    let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .arg("flash")
        .arg(&path)
        .args(["--port", &fake.path, "--force-other-device", "--db"])
        .arg(format!("sqlite://{}", db.display()))
        .output()
        .expect("the imucal binary runs");
    let _ = std::fs::remove_file(&path);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let records =
        imucal::history::HistoryStore::open(&imucal::history::DbLocation::Sqlite(db.clone()))
            .and_then(|mut store| store.records(None))
            .expect("the history reads back");
    let _ = std::fs::remove_file(&db);
    assert_eq!(records.len(), 1);
    assert_eq!(
        records[0].record.board,
        imucal::history::BoardWrite::FromOtherBoard {
            measured_on: "00000000000000000000000000001234".into()
        }
    );
}

#[test]
fn a_gyroscope_matrix_that_mirrors_an_axis_never_reaches_the_board() {
    let fake = FakeDevice::start(FakeConfig::default());
    let path = temp_file("mirrored.json");
    let mut set = calibrated_set();
    // The z rate reversed: every turn about z would read the wrong way after calibration.
    set.gyro.a[2][2] = -1.0;
    std::fs::write(&path, ParamsFile::from(&set).to_json()).expect("temp dir writable");
    let out = flash(&path, &fake.path, &[]);
    let _ = std::fs::remove_file(&path);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("gyro.A has a negative determinant") && stderr.contains("axis mapping"),
        "{stderr}"
    );
    assert_eq!(fake.state().commits, 0, "nothing committed");
}

#[test]
fn a_file_without_a_magnetometer_keeps_the_boards_field_and_the_history_records_what_was_written() {
    let fake = FakeDevice::start(FakeConfig::default());
    let mut full = calibrated_set();
    full.reference.field_ut = 48.0;
    full.residuals.mag_rms = 0.3;
    let path = temp_file("with-mag.json");
    std::fs::write(&path, ParamsFile::from(&full).to_json()).expect("temp dir writable");
    assert!(flash(&path, &fake.path, &[]).status.success());

    // What `fit --params-out` writes for a recording without a magnetometer: the field and the
    // residual are placeholders, and the file says the magnetometer was not fitted.
    let mut update = CalibrationSet::identity();
    update.accel.b = [0.5, 0.5, 0.5];
    let mut file = ParamsFile::from(&update);
    file.not_fitted
        .insert("mag".into(), "not in the recording".into());
    std::fs::write(&path, file.to_json()).expect("temp dir writable");
    let db = temp_file("kept-mag.sqlite");
    let _ = std::fs::remove_file(&db);
    let out = flash_recording_in(&path, &fake.path, &db);
    let _ = std::fs::remove_file(&path);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let active = fake.state().active;
    assert_eq!(active.mag, full.mag, "the board's magnetometer is kept");
    assert_eq!(
        active.reference.field_ut, 48.0,
        "with the field it was fitted to"
    );
    assert_eq!(active.residuals.mag_rms, 0.3);

    let records =
        imucal::history::HistoryStore::open(&imucal::history::DbLocation::Sqlite(db.clone()))
            .and_then(|mut store| store.records(None))
            .expect("the history reads back");
    let _ = std::fs::remove_file(&db);
    let recorded = &records.last().expect("the flash is recorded").record;
    assert_eq!(
        recorded
            .params
            .to_calibration_set("history")
            .expect("a valid set"),
        active,
        "the history holds the set whose CRC it records"
    );
    assert!(!recorded.params.not_fitted.contains_key("mag"));
}

#[test]
fn a_sensor_the_file_leaves_out_and_the_board_never_calibrated_is_recorded_as_not_calibrated() {
    // A board fresh from the factory holds the identity set: keeping its magnetometer keeps
    // no calibration, so the history must not give the fleet its zero offset as a value.
    let fake = FakeDevice::start(FakeConfig::default());
    let mut update = CalibrationSet::identity();
    update.accel.b = [0.5, 0.5, 0.5];
    update.residuals.accel_rms = 0.01;
    let mut file = ParamsFile::from(&update);
    file.not_fitted
        .insert("mag".into(), "no --field-ut was given".into());
    let path = temp_file("never-calibrated-mag.json");
    std::fs::write(&path, file.to_json()).expect("temp dir writable");
    let db = temp_file("never-calibrated-mag.sqlite");
    let _ = std::fs::remove_file(&db);
    let out = flash_recording_in(&path, &fake.path, &db);
    let _ = std::fs::remove_file(&path);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert_eq!(fake.state().active.mag, SensorCalibration::identity());

    let records =
        imucal::history::HistoryStore::open(&imucal::history::DbLocation::Sqlite(db.clone()))
            .and_then(|mut store| store.records(None))
            .expect("the history reads back");
    let _ = std::fs::remove_file(&db);
    let recorded = &records.last().expect("the flash is recorded").record;
    assert!(
        recorded
            .params
            .not_fitted
            .get("mag")
            .is_some_and(|why| why.contains("held no mag calibration")),
        "{:?}",
        recorded.params.not_fitted
    );
    let parameters = recorded.parameters();
    assert!(
        parameters.keys().all(|name| !name.starts_with("mag.")),
        "{parameters:?}"
    );
    assert!(parameters.contains_key("accel.b.x"));
}

#[test]
fn a_file_without_its_device_block_is_still_checked_against_the_boards_ranges() {
    // A BMM150's hard iron of 380 µT, measured under its ±1300 µT range, with the file's
    // `device` block removed: within the ±400 µT of this board's magnetometer, so the set is
    // one the board accepts, but with the 48 µT field on top no reading of this part could
    // have shown it.
    let fake = FakeDevice::start(FakeConfig::default());
    let mut set = calibrated_set();
    set.mag.b = [380.0, -20.0, 35.0];
    set.reference.field_ut = 48.0;
    let path = temp_file("no-device-block.json");
    std::fs::write(&path, ParamsFile::from(&set).to_json()).expect("temp dir writable");
    let out = flash(&path, &fake.path, &[]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("is not for this board"), "{stderr}");
    assert!(
        stderr.contains("magnetometer offset") && stderr.contains("±400 µT range"),
        "{stderr}"
    );
    assert!(
        !stderr.contains("recording"),
        "where the file came from is not known: {stderr}"
    );
    assert_eq!(fake.state().commits, 0, "nothing written");

    let out = flash(&path, &fake.path, &["--force-other-device"]);
    let _ = std::fs::remove_file(&path);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert_eq!(fake.state().active.mag.b, set.mag.b);
}

/// `imucal flash PATH --port PORT --db DB`.
fn flash_recording_in(
    path: &std::path::Path,
    port: &str,
    db: &std::path::Path,
) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_imucal"))
        .arg("flash")
        .arg(path)
        .args(["--port", port, "--db"])
        .arg(db)
        .output()
        .expect("the imucal binary runs")
}

#[test]
fn a_set_past_every_common_parts_bounds_is_refused_as_calibrate_refuses_it_unless_accepted() {
    let fake = FakeDevice::start(FakeConfig::default());
    // A damaged accelerometer's offset, and a hand-edited gain of 1.5 on the x axis.
    for (name, edit) in [
        (
            "offset",
            (|s: &mut CalibrationSet| s.accel.b[0] = 3.1547) as fn(&mut CalibrationSet),
        ),
        ("gain", |s: &mut CalibrationSet| s.accel.a[0][0] = 1.5),
    ] {
        let mut set = calibrated_set();
        edit(&mut set);
        let path = temp_file(&format!("past-{name}.json"));
        std::fs::write(&path, ParamsFile::from(&set).to_json()).expect("temp dir writable");
        let before = fake.state().active;
        let out = flash(&path, &fake.path, &[]);
        let stderr = text(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{name}: {stderr}");
        assert!(
            stderr.contains("of every common part") && stderr.contains("--accept-outlier"),
            "{name}: {stderr}"
        );
        assert_eq!(fake.state().active, before, "{name}: nothing written");
        let out = flash(&path, &fake.path, &["--accept-outlier"]);
        let stderr = text(&out.stderr);
        let _ = std::fs::remove_file(&path);
        assert!(out.status.success(), "{name}: {stderr}");
        assert!(stderr.contains("(--accept-outlier)"), "{name}: {stderr}");
        assert_eq!(
            fake.state().active.accel,
            set.accel,
            "{name}: written when accepted"
        );
    }
}

#[test]
fn a_file_with_nan_or_of_an_unread_format_or_a_huge_value_says_so_plainly() {
    let fake = FakeDevice::start(FakeConfig::default());
    let json = ParamsFile::from(&calibrated_set()).to_json();
    let path = temp_file("plain.json");
    let pretty: serde_json::Value = serde_json::from_str(&json).expect("JSON");
    let pretty = serde_json::to_string_pretty(&pretty).expect("JSON");
    let with_nan = pretty.replacen("0.25", "NaN", 1);
    assert_ne!(with_nan, pretty);
    let format_0 = pretty.replacen("\"format\": 2", "\"format\": 0", 1);
    assert_ne!(format_0, pretty);
    let huge = pretty.replacen("0.25", "1e300", 1);
    for (text_of_file, words) in [
        (
            with_nan,
            "NaN or Infinity are not allowed in JSON parameters",
        ),
        (format_0, "reads formats 1 to 2"),
        (huge, "1e300"),
    ] {
        std::fs::write(&path, &text_of_file).expect("temp dir writable");
        let out = flash(&path, &fake.path, &[]);
        let stderr = text(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{stderr}");
        assert!(stderr.contains(words), "{words}: {stderr}");
        assert!(stderr.len() < 600, "{stderr}");
    }
    let _ = std::fs::remove_file(&path);
}
