//! Reading recordings: the CSV format (columns in any order, absent sensors, labels, files
//! without time), the IMU-TK text format, sibling magnetometer files, and error messages.

use std::path::{Path, PathBuf};

use imucal::recording::{
    AccelUnit, Format, GyroUnit, LabelKind, LoadOptions, MagUnit, Recording, RecordingError,
    Sensor, Units,
};

fn real(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../data/real")
        .join(name)
}

/// A fresh scratch directory for one test.
fn scratch(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("imucal-recording-{}-{test}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temporary directory is writable");
    dir
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).expect("temporary file is writable");
    path
}

fn load_err(path: &Path) -> RecordingError {
    match Recording::load(path, &LoadOptions::default()) {
        Ok(_) => panic!("{} should have been rejected", path.display()),
        Err(e) => e,
    }
}

#[test]
fn columns_in_any_order_are_read_as_written_with_absent_sensors_left_out() {
    let dir = scratch("order");
    let path = write(
        &dir,
        "r.csv",
        "az,temp_c,t_s,ay,ax,pose\n9.8,25.0,0.0,0.1,-0.2,3\n9.7,25.5,0.01,0.2,-0.3,3\n",
    );
    let rec = Recording::load(&path, &LoadOptions::default()).expect("valid file");
    let accel = rec.accel.as_ref().expect("accelerometer present");
    assert_eq!(accel[1].as_slice(), &[-0.3, 0.2, 9.7]);
    assert_eq!(rec.time, vec![0.0, 0.01]);
    assert_eq!(rec.temp_c, Some(vec![25.0, 25.5]));
    assert!(rec.gyro.is_none() && rec.mag.is_none());
    let labels = rec.labels.expect("pose column present");
    assert_eq!(labels.kind, LabelKind::Pose);
    assert_eq!(labels.value(0), 3, "an integer label keeps its value");
}

#[test]
fn unit_flags_keep_values_and_give_the_factor_to_si() {
    let units = Units {
        accel: AccelUnit::G,
        gyro: GyroUnit::Dps,
        mag: MagUnit::Gauss,
    };
    let rec = Recording::load(
        &real("sf_mpu6050_hmc5883l_full_sphere.csv"),
        &LoadOptions {
            units,
            ..Default::default()
        },
    )
    .expect("copied real recording reads");
    // First row of the file, verbatim.
    assert_eq!(rec.accel.as_ref().expect("accel")[0].x, 0.05200195312);
    assert_eq!(rec.units.to_si(Sensor::Accel), Some(9.80665));
    assert_eq!(rec.units.to_si(Sensor::Mag), Some(100.0));
}

#[test]
fn sibling_magnetometer_file_is_found_with_its_own_clock() {
    let rec = Recording::load(
        &real("sf_mpu6050_hmc5883l_full_sphere.csv"),
        &LoadOptions::default(),
    )
    .expect("reads");
    let mag = rec.mag.as_ref().expect("sibling _mag.csv is picked up");
    // Row counts from the data set's notes: 10528 inertial rows, 8190 magnetometer rows.
    assert_eq!(rec.len(), 10528);
    assert_eq!(mag.samples.len(), 8190);
    assert_eq!(mag.time.len(), 8190);
    let without = Recording::load(
        &real("sf_mpu6050_hmc5883l_full_sphere.csv"),
        &LoadOptions {
            no_mag_sibling: true,
            ..Default::default()
        },
    )
    .expect("reads");
    assert!(without.mag.is_none());
    // This magnetometer file has no temperature column; the main file's is its own.
    assert!(mag.temp_c.is_none() && rec.temp_c.is_some());
}

#[test]
fn a_magnetometer_file_keeps_its_own_temperature_column() {
    let dir = scratch("mag-temp");
    let main = write(&dir, "r.csv", "t_s,ax,ay,az\n0,0,0,9.8\n1,0,0,9.8\n");
    write(
        &dir,
        "r_mag.csv",
        "t_s,mx,my,mz,temp_c\n0.5,20,0,40,31.5\n1.5,21,0,40,32.0\n",
    );
    let rec = Recording::load(&main, &LoadOptions::default()).expect("reads");
    let mag = rec.mag.as_ref().expect("the sibling");
    assert_eq!(mag.temp_c.as_deref(), Some(&[31.5, 32.0][..]));
}

#[test]
fn a_bad_sibling_magnetometer_file_is_named_as_such_with_the_option_that_leaves_it_out() {
    let dir = scratch("bad-sibling");
    let main = write(&dir, "rec.csv", "t_s,ax,ay,az\n0,0,0,9.8\n0.01,0,0,9.8\n");
    write(&dir, "rec_mag.csv", "t_s,mx,my,mz\n0,1,2\n");
    let err = load_err(&main);
    let text = err.to_string();
    assert!(matches!(err, RecordingError::SiblingMag { .. }), "{text}");
    assert!(
        text.contains("rec_mag.csv")
            && text.contains("line 2")
            && text.contains("--no-mag-sibling"),
        "{text}"
    );
    let options = LoadOptions {
        no_mag_sibling: true,
        ..Default::default()
    };
    assert!(Recording::load(&main, &options).is_ok());
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn numbers_and_labels_in_quotes_are_read_as_without() {
    let dir = scratch("quoted");
    let plain = write(
        &dir,
        "plain.csv",
        "t_s,ax,ay,az,segment\n0,0.5,0,9.8,x_p\n0.01,0.25,0,9.8,x_p\n",
    );
    let quoted = write(
        &dir,
        "quoted.csv",
        "\"t_s\",\"ax\",\"ay\",\"az\",\"segment\"\n\"0\",\"0.5\",\"0\",\"9.8\",\"x_p\"\n\"0.01\",\"0.25\",\"0\",\"9.8\",\"x_p\"\n",
    );
    let a = Recording::load(&plain, &LoadOptions::default()).expect("plain reads");
    let b = Recording::load(&quoted, &LoadOptions::default()).expect("quoted reads");
    assert_eq!(a.accel, b.accel);
    assert_eq!(a.time, b.time);
    assert_eq!(
        b.labels.as_ref().map(|l| l.names.clone()),
        Some(vec!["x_p".to_string()])
    );
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn a_gyroscope_file_given_for_a_csv_recording_is_refused_not_ignored() {
    let options = LoadOptions {
        gyro_file: Some(real("imutk_xsens_multipos.csv")),
        ..Default::default()
    };
    let err = Recording::load(&real("imucal_nilspod_ferraris.csv"), &options)
        .expect_err("a CSV holds its own gyroscope columns");
    assert!(
        matches!(err, RecordingError::GyroFileWithCsv { .. }),
        "{err}"
    );
}

#[test]
fn segment_labels_of_the_real_ferraris_session_are_kept_by_name() {
    let rec = Recording::load(
        &real("imucal_nilspod_ferraris.csv"),
        &LoadOptions::default(),
    )
    .expect("reads");
    let labels = rec.labels.expect("segment column");
    assert_eq!(labels.kind, LabelKind::Segment);
    let names: Vec<&str> = labels.names.iter().map(String::as_str).collect();
    assert_eq!(
        names,
        ["x_p", "x_a", "y_p", "y_a", "z_p", "z_a", "x_rot", "y_rot", "z_rot"]
    );
    // `-` marks rows between sections: the first 540 rows precede x_p (from the shipped annotation).
    assert_eq!(
        labels.per_row.iter().take_while(|l| l.is_none()).count(),
        540
    );
}

#[test]
fn a_file_without_time_is_indexed_by_row_or_by_the_given_rate() {
    let dir = scratch("notime");
    let path = write(&dir, "ck.csv", "ax,ay,az\n0,0,1\n0,0,1\n0,0,1\n");
    let indexed = Recording::load(&path, &LoadOptions::default()).expect("reads");
    assert!(indexed.time_is_index);
    assert_eq!(indexed.time, vec![0.0, 1.0, 2.0]);
    let timed = Recording::load(
        &path,
        &LoadOptions {
            rate_hz: Some(50.0),
            ..Default::default()
        },
    )
    .expect("reads");
    assert!(!timed.time_is_index);
    assert_eq!(timed.time, vec![0.0, 0.02, 0.04]);
    assert!(matches!(
        Recording::load(
            &path,
            &LoadOptions {
                rate_hz: Some(-1.0),
                ..Default::default()
            }
        ),
        Err(RecordingError::BadRate(_))
    ));
}

#[test]
fn a_bad_number_is_reported_with_file_line_and_column() {
    let dir = scratch("badnum");
    let path = write(
        &dir,
        "bad.csv",
        "t_s,ax,ay,az\n0,1,2,3\n# comment\n0.1,1,2,abc\n",
    );
    let message = load_err(&path).to_string();
    assert!(message.contains("bad.csv"), "{message}");
    assert!(
        message.contains("line 4, column `az`: `abc` is not a finite number"),
        "{message}"
    );
    let nan = write(&dir, "nan.csv", "t_s,ax,ay,az\n0,NaN,2,3\n");
    assert!(load_err(&nan)
        .to_string()
        .contains("line 2, column `ax`: `NaN`"));
}

#[test]
fn malformed_headers_and_rows_are_refused_with_the_fix() {
    let dir = scratch("header");
    let partial = write(&dir, "p.csv", "t_s,ax,ay\n0,1,2\n");
    assert!(load_err(&partial)
        .to_string()
        .contains("`ax` is present but `az` is not"));
    let none = write(&dir, "n.csv", "t_s,foo\n0,1\n");
    assert!(matches!(load_err(&none), RecordingError::NoSensor { .. }));
    let short = write(&dir, "s.csv", "t_s,ax,ay,az\n0,1,2,3\n0.1,1,2\n");
    assert!(load_err(&short)
        .to_string()
        .contains("line 3: 3 fields but the header names 4 columns"));
    let back = write(&dir, "b.csv", "t_s,ax,ay,az\n1,1,2,3\n0.5,1,2,3\n");
    assert!(matches!(
        load_err(&back),
        RecordingError::TimeBackwards { line: 3, .. }
    ));
    // A clock that never advanced: every hold would last 0 s.
    let frozen = write(&dir, "f.csv", "t_s,ax,ay,az\n0,1,2,3\n0,1,2,3\n0,1,2,3\n");
    let error = load_err(&frozen);
    assert!(
        matches!(error, RecordingError::TimeConstant { rows: 3, .. }),
        "{error}"
    );
    assert!(error.to_string().contains("--rate"), "{error}");
    let empty = write(&dir, "e.csv", "");
    assert!(matches!(load_err(&empty), RecordingError::Empty { .. }));
    let dup = write(&dir, "d.csv", "ax,ay,az,ax\n1,2,3,4\n");
    assert!(matches!(
        load_err(&dup),
        RecordingError::DuplicateColumn { .. }
    ));
}

#[test]
fn imutk_text_files_read_back_the_same_samples_as_the_csv_copy() {
    let csv =
        Recording::load(&real("imutk_xsens_multipos.csv"), &LoadOptions::default()).expect("reads");
    let dir = scratch("imutk");
    let triad = |x: &[imucal::fit::Vec3]| {
        csv.time
            .iter()
            .zip(x)
            .map(|(t, v)| format!("{t:.6} {} {} {}\n", v.x, v.y, v.z))
            .collect::<String>()
    };
    let acc = write(
        &dir,
        "xsens_acc.mat",
        &triad(csv.accel.as_ref().expect("accel")),
    );
    let gyro = write(
        &dir,
        "xsens_gyro.mat",
        &triad(csv.gyro.as_ref().expect("gyro")),
    );
    let options = LoadOptions {
        gyro_file: Some(gyro),
        ..Default::default()
    };
    let text = Recording::load(&acc, &options).expect("auto-detected as IMU-TK");
    assert_eq!(text.accel, csv.accel);
    assert_eq!(text.gyro, csv.gyro);
    assert_eq!(text.time, csv.time);

    let truncated = write(&dir, "short_gyro.mat", "0.03 1 2 3\n");
    let options = LoadOptions {
        gyro_file: Some(truncated),
        format: Format::Imutk,
        ..Default::default()
    };
    let message = Recording::load(&acc, &options)
        .expect_err("row counts differ")
        .to_string();
    assert!(
        message.contains("51175 accelerometer rows but 1 gyroscope rows"),
        "{message}"
    );
}

#[test]
fn rows_that_repeat_the_row_before_exactly_are_read_once_and_counted() {
    let dir = scratch("repeated-rows");
    let text = "t_s,ax,ay,az,mx,my,mz\n\
                0.00,0.1,0.2,9.8,20,0,40\n\
                0.01,0.1,0.2,9.8,20,0,40\n\
                0.01,0.1,0.2,9.8,20,0,40\n\
                0.02,0.1,0.2,9.7,20,0,40\n\
                0.02,0.1,0.2,9.8,20,0,40\n\
                0.03,0.1,0.2,9.8,20,0,40\n";
    let path = write(&dir, "repeated.csv", text);
    let recording = Recording::load(&path, &LoadOptions::default()).expect("loads");
    // The third row repeats the second exactly and is left out; the fifth repeats only the
    // fourth's time stamp (a different value) and stays. A quantised sensor at rest repeats
    // its values at new time stamps, which also stay.
    assert_eq!(recording.repeated_rows, 1);
    assert_eq!(recording.time, vec![0.0, 0.01, 0.02, 0.02, 0.03]);
    assert_eq!(recording.accel.as_ref().map(Vec::len), Some(5));
    assert_eq!(recording.mag.as_ref().map(|m| m.samples.len()), Some(5));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn units_written_after_column_names_are_the_columns_units() {
    let dir = scratch("header-units");
    let path = write(
        &dir,
        "r.csv",
        "t_s [s],ax [g],ay [g],az [g],gx (deg/s),gy (deg/s),gz (deg/s),mx [uT],my [uT],mz [uT],temp_c [°C]\n\
         0.00,0.01,0.02,1.0,0.5,-0.5,0.1,20,-3,40,25\n\
         0.01,0.01,0.02,1.0,0.5,-0.5,0.1,20,-3,40,25\n",
    );
    let rec = Recording::load(&path, &LoadOptions::default()).expect("a unit in a name is read");
    assert_eq!(
        rec.units,
        Units {
            accel: AccelUnit::G,
            gyro: GyroUnit::Dps,
            mag: MagUnit::Ut
        }
    );
    assert!(rec.ignored_columns.is_empty(), "{:?}", rec.ignored_columns);
    assert_eq!(rec.accel.expect("accel read")[0].z, 1.0);
    assert_eq!(rec.temp_c, Some(vec![25.0, 25.0]));
    // A unit option that says the same is no conflict.
    let agreeing = LoadOptions {
        units: Units {
            accel: AccelUnit::G,
            ..Units::default()
        },
        units_stated: vec![Sensor::Accel],
        ..LoadOptions::default()
    };
    assert!(Recording::load(&path, &agreeing).is_ok());
}

#[test]
fn a_unit_option_that_contradicts_the_header_is_refused_naming_both() {
    let dir = scratch("header-units-conflict");
    let path = write(
        &dir,
        "r.csv",
        "t_s,ax [m/s2],ay [m/s2],az [m/s2]\n0,0,0,9.8\n0.01,0,0,9.8\n",
    );
    let options = LoadOptions {
        units: Units {
            accel: AccelUnit::G,
            ..Units::default()
        },
        units_stated: vec![Sensor::Accel],
        ..LoadOptions::default()
    };
    let text = match Recording::load(&path, &options) {
        Ok(_) => panic!("a header in m/s² read as g"),
        Err(e) => e.to_string(),
    };
    assert!(
        text.contains("`ax [m/s2]`")
            && text.contains("m/s²")
            && text.contains("--accel-unit says g"),
        "{text}"
    );
    // Left at its default, the option gives way to the header.
    let defaulted = LoadOptions {
        units_stated: Vec::new(),
        ..options
    };
    let rec = Recording::load(&path, &defaulted).expect("the header's unit is used");
    assert_eq!(rec.units.accel, AccelUnit::Mps2);
}

#[test]
fn a_unit_imucal_does_not_read_is_refused_naming_the_column_and_the_units_it_reads() {
    let dir = scratch("header-units-unknown");
    let path = write(&dir, "r.csv", "t_s,ax [mg],ay [mg],az [mg]\n0,0,0,1000\n");
    let text = load_err(&path).to_string();
    assert!(
        text.contains("`ax [mg]`")
            && text.contains("`mg`")
            && text.contains("m/s2")
            && text.contains("counts"),
        "{text}"
    );
    let mixed = write(&dir, "m.csv", "t_s,ax [g],ay [m/s2],az [g]\n0,0,0,1\n");
    let text = load_err(&mixed).to_string();
    assert!(text.contains("`ax [g]` and `ay [m/s2]`"), "{text}");
}
