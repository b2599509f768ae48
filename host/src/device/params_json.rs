//! The calibration parameter file (JSON) that `imucal calibrate` writes and `imucal flash`
//! reads. It mirrors the protocol's `CalibrationSet` (model `y = (1+s·ΔT)∘(A·u')`,
//! `u = x − b(T)`, see `imucal_protocol::CalibrationSet`), versioned by `"format": 2`:
//!
//! ```json
//! { "format": 2, "created_unix_s": 1763700000,
//!   "accel": { "A": [[1,0,0],[0,1,0],[0,0,1]], "b": [0,0,0], "t_ref_c": 25,
//!              "bias_temp": { "coeffs": [[0,0,0],[0,0,0],[0,0,0]] },
//!              "scale_temp": [0,0,0], "nonlinearity": { "quadratic": [0,0,0], "cubic": [0,0,0] } },
//!   "gyro": { "A": ..., "b": ... }, "mag": { "A": ..., "b": ... },
//!   "gyro_g_sensitivity": [[0,0,0],[0,0,0],[0,0,0]],
//!   "reference": { "gravity_mps2": 9.80665, "field_ut": 48.5 },
//!   "residuals": { "accel_rms": 0.01, "gyro_rms": 0.0, "mag_rms": 0.3 } }
//! ```
//!
//! Extended terms are optional (absent or `null`); a sensor left out is identity, and
//! `not_fitted` says why a sensor was left out. A sensor whose data had no known scale carries
//! `"input_unit": "counts"`: its `A` maps counts, which suits other firmware reading raw counts
//! but not this board. `provenance` records the tool, source, methods and time. Units are those
//! of the protocol: m/s², rad/s, µT, °C.
//! Format 1 files are still read: their reference temperature sat inside `bias_temp`, and a
//! sensor without one used 0 °C.

use std::collections::BTreeMap;
use std::path::Path;

use imucal_protocol::{
    BiasTemperature, CalibrationSet, FitResiduals, Nonlinearity, ReferenceMagnitudes,
    SensorCalibration, PARAMS_FORMAT_VERSION,
};
use serde::{Deserialize, Serialize};

pub use super::board_identity::{DeviceJson, RangesJson};

/// Format version of the parameter file written by this tool.
pub const PARAMS_FILE_FORMAT: u16 = 2;

/// Largest reference gravity accepted, m/s² (ten times Earth's).
const MAX_REFERENCE_GRAVITY: f64 = 100.0;

/// Largest reference field accepted, µT (a magnetometer's range is a few mT at most).
const MAX_REFERENCE_FIELD_UT: f64 = 10_000.0;

/// What to pass instead of something that is not a parameter file.
const PASS_PARAMS: &str =
    "pass a parameter file (the params.json of `imucal calibrate` or `imucal fit --params-out`)";

/// What `value` is when it is JSON of another kind than a parameter file (` but …`, or a
/// note of why not); `None` for anything that may be a parameter file (one with a misspelled
/// key is told about that key instead).
fn other_json(value: &serde_json::Value) -> Option<String> {
    match value {
        serde_json::Value::Array(items) => {
            let poses = items
                .first()
                .is_some_and(|p| p.get("target").is_some() && p.get("stats").is_some());
            Some(if poses {
                " but the poses of a calibration session".to_string()
            } else {
                " but a JSON list".to_string()
            })
        }
        serde_json::Value::Object(map) => {
            if map.keys().any(|key| KNOWN_KEYS.contains(&key.as_str())) {
                None
            } else if map.contains_key("accel_rest_error_mg") && map.contains_key("verdict") {
                Some(" but the summary of a calibration session".to_string())
            } else {
                Some(
                    " (it has none of a parameter file's keys, such as `format` or `accel`)"
                        .to_string(),
                )
            }
        }
        _ => Some(" but a single JSON value".to_string()),
    }
}

/// Oldest parameter file format this tool reads.
pub const OLDEST_PARAMS_FILE_FORMAT: u16 = 1;

/// Why a parameter file could not be read.
#[derive(Debug, thiserror::Error)]
pub enum ParamsFileError {
    /// The file could not be read.
    #[error("cannot read the parameter file `{path}` ({cause}); check the path")]
    Io {
        /// The file.
        path: String,
        /// The operating system's error.
        cause: std::io::Error,
    },
    /// A directory stands where a parameter file is named.
    #[error("`{path}` is a directory, not a parameter file; {fix}")]
    Directory {
        /// The directory.
        path: String,
        /// The file to pass instead.
        fix: String,
    },
    /// JSON of another kind: a session's summary or poses, say.
    #[error("`{path}` is not a parameter file{what}; {fix}")]
    NotParameterFile {
        /// The file.
        path: String,
        /// What the file is, when it can be told (` but …`), else empty.
        what: String,
        /// The file to pass instead.
        fix: String,
    },
    /// The file is not valid parameter JSON.
    #[error("`{path}` is not a valid parameter file: {cause}; it should be the JSON written by `imucal calibrate`")]
    Json {
        /// The file.
        path: String,
        /// The parser's error (with line and column).
        cause: serde_json::Error,
    },
    /// A value is written `NaN` or `Infinity`, which JSON has no number for.
    #[error("`{path}` line {line} column {column}: `{word}` is not a number in JSON, and NaN or Infinity are not allowed in JSON parameters (a fit that gives them failed); refit the calibration, or correct the value")]
    NotANumber {
        /// The file.
        path: String,
        /// `NaN`, `Infinity` or `-Infinity` as written.
        word: String,
        /// Line of the value.
        line: usize,
        /// Column of the value.
        column: usize,
    },
    /// The file's `format` is not one this tool reads.
    #[error("`{path}` has parameter format {found}, this imucal reads formats {OLDEST_PARAMS_FILE_FORMAT} to {PARAMS_FILE_FORMAT}; use the imucal version that wrote it or refit")]
    UnsupportedFormat {
        /// The file.
        path: String,
        /// The format found.
        found: u16,
    },
    /// A sensor's `input_unit` is not one a parameter file can name.
    #[error("`{path}`: {sensor}.input_unit is `{unit}`, but the only input unit a parameter file names is `counts` (leave it out for m/s², rad/s or µT); correct it or fit the recording again")]
    UnknownInputUnit {
        /// The file.
        path: String,
        /// The sensor.
        sensor: &'static str,
        /// The unit found.
        unit: String,
    },
    /// A top-level key is not one of the file's (a misspelled sensor would otherwise be identity).
    #[error("`{path}`: `{key}` is not a parameter file key; the keys are {}; correct or remove it", KNOWN_KEYS.join(", "))]
    UnknownKey {
        /// The file.
        path: String,
        /// The key found.
        key: String,
    },
    /// A reference or residual is outside what it can physically be.
    #[error("`{path}`: {field} is {}, but it must be {expected}; correct the file or refit", shown_ref(.value))]
    Implausible {
        /// The file.
        path: String,
        /// Which value.
        field: String,
        /// The value found.
        value: f64,
        /// What it must be.
        expected: &'static str,
    },
    /// A value is not finite or does not fit an `f32`.
    #[error(
        "`{path}`: {field} is {}, which is not a finite 32-bit number; refit the calibration",
        shown_ref(.value)
    )]
    NonFinite {
        /// The file.
        path: String,
        /// Which value.
        field: String,
        /// The value found.
        value: f64,
    },
}

/// Temperature dependence of an offset: cubic in `ΔT = T − t_ref_c`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BiasTemperatureJson {
    /// Reference temperature, °C (format 1 only; format 2 has it per sensor).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub t_ref_c: Option<f64>,
    /// `coeffs[k][axis]`: degree-(k+1) coefficient per raw axis, unit per °C^(k+1).
    pub coeffs: [[f64; 3]; 3],
}

/// Scale non-linearity per axis.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NonlinearityJson {
    /// Quadratic coefficients, 1/unit.
    pub quadratic: [f64; 3],
    /// Cubic coefficients, 1/unit².
    pub cubic: [f64; 3],
}

/// One sensor's calibration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorJson {
    /// Correction matrix `A`, row-major.
    #[serde(rename = "A")]
    pub a: [[f64; 3]; 3],
    /// Offset `b`, in the sensor's unit.
    pub b: [f64; 3],
    /// Reference temperature of the temperature terms, °C (always written; absent in format 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub t_ref_c: Option<f64>,
    /// Temperature dependence of the offset.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bias_temp: Option<BiasTemperatureJson>,
    /// Relative scale change per °C, per output axis.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale_temp: Option<[f64; 3]>,
    /// Scale non-linearity.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub nonlinearity: Option<NonlinearityJson>,
    /// Unit of the input `x` when it is not the board's nominal unit (only `"counts"`: data
    /// without a known scale). Absent: m/s², rad/s or µT.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub input_unit: Option<String>,
}

/// The one `input_unit` a parameter file names: raw counts of a sensor without a known scale.
pub const COUNTS_UNIT: &str = "counts";

impl Default for SensorJson {
    fn default() -> Self {
        Self::from(&SensorCalibration::identity())
    }
}

/// Where a calibration came from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Provenance {
    /// The tool and its version, e.g. `imucal 0.3.0`.
    pub tool: String,
    /// The recording (path as given) or the board session it was fitted from.
    pub source: String,
    /// The board's device id, when the data came from a board that reported one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub device_id: Option<String>,
    /// Fitting method per sensor (`accel`, `gyro`, `mag`).
    pub methods: BTreeMap<String, String>,
    /// Unit of each sensor's data as read (`counts` when no scale was known).
    pub input_units: BTreeMap<String, String>,
    /// When it was fitted, seconds since the Unix epoch.
    pub created_unix_s: u64,
    /// What the board ran when it was not imucal's firmware: [`MOTIONCAL_SKETCH`] for a
    /// board running a MotionCal calibration sketch, whose readings (scales, axes, the
    /// sketch's own conversions) are not those imucal's firmware calibrates. Absent: imucal's
    /// firmware, or a recording.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub board_firmware: Option<String>,
}

/// [`Provenance::board_firmware`] of a calibration measured on a MotionCal sketch board.
pub const MOTIONCAL_SKETCH: &str = "motioncal-sketch";

impl Provenance {
    /// This tool's name and version.
    pub fn tool() -> String {
        format!("imucal {}", env!("CARGO_PKG_VERSION"))
    }
}

/// Reference magnitudes of the fit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReferenceJson {
    /// Local gravity, m/s².
    pub gravity_mps2: f64,
    /// Local field magnitude, µT.
    pub field_ut: f64,
}

/// Residual RMS of the fit per sensor.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ResidualsJson {
    /// m/s².
    pub accel_rms: f64,
    /// rad/s.
    pub gyro_rms: f64,
    /// µT.
    pub mag_rms: f64,
}

/// Every top-level key of a parameter file; any other is refused on reading.
pub const KNOWN_KEYS: [&str; 11] = [
    "format",
    "created_unix_s",
    "accel",
    "gyro",
    "mag",
    "gyro_g_sensitivity",
    "reference",
    "residuals",
    "not_fitted",
    "provenance",
    "device",
];

/// A value for a message: plain when short, in scientific notation when plain notation would
/// run to many digits (1e300 is not written out in 301).
pub fn shown_value(value: f64) -> String {
    let magnitude = value.abs();
    if magnitude != 0.0 && !(1e-4..1e6).contains(&magnitude) {
        format!("{value:e}")
    } else {
        format!("{value}")
    }
}

fn shown_ref(value: &f64) -> String {
    shown_value(*value)
}

/// `NaN`, `Infinity` or `-Infinity` where the JSON parser stopped, if that is why it stopped.
fn not_a_json_number(text: &str, cause: &serde_json::Error) -> Option<String> {
    let line = text.lines().nth(cause.line().checked_sub(1)?)?;
    // The parser's column is at or just past the first character it could not take.
    let start = cause.column().saturating_sub(1);
    let around = line
        .get(start.saturating_sub(1)..)
        .or_else(|| line.get(start..))?;
    let rest = around.trim_start_matches(|c: char| c == ',' || c == ':' || c.is_whitespace());
    ["-Infinity", "Infinity", "NaN", "-NaN", "nan", "inf", "-inf"]
        .into_iter()
        .find(|word| rest.starts_with(word))
        .map(str::to_string)
}

/// The sensors a parameter file calibrates, by key.
pub const SENSOR_KEYS: [&str; 3] = ["accel", "gyro", "mag"];

/// The whole parameter file. Unknown top-level keys are refused when it is read.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParamsFile {
    /// File format version ([`PARAMS_FILE_FORMAT`]).
    pub format: u16,
    /// Creation time, seconds since the Unix epoch.
    #[serde(default)]
    pub created_unix_s: u64,
    /// Accelerometer (identity when absent).
    #[serde(default)]
    pub accel: SensorJson,
    /// Gyroscope (identity when absent).
    #[serde(default)]
    pub gyro: SensorJson,
    /// Magnetometer (identity when absent).
    #[serde(default)]
    pub mag: SensorJson,
    /// Gyro g-sensitivity `K`, rad/s per m/s², row-major.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gyro_g_sensitivity: Option<[[f64; 3]; 3]>,
    /// Reference magnitudes.
    pub reference: ReferenceJson,
    /// Fit residuals.
    #[serde(default)]
    pub residuals: ResidualsJson,
    /// Sensors the file leaves out on purpose, with the reason (they are identity when flashed).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub not_fitted: BTreeMap<String, String>,
    /// Where the calibration came from.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub provenance: Option<Provenance>,
    /// The board it was made for (absent in files fitted offline from a recording).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub device: Option<DeviceJson>,
    /// Sensors (of [`SENSOR_KEYS`]) absent from the file as read: `flash` keeps the board's
    /// current calibration for them. Not written.
    #[serde(skip)]
    pub absent_sensors: Vec<String>,
}

impl From<&SensorCalibration> for SensorJson {
    fn from(c: &SensorCalibration) -> Self {
        Self {
            a: c.a.map(|row| row.map(f64::from)),
            b: c.b.map(f64::from),
            t_ref_c: Some(f64::from(c.t_ref_c)),
            bias_temp: c.bias_temp.map(|t| BiasTemperatureJson {
                t_ref_c: None,
                coeffs: t.coeffs.map(|row| row.map(f64::from)),
            }),
            scale_temp: c.scale_temp.map(|s| s.map(f64::from)),
            nonlinearity: c.nonlinearity.map(|n| NonlinearityJson {
                quadratic: n.quadratic.map(f64::from),
                cubic: n.cubic.map(f64::from),
            }),
            input_unit: None,
        }
    }
}

impl From<&CalibrationSet> for ParamsFile {
    fn from(set: &CalibrationSet) -> Self {
        Self {
            format: PARAMS_FILE_FORMAT,
            created_unix_s: set.created_unix_s,
            accel: SensorJson::from(&set.accel),
            gyro: SensorJson::from(&set.gyro),
            mag: SensorJson::from(&set.mag),
            gyro_g_sensitivity: set
                .gyro_g_sensitivity
                .map(|k| k.map(|row| row.map(f64::from))),
            reference: ReferenceJson {
                gravity_mps2: f64::from(set.reference.gravity_mps2),
                field_ut: f64::from(set.reference.field_ut),
            },
            residuals: ResidualsJson {
                accel_rms: f64::from(set.residuals.accel_rms),
                gyro_rms: f64::from(set.residuals.gyro_rms),
                mag_rms: f64::from(set.residuals.mag_rms),
            },
            not_fitted: BTreeMap::new(),
            provenance: None,
            device: None,
            absent_sensors: Vec::new(),
        }
    }
}

/// Narrows values to `f32`, naming the first that is not finite there.
struct Narrow<'a> {
    path: &'a str,
}

impl Narrow<'_> {
    fn one(&self, field: &str, value: f64) -> Result<f32, ParamsFileError> {
        let narrowed = value as f32;
        if narrowed.is_finite() {
            Ok(narrowed)
        } else {
            Err(ParamsFileError::NonFinite {
                path: self.path.to_string(),
                field: field.to_string(),
                value,
            })
        }
    }

    fn vec3(&self, field: &str, v: &[f64; 3]) -> Result<[f32; 3], ParamsFileError> {
        Ok([
            self.one(&format!("{field}[0]"), v[0])?,
            self.one(&format!("{field}[1]"), v[1])?,
            self.one(&format!("{field}[2]"), v[2])?,
        ])
    }

    fn mat3(&self, field: &str, m: &[[f64; 3]; 3]) -> Result<[[f32; 3]; 3], ParamsFileError> {
        Ok([
            self.vec3(&format!("{field}[0]"), &m[0])?,
            self.vec3(&format!("{field}[1]"), &m[1])?,
            self.vec3(&format!("{field}[2]"), &m[2])?,
        ])
    }

    fn sensor(&self, name: &str, s: &SensorJson) -> Result<SensorCalibration, ParamsFileError> {
        Ok(SensorCalibration {
            a: self.mat3(&format!("{name}.A"), &s.a)?,
            b: self.vec3(&format!("{name}.b"), &s.b)?,
            // Format 1 kept T_ref in the bias polynomial and meant 0 °C without one.
            t_ref_c: self.one(
                &format!("{name}.t_ref_c"),
                s.t_ref_c
                    .or(s.bias_temp.as_ref().and_then(|t| t.t_ref_c))
                    .unwrap_or(0.0),
            )?,
            bias_temp: match &s.bias_temp {
                Some(t) => Some(BiasTemperature {
                    coeffs: self.mat3(&format!("{name}.bias_temp.coeffs"), &t.coeffs)?,
                }),
                None => None,
            },
            scale_temp: match &s.scale_temp {
                Some(v) => Some(self.vec3(&format!("{name}.scale_temp"), v)?),
                None => None,
            },
            nonlinearity: match &s.nonlinearity {
                Some(n) => Some(Nonlinearity {
                    quadratic: self
                        .vec3(&format!("{name}.nonlinearity.quadratic"), &n.quadratic)?,
                    cubic: self.vec3(&format!("{name}.nonlinearity.cubic"), &n.cubic)?,
                }),
                None => None,
            },
        })
    }
}

impl ParamsFile {
    /// `(sensor, unit)` for every sensor whose input is not the board's nominal unit.
    pub fn non_nominal_inputs(&self) -> Vec<(&'static str, &str)> {
        [
            ("accel", &self.accel),
            ("gyro", &self.gyro),
            ("mag", &self.mag),
        ]
        .into_iter()
        .filter_map(|(name, s)| s.input_unit.as_deref().map(|u| (name, u)))
        .collect()
    }

    /// Parses a parameter file from JSON text; `path` names it in errors.
    /// Unknown top-level keys, an unsupported format and implausible references or residuals
    /// are errors naming the field.
    pub fn from_json(text: &str, path: &str) -> Result<Self, ParamsFileError> {
        let json_error = |cause| ParamsFileError::Json {
            path: path.to_string(),
            cause,
        };
        let value: serde_json::Value =
            serde_json::from_str(text).map_err(|cause| match not_a_json_number(text, &cause) {
                Some(word) => ParamsFileError::NotANumber {
                    path: path.to_string(),
                    word,
                    line: cause.line(),
                    column: cause.column(),
                },
                None => json_error(cause),
            })?;
        if let Some(what) = other_json(&value) {
            return Err(ParamsFileError::NotParameterFile {
                path: path.to_string(),
                what,
                fix: PASS_PARAMS.to_string(),
            });
        }
        let keys: Vec<String> = value
            .as_object()
            .map(|o| o.keys().cloned().collect())
            .unwrap_or_default();
        if let Some(key) = keys.iter().find(|k| !KNOWN_KEYS.contains(&k.as_str())) {
            return Err(ParamsFileError::UnknownKey {
                path: path.to_string(),
                key: key.clone(),
            });
        }
        let mut file: Self = serde_json::from_value(value).map_err(json_error)?;
        if !(OLDEST_PARAMS_FILE_FORMAT..=PARAMS_FILE_FORMAT).contains(&file.format) {
            return Err(ParamsFileError::UnsupportedFormat {
                path: path.to_string(),
                found: file.format,
            });
        }
        file.absent_sensors = SENSOR_KEYS
            .iter()
            .filter(|k| !keys.iter().any(|key| key == *k))
            .map(|k| k.to_string())
            .collect();
        file.check_metadata(path)?;
        Ok(file)
    }

    /// References must be physical magnitudes, residuals non-negative RMS values, and an input
    /// unit the one the format defines.
    fn check_metadata(&self, path: &str) -> Result<(), ParamsFileError> {
        for (sensor, json) in [
            ("accel", &self.accel),
            ("gyro", &self.gyro),
            ("mag", &self.mag),
        ] {
            if let Some(unit) = json.input_unit.as_deref().filter(|u| *u != COUNTS_UNIT) {
                return Err(ParamsFileError::UnknownInputUnit {
                    path: path.to_string(),
                    sensor,
                    unit: unit.to_string(),
                });
            }
        }
        let implausible = |field: &str, value: f64, expected| ParamsFileError::Implausible {
            path: path.to_string(),
            field: field.to_string(),
            value,
            expected,
        };
        // Gravity is 9.76–9.84 m/s² on the Earth's surface; the bounds leave room for a
        // normalised fit (1) and anything a centrifuge or another planet might be given.
        let g = self.reference.gravity_mps2;
        if !(g.is_finite() && g > 0.0 && g <= MAX_REFERENCE_GRAVITY) {
            return Err(implausible(
                "reference.gravity_mps2",
                g,
                "a positive number of m/s² (9.8 on Earth)",
            ));
        }
        // The geomagnetic field is 22–67 µT; 1 marks a fit normalised to the unit sphere.
        let h = self.reference.field_ut;
        if !(h.is_finite() && h > 0.0 && h <= MAX_REFERENCE_FIELD_UT) {
            return Err(implausible(
                "reference.field_ut",
                h,
                "a positive number of µT (about 25–65 on Earth, 1 for a normalised fit)",
            ));
        }
        let r = &self.residuals;
        for (field, value) in [
            ("residuals.accel_rms", r.accel_rms),
            ("residuals.gyro_rms", r.gyro_rms),
            ("residuals.mag_rms", r.mag_rms),
        ] {
            if !(value.is_finite() && value >= 0.0 && value <= f64::from(f32::MAX)) {
                return Err(implausible(
                    field,
                    value,
                    "a root mean square: a finite number of zero or more",
                ));
            }
        }
        Ok(())
    }

    /// Reads and parses a parameter file. A session directory, or another file of one, is
    /// refused with the session's `params.json` named.
    pub fn load(path: &Path) -> Result<Self, ParamsFileError> {
        let shown = path.display().to_string();
        if path.is_dir() {
            let inside = path.join("params.json");
            return Err(ParamsFileError::Directory {
                path: shown,
                fix: if inside.is_file() {
                    format!("pass the parameter file in it, `{}`", inside.display())
                } else {
                    PASS_PARAMS.to_string()
                },
            });
        }
        let text = std::fs::read_to_string(path).map_err(|cause| ParamsFileError::Io {
            path: shown.clone(),
            cause,
        })?;
        Self::from_json(&text, &shown).map_err(|error| match error {
            ParamsFileError::NotParameterFile { path: p, what, .. } => {
                let beside = path
                    .parent()
                    .map(|dir| dir.join("params.json"))
                    .filter(|params| params.is_file() && params.file_name() != path.file_name());
                ParamsFileError::NotParameterFile {
                    path: p,
                    what,
                    fix: match beside {
                        Some(params) => format!(
                            "the parameters of its session are in `{}`; pass that file",
                            params.display()
                        ),
                        None => PASS_PARAMS.to_string(),
                    },
                }
            }
            other => other,
        })
    }

    /// The file bound to the board that sent `welcome` (its id, sensors, ranges, firmware).
    pub fn bound_to(mut self, welcome: &imucal_protocol::Welcome) -> Self {
        self.device = Some(DeviceJson::from_welcome(welcome));
        self
    }

    /// The sensors the file calibrates: those neither listed as not fitted nor absent from the
    /// board.
    pub fn fitted_sensors(&self) -> Vec<&'static str> {
        SENSOR_KEYS
            .into_iter()
            .filter(|s| self.left_out_because(s).is_none())
            .collect()
    }

    /// The sensors (of [`SENSOR_KEYS`]) the file holds no calibration of, each with the reason:
    /// listed under `not_fitted`, or with no entry at all.
    pub fn left_out(&self) -> Vec<(&'static str, String)> {
        SENSOR_KEYS
            .into_iter()
            .filter_map(|s| Some((s, self.left_out_because(s)?)))
            .collect()
    }

    fn left_out_because(&self, sensor: &str) -> Option<String> {
        match self.not_fitted.get(sensor) {
            Some(why) => Some(why.clone()),
            None if self.absent_sensors.iter().any(|a| a == sensor) => {
                Some(format!("the file has no `{sensor}` entry"))
            }
            None => None,
        }
    }

    /// The file as `flash` wrote it to a board (`written`, the set it committed): each sensor
    /// the file left out takes what was written for it, with its residual and reference
    /// magnitude (gravity for the accelerometer, the field for the magnetometer). Those in
    /// `kept` kept the board's own calibration and are no longer listed as not fitted, unless
    /// the board held none (its identity); the others were set to identity and stay listed.
    /// What a history records of a flash, so that its parameters are the ones the board's CRC
    /// is of, and a sensor the board holds no calibration of is no measurement of it.
    pub fn as_written(&self, written: &CalibrationSet, kept: &[&str]) -> Self {
        let mut out = self.clone();
        let whole = Self::from(written);
        for (sensor, why) in self.left_out() {
            let on_board = match sensor {
                "accel" => &written.accel,
                "gyro" => &written.gyro,
                _ => &written.mag,
            };
            match sensor {
                "accel" => {
                    out.accel = whole.accel.clone();
                    out.residuals.accel_rms = whole.residuals.accel_rms;
                    out.reference.gravity_mps2 = whole.reference.gravity_mps2;
                }
                "gyro" => {
                    out.gyro = whole.gyro.clone();
                    out.gyro_g_sensitivity = whole.gyro_g_sensitivity;
                    out.residuals.gyro_rms = whole.residuals.gyro_rms;
                }
                _ => {
                    out.mag = whole.mag.clone();
                    out.residuals.mag_rms = whole.residuals.mag_rms;
                    out.reference.field_ut = whole.reference.field_ut;
                }
            }
            out.absent_sensors.retain(|a| a != sensor);
            if !kept.contains(&sensor) {
                out.not_fitted.insert(
                    sensor.to_string(),
                    format!("set to identity by flash --reset ({why})"),
                );
            } else if *on_board == SensorCalibration::identity() {
                // The board's identity is its "uncalibrated": keeping it calibrates nothing.
                out.not_fitted.insert(
                    sensor.to_string(),
                    format!("the board held no {sensor} calibration to keep ({why})"),
                );
            } else {
                out.not_fitted.remove(sensor);
            }
        }
        out
    }

    /// Why the file is of no use to a board, when it calibrates no sensor at all: writing or
    /// exporting it would only put identities in place of a calibration.
    pub fn holds_nothing(&self) -> Option<String> {
        if !self.fitted_sensors().is_empty() {
            return None;
        }
        let reasons: Vec<String> = self
            .not_fitted
            .iter()
            .map(|(sensor, why)| format!("{sensor}: {why}"))
            .collect();
        Some(format!(
            "it holds no calibration (no sensor could go into it{}); fit a recording that has the \
             sensor's data, or calibrate the board with `imucal calibrate`",
            if reasons.is_empty() {
                String::new()
            } else {
                format!(": {}", reasons.join("; "))
            }
        ))
    }

    /// Whether it was measured on a board running a MotionCal sketch (its provenance says so).
    pub fn from_sketch_board(&self) -> bool {
        self.provenance
            .as_ref()
            .and_then(|p| p.board_firmware.as_deref())
            == Some(MOTIONCAL_SKETCH)
    }

    /// The device id the file names: its board's, else the one `fit --device` recorded.
    pub fn device_id(&self) -> Option<&str> {
        self.device.as_ref().map(|d| d.id.as_str()).or(self
            .provenance
            .as_ref()
            .and_then(|p| p.device_id.as_deref()))
    }

    /// Pretty JSON text of the file.
    pub fn to_json(&self) -> String {
        // Plain data of numbers and fixed keys always serialises.
        serde_json::to_string_pretty(self).unwrap_or_default()
    }

    /// The protocol parameter set; `path` names the file in errors.
    pub fn to_calibration_set(&self, path: &str) -> Result<CalibrationSet, ParamsFileError> {
        let narrow = Narrow { path };
        Ok(CalibrationSet {
            format_version: PARAMS_FORMAT_VERSION,
            created_unix_s: self.created_unix_s,
            accel: narrow.sensor("accel", &self.accel)?,
            gyro: narrow.sensor("gyro", &self.gyro)?,
            mag: narrow.sensor("mag", &self.mag)?,
            gyro_g_sensitivity: match &self.gyro_g_sensitivity {
                Some(k) => Some(narrow.mat3("gyro_g_sensitivity", k)?),
                None => None,
            },
            reference: ReferenceMagnitudes {
                gravity_mps2: narrow.one("reference.gravity_mps2", self.reference.gravity_mps2)?,
                field_ut: narrow.one("reference.field_ut", self.reference.field_ut)?,
            },
            residuals: FitResiduals {
                accel_rms: narrow.one("residuals.accel_rms", self.residuals.accel_rms)?,
                gyro_rms: narrow.one("residuals.gyro_rms", self.residuals.gyro_rms)?,
                mag_rms: narrow.one("residuals.mag_rms", self.residuals.mag_rms)?,
            },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn extended_set() -> CalibrationSet {
        let mut set = CalibrationSet::identity();
        set.created_unix_s = 1_763_700_000;
        set.accel.a = [[1.01, 0.002, 0.0], [0.0, 0.99, -0.003], [0.001, 0.0, 1.02]];
        set.accel.b = [0.12, -0.05, 0.3];
        set.gyro.t_ref_c = 31.5;
        set.gyro.bias_temp = Some(BiasTemperature {
            coeffs: [[1e-4, -2e-4, 3e-5], [1e-6, 0.0, 0.0], [0.0; 3]],
        });
        set.mag.scale_temp = Some([1e-4, 2e-4, -1e-4]);
        set.accel.nonlinearity = Some(Nonlinearity {
            quadratic: [1e-4, 0.0, 0.0],
            cubic: [0.0, 1e-6, 0.0],
        });
        set.gyro_g_sensitivity = Some([[1e-4, 0.0, 0.0], [0.0, 1e-4, 0.0], [0.0, 0.0, 1e-4]]);
        set.reference.field_ut = 48.5;
        set
    }

    #[test]
    fn a_format_1_file_keeps_its_reference_temperature_meaning() {
        // Format 1: T_ref inside bias_temp, and 0 °C for a sensor without a bias polynomial.
        let text = r#"{ "format": 1, "reference": { "gravity_mps2": 9.81, "field_ut": 1 },
            "accel": { "A": [[1,0,0],[0,1,0],[0,0,1]], "b": [0,0,0], "scale_temp": [1e-4,0,0] },
            "gyro": { "A": [[1,0,0],[0,1,0],[0,0,1]], "b": [0,0,0],
                      "bias_temp": { "t_ref_c": 30, "coeffs": [[1e-4,0,0],[0,0,0],[0,0,0]] } } }"#;
        let set = ParamsFile::from_json(text, "old.json")
            .unwrap()
            .to_calibration_set("old.json")
            .unwrap();
        assert_eq!((set.accel.t_ref_c, set.gyro.t_ref_c), (0.0, 30.0));
        assert_eq!(set.format_version, PARAMS_FORMAT_VERSION);
    }

    #[test]
    fn parameter_file_round_trips_a_set_with_every_extended_term_bit_exactly() {
        let set = extended_set();
        let text = ParamsFile::from(&set).to_json();
        let back = ParamsFile::from_json(&text, "p.json")
            .and_then(|f| f.to_calibration_set("p.json"))
            .expect("own output parses");
        // f32 → f64 → JSON → f64 → f32 is exact (serde_json prints shortest round-trip f64).
        assert_eq!(back, set);
        assert_eq!(back.crc32(), set.crc32());
    }

    #[test]
    fn absent_sensors_are_identity_and_the_format_is_checked() {
        let text = r#"{"format": 1, "accel": {"A": [[1,0,0],[0,1,0],[0,0,1]], "b": [0.1,0,0]},
                      "reference": {"gravity_mps2": 9.81, "field_ut": 1}}"#;
        let set = ParamsFile::from_json(text, "a.json")
            .and_then(|f| f.to_calibration_set("a.json"))
            .expect("minimal file parses");
        assert_eq!(set.gyro, SensorCalibration::identity());
        assert_eq!(set.accel.b, [0.1, 0.0, 0.0]);
        let wrong = text.replace("\"format\": 1", "\"format\": 3");
        let message = ParamsFile::from_json(&wrong, "a.json")
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(
            message.contains("format 3") && message.contains("formats 1 to 2"),
            "{message}"
        );
    }

    #[test]
    fn a_value_beyond_f32_range_is_named_in_the_error() {
        let text = r#"{"format": 1, "accel": {"A": [[1,0,0],[0,1e300,0],[0,0,1]], "b": [0,0,0]},
                      "reference": {"gravity_mps2": 9.81, "field_ut": 1}}"#;
        let message = ParamsFile::from_json(text, "big.json")
            .and_then(|f| f.to_calibration_set("big.json"))
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(message.contains("accel.A[1][1]"), "{message}");
    }
}
