//! The calibration parameter file (JSON) that `imucal calibrate` writes and `imucal flash`
//! reads. It mirrors the protocol's `CalibrationSet` (model `y = (1+s·ΔT)∘(A·u')`,
//! `u = x − b(T)`, see `imucal_protocol::CalibrationSet`), versioned by `"format": 1`:
//!
//! ```json
//! { "format": 1, "created_unix_s": 1763700000,
//!   "accel": { "A": [[1,0,0],[0,1,0],[0,0,1]], "b": [0,0,0],
//!              "bias_temp": { "t_ref_c": 25, "coeffs": [[0,0,0],[0,0,0],[0,0,0]] },
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

use std::collections::BTreeMap;
use std::path::Path;

use imucal_protocol::{
    BiasTemperature, CalibrationSet, FitResiduals, Nonlinearity, ReferenceMagnitudes,
    SensorCalibration, PARAMS_FORMAT_VERSION,
};
use serde::{Deserialize, Serialize};

/// Format version of the parameter file written by this tool.
pub const PARAMS_FILE_FORMAT: u16 = 1;

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
    /// The file is not valid parameter JSON.
    #[error("`{path}` is not a valid parameter file: {cause}; it should be the JSON written by `imucal calibrate`")]
    Json {
        /// The file.
        path: String,
        /// The parser's error (with line and column).
        cause: serde_json::Error,
    },
    /// The file's `format` is not one this tool reads.
    #[error("`{path}` has parameter format {found}, this imucal reads format {PARAMS_FILE_FORMAT}; use the imucal version that wrote it or refit")]
    UnsupportedFormat {
        /// The file.
        path: String,
        /// The format found.
        found: u16,
    },
    /// A value is not finite or does not fit an `f32`.
    #[error(
        "`{path}`: {field} is {value}, which is not a finite 32-bit number; refit the calibration"
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
    /// Reference temperature, °C.
    pub t_ref_c: f64,
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
}

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

/// The whole parameter file. Unknown top-level keys (such as a report) are ignored.
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
}

impl From<&SensorCalibration> for SensorJson {
    fn from(c: &SensorCalibration) -> Self {
        Self {
            a: c.a.map(|row| row.map(f64::from)),
            b: c.b.map(f64::from),
            bias_temp: c.bias_temp.map(|t| BiasTemperatureJson {
                t_ref_c: f64::from(t.t_ref_c),
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
            bias_temp: match &s.bias_temp {
                Some(t) => Some(BiasTemperature {
                    t_ref_c: self.one(&format!("{name}.bias_temp.t_ref_c"), t.t_ref_c)?,
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
    /// `sensor (unit)` for every sensor whose input is not the board's nominal unit.
    pub fn non_nominal_inputs(&self) -> Vec<String> {
        [
            ("accel", &self.accel),
            ("gyro", &self.gyro),
            ("mag", &self.mag),
        ]
        .into_iter()
        .filter_map(|(name, s)| s.input_unit.as_ref().map(|u| format!("{name} ({u})")))
        .collect()
    }

    /// Parses a parameter file from JSON text; `path` names it in errors.
    pub fn from_json(text: &str, path: &str) -> Result<Self, ParamsFileError> {
        let file: Self = serde_json::from_str(text).map_err(|cause| ParamsFileError::Json {
            path: path.to_string(),
            cause,
        })?;
        if file.format != PARAMS_FILE_FORMAT {
            return Err(ParamsFileError::UnsupportedFormat {
                path: path.to_string(),
                found: file.format,
            });
        }
        Ok(file)
    }

    /// Reads and parses a parameter file.
    pub fn load(path: &Path) -> Result<Self, ParamsFileError> {
        let shown = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|cause| ParamsFileError::Io {
            path: shown.clone(),
            cause,
        })?;
        Self::from_json(&text, &shown)
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
        set.gyro.bias_temp = Some(BiasTemperature {
            t_ref_c: 25.0,
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
        let wrong = text.replace("\"format\": 1", "\"format\": 2");
        let message = ParamsFile::from_json(&wrong, "a.json")
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(
            message.contains("format 2") && message.contains("format 1"),
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
