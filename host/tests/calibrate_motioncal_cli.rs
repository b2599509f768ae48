//! `imucal calibrate --sim --sim-protocol motioncal --yes` end to end through the binary: the
//! simulated Adafruit calibration-sketch board is calibrated, the packet saved in the session
//! directory passes its CRC and decodes to the fitted set in the symmetric gauge, and the board's
//! EEPROM holds exactly those values; every reading is kept as a recording, also after a Ctrl-C.

use std::path::Path;
use std::process::Command;

use imucal::compat::{decode_packet, AdafruitCalibration};
use imucal::device::ParamsFile;
use imucal_hil_sim::motioncal_board::MotionCalBoard;

const SEED: u64 = 7;

fn f32s(value: &serde_json::Value) -> Vec<f32> {
    value
        .as_array()
        .expect("an array")
        .iter()
        .map(|v| v.as_f64().expect("a number") as f32)
        .collect()
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

#[test]
fn the_simulated_sketch_board_is_calibrated_end_to_end_and_stores_the_fitted_packet() {
    let tmp = std::env::temp_dir().join(format!("imucal-motioncal-cli-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&tmp);
    std::fs::create_dir_all(&tmp).unwrap();
    let out = tmp.join("session");
    let run = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .args(["calibrate", "--sim", "--sim-protocol", "motioncal", "--yes"])
        // The board cannot apply the accelerometer's matrix, so the verdict is poor for this
        // firmware; the packet, which still corrects the offsets, is sent when asked to.
        .args([
            "--accept-poor",
            "--sim-seed",
            &SEED.to_string(),
            "--speed",
            "20",
            "-o",
        ])
        .arg(&out)
        .env("IMUCAL_DB", tmp.join("history.sqlite"))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(stdout.contains("cannot apply"), "{stdout}");
    // The verdict is of what the board applies: the library drops the accelerometer's scale,
    // which on this simulated part costs more than the 2 mg budget on the poses.
    let summary: serde_json::Value =
        serde_json::from_str(&read(&out.join("motioncal.json"))).unwrap();
    assert_eq!(summary["verdict"]["level"], "poor", "{summary}");
    assert!(
        summary["verdict"]["reasons"]
            .as_array()
            .is_some_and(|r| r.iter().any(|r| r
                .as_str()
                .is_some_and(|r| r.contains("applies only the accelerometer's offsets")
                    && r.contains("measuring again cannot change that")))),
        "{summary}"
    );
    assert!(stdout.contains("echoed Cal1:/Cal2: matching"), "{stdout}");
    // Every reading is kept, one row each, as a recording.
    let readings = read(&out.join("readings.csv"));
    assert_eq!(
        readings.lines().count() as u64 - 1,
        summary["readings"].as_u64().unwrap(),
        "one row per reading"
    );

    // The packet as sent: its CRC checks, and it is the fitted set in the symmetric gauge,
    // bit for bit (both are the same f32 values).
    let packet = std::fs::read(out.join("motioncal.bin")).unwrap();
    let sent = decode_packet(&packet).expect("the saved packet's CRC and header check");
    let params = ParamsFile::from_json(&read(&out.join("params.json")), "params.json").unwrap();
    let set = params.to_calibration_set("params.json").unwrap();
    let fitted = AdafruitCalibration::from_set(&set).unwrap().calibration;
    assert_eq!(sent, fitted);
    assert_eq!(sent.accel_zerog, set.accel.b);
    assert_eq!(sent.gyro_zerorate, set.gyro.b);

    // The board's EEPROM holds exactly what was sent.
    let eeprom: serde_json::Value =
        serde_json::from_str(&read(&out.join("sim-eeprom.json"))).unwrap();
    assert_eq!(eeprom["stored_count"], 1);
    assert_eq!(f32s(&eeprom["accel_zerog"]), sent.accel_zerog);
    assert_eq!(f32s(&eeprom["gyro_zerorate"]), sent.gyro_zerorate);
    assert_eq!(f32s(&eeprom["mag_hardiron"]), sent.mag_hardiron);
    assert_eq!(f32s(&eeprom["mag_softiron"]), sent.mag_softiron.concat());

    // Against the simulated sensor's truth: the hard iron is the magnetometer's offset. 0.5 µT
    // is ten times the fit's typical σ on a 48 µT sphere (≈0.02 µT), which still catches a wrong
    // unit, axis or sign while allowing for the tumble's uneven coverage.
    let truth = *MotionCalBoard::new(SEED).unwrap().truth();
    for axis in 0..3 {
        let error = f64::from(sent.mag_hardiron[axis]) - truth.mag.b_true[axis];
        assert!(error.abs() < 0.5, "hard iron axis {axis} off by {error} µT");
    }
    // Without --field-ut the simulated site's field is the reference, as with imucal's
    // firmware: the set and the packet carry it, not the sensor's mean radius.
    let site = MotionCalBoard::new(SEED).unwrap().site_field_ut();
    let written: serde_json::Value = serde_json::from_str(&read(&out.join("params.json"))).unwrap();
    assert_eq!(written["reference"]["field_ut"].as_f64(), Some(site));
    assert_eq!(sent.mag_field, site as f32);
    std::fs::remove_dir_all(&tmp).ok();
}

#[test]
fn ctrl_c_in_a_sketch_session_keeps_its_readings_as_a_recording_that_fit_reads() {
    use std::io::BufRead;
    let tmp = std::env::temp_dir().join(format!("imucal-motioncal-int-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&tmp);
    std::fs::create_dir_all(&tmp).unwrap();
    let out = tmp.join("session");
    let mut child = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .args(["calibrate", "--sim", "--sim-protocol", "motioncal", "--yes"])
        .args([
            "--sim-seed",
            &SEED.to_string(),
            "--speed",
            "20",
            "--no-history",
            "-o",
        ])
        .arg(&out)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Interrupt once two positions are held, so that there is something to keep.
    let stderr = child.stderr.take().unwrap();
    let mut lines = std::io::BufReader::new(stderr).lines();
    let mut seen = String::new();
    for line in lines.by_ref() {
        let line = line.unwrap();
        seen.push_str(&line);
        seen.push('\n');
        if line.contains("— 2/12") {
            break;
        }
    }
    assert!(seen.contains("— 2/12"), "no second position: {seen}");
    let status = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let rest: Vec<String> = lines.map_while(Result::ok).collect();
    let rest = rest.join("\n");
    let exit = child.wait().unwrap();
    assert_eq!(exit.code(), Some(1), "an interrupted session fails: {rest}");
    assert!(rest.contains("nothing was sent to the board"), "{rest}");
    let readings = out.join("readings.csv");
    assert!(rest.contains("readings.csv"), "the file is named: {rest}");
    // The saved readings are a recording: still detection finds the held positions again.
    let still = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .args(["still", "--json"])
        .arg(&readings)
        .output()
        .unwrap();
    let report: serde_json::Value = serde_json::from_slice(&still.stdout)
        .unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(&still.stderr)));
    let holds = report["intervals"].as_array().map_or(0, Vec::len);
    assert!(
        holds >= 2,
        "the two held positions are found again: {report}"
    );
    std::fs::remove_dir_all(&tmp).ok();
}
