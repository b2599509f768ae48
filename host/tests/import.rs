//! Importers: MotionCal `Raw:` serial logs and delimited files read through a column mapping.

use std::path::Path;

use imucal::compat::motioncal::{RawAccelScaling, SketchReading};
use imucal::recording::mapping::{self, ColumnMapping};
use imucal::recording::motioncal;
use imucal::recording::{AccelUnit, GyroUnit, MagUnit, Sensor, Units};

/// A log as the Adafruit/PJRC calibration sketch prints it, with MotionCal's other lines mixed in.
const MOTIONCAL_LOG: &str = "\
Adafruit AHRS calibration
Raw:0,0,8192,16,-32,0,250,-120,-400
Uni:0.00,0.00,9.81,0.0175,-0.0349,0.0000,25.00,-12.00,-40.00
Raw:-4096,8192,0,0,0,160,-250,120,401
Ori: 0.0,0.0,0.0
Raw:1,2,3,4,5,6,7,8,9
";

#[test]
fn motioncal_raw_lines_convert_with_the_sketch_scales_and_skip_other_lines() {
    let recording = motioncal::parse(MOTIONCAL_LOG, Path::new("log.txt"), Some(50.0)).unwrap();
    assert_eq!(recording.len(), 3);
    let accel = recording.accel.as_ref().unwrap();
    let gyro = recording.gyro.as_ref().unwrap();
    let mag = &recording.mag.as_ref().unwrap().samples;
    // Adafruit's sketch: 8192 counts = 9.8 m/s² (not standard gravity); 16 counts = 1 °/s;
    // 10 counts = 1 µT. The accelerometer's are exact (8192 is a power of two).
    assert_eq!(accel[0].z, 9.8);
    assert_eq!(accel[1].x, -4.9);
    assert!((gyro[0].y - (-2.0_f64).to_radians()).abs() < 1e-15);
    assert!((gyro[1].z - 10.0_f64.to_radians()).abs() < 1e-15);
    assert!((mag[0].x - 25.0).abs() < 1e-12 && (mag[1].z - 40.1).abs() < 1e-12);
    assert_eq!(
        recording.units,
        Units {
            accel: AccelUnit::Mps2,
            gyro: GyroUnit::Rads,
            mag: MagUnit::Ut
        }
    );
    assert_eq!(recording.time, vec![0.0, 0.02, 0.04]);
    assert!(!recording.time_is_index);
    assert!(motioncal::looks_like_motioncal(MOTIONCAL_LOG));
}

#[test]
fn a_saved_motioncal_log_reads_the_values_a_live_sketch_board_gives() {
    let counts = [-4096, 8192, 123, 16, -32, 160, -250, 120, 401];
    let line = format!("Raw:{}\n", counts.map(|c| c.to_string()).join(","));
    let recording = motioncal::parse(&line, Path::new("log.txt"), Some(50.0)).unwrap();
    // What `imucal record`/`stream` make of the same line from a board running the sketch.
    let live = SketchReading::from_raw(counts, RawAccelScaling::AdafruitSketch);
    let si = |v: &imucal::fit::Vec3| [v.x, v.y, v.z];
    assert_eq!(si(&recording.accel.as_ref().unwrap()[0]), live.accel);
    assert_eq!(si(&recording.gyro.as_ref().unwrap()[0]), live.gyro);
    assert_eq!(si(&recording.mag.as_ref().unwrap().samples[0]), live.mag);
    let units = recording.units;
    assert_eq!(
        [
            units.to_si(Sensor::Accel),
            units.to_si(Sensor::Gyro),
            units.to_si(Sensor::Mag)
        ],
        [Some(1.0); 3],
        "the live readings are in SI units"
    );
}

#[test]
fn motioncal_without_rate_counts_rows_and_garbled_lines_are_named() {
    let recording = motioncal::parse("Raw:1,2,3,4,5,6,7,8,9\n", Path::new("a"), None).unwrap();
    assert!(recording.time_is_index);
    let short = motioncal::parse("x\nRaw:1,2,3,4,5,6,7,8\n", Path::new("log.txt"), None)
        .unwrap_err()
        .to_string();
    assert!(
        short.contains("line 2") && short.contains("found 8"),
        "{short}"
    );
    let garbled = motioncal::parse("Raw:1,2,3,4,5,6,7,8,9x\n", Path::new("log.txt"), None)
        .unwrap_err()
        .to_string();
    assert!(garbled.contains("`9x` is not one"), "{garbled}");
    let empty = motioncal::parse("hello\n", Path::new("log.txt"), None).unwrap_err();
    assert!(
        empty.to_string().contains("not a MotionCal serial log"),
        "{empty}"
    );
}

const SEMICOLON_CSV: &str = "\
\"Timestamp\";\"AccX\";\"AccY\";\"AccZ\";\"GyrX\";\"GyrY\";\"GyrZ\";\"Temperature\";\"Extra\"
1000;0.01;-0.02;9.81;0.001;0.002;-0.003;24.5;x
1010;0.02;-0.01;9.80;0.000;0.001;-0.002;24.6;y
1025;9.81;0.00;0.10;0.000;0.000;0.000;24.6;z
";

#[test]
fn mapped_columns_are_read_with_the_time_unit_of_the_key() {
    let mapping: ColumnMapping =
        "t_ms=Timestamp,ax=AccX,ay=AccY,az=AccZ,gx=GyrX,gy=GyrY,gz=GyrZ,temp_c=temperature"
            .parse()
            .unwrap();
    let recording = mapping::parse(
        SEMICOLON_CSV,
        Path::new("export.csv"),
        &mapping,
        Units::default(),
        &[],
        None,
    )
    .unwrap();
    assert_eq!(recording.len(), 3);
    // Milliseconds to seconds: 1000 ms → 1 s; 1 ulp of 1.025 bounds the product's rounding.
    assert!((recording.time[2] - 1.025).abs() < 1e-15);
    assert_eq!(recording.accel.as_ref().unwrap()[2].x, 9.81);
    assert_eq!(recording.gyro.as_ref().unwrap()[0].z, -0.003);
    assert_eq!(recording.temp_c.as_ref().unwrap()[1], 24.6);
    assert!(recording.mag.is_none());
    assert!(!recording.time_is_index);
}

#[test]
fn mapping_errors_name_the_problem_and_the_available_columns() {
    let partial = "ax=AccX,ay=AccY"
        .parse::<ColumnMapping>()
        .unwrap_err()
        .to_string();
    assert!(partial.contains("all three"), "{partial}");
    let unknown = "qx=AccX".parse::<ColumnMapping>().unwrap_err().to_string();
    assert!(
        unknown.contains("`qx` is not an imucal column"),
        "{unknown}"
    );
    let mapping: ColumnMapping = "ax=AccelX,ay=AccY,az=AccZ".parse().unwrap();
    let missing = mapping::parse(
        SEMICOLON_CSV,
        Path::new("e.csv"),
        &mapping,
        Units::default(),
        &[],
        None,
    )
    .unwrap_err()
    .to_string();
    assert!(
        missing.contains("`AccelX`") && missing.contains("AccX, AccY"),
        "{missing}"
    );
    let bad_row = "a,b,c\n1,2,3\n1,zz,3\n";
    let mapping: ColumnMapping = "ax=a,ay=b,az=c".parse().unwrap();
    let error = mapping::parse(
        bad_row,
        Path::new("e.csv"),
        &mapping,
        Units::default(),
        &[],
        Some(10.0),
    )
    .unwrap_err()
    .to_string();
    assert!(
        error.contains("line 3") && error.contains("`zz`"),
        "{error}"
    );
}

#[test]
fn a_mapped_pose_or_segment_column_labels_the_rows() {
    let text = "\
Time;Label;AccX;AccY;AccZ
0.00;up;0.0;0.0;9.81
0.01;up;0.0;0.0;9.80
0.02;-;3.0;1.0;7.0
0.03;\"down\";0.0;0.0;-9.81
";
    let mapping: ColumnMapping = "t_s=Time,pose=Label,ax=AccX,ay=AccY,az=AccZ"
        .parse()
        .unwrap();
    let recording = mapping::parse(
        text,
        Path::new("p.csv"),
        &mapping,
        Units::default(),
        &[],
        None,
    )
    .expect("reads");
    let labels = recording.labels.expect("a pose column");
    assert_eq!(labels.kind, imucal::recording::LabelKind::Pose);
    assert_eq!(labels.names, ["up", "down"]);
    // `-` is no label; quotes are not part of one.
    assert_eq!(labels.per_row, [Some(0), Some(0), None, Some(1)]);

    let segments: ColumnMapping = "t_s=Time,segment=Label,ax=AccX,ay=AccY,az=AccZ"
        .parse()
        .unwrap();
    let recording = mapping::parse(
        text,
        Path::new("p.csv"),
        &segments,
        Units::default(),
        &[],
        None,
    )
    .expect("reads");
    let labels = recording.labels.expect("a segment column");
    assert_eq!(labels.kind, imucal::recording::LabelKind::Segment);

    let twice = "pose=Label,segment=Label,ax=AccX,ay=AccY,az=AccZ"
        .parse::<ColumnMapping>()
        .unwrap_err()
        .to_string();
    assert!(twice.contains("two label columns"), "{twice}");
}

#[test]
fn units_written_after_mapped_column_names_are_the_sensors_units_unless_an_option_says_otherwise() {
    let text = "Time;AccX [g];AccY [g];AccZ [g];GyrX (dps);GyrY (dps);GyrZ (dps)\n\
                0.00;0.01;0.02;1.00;0.5;0.0;-0.5\n\
                0.01;0.01;0.02;1.00;0.5;0.0;-0.5\n";
    let mapping: ColumnMapping =
        "t_s=Time,ax=AccX [g],ay=AccY [g],az=AccZ [g],gx=GyrX (dps),gy=GyrY (dps),gz=GyrZ (dps)"
            .parse()
            .expect("a valid mapping");
    let recording = mapping::parse(
        text,
        Path::new("u.csv"),
        &mapping,
        Units::default(),
        &[],
        None,
    )
    .expect("reads");
    assert_eq!(recording.units.accel, AccelUnit::G);
    assert_eq!(recording.units.gyro, GyroUnit::Dps);
    // --accel-unit mps2 given against the names' g: refused, naming both.
    let stated = Units {
        accel: AccelUnit::Mps2,
        ..Units::default()
    };
    let error = mapping::parse(
        text,
        Path::new("u.csv"),
        &mapping,
        stated,
        &[Sensor::Accel],
        None,
    )
    .expect_err("the option contradicts the header")
    .to_string();
    assert!(
        error.contains("--accel-unit") && error.contains("AccX [g]"),
        "{error}"
    );
}
