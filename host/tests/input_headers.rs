//! Headers as loggers write them, on the command line: units after the column names, and sensor
//! columns under names imucal does not read, which must not cost a sensor in silence.

use std::path::PathBuf;
use std::process::Command;

use serde_json::Value;

fn imucal(args: &[&str]) -> (Option<i32>, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .args(args)
        .output()
        .expect("the binary runs");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// The NilsPod recording (accelerometer in m/s², gyroscope in °/s) with its header replaced.
fn nilspod_with_header(name: &str, header: &str) -> String {
    let source =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data/real/imucal_nilspod_ferraris.csv");
    let text = std::fs::read_to_string(source).expect("the real recording is in the repository");
    let (_, rows) = text.split_once('\n').expect("a header line");
    let dir = std::env::temp_dir().join(format!("imucal-input-headers-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temporary directory is writable");
    let path = dir.join(name);
    std::fs::write(&path, format!("{header}\n{rows}")).expect("scratch file is writable");
    path.display().to_string()
}

#[test]
fn units_in_the_header_read_every_sensor_in_them_without_unit_flags() {
    let path = nilspod_with_header(
        "units.csv",
        "t_s,ax [m/s2],ay [m/s2],az [m/s2],gx (dps),gy (dps),gz (dps),segment",
    );
    let (code, stdout, stderr) = imucal(&["still", &path, "--json"]);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(!stderr.contains("not read"), "{stderr}");
    let json: Value = serde_json::from_str(&stdout).expect("JSON");
    assert_eq!(json["units"]["accel_mean"], "m/s²", "{json}");
    assert_eq!(json["units"]["gyro_mean"], "°/s", "{json}");
    let (plain, plain_stdout, _) = imucal(&[
        "still",
        &PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("../data/real/imucal_nilspod_ferraris.csv")
            .display()
            .to_string(),
        "--gyro-unit",
        "dps",
        "--json",
    ]);
    assert_eq!(plain, Some(0));
    let plain: Value = serde_json::from_str(&plain_stdout).expect("JSON");
    assert_eq!(
        json["intervals"], plain["intervals"],
        "the same holds as with --gyro-unit dps"
    );
    // A flag that contradicts the header is refused, naming both, with the usage status: the
    // command line is what is fixed.
    let (code, _, stderr) = imucal(&["still", &path, "--gyro-unit", "rads"]);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(
        stderr.contains("`gx (dps)`") && stderr.contains("--gyro-unit says rad/s"),
        "{stderr}"
    );
}

#[test]
fn sensor_columns_under_other_names_are_refused_rather_than_the_sensor_dropped() {
    let path = nilspod_with_header("accx.csv", "t_s,AccX,AccY,AccZ,gx,gy,gz,segment");
    for command in ["still", "fit"] {
        let (code, _, stderr) = imucal(&[command, &path, "--gyro-unit", "dps"]);
        assert_eq!(code, Some(1), "{command}: {stderr}");
        assert!(
            stderr.contains("`accx`, `accy`, `accz`")
                && stderr.contains("`ax ay az`")
                && stderr.contains("--columns ax=accx,ay=accy,az=accz"),
            "{command}: {stderr}"
        );
    }
    // Fitting another sensor alone does not need them: they are only said to be unread.
    let (code, _, stderr) = imucal(&["fit", &path, "--gyro-unit", "dps", "--sensor", "gyro"]);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(stderr.contains("not read from"), "{stderr}");
}
