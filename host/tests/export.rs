//! `imucal export`: the C header and the Rust module compile, and applied to readings they give
//! what the host computes within f32 precision; the JSON carries its schema and the values.

use std::path::PathBuf;
use std::process::Command;

use imucal::export::{apply_set, export, ExportFormat, EXPORT_SCHEMA_NAME, EXPORT_SCHEMA_VERSION};
use imucal_protocol::{BiasTemperature, CalibrationSet, Nonlinearity, SensorCalibration};

/// A set using every term of the model, with values of realistic size.
fn full_set() -> CalibrationSet {
    let mut set = CalibrationSet::identity();
    set.created_unix_s = 1_763_700_000;
    set.accel = SensorCalibration {
        a: [
            [1.0123, 0.0021, -0.0034],
            [0.0, 0.9876, 0.0045],
            [0.0, 0.0, 1.0045],
        ],
        b: [0.123, -0.0456, 0.0789],
        bias_temp: Some(BiasTemperature {
            t_ref_c: 25.0,
            coeffs: [[1.2e-3, -8e-4, 5e-4], [2e-5, 0.0, -1e-5], [0.0, 3e-7, 0.0]],
        }),
        scale_temp: Some([1e-4, -5e-5, 2e-5]),
        nonlinearity: Some(Nonlinearity {
            quadratic: [1e-4, -2e-4, 5e-5],
            cubic: [1e-6, 0.0, -2e-6],
        }),
    };
    set.gyro = SensorCalibration {
        a: [
            [1.01, -0.002, 0.003],
            [0.001, 0.995, -0.004],
            [0.002, 0.001, 1.003],
        ],
        b: [0.0123, -0.0071, 0.0034],
        bias_temp: None,
        scale_temp: Some([2e-4, 1e-4, -1e-4]),
        nonlinearity: None,
    };
    set.mag = SensorCalibration {
        a: [[0.97, 0.012, -0.008], [0.0, 1.031, 0.02], [0.0, 0.0, 0.994]],
        b: [12.5, -30.25, 7.125],
        ..SensorCalibration::identity()
    };
    set.gyro_g_sensitivity = Some([[1e-4, 0.0, 2e-5], [0.0, -1e-4, 0.0], [3e-5, 0.0, 5e-5]]);
    set.reference.field_ut = 48.5;
    set
}

/// One sample: accelerometer m/s², gyroscope rad/s, magnetometer µT, temperature °C.
type Reading = ([f64; 3], [f64; 3], [f64; 3], f64);

/// Readings spread over the sensors' ranges.
const READINGS: [Reading; 3] = [
    (
        [9.81, 0.12, -0.3],
        [0.01, -0.02, 0.5],
        [20.0, -5.0, 40.0],
        31.5,
    ),
    (
        [-0.2, -9.7, 0.4],
        [-1.5, 0.3, 0.0],
        [-35.0, 12.0, -8.0],
        18.0,
    ),
    ([3.0, 4.0, 8.1], [0.0, 0.0, 0.0], [0.5, 45.0, 3.0], 25.0),
];

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("imucal-export-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temporary directory");
    dir
}

fn run(command: &mut Command) -> String {
    let output = command.output().expect("the compiler runs");
    assert!(
        output.status.success(),
        "{command:?} failed:\n{}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8_lossy(&output.stdout).into_owned()
}

/// Compares printed outputs (9 numbers per reading) with the host's f64 apply. Each output
/// passes through about twenty f32 roundings (ε = 6e-8 relative) on operands at most ~50 in
/// size, so 2e-5 absolute plus 1e-6 relative bounds f32 evaluation and nothing looser.
fn assert_matches_host(set: &CalibrationSet, printed: &str) {
    let values: Vec<f64> = printed
        .split_whitespace()
        .map(|v| v.parse().expect("a number"))
        .collect();
    assert_eq!(values.len(), READINGS.len() * 9, "{printed}");
    for (i, (a, g, m, t)) in READINGS.iter().enumerate() {
        let host = apply_set(set, *a, *g, *m, *t);
        for (j, expected) in host.iter().flatten().enumerate() {
            let got = values[i * 9 + j];
            assert!(
                (got - expected).abs() <= 2e-5 + 1e-6 * expected.abs(),
                "reading {i} output {j}: exported code gives {got}, host {expected}"
            );
        }
    }
}

#[test]
fn c_header_compiles_warning_free_and_applies_like_the_host() {
    let set = full_set();
    let dir = scratch("c");
    let header = export(&set, ExportFormat::CHeader, "params.json");
    assert!(header.contains("#pragma once"));
    assert!(header.contains("static const float imucal_accel_A[3][3]"));
    assert!(header.contains("y = A * (x - b)"));
    std::fs::write(dir.join("imucal_calibration.h"), &header).unwrap();
    let mut program =
        String::from("#include <stdio.h>\n#include \"imucal_calibration.h\"\nint main(void) {\n");
    for (a, g, m, t) in READINGS {
        program.push_str(&format!(
            "  {{ const float a[3] = {{{:?}f, {:?}f, {:?}f}}, g[3] = {{{:?}f, {:?}f, {:?}f}}, m[3] = {{{:?}f, {:?}f, {:?}f}};\n    float fa[3], fg[3], fm[3];\n    imucal_apply_accel(a, {t:?}f, fa);\n    imucal_apply_gyro(g, {t:?}f, fa, fg);\n    imucal_apply_mag(m, fm);\n    for (int i = 0; i < 3; i++) printf(\"%.9g %.9g %.9g\\n\", fa[i], fg[i], fm[i]);\n  }}\n",
            a[0], a[1], a[2], g[0], g[1], g[2], m[0], m[1], m[2]
        ));
    }
    program.push_str("  return 0;\n}\n");
    std::fs::write(dir.join("main.c"), program).unwrap();
    let strict = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic"];
    // Included twice: `#pragma once` must make the second inclusion harmless.
    std::fs::write(
        dir.join("check.c"),
        "#include \"imucal_calibration.h\"\n#include \"imucal_calibration.h\"\n",
    )
    .unwrap();
    run(Command::new("gcc")
        .args(strict)
        .arg("-fsyntax-only")
        .arg(dir.join("check.c")));
    run(Command::new("gcc")
        .args(strict)
        .arg("-O2")
        .arg("-o")
        .arg(dir.join("apply"))
        .arg(dir.join("main.c")));
    let printed = run(&mut Command::new(dir.join("apply")));
    // The C program prints per axis (accel, gyro, mag); reorder to per sensor.
    let rows: Vec<Vec<&str>> = printed
        .lines()
        .map(|l| l.split_whitespace().collect())
        .collect();
    let mut per_sensor = Vec::new();
    for reading in rows.chunks(3) {
        for sensor in 0..3 {
            for axis in reading {
                per_sensor.push(axis[sensor]);
            }
        }
    }
    assert_matches_host(&set, &per_sensor.join(" "));
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn rust_module_compiles_without_warnings_and_applies_like_the_host() {
    let set = full_set();
    let dir = scratch("rust");
    let module = export(&set, ExportFormat::Rust, "params.json");
    assert!(module.contains("pub const ACCEL_A: [[f32; 3]; 3]"));
    std::fs::write(dir.join("imucal_calibration.rs"), &module).unwrap();
    let mut main = String::from("#[allow(dead_code)] // the constants not read here\nmod imucal_calibration { include!(\"imucal_calibration.rs\"); }\nuse imucal_calibration::*;\nfn main() {\n");
    for (a, g, m, t) in READINGS {
        main.push_str(&format!(
            "    let fa = apply_accel([{:?}, {:?}, {:?}], {t:?});\n    let fg = apply_gyro([{:?}, {:?}, {:?}], {t:?}, fa);\n    let fm = apply_mag([{:?}, {:?}, {:?}]);\n    for v in fa.iter().chain(&fg).chain(&fm) {{ print!(\"{{v:e}} \"); }}\n",
            a[0], a[1], a[2], g[0], g[1], g[2], m[0], m[1], m[2]
        ));
    }
    main.push_str("}\n");
    std::fs::write(dir.join("main.rs"), main).unwrap();
    let rustc = std::env::var("RUSTC").unwrap_or_else(|_| "rustc".to_string());
    run(Command::new(&rustc)
        .args([
            "--edition",
            "2021",
            "--crate-type",
            "lib",
            "-D",
            "warnings",
            "--out-dir",
        ])
        .arg(&dir)
        .arg(dir.join("imucal_calibration.rs")));
    run(Command::new(&rustc)
        .args(["--edition", "2021", "-D", "warnings", "-o"])
        .arg(dir.join("apply"))
        .arg(dir.join("main.rs")));
    let printed = run(&mut Command::new(dir.join("apply")));
    assert_matches_host(&set, &printed);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn plain_calibration_exports_only_a_and_b_and_a_temperature_free_apply() {
    let mut set = CalibrationSet::identity();
    set.accel.b = [0.1, 0.2, 0.3];
    let header = export(&set, ExportFormat::CHeader, "p.json");
    assert!(!header.contains("bias_temp") && !header.contains("scale_temp"));
    assert!(header.contains("imucal_apply_accel(const float x[3], float y[3])"));
    let module = export(&set, ExportFormat::Rust, "p.json");
    assert!(module.contains("pub fn apply_accel(x: [f32; 3]) -> [f32; 3]"));
}

#[test]
fn json_export_names_its_schema_and_keeps_every_f32_exactly() {
    let set = full_set();
    let text = export(&set, ExportFormat::Json, "params.json");
    let doc: serde_json::Value = serde_json::from_str(&text).expect("valid JSON");
    assert_eq!(doc["schema"], EXPORT_SCHEMA_NAME);
    assert_eq!(doc["schema_version"], EXPORT_SCHEMA_VERSION);
    assert_eq!(doc["matrix_order"], "row-major");
    let a01 = doc["accel"]["A"][0][1].as_f64().unwrap() as f32;
    assert_eq!(a01, set.accel.a[0][1]);
    let b2 = doc["mag"]["b"][2].as_f64().unwrap() as f32;
    assert_eq!(b2, set.mag.b[2]);
    assert_eq!(doc["accel"]["bias_temp"]["t_ref_c"], 25.0);
    assert!(doc["mag"].get("bias_temp").is_none());
    assert_eq!(
        doc["gyro_g_sensitivity"][2][0].as_f64().unwrap() as f32,
        3e-5f32
    );
}
