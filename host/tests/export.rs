//! One calibration model, four implementations: the firmware's folded `f32` path
//! (`imucal_firmware::apply::Correction`), the protocol's `f64` reference
//! (`imucal_protocol::model::apply`), and the C header and Rust module of `imucal export`,
//! compiled here with gcc and rustc. The same sets (plain, every extended term, scale
//! temperature alone) and the same raw samples (rails included, temperatures far beyond the
//! ±125 °C ΔT clamp) go through all four, which must agree within f32 precision. Export also
//! refuses what the board refuses, and its JSON carries its schema and exact values.

use std::path::{Path, PathBuf};
use std::process::Command;

use imucal::export::{export, ExportFormat, EXPORT_SCHEMA_NAME, EXPORT_SCHEMA_VERSION};
use imucal_firmware::apply::Correction;
use imucal_protocol::{
    model, BiasTemperature, CalibrationSet, InvalidParamsReason, NominalSample, Nonlinearity,
    ParamField, RawSample, SensorCalibration, SensorKind, SensorScales,
};

/// An LSM9DS1-like board: ±2 g, ±250 °/s, ±4 gauss, 16 counts per °C about 25 °C.
const SCALES: SensorScales = SensorScales::EXAMPLE_LSM9DS1;

/// A set with `A` and `b` only.
fn plain_set() -> CalibrationSet {
    let mut set = CalibrationSet::identity();
    set.created_unix_s = 1_763_700_000;
    set.accel.a = [
        [1.0123, 0.0021, -0.0034],
        [0.0, 0.9876, 0.0045],
        [0.0, 0.0, 1.0045],
    ];
    set.accel.b = [0.123, -0.0456, 0.0789];
    set.gyro.a = [
        [1.01, -0.002, 0.003],
        [0.001, 0.995, -0.004],
        [0.002, 0.001, 1.003],
    ];
    set.gyro.b = [0.0123, -0.0071, 0.0034];
    set.mag.a = [[0.97, 0.012, -0.008], [0.0, 1.031, 0.02], [0.0, 0.0, 0.994]];
    set.mag.b = [12.5, -30.25, 7.125];
    set.reference.field_ut = 48.5;
    set
}

/// Every term of the model, with values of a poor but real MEMS part and distinct `T_ref`s.
fn full_set() -> CalibrationSet {
    let mut set = plain_set();
    set.accel = SensorCalibration {
        t_ref_c: 25.0,
        bias_temp: Some(BiasTemperature {
            coeffs: [[1.2e-3, -8e-4, 5e-4], [2e-5, 0.0, -1e-5], [0.0, 3e-7, 0.0]],
        }),
        scale_temp: Some([1e-4, -5e-5, 2e-5]),
        nonlinearity: Some(Nonlinearity {
            quadratic: [1e-4, -2e-4, 5e-5],
            cubic: [1e-6, 0.0, -2e-6],
        }),
        ..set.accel
    };
    set.gyro = SensorCalibration {
        t_ref_c: 31.5,
        bias_temp: Some(BiasTemperature {
            coeffs: [[1e-4, -2e-4, 3e-5], [0.0; 3], [0.0; 3]],
        }),
        scale_temp: Some([2e-4, 1e-4, -1e-4]),
        ..set.gyro
    };
    set.mag.t_ref_c = 18.0;
    set.mag.scale_temp = Some([0.0, 0.0, 3e-4]);
    set.gyro_g_sensitivity = Some([[1e-4, 0.0, 2e-5], [0.0, -1e-4, 0.0], [3e-5, 0.0, 5e-5]]);
    set
}

/// Scale temperature alone, about its own reference (format 1 took 0 °C here).
fn scale_temperature_only_set() -> CalibrationSet {
    let mut set = plain_set();
    set.accel.t_ref_c = 25.0;
    set.accel.scale_temp = Some([1e-4; 3]);
    set
}

/// Raw samples over the count range, at −40, 10, 25, 40 and 85 °C and on both thermometer
/// rails (−2023 °C and 2073 °C, far beyond the clamp).
fn samples() -> Vec<RawSample> {
    let temps = [-1040i16, -240, 0, 240, 960, i16::MIN, i16::MAX];
    let vectors = [
        [16_384i16, 200, -300],
        [-150, -16_200, 700],
        [5_000, 6_500, 13_000],
        [i16::MAX, i16::MIN, 0],
    ];
    let mut out = Vec::new();
    for (i, temp) in temps.into_iter().enumerate() {
        for (j, v) in vectors.iter().enumerate() {
            let k = (i + j) % vectors.len();
            out.push(RawSample {
                accel: *v,
                gyro: vectors[k].map(|c| c / 8),
                mag: vectors[(k + 1) % vectors.len()].map(|c| c / 2),
                temp,
            });
        }
    }
    out
}

/// A sample in nominal units as `f32`, as a board without imucal firmware would hold it.
fn nominal_f32(raw: &RawSample) -> [f32; 10] {
    let s = SCALES;
    let scale = |c: [i16; 3], per: f32| c.map(|v| f32::from(v) * per);
    let [a, g, m] = [
        scale(raw.accel, s.accel_mps2_per_count),
        scale(raw.gyro, s.gyro_rads_per_count),
        scale(raw.mag, s.mag_ut_per_count),
    ];
    let t = s.temp_offset_c + s.temp_c_per_count * f32::from(raw.temp);
    [a[0], a[1], a[2], g[0], g[1], g[2], m[0], m[1], m[2], t]
}

/// The protocol's f64 reference on the same f32 nominal values the exports receive.
fn reference(set: &CalibrationSet, raw: &RawSample) -> [f64; 9] {
    let x = nominal_f32(raw).map(f64::from);
    let out = model::apply(
        set,
        &NominalSample {
            accel: [x[0], x[1], x[2]],
            gyro: [x[3], x[4], x[5]],
            mag: [x[6], x[7], x[8]],
            temp_c: x[9],
        },
    );
    let [a, g, m] = [out.accel, out.gyro, out.mag];
    [a[0], a[1], a[2], g[0], g[1], g[2], m[0], m[1], m[2]]
}

fn firmware(set: &CalibrationSet, raw: &RawSample) -> [f64; 9] {
    let out = Correction::new(set, &SCALES)
        .expect("the test sets are valid")
        .apply(raw);
    let [a, g, m] = [out.accel, out.gyro, out.mag];
    [a[0], a[1], a[2], g[0], g[1], g[2], m[0], m[1], m[2]].map(f64::from)
}

/// Each output passes through about twenty f32 roundings (ε = 6e-8) of operands up to about
/// twice the sensor's full scale, so 1e-5 of full scale bounds f32 evaluation in any order and
/// nothing looser: a missing term or a different ΔT rule moves outputs by 1e-3 and more.
fn assert_agree(what: &str, set_name: &str, got: &[f64], truth: &[f64; 9], sample: usize) {
    let full_scale = [
        SCALES.accel_range_mps2,
        SCALES.gyro_range_rads,
        SCALES.mag_range_ut,
    ];
    for (i, (got, want)) in got.iter().zip(truth).enumerate() {
        let tolerance = 1e-5 * f64::from(full_scale[i / 3]);
        assert!(
            (got - want).abs() <= tolerance,
            "{set_name}, sample {sample}, output {i}: {what} gives {got}, the reference {want}"
        );
    }
}

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

fn has_temperature(cal: &SensorCalibration) -> bool {
    cal.bias_temp.is_some() || cal.scale_temp.is_some()
}

/// The samples as rows of `{x0, …, x8, T}` literals, in C (`f` suffix) or Rust syntax.
fn sample_rows(suffix: &str) -> String {
    samples()
        .iter()
        .map(|raw| {
            let values: Vec<String> = nominal_f32(raw)
                .iter()
                .map(|v| format!("{v:?}{suffix}"))
                .collect();
            values.join(", ")
        })
        .collect::<Vec<_>>()
        .join(if suffix.is_empty() {
            "],\n    ["
        } else {
            "},\n    {"
        })
}

/// Compiles the C header of `set` with a driver that prints the nine outputs per sample.
fn compiled_c(set: &CalibrationSet, dir: &Path) -> String {
    let header = export(set, ExportFormat::CHeader, "params.json").expect("a valid set");
    std::fs::write(dir.join("imucal_calibration.h"), &header).unwrap();
    let temp = |cal: &SensorCalibration| if has_temperature(cal) { "s[9], " } else { "" };
    let g_sensitivity = if set.gyro_g_sensitivity.is_some() {
        "fa, "
    } else {
        ""
    };
    let program = format!(
        "#include <stdio.h>\n#include \"imucal_calibration.h\"\nstatic const float samples[][10] = {{\n    {{{rows}}},\n}};\nint main(void) {{\n  for (unsigned n = 0; n < sizeof samples / sizeof samples[0]; n++) {{\n    const float *s = samples[n];\n    float fa[3], fg[3], fm[3];\n    imucal_apply_accel(s, {ta}fa);\n    imucal_apply_gyro(s + 3, {tg}{g_sensitivity}fg);\n    imucal_apply_mag(s + 6, {tm}fm);\n    printf(\"%.9g %.9g %.9g %.9g %.9g %.9g %.9g %.9g %.9g\\n\", fa[0], fa[1], fa[2], fg[0], fg[1], fg[2], fm[0], fm[1], fm[2]);\n  }}\n  return 0;\n}}\n",
        rows = sample_rows("f"),
        ta = temp(&set.accel),
        tg = temp(&set.gyro),
        tm = temp(&set.mag),
    );
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
        .arg(dir.join("apply_c"))
        .arg(dir.join("main.c")));
    run(&mut Command::new(dir.join("apply_c")))
}

/// Compiles the Rust module of `set` (alone as a library with `-D warnings`, then with a
/// driver) and returns what the driver prints: nine outputs per sample.
fn compiled_rust(set: &CalibrationSet, dir: &Path) -> String {
    let module = export(set, ExportFormat::Rust, "params.json").expect("a valid set");
    std::fs::write(dir.join("imucal_calibration.rs"), &module).unwrap();
    let temp = |cal: &SensorCalibration| if has_temperature(cal) { ", s[9]" } else { "" };
    let g_sensitivity = if set.gyro_g_sensitivity.is_some() {
        ", fa"
    } else {
        ""
    };
    let main = format!(
        "#[allow(dead_code)] // the constants not read here\nmod imucal_calibration {{ include!(\"imucal_calibration.rs\"); }}\nuse imucal_calibration::*;\nconst SAMPLES: &[[f32; 10]] = &[\n    [{rows}],\n];\nfn main() {{\n    for s in SAMPLES {{\n        let fa = apply_accel([s[0], s[1], s[2]]{ta});\n        let fg = apply_gyro([s[3], s[4], s[5]]{tg}{g_sensitivity});\n        let fm = apply_mag([s[6], s[7], s[8]]{tm});\n        for v in fa.iter().chain(&fg).chain(&fm) {{ print!(\"{{v:e}} \"); }}\n        println!();\n    }}\n}}\n",
        rows = sample_rows(""),
        ta = temp(&set.accel),
        tg = temp(&set.gyro),
        tm = temp(&set.mag),
    );
    std::fs::write(dir.join("main.rs"), main).unwrap();
    let rustc = std::env::var("RUSTC").unwrap_or_else(|_| "rustc".to_string());
    run(Command::new(&rustc)
        .args(["--edition", "2021", "--crate-type", "lib", "-D", "warnings"])
        .arg("--out-dir")
        .arg(dir)
        .arg(dir.join("imucal_calibration.rs")));
    run(Command::new(&rustc)
        .args(["--edition", "2021", "-D", "warnings", "-o"])
        .arg(dir.join("apply_rs"))
        .arg(dir.join("main.rs")));
    run(&mut Command::new(dir.join("apply_rs")))
}

fn parse_rows(printed: &str) -> Vec<Vec<f64>> {
    printed
        .lines()
        .map(|line| {
            line.split_whitespace()
                .map(|v| v.parse().expect("a number"))
                .collect()
        })
        .collect()
}

fn gcc_available() -> bool {
    Command::new("gcc").arg("--version").output().is_ok()
}

#[test]
fn firmware_reference_and_compiled_c_and_rust_exports_agree_on_every_set() {
    let sets = [
        ("plain", plain_set()),
        ("every extended term", full_set()),
        ("scale temperature alone", scale_temperature_only_set()),
    ];
    let with_c = gcc_available();
    if !with_c {
        eprintln!("SKIPPED the C export: no `gcc` on PATH (install a C compiler to run it)");
    }
    let samples = samples();
    for (name, set) in &sets {
        let dir = scratch(&name.replace(' ', "-"));
        let mut implementations = vec![(
            "the firmware",
            samples
                .iter()
                .map(|raw| firmware(set, raw).to_vec())
                .collect(),
        )];
        implementations.push(("the Rust export", parse_rows(&compiled_rust(set, &dir))));
        if with_c {
            implementations.push(("the C export", parse_rows(&compiled_c(set, &dir))));
        }
        for (what, rows) in &implementations {
            assert_eq!(rows.len(), samples.len(), "{what} printed {rows:?}");
            for (n, (row, raw)) in rows.iter().zip(&samples).enumerate() {
                assert_eq!(row.len(), 9, "{what}: {row:?}");
                assert_agree(what, name, row, &reference(set, raw), n);
            }
        }
        let _ = std::fs::remove_dir_all(dir);
    }
}

#[test]
fn the_cross_check_tolerance_detects_a_missing_clamp() {
    // Guards the test above: without the clamp the full set's output at the rail differs from
    // the reference by far more than the tolerance.
    let set = full_set();
    let hot = RawSample {
        accel: [16_384, 0, 0],
        temp: i16::MAX,
        ..RawSample::default()
    };
    let x = nominal_f32(&hot).map(f64::from);
    let dt = x[9] - f64::from(set.accel.t_ref_c);
    let unclamped = (1.0 + 1e-4 * dt) * f64::from(set.accel.a[0][0]) * x[0];
    let clamped = reference(&set, &hot)[0];
    assert!((unclamped - clamped).abs() > 1e-5 * 19.6 * 100.0);
}

/// Makes a valid set invalid.
type Corruption = fn(&mut CalibrationSet);

#[test]
fn export_refuses_what_the_board_would_refuse_naming_the_field() {
    let cases: [(Corruption, InvalidParamsReason); 4] = [
        (
            |s| s.accel.a = [[1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            InvalidParamsReason::IllConditioned(SensorKind::Accel),
        ),
        (
            |s| s.gyro.a = [[9.8, 0.0, 0.0], [0.0, 9.8, 0.0], [0.0, 0.0, 9.8]],
            InvalidParamsReason::GainOutOfRange(SensorKind::Gyro),
        ),
        (
            |s| s.mag.t_ref_c = 1e30,
            InvalidParamsReason::ReferenceTemperatureOutOfRange(SensorKind::Mag),
        ),
        (
            |s| s.accel.b[1] = f32::NAN,
            InvalidParamsReason::NonFinite(ParamField::Offset(SensorKind::Accel)),
        ),
    ];
    for (corrupt, reason) in cases {
        let mut set = plain_set();
        corrupt(&mut set);
        for format in [
            ExportFormat::CHeader,
            ExportFormat::Rust,
            ExportFormat::Json,
        ] {
            assert_eq!(export(&set, format, "p.json"), Err(reason));
        }
    }
    let sentence = InvalidParamsReason::ReferenceTemperatureOutOfRange(SensorKind::Mag).to_string();
    assert!(sentence.contains("mag.t_ref_c"), "{sentence}");
}

#[test]
fn plain_calibration_exports_only_a_and_b_and_a_temperature_free_apply() {
    let mut set = CalibrationSet::identity();
    set.accel.b = [0.1, 0.2, 0.3];
    let header = export(&set, ExportFormat::CHeader, "p.json").unwrap();
    assert!(!header.contains("bias_temp") && !header.contains("scale_temp"));
    assert!(header.contains("imucal_apply_accel(const float x[3], float y[3])"));
    assert!(header.contains("y = A * (x - b)"));
    let module = export(&set, ExportFormat::Rust, "p.json").unwrap();
    assert!(module.contains("pub fn apply_accel(x: [f32; 3]) -> [f32; 3]"));
}

#[test]
fn json_export_names_its_schema_and_keeps_every_f32_exactly() {
    let set = full_set();
    let text = export(&set, ExportFormat::Json, "params.json").unwrap();
    let doc: serde_json::Value = serde_json::from_str(&text).expect("valid JSON");
    assert_eq!(doc["schema"], EXPORT_SCHEMA_NAME);
    assert_eq!(doc["schema_version"], EXPORT_SCHEMA_VERSION);
    assert_eq!(doc["matrix_order"], "row-major");
    let a01 = doc["accel"]["A"][0][1].as_f64().unwrap() as f32;
    assert_eq!(a01, set.accel.a[0][1]);
    let b2 = doc["mag"]["b"][2].as_f64().unwrap() as f32;
    assert_eq!(b2, set.mag.b[2]);
    assert_eq!(doc["gyro"]["t_ref_c"], 31.5);
    assert_eq!(doc["mag"]["t_ref_c"], 18.0);
    assert!(doc["mag"].get("bias_temp").is_none());
    assert_eq!(
        doc["gyro_g_sensitivity"][2][0].as_f64().unwrap() as f32,
        3e-5f32
    );
}

#[test]
fn a_sensor_the_parameter_file_does_not_calibrate_is_exported_marked_as_not_calibrated() {
    let dir = scratch("uncalibrated");
    // A file with the accelerometer and gyroscope only: its magnetometer is left as the board
    // has it by `flash`, but an export can only give the identity, and must say so.
    let mut file = serde_json::to_value(imucal::device::ParamsFile::from(&plain_set()))
        .expect("a parameter file serialises");
    file.as_object_mut()
        .expect("a JSON object")
        .remove("mag")
        .expect("the file had a magnetometer entry");
    let params = dir.join("params.json");
    std::fs::write(&params, file.to_string()).expect("write the parameter file");
    let export = |format: &str| {
        let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
            .args(["export", "--format", format])
            .arg(&params)
            .output()
            .expect("the imucal binary runs");
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        (
            String::from_utf8_lossy(&out.stdout).into_owned(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };

    let (json, note) = export("json");
    assert!(
        note.contains("no mag calibration") && note.contains("no `mag` entry"),
        "{note}"
    );
    let json: serde_json::Value = serde_json::from_str(&json).expect("the export is JSON");
    assert_eq!(json["mag"]["calibrated"], false);
    assert!(json["mag"]["not_calibrated_because"]
        .as_str()
        .is_some_and(|why| why.contains("no `mag` entry")));
    assert_eq!(json["accel"]["calibrated"], true);
    assert!(json["accel"].get("not_calibrated_because").is_none());
    // The file's field and magnetometer residual are placeholders, not measurements.
    assert!(json["reference"]["field_ut"].is_null(), "{json}");
    assert!(json["residuals_rms"]["mag_ut"].is_null(), "{json}");
    assert!(json["residuals_rms"]["accel_mps2"].is_number(), "{json}");

    let (header, _) = export("c-header");
    assert!(
        header.contains("#define IMUCAL_MAG_CALIBRATED 0"),
        "{header}"
    );
    assert!(
        header.contains("#define IMUCAL_ACCEL_CALIBRATED 1"),
        "{header}"
    );
    assert!(header.contains("NOT CALIBRATED: mag"), "{header}");
    assert!(!header.contains("#define IMUCAL_FIELD_UT"), "{header}");
    assert!(
        header.contains("IMUCAL_FIELD_UT is not defined"),
        "{header}"
    );
    // The Adafruit library keeps its own default field rather than the placeholder.
    let (calib, note) = export("adafruit-json");
    let calib: serde_json::Value = serde_json::from_str(&calib).expect("sensor_calib.json");
    assert_eq!(calib["mag_field"].as_f64(), Some(50.0), "{calib}");
    assert!(note.contains("library's default of 50"), "{note}");
    let (module, _) = export("rust");
    assert!(!module.contains("pub const FIELD_UT"), "{module}");
    assert!(
        module.contains("pub const MAG_CALIBRATED: bool = false;"),
        "{module}"
    );
    assert!(
        module.contains("pub const GYRO_CALIBRATED: bool = true;"),
        "{module}"
    );
}

#[test]
fn a_reason_read_from_the_parameter_file_cannot_end_the_generated_comment() {
    let dir = scratch("comment");
    let mut file = serde_json::to_value(imucal::device::ParamsFile::from(&plain_set()))
        .expect("a parameter file serialises");
    file["not_fitted"] = serde_json::json!({ "mag": "line one\nline two */ #error boom /*" });
    let params = dir.join("params.json");
    std::fs::write(&params, file.to_string()).expect("write the parameter file");
    for format in ["c-header", "rust"] {
        let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
            .args(["export", "--format", format])
            .arg(&params)
            .output()
            .expect("the imucal binary runs");
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(
            text.contains("line one line two * / #error boom /*"),
            "{text}"
        );
        // Every line holding the reason is inside a comment.
        for line in text.lines().filter(|l| l.contains("#error")) {
            let line = line.trim_start();
            assert!(
                line.starts_with("* ") || line.starts_with("//") || line.starts_with("/*"),
                "{line}"
            );
        }
    }
}

#[test]
fn export_of_a_session_file_or_directory_names_the_sessions_parameter_file() {
    let dir = scratch("session-files");
    let session = dir.join("S");
    std::fs::create_dir_all(&session).expect("session directory");
    let params = imucal::device::ParamsFile::from(&plain_set());
    std::fs::write(session.join("params.json"), params.to_json()).expect("params");
    // The shapes `calibrate` writes next to it: a summary object and a list of poses.
    std::fs::write(
        session.join("summary.json"),
        r#"{"verified": true, "accel_rest_error_mg": 0.3, "verdict": {}, "params": {}}"#,
    )
    .expect("summary");
    std::fs::write(
        session.join("poses.json"),
        r#"[{"target": "+Z up", "target_index": 0, "stats": {"n": 72}}]"#,
    )
    .expect("poses");
    let expected_params = format!("`{}`", session.join("params.json").display());
    for (given, what) in [
        (
            "summary.json",
            "is not a parameter file but the summary of a calibration session",
        ),
        (
            "poses.json",
            "is not a parameter file but the poses of a calibration session",
        ),
        ("", "is a directory, not a parameter file"),
    ] {
        let path = if given.is_empty() {
            session.clone()
        } else {
            session.join(given)
        };
        let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
            .args(["export", &path.display().to_string()])
            .output()
            .expect("the binary runs");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{given}: {stderr}");
        assert!(
            stderr.contains(what) && stderr.contains(&expected_params),
            "{given}: {stderr}"
        );
        assert!(
            !stderr.contains("is not a parameter file key")
                && !stderr.contains("invalid type")
                && !stderr.contains("os error"),
            "{given}: {stderr}"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn an_input_unit_the_format_does_not_define_is_refused_naming_it() {
    let dir = scratch("input-unit");
    let mut file = serde_json::to_value(imucal::device::ParamsFile::from(&plain_set()))
        .expect("a parameter file serialises");
    file["accel"]["input_unit"] = serde_json::json!("furlongs");
    let params = dir.join("params.json");
    std::fs::write(&params, file.to_string()).expect("write the parameter file");
    let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .args(["export", "--format", "c-header"])
        .arg(&params)
        .output()
        .expect("the imucal binary runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(
        stderr.contains("accel.input_unit is `furlongs`") && stderr.contains("`counts`"),
        "{stderr}"
    );
    assert!(out.stdout.is_empty(), "nothing is exported");
}
