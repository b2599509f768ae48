//! Exporting a calibration for firmware that is not imucal's: a C header, a Rust module, or a
//! versioned JSON document (schema in `docs/PARAMS_FORMAT.md`).
//!
//! Every export carries the model of `imucal_protocol::CalibrationSet`, per sensor:
//!
//! ```text
//! ΔT = clamp(T − T_ref, ±125 °C) (T_ref = the sensor's t_ref_c; the protocol's one ΔT rule)
//! u  = x − (b + c1·ΔT + c2·ΔT² + c3·ΔT³)
//! u' = u + q∘u² + k∘u³
//! y  = (1 + s·ΔT)∘(A·u')        and for the gyroscope  y −= K·f  (f = calibrated accelerometer)
//! ```
//!
//! which without extended terms is `y = A·(x − b)`. Values are exported as the `f32` numbers the
//! board stores, printed with the shortest text that reads back to the same `f32`, so an export
//! applies exactly what `imucal flash` would write. The generated code contains only the terms
//! the file has, so a plain calibration yields a plain `y = A·(x − b)`.
//!
//! A set is exported only after `imucal_protocol::validate_for_ranges` accepts it, so no export
//! exists of a set an imucal board would refuse (singular `A`, a gain in the wrong units, an
//! absurd `T_ref`, NaN). The target board is not known here, so the offset and term bounds use
//! the widest ranges imucal supports ([`FullScale::WIDEST_SUPPORTED`]). The reference for what
//! the generated code computes is `imucal_protocol::model::apply`.

use imucal_protocol::{
    validate_for_ranges, CalibrationSet, FullScale, InvalidParamsReason, ParamField,
    SensorCalibration, SensorKind, MAX_DELTA_T_C,
};
use serde_json::{json, Value};

/// Version of the export JSON schema ([`ExportFormat::Json`]); raised on any incompatible change
/// (2: `t_ref_c` per sensor, ΔT clamped).
pub const EXPORT_SCHEMA_VERSION: u32 = 2;

/// Name of the export JSON schema, written in its `schema` field.
pub const EXPORT_SCHEMA_NAME: &str = "imucal-calibration-export";

/// What an export states about its sensors beyond their numbers.
#[derive(Debug, Default, Clone, Copy)]
pub struct SensorNotes<'a> {
    /// Sensors whose calibration takes raw readings, with their input unit
    /// (`("accel", "counts")`): the comment and the JSON state it in place of the nominal unit.
    pub raw_inputs: &'a [(&'a str, &'a str)],
    /// Sensors the parameter file holds no calibration of, with the reason: exported as the
    /// identity, and marked so where they are defined (`"calibrated": false` in the JSON), so
    /// firmware built from the export does not pass an uncalibrated sensor off as calibrated.
    pub uncalibrated: &'a [(&'a str, &'a str)],
}

impl SensorNotes<'_> {
    fn raw_unit(&self, name: &str) -> Option<&str> {
        self.raw_inputs
            .iter()
            .find(|(raw, _)| *raw == name)
            .map(|(_, unit)| *unit)
    }

    /// The field magnitude of the magnetometer's output, `None` when the file does not calibrate
    /// the magnetometer (its `field_ut` is then a placeholder, not a field).
    fn field_ut(&self, set: &CalibrationSet) -> Option<f32> {
        self.uncalibrated_because("mag")
            .is_none()
            .then_some(set.reference.field_ut)
    }

    /// The fit's residual RMS of `name`, `None` when the file does not calibrate it.
    fn residual(&self, name: &str, rms: f32) -> Option<f32> {
        self.uncalibrated_because(name).is_none().then_some(rms)
    }

    fn uncalibrated_because(&self, name: &str) -> Option<&str> {
        self.uncalibrated
            .iter()
            .find(|(sensor, _)| *sensor == name)
            .map(|(_, why)| *why)
    }
}

/// What to generate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExportFormat {
    /// A C99 header: `static const float` arrays and `static inline` apply functions.
    CHeader,
    /// A Rust module: `pub const` arrays and `pub fn` apply functions.
    Rust,
    /// The versioned JSON document.
    Json,
}

/// Said in place of the field constant `name` when the magnetometer is not calibrated: the
/// file's `field_ut` is then a placeholder, and a constant would pass it off as a measured field.
fn no_field_comment(open: &str, name: &str, close: &str) -> String {
    format!("{open}{name} is not defined: the magnetometer is not calibrated, so there is no field{close}")
}

/// The three sensors in export order, with their names and units.
const SENSORS: [(&str, &str); 3] = [("accel", "m/s²"), ("gyro", "rad/s"), ("mag", "µT")];

fn sensor<'a>(set: &'a CalibrationSet, name: &str) -> &'a SensorCalibration {
    match name {
        "accel" => &set.accel,
        "gyro" => &set.gyro,
        _ => &set.mag,
    }
}

/// Whether a sensor's model depends on the temperature.
fn uses_temperature(cal: &SensorCalibration) -> bool {
    cal.bias_temp.is_some() || cal.scale_temp.is_some()
}

/// The export of `set` in `format`; `source` names the parameter file in the generated comment.
/// A set that fails validation is refused with the reason (which names the field and bound).
pub fn export(
    set: &CalibrationSet,
    format: ExportFormat,
    source: &str,
) -> Result<String, InvalidParamsReason> {
    export_checked_as(set, set, format, source, SensorNotes::default())
}

/// [`export`] of `set`, validated as `checked`: the set with the sensors whose calibration
/// takes raw counts (no nominal unit, so the board's limits do not apply to them) replaced by
/// identity. Those sensors are still refused when any of their numbers is not finite.
/// `notes` names them with their input unit, and the sensors the file does not calibrate.
pub fn export_checked_as(
    set: &CalibrationSet,
    checked: &CalibrationSet,
    format: ExportFormat,
    source: &str,
    notes: SensorNotes<'_>,
) -> Result<String, InvalidParamsReason> {
    validate_for_ranges(checked, &FullScale::WIDEST_SUPPORTED)?;
    let finite = |s: &SensorCalibration| s.a.iter().flatten().chain(&s.b).all(|v| v.is_finite());
    if let Some(kind) = [
        (SensorKind::Accel, &set.accel),
        (SensorKind::Gyro, &set.gyro),
        (SensorKind::Mag, &set.mag),
    ]
    .into_iter()
    .find_map(|(kind, s)| (!finite(s)).then_some(kind))
    {
        return Err(InvalidParamsReason::NonFinite(ParamField::Matrix(kind)));
    }
    Ok(match format {
        ExportFormat::CHeader => c_header(set, source, notes),
        ExportFormat::Rust => rust_module(set, source, notes),
        ExportFormat::Json => {
            // A tree of numbers and strings always serialises.
            serde_json::to_string_pretty(&json_document(set, source, notes)).unwrap_or_default()
                + "\n"
        }
    })
}

/// Shortest decimal text that reads back to the same `f32` (always with `.` or `e`).
fn float_text(v: f32) -> String {
    format!("{v:?}")
}

fn c_float(v: f32) -> String {
    float_text(v) + "f"
}

fn list(values: &[f32], each: fn(f32) -> String) -> String {
    values
        .iter()
        .map(|v| each(*v))
        .collect::<Vec<_>>()
        .join(", ")
}

fn c_vec(v: &[f32; 3]) -> String {
    format!("{{{}}}", list(v, c_float))
}

fn c_mat(m: &[[f32; 3]; 3]) -> String {
    format!(
        "{{\n    {},\n    {},\n    {},\n}}",
        c_vec(&m[0]),
        c_vec(&m[1]),
        c_vec(&m[2])
    )
}

fn model_comment(prefix: &str, notes: SensorNotes<'_>) -> String {
    let mut lines: Vec<String> = [
        "Model per sensor (as the imucal firmware applies it):",
        "  dT = clamp(T - T_ref, -125, 125)    (degC; T_ref = the sensor's t_ref_c)",
        "  u  = x - (b + c1*dT + c2*dT^2 + c3*dT^3)",
        "  u' = u + q.*u^2 + k.*u^3            (element-wise)",
        "  y  = (1 + s*dT) .* (A * u')         gyroscope: y -= K * f (f = calibrated accel)",
        "Without extended terms this is y = A * (x - b). Matrices are row-major: A[row][col].",
        "Inputs x in the sensor's nominal unit, outputs y in m/s^2, rad/s, uT; T in degC.",
    ]
    .map(String::from)
    .to_vec();
    for (sensor, unit) in notes.raw_inputs {
        lines.push(format!(
            "Except: {sensor} inputs x are raw readings in {unit} (as fitted), not the nominal unit."
        ));
    }
    for (sensor, why) in notes.uncalibrated {
        lines.push(format!(
            "NOT CALIBRATED: {sensor} is the identity here ({}); its readings pass unchanged.",
            comment_safe(why)
        ));
    }
    lines
        .iter()
        .map(|line| format!("{prefix}{line}").trim_end().to_string())
        .collect::<Vec<_>>()
        .join("\n")
}

/// `text` from a parameter file (a reason, a file name) made safe inside a generated comment:
/// a line break would end a `//` comment and `*/` a C one, turning the rest into code.
fn comment_safe(text: &str) -> String {
    text.chars()
        .map(|c| if c.is_control() { ' ' } else { c })
        .collect::<String>()
        .replace("*/", "* /")
}

/// The heading of a sensor's block: its output unit, or that it is not calibrated.
fn heading(name: &str, unit: &str, notes: SensorNotes<'_>) -> String {
    match notes.uncalibrated_because(name) {
        Some(why) => format!("NOT CALIBRATED, identity ({})", comment_safe(why)),
        None => format!("output in {unit}"),
    }
}

/// The C header.
fn c_header(set: &CalibrationSet, source: &str, notes: SensorNotes<'_>) -> String {
    let mut out = String::new();
    out.push_str(&format!(
        "/*\n * IMU calibration exported by imucal from {} (parameter format {}).\n *\n{}\n */\n#pragma once\n\n",
        comment_safe(source),
        set.format_version,
        model_comment(" * ", notes)
    ));
    out.push_str(&format!(
        "#define IMUCAL_PARAMS_FORMAT {}\n#define IMUCAL_GRAVITY_MPS2 {}\n{}\n",
        set.format_version,
        c_float(set.reference.gravity_mps2),
        match notes.field_ut(set) {
            Some(field) => format!("#define IMUCAL_FIELD_UT {}", c_float(field)),
            None => no_field_comment("/* ", "IMUCAL_FIELD_UT", " */"),
        }
    ));
    for (name, unit) in SENSORS {
        let cal = sensor(set, name);
        out.push_str(&format!(
            "\n/* {name}: {} */\n#define IMUCAL_{}_CALIBRATED {}\n",
            heading(name, unit, notes),
            name.to_uppercase(),
            u8::from(notes.uncalibrated_because(name).is_none())
        ));
        out.push_str(&format!(
            "static const float imucal_{name}_A[3][3] = {};\n",
            c_mat(&cal.a)
        ));
        out.push_str(&format!(
            "static const float imucal_{name}_b[3] = {};\n",
            c_vec(&cal.b)
        ));
        // Only a sensor with a temperature term reads T_ref; an unused static would warn.
        if uses_temperature(cal) {
            out.push_str(&format!(
                "static const float imucal_{name}_t_ref_c = {};\n",
                c_float(cal.t_ref_c)
            ));
        }
        if let Some(t) = &cal.bias_temp {
            out.push_str(&format!(
                "/* bias_temp[k][axis]: degree k+1 offset coefficient per degC^(k+1) */\nstatic const float imucal_{name}_bias_temp[3][3] = {};\n",
                c_mat(&t.coeffs)
            ));
        }
        if let Some(s) = &cal.scale_temp {
            out.push_str(&format!(
                "static const float imucal_{name}_scale_temp[3] = {};\n",
                c_vec(s)
            ));
        }
        if let Some(n) = &cal.nonlinearity {
            out.push_str(&format!(
                "static const float imucal_{name}_quadratic[3] = {};\nstatic const float imucal_{name}_cubic[3] = {};\n",
                c_vec(&n.quadratic),
                c_vec(&n.cubic)
            ));
        }
        if name == "gyro" {
            if let Some(k) = &set.gyro_g_sensitivity {
                out.push_str(&format!(
                    "/* g-sensitivity K, rad/s per m/s^2 */\nstatic const float imucal_gyro_g_sensitivity[3][3] = {};\n",
                    c_mat(k)
                ));
            }
        }
        out.push_str(&c_apply(set, name, cal));
    }
    out
}

fn c_apply(set: &CalibrationSet, name: &str, cal: &SensorCalibration) -> String {
    let temperature = uses_temperature(cal);
    let g_sensitivity = name == "gyro" && set.gyro_g_sensitivity.is_some();
    let mut params = vec!["const float x[3]".to_string()];
    if temperature {
        params.push("float temp_c".to_string());
    }
    if g_sensitivity {
        params.push("const float accel_calibrated[3]".to_string());
    }
    params.push("float y[3]".to_string());
    let mut body = String::new();
    if temperature {
        let limit = c_float(MAX_DELTA_T_C);
        body.push_str(&format!(
            "    float dt = temp_c - imucal_{name}_t_ref_c;\n    if (dt > {limit}) dt = {limit};\n    if (dt < -{limit}) dt = -{limit};\n"
        ));
    }
    body.push_str("    float u[3];\n    for (int i = 0; i < 3; i++) {\n");
    body.push_str(&format!("        u[i] = x[i] - imucal_{name}_b[i];\n"));
    if cal.bias_temp.is_some() {
        body.push_str(&format!(
            "        u[i] -= dt * (imucal_{name}_bias_temp[0][i] + dt * (imucal_{name}_bias_temp[1][i] + dt * imucal_{name}_bias_temp[2][i]));\n"
        ));
    }
    if cal.nonlinearity.is_some() {
        body.push_str(&format!(
            "        u[i] += u[i] * u[i] * (imucal_{name}_quadratic[i] + imucal_{name}_cubic[i] * u[i]);\n"
        ));
    }
    body.push_str("    }\n    for (int r = 0; r < 3; r++) {\n");
    body.push_str(&format!(
        "        y[r] = imucal_{name}_A[r][0] * u[0] + imucal_{name}_A[r][1] * u[1] + imucal_{name}_A[r][2] * u[2];\n"
    ));
    if cal.scale_temp.is_some() {
        body.push_str(&format!(
            "        y[r] *= 1.0f + imucal_{name}_scale_temp[r] * dt;\n"
        ));
    }
    if g_sensitivity {
        body.push_str(
            "        y[r] -= imucal_gyro_g_sensitivity[r][0] * accel_calibrated[0] + imucal_gyro_g_sensitivity[r][1] * accel_calibrated[1] + imucal_gyro_g_sensitivity[r][2] * accel_calibrated[2];\n",
        );
    }
    body.push_str("    }\n");
    format!(
        "/* Calibrated {name} reading y from the reading x. */\nstatic inline void imucal_apply_{name}({})\n{{\n{body}}}\n",
        params.join(", ")
    )
}

fn rust_vec(v: &[f32; 3]) -> String {
    format!("[{}]", list(v, float_text))
}

fn rust_mat(m: &[[f32; 3]; 3]) -> String {
    format!(
        "[\n    {},\n    {},\n    {},\n]",
        rust_vec(&m[0]),
        rust_vec(&m[1]),
        rust_vec(&m[2])
    )
}

/// The Rust module (plain `//` comments, so it can be pasted or `include!`d anywhere).
fn rust_module(set: &CalibrationSet, source: &str, notes: SensorNotes<'_>) -> String {
    let mut out = format!(
        "// IMU calibration exported by imucal from {} (parameter format {}).\n//\n{}\n\n",
        comment_safe(source),
        set.format_version,
        model_comment("// ", notes)
    );
    out.push_str(&format!(
        "/// Parameter format of the source file.\npub const PARAMS_FORMAT: u16 = {};\n/// Local gravity of the fit, m/s².\npub const GRAVITY_MPS2: f32 = {};\n{}\n",
        set.format_version,
        float_text(set.reference.gravity_mps2),
        match notes.field_ut(set) {
            Some(field) => format!(
                "/// Local field magnitude of the fit, µT.\npub const FIELD_UT: f32 = {};",
                float_text(field)
            ),
            None => no_field_comment("// ", "FIELD_UT", ""),
        }
    ));
    for (name, unit) in SENSORS {
        let cal = sensor(set, name);
        let upper = name.to_uppercase();
        out.push_str(&format!(
            "\n/// Whether the file calibrates the {name} (else `A`, `b` are the identity).\npub const {upper}_CALIBRATED: bool = {};\n/// {name}: correction matrix `A` (row-major); {}.\npub const {upper}_A: [[f32; 3]; 3] = {};\n/// {name}: offset `b`, in the input unit.\npub const {upper}_B: [f32; 3] = {};\n/// {name}: reference temperature of the temperature terms, °C.\npub const {upper}_T_REF_C: f32 = {};\n",
            notes.uncalibrated_because(name).is_none(),
            heading(name, unit, notes),
            rust_mat(&cal.a),
            rust_vec(&cal.b),
            float_text(cal.t_ref_c)
        ));
        if let Some(t) = &cal.bias_temp {
            out.push_str(&format!(
                "/// {name}: offset coefficients `[degree − 1][axis]`, per °C^degree.\npub const {upper}_BIAS_TEMP: [[f32; 3]; 3] = {};\n",
                rust_mat(&t.coeffs)
            ));
        }
        if let Some(s) = &cal.scale_temp {
            out.push_str(&format!(
                "/// {name}: relative scale change per °C, per output axis.\npub const {upper}_SCALE_TEMP: [f32; 3] = {};\n",
                rust_vec(s)
            ));
        }
        if let Some(n) = &cal.nonlinearity {
            out.push_str(&format!(
                "/// {name}: quadratic non-linearity per axis.\npub const {upper}_QUADRATIC: [f32; 3] = {};\n/// {name}: cubic non-linearity per axis.\npub const {upper}_CUBIC: [f32; 3] = {};\n",
                rust_vec(&n.quadratic),
                rust_vec(&n.cubic)
            ));
        }
        if name == "gyro" {
            if let Some(k) = &set.gyro_g_sensitivity {
                out.push_str(&format!(
                    "/// Gyroscope g-sensitivity `K`, rad/s per m/s² (row-major).\npub const GYRO_G_SENSITIVITY: [[f32; 3]; 3] = {};\n",
                    rust_mat(k)
                ));
            }
        }
        out.push_str(&rust_apply(set, name, cal));
    }
    out
}

fn rust_apply(set: &CalibrationSet, name: &str, cal: &SensorCalibration) -> String {
    let upper = name.to_uppercase();
    let temperature = uses_temperature(cal);
    let g_sensitivity = name == "gyro" && set.gyro_g_sensitivity.is_some();
    let mut params = vec!["x: [f32; 3]".to_string()];
    if temperature {
        params.push("temp_c: f32".to_string());
    }
    if g_sensitivity {
        params.push("accel_calibrated: [f32; 3]".to_string());
    }
    let mut body = String::new();
    if temperature {
        let limit = float_text(MAX_DELTA_T_C);
        body.push_str(&format!(
            "    let dt = (temp_c - {upper}_T_REF_C).clamp(-{limit}, {limit});\n"
        ));
    }
    body.push_str("    let mut u = [0.0f32; 3];\n    for i in 0..3 {\n");
    body.push_str(&format!("        u[i] = x[i] - {upper}_B[i];\n"));
    if cal.bias_temp.is_some() {
        body.push_str(&format!(
            "        u[i] -= dt * ({upper}_BIAS_TEMP[0][i] + dt * ({upper}_BIAS_TEMP[1][i] + dt * {upper}_BIAS_TEMP[2][i]));\n"
        ));
    }
    if cal.nonlinearity.is_some() {
        body.push_str(&format!(
            "        u[i] += u[i] * u[i] * ({upper}_QUADRATIC[i] + {upper}_CUBIC[i] * u[i]);\n"
        ));
    }
    body.push_str("    }\n    let mut y = [0.0f32; 3];\n    for r in 0..3 {\n");
    body.push_str(&format!(
        "        y[r] = {upper}_A[r][0] * u[0] + {upper}_A[r][1] * u[1] + {upper}_A[r][2] * u[2];\n"
    ));
    if cal.scale_temp.is_some() {
        body.push_str(&format!(
            "        y[r] *= 1.0 + {upper}_SCALE_TEMP[r] * dt;\n"
        ));
    }
    if g_sensitivity {
        body.push_str(
            "        y[r] -= GYRO_G_SENSITIVITY[r][0] * accel_calibrated[0] + GYRO_G_SENSITIVITY[r][1] * accel_calibrated[1] + GYRO_G_SENSITIVITY[r][2] * accel_calibrated[2];\n",
        );
    }
    body.push_str("    }\n    y\n");
    format!(
        "/// Calibrated {name} reading from the reading `x`.\n#[allow(clippy::needless_range_loop)]\npub fn apply_{name}({}) -> [f32; 3] {{\n{body}}}\n",
        params.join(", ")
    )
}

fn json_sensor(cal: &SensorCalibration, unit: &str) -> Value {
    let mut object = json!({
        "unit": unit,
        "A": cal.a,
        "b": cal.b,
        "t_ref_c": cal.t_ref_c,
    });
    if let Some(t) = &cal.bias_temp {
        object["bias_temp"] = json!({ "coeffs": t.coeffs });
    }
    if let Some(s) = &cal.scale_temp {
        object["scale_temp"] = json!(s);
    }
    if let Some(n) = &cal.nonlinearity {
        object["nonlinearity"] = json!({ "quadratic": n.quadratic, "cubic": n.cubic });
    }
    object
}

/// The JSON document of schema [`EXPORT_SCHEMA_NAME`] version [`EXPORT_SCHEMA_VERSION`].
/// Each sensor's `input_unit` is its nominal unit, or its entry in `notes.raw_inputs`; a sensor
/// in `notes.uncalibrated` has `"calibrated": false` and `not_calibrated_because`.
pub fn json_document(set: &CalibrationSet, source: &str, notes: SensorNotes<'_>) -> Value {
    let mut document = json!({
        "schema": EXPORT_SCHEMA_NAME,
        "schema_version": EXPORT_SCHEMA_VERSION,
        "source": source,
        "params_format": set.format_version,
        "created_unix_s": set.created_unix_s,
        "model": "y = (1 + s*dT) .* (A * u'), u' = u + q.*u^2 + k.*u^3, u = x - (b + c1*dT + c2*dT^2 + c3*dT^3), dT = clamp(T - t_ref_c, -125, 125); gyroscope y -= K * f",
        "matrix_order": "row-major",
        "reference": {
            "gravity_mps2": set.reference.gravity_mps2,
            "field_ut": notes.field_ut(set),
        },
        "residuals_rms": {
            "accel_mps2": notes.residual("accel", set.residuals.accel_rms),
            "gyro_rads": notes.residual("gyro", set.residuals.gyro_rms),
            "mag_ut": notes.residual("mag", set.residuals.mag_rms),
        },
    });
    for (name, _) in SENSORS {
        let unit = match name {
            "accel" => "m/s^2",
            "gyro" => "rad/s",
            _ => "uT",
        };
        document[name] = json_sensor(sensor(set, name), unit);
        document[name]["input_unit"] = json!(notes.raw_unit(name).unwrap_or(unit));
        document[name]["calibrated"] = json!(notes.uncalibrated_because(name).is_none());
        if let Some(why) = notes.uncalibrated_because(name) {
            document[name]["not_calibrated_because"] = json!(why);
        }
    }
    if let Some(k) = &set.gyro_g_sensitivity {
        document["gyro_g_sensitivity"] = json!(k);
    }
    document
}
