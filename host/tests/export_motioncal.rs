//! `imucal export --format motioncal|adafruit-json`: the packet file is byte-exact to one built
//! here by hand from the documented layout (signature 117, 84; sixteen f32 little-endian; CRC-16
//! with the reflected polynomial 0xA001 from 0xFFFF over bytes 0–65, low byte first), and the
//! magnetometer travels in the symmetric gauge.

use std::path::PathBuf;
use std::process::Command;

use imucal::compat::{decode_packet, AdafruitCalibration};
use imucal::device::ParamsFile;
use imucal_protocol::{CalibrationSet, SensorCalibration};

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("imucal-mc-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temporary directory");
    dir
}

/// A set whose offsets and diagonal magnetometer matrix are known f32 values: a diagonal
/// positive matrix is its own symmetric form, so every float of the packet is known exactly.
fn diagonal_set() -> CalibrationSet {
    let mut set = CalibrationSet::identity();
    set.accel.b = [0.123, -0.0456, 0.0789];
    set.accel.a = [[1.01, 0.002, 0.0], [0.0, 0.99, 0.0], [0.0, 0.0, 1.0]];
    set.gyro.b = [0.0123, -0.0071, 0.0034];
    set.mag = SensorCalibration {
        a: [[0.97, 0.0, 0.0], [0.0, 1.031, 0.0], [0.0, 0.0, 0.994]],
        b: [12.5, -30.25, 7.125],
        ..SensorCalibration::identity()
    };
    set.reference.field_ut = 48.5;
    set
}

fn write_params(set: &CalibrationSet, dir: &std::path::Path) -> PathBuf {
    let path = dir.join("params.json");
    std::fs::write(&path, ParamsFile::from(set).to_json()).expect("write params");
    path
}

fn export(params: &std::path::Path, format: &str, out: &std::path::Path) -> String {
    let output = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .args(["export", params.to_str().unwrap(), "--format", format, "-o"])
        .arg(out)
        .output()
        .expect("imucal runs");
    let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
    assert!(output.status.success(), "export failed: {stderr}");
    stderr
}

/// The packet built by hand: no library code, its own CRC loop.
fn packet_by_hand(floats: [f32; 16]) -> Vec<u8> {
    let mut bytes = vec![117u8, 84];
    for f in floats {
        let n = f.to_bits();
        bytes.extend([n as u8, (n >> 8) as u8, (n >> 16) as u8, (n >> 24) as u8]);
    }
    let mut crc: u16 = 0xFFFF;
    for &b in &bytes {
        crc ^= u16::from(b);
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xA001
            } else {
                crc >> 1
            };
        }
    }
    bytes.push((crc & 0xFF) as u8);
    bytes.push((crc >> 8) as u8);
    bytes
}

#[test]
fn exported_motioncal_packet_is_byte_exact_to_the_documented_layout() {
    let dir = scratch("exact");
    let params = write_params(&diagonal_set(), &dir);
    let out = dir.join("cal.bin");
    let note = export(&params, "motioncal", &out);
    let written = std::fs::read(&out).expect("cal.bin written");
    let expected = packet_by_hand([
        0.123, -0.0456, 0.0789, // accel zero-g, m/s²
        0.0123, -0.0071, 0.0034, // gyro zero-rate, rad/s
        12.5, -30.25, 7.125, // hard iron, µT
        48.5,  // field, µT
        0.97, 1.031, 0.994, // soft iron diagonal
        0.0, 0.0, 0.0, // soft iron [0][1], [0][2], [1][2]
    ]);
    assert_eq!(written.len(), 68);
    assert_eq!(written, expected);
    // The accelerometer matrix is not identity: the user is told it is dropped.
    assert!(note.contains("accel: scale and misalignment"), "{note}");
}

/// `(AᵀA)^½` by the Denman–Beavers iteration (independent of the library's eigen route).
fn sqrt_by_iteration(m: [[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let mat = nalgebra::Matrix3::from_fn(|r, c| m[r][c]);
    let (mut y, mut z) = (mat, nalgebra::Matrix3::identity());
    for _ in 0..50 {
        let (yi, zi) = (y.try_inverse().unwrap(), z.try_inverse().unwrap());
        (y, z) = ((y + zi) * 0.5, (z + yi) * 0.5);
    }
    [0, 1, 2].map(|r| [0, 1, 2].map(|c| y[(r, c)]))
}

#[test]
fn triangular_magnetometer_matrix_is_sent_as_the_symmetric_square_root_of_ata() {
    let mut set = diagonal_set();
    set.mag.a = [[0.97, 0.012, -0.008], [0.0, 1.031, 0.02], [0.0, 0.0, 0.994]];
    let dir = scratch("gauge");
    let params = write_params(&set, &dir);
    let out = dir.join("cal.bin");
    export(&params, "motioncal", &out);
    let decoded = decode_packet(&std::fs::read(&out).unwrap()).expect("packet decodes, CRC ok");
    let a = set.mag.a.map(|r| r.map(f64::from));
    let ata = [0, 1, 2].map(|i| [0, 1, 2].map(|j| (0..3).map(|k| a[k][i] * a[k][j]).sum()));
    let s = sqrt_by_iteration(ata);
    for (r, row) in s.iter().enumerate() {
        for (c, expected) in row.iter().enumerate() {
            // f32 storage: about 1e-7 relative.
            let got = f64::from(decoded.mag_softiron[r][c]);
            assert!(
                (got - expected).abs() < 2e-7,
                "[{r}][{c}] {got} vs {expected}"
            );
        }
    }
    assert_eq!(decoded.mag_hardiron, set.mag.b);
}

#[test]
fn adafruit_json_has_the_flash_backend_keys_and_reads_back() {
    let set = diagonal_set();
    let dir = scratch("json");
    let params = write_params(&set, &dir);
    let out = dir.join("sensor_calib.json");
    export(&params, "adafruit-json", &out);
    let text = std::fs::read_to_string(&out).unwrap();
    let doc: serde_json::Value = serde_json::from_str(&text).expect("valid JSON");
    let keys: Vec<&str> = doc
        .as_object()
        .unwrap()
        .keys()
        .map(String::as_str)
        .collect();
    for key in [
        "mag_hardiron",
        "mag_softiron",
        "mag_field",
        "gyro_zerorate",
        "accel_zerog",
    ] {
        assert!(keys.contains(&key), "missing {key} in {text}");
    }
    assert_eq!(doc["mag_softiron"].as_array().unwrap().len(), 9);
    let back = AdafruitCalibration::from_sensor_calib_json(&text).unwrap();
    let conversion = AdafruitCalibration::from_set(&set).unwrap();
    assert_eq!(back, conversion.calibration);
}

#[test]
fn motioncal_export_without_an_output_file_is_refused_with_the_fix() {
    let dir = scratch("noout");
    let params = write_params(&diagonal_set(), &dir);
    let output = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .args(["export", params.to_str().unwrap(), "--format", "motioncal"])
        .output()
        .unwrap();
    assert!(!output.status.success());
    assert!(String::from_utf8_lossy(&output.stderr).contains("-o cal.bin"));
}
