//! One calibration as kept in the history: who, when, with what, the parameter set and how sure
//! the fit was. The named scalar parameters ([`CalibrationRecord::parameters`]) are what the
//! history compares between calibrations and the fleet statistics compare between boards.

use std::collections::BTreeMap;
use std::time::{SystemTime, UNIX_EPOCH};

use serde::{Deserialize, Serialize};

use crate::device::params_json::SensorJson;
use crate::device::ParamsFile;
use crate::session::{CapturedPose, SessionFit, SessionSummary, Uncertainties};

/// How `fit --params-out` names the "device" of a recording fitted without `--device`:
/// `recording:` and the file's stem. Such a record describes no board, so the fleet does not
/// count it.
pub const RECORDING_DEVICE_PREFIX: &str = "recording:";

/// What produced a calibration record.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RecordSource {
    /// A guided session (`imucal calibrate`) that fitted the set; [`CalibrationRecord::board`]
    /// says whether it was written.
    Guided,
    /// `imucal fit --params-out`: a set fitted from a recording.
    Fit,
    /// `imucal flash`: a parameter file written to a board.
    Flash,
    /// `imucal params reset`: the board's calibration set to identity.
    Reset,
}

impl AsRef<ParamsFile> for CalibrationRecord {
    fn as_ref(&self) -> &ParamsFile {
        &self.params
    }
}

impl CalibrationRecord {
    /// Whether the record is of a recording fitted offline without a board named
    /// ([`RECORDING_DEVICE_PREFIX`]).
    pub fn names_no_board(&self) -> bool {
        self.device_id.starts_with(RECORDING_DEVICE_PREFIX)
    }
}

impl RecordSource {
    /// The name stored in the database.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Guided => "guided",
            Self::Fit => "fit",
            Self::Flash => "flash",
            Self::Reset => "reset",
        }
    }

    /// The source named `name` in the database.
    pub fn parse(name: &str) -> Option<Self> {
        match name {
            "guided" => Some(Self::Guided),
            "fit" => Some(Self::Fit),
            "flash" => Some(Self::Flash),
            "reset" => Some(Self::Reset),
            _ => None,
        }
    }
}

/// Die temperatures seen while the data of a calibration was taken, °C.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TemperatureSpan {
    /// Lowest.
    pub min_c: f64,
    /// Mean.
    pub mean_c: f64,
    /// Highest.
    pub max_c: f64,
}

/// Whether a record's set went onto the board it names.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(tag = "state", rename_all = "snake_case")]
pub enum BoardWrite {
    /// Written to the board (for `fit`: saved to a file to be written).
    #[default]
    Written,
    /// Written to the board, but measured in the session of another board
    /// (`flash --force-other-device`).
    FromOtherBoard {
        /// The board whose session produced the set.
        measured_on: String,
    },
    /// Not written: the board keeps its earlier set.
    NotWritten {
        /// Why, e.g. `outlier against the fleet`.
        reason: String,
    },
}

impl BoardWrite {
    /// Whether the set is on the board.
    pub fn on_board(&self) -> bool {
        !matches!(self, Self::NotWritten { .. })
    }

    /// The state in words for tables (`None` for an ordinary written set).
    pub fn label(&self) -> Option<String> {
        match self {
            Self::Written => None,
            Self::FromOtherBoard { measured_on } => Some(format!(
                "written from the session of another board ({measured_on})"
            )),
            Self::NotWritten { reason } => Some(format!("NOT WRITTEN to the board: {reason}")),
        }
    }
}

/// Verdict of the fit, when the producer judged it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RecordVerdict {
    /// `good`, `marginal` or `poor`.
    pub level: String,
    /// One sentence per check that missed its budget.
    pub reasons: Vec<String>,
}

/// One calibration of one board.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CalibrationRecord {
    /// The board's id (hex, as the board reports it), or a name given for recordings.
    pub device_id: String,
    /// When the calibration was recorded, milliseconds since the Unix epoch (UTC).
    pub recorded_unix_ms: i64,
    /// The `imucal` version that produced it.
    pub tool_version: String,
    /// The board's firmware version (`major.minor.patch`), when a board was involved.
    pub firmware_version: Option<String>,
    /// What produced it.
    pub source: RecordSource,
    /// The parameter set.
    pub params: ParamsFile,
    /// CRC-32 of the parameter set as the board stores it (in JSON as `info` and the session
    /// files print it: `"0x9a2711ba"`).
    #[serde(with = "crc_text")]
    pub params_crc: u32,
    /// One-sigma uncertainty of named parameters, in the parameters' units (see
    /// [`CalibrationRecord::parameters`]); parameters without an estimate are absent.
    pub sigma: BTreeMap<String, f64>,
    /// Residual RMS of the fit per sensor (m/s², rad/s, µT).
    pub residuals: BTreeMap<String, f64>,
    /// Sample noise (standard deviation per sample) per sensor axis while still, e.g.
    /// `gyro.noise.x` in rad/s.
    pub noise: BTreeMap<String, f64>,
    /// Die temperatures during the capture.
    pub temperatures: Option<TemperatureSpan>,
    /// The fit's verdict.
    pub verdict: Option<RecordVerdict>,
    /// Who ran the calibration.
    pub operator: Option<String>,
    /// Which station or fixture.
    pub station: Option<String>,
    /// Whether the set went onto the board (records made before this was kept read as written,
    /// unless their verdict says "not written").
    #[serde(default)]
    pub board: BoardWrite,
}

/// Axis letters used in parameter names.
pub const AXES: [&str; 3] = ["x", "y", "z"];

/// Milliseconds since the Unix epoch, now.
pub fn now_unix_ms() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| i64::try_from(d.as_millis()).unwrap_or(i64::MAX))
}

/// The tool's own version.
pub fn tool_version() -> String {
    env!("CARGO_PKG_VERSION").to_string()
}

impl CalibrationRecord {
    /// A record of `params` for `device_id` made now, with no σ, noise, temperatures, verdict,
    /// operator or station (fill them in as known).
    pub fn new(device_id: &str, source: RecordSource, params: ParamsFile, params_crc: u32) -> Self {
        let residuals = BTreeMap::from([
            ("accel".to_string(), params.residuals.accel_rms),
            ("gyro".to_string(), params.residuals.gyro_rms),
            ("mag".to_string(), params.residuals.mag_rms),
        ]);
        Self {
            device_id: device_id.to_string(),
            recorded_unix_ms: now_unix_ms(),
            tool_version: tool_version(),
            firmware_version: None,
            source,
            params,
            params_crc,
            sigma: BTreeMap::new(),
            residuals,
            noise: BTreeMap::new(),
            temperatures: None,
            verdict: None,
            operator: None,
            station: None,
            board: BoardWrite::Written,
        }
    }

    /// The record of a guided session: its summary (set, CRC, σ, verdict) and its poses (noise
    /// and temperatures).
    pub fn from_session(summary: &SessionSummary, poses: &[CapturedPose]) -> Self {
        let crc = parse_crc(&summary.params_crc).unwrap_or(0);
        let mut record = Self::new(
            &summary.device_id,
            RecordSource::Guided,
            summary.params.clone(),
            crc,
        );
        record.add_fit_sigma(&summary.uncertainties, summary.gravity_mps2);
        record.noise = still_noise(poses);
        record.temperatures = temperature_span(poses);
        record.verdict = record_verdict(&summary.verdict);
        if let Some(reason) = &summary.not_written_because {
            record.board = BoardWrite::NotWritten {
                reason: reason.clone(),
            };
        }
        record
    }

    /// The record of a session's fit before it is written (set, CRC, σ, verdict; no noise or
    /// temperatures): what a board is compared with its fleet on.
    pub fn from_fit(device_id: &str, fit: &SessionFit) -> Self {
        let mut record = Self::new(
            device_id,
            RecordSource::Guided,
            ParamsFile::from(&fit.set),
            fit.set.crc32(),
        );
        record.add_fit_sigma(&fit.uncertainties, fit.gravity_mps2);
        record.verdict = record_verdict(&fit.verdict);
        record
    }

    /// σ of the offsets and gains from the fit's uncertainties (`g`: gravity, m/s², for mg).
    fn add_fit_sigma(&mut self, u: &Uncertainties, g: f64) {
        for (i, axis) in AXES.iter().enumerate() {
            self.sigma
                .insert(format!("accel.b.{axis}"), u.accel_bias_mg[i] * 1e-3 * g);
            self.sigma
                .insert(format!("accel.A.{axis}{axis}"), u.accel_scale_ppm[i] * 1e-6);
            self.sigma
                .insert(format!("gyro.b.{axis}"), u.gyro_bias_dps[i].to_radians());
            self.sigma.insert(format!("mag.b.{axis}"), u.mag_bias_ut[i]);
        }
        self.sigma.retain(|_, s| s.is_finite() && *s > 0.0);
    }

    /// Every named scalar parameter of the record: `SENSOR.b.AXIS` (offset), `SENSOR.A.ROWCOL`
    /// (correction matrix), the noise (`SENSOR.noise.AXIS`) and the residual RMS
    /// (`SENSOR.residual`). Units are the sensor's (m/s², rad/s, µT); `A` is dimensionless. A
    /// sensor the record did not calibrate (not fitted, or absent) has none of these: its
    /// placeholder identity is no measurement.
    pub fn parameters(&self) -> BTreeMap<String, f64> {
        let mut out = BTreeMap::new();
        for (name, sensor) in [
            ("accel", &self.params.accel),
            ("gyro", &self.params.gyro),
            ("mag", &self.params.mag),
        ] {
            insert_sensor(&mut out, name, sensor);
        }
        out.extend(self.noise.iter().map(|(k, v)| (k.clone(), *v)));
        out.extend(
            self.residuals
                .iter()
                .filter(|(_, v)| **v > 0.0)
                .map(|(k, v)| (format!("{k}.residual"), *v)),
        );
        let fitted = self.params.fitted_sensors();
        out.retain(|name, _| {
            name.split('.')
                .next()
                .is_some_and(|sensor| fitted.contains(&sensor))
        });
        out
    }

    /// The first value that is not a finite number (a parameter, σ or temperature), named;
    /// such a record is refused rather than stored.
    pub fn non_finite(&self) -> Option<(String, f64)> {
        let temperatures = self.temperatures.iter().flat_map(|t| {
            [
                ("temperatures.min_c".to_string(), t.min_c),
                ("temperatures.mean_c".to_string(), t.mean_c),
                ("temperatures.max_c".to_string(), t.max_c),
            ]
        });
        self.parameters()
            .into_iter()
            .chain(self.sigma.iter().map(|(k, v)| (format!("σ of {k}"), *v)))
            .chain(temperatures)
            .find(|(_, v)| !v.is_finite())
    }
}

fn insert_sensor(out: &mut BTreeMap<String, f64>, name: &str, sensor: &SensorJson) {
    for (i, row) in AXES.iter().enumerate() {
        out.insert(format!("{name}.b.{row}"), sensor.b[i]);
        for (j, col) in AXES.iter().enumerate() {
            out.insert(format!("{name}.A.{row}{col}"), sensor.a[i][j]);
        }
    }
}

/// A CRC in JSON as the hex text the rest of imucal prints (a plain number is read too).
mod crc_text {
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(crc: &u32, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(&format!("{crc:#010x}"))
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(deserializer: D) -> Result<u32, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Crc {
            Number(u32),
            Text(String),
        }
        match Crc::deserialize(deserializer)? {
            Crc::Number(n) => Ok(n),
            Crc::Text(t) => super::parse_crc(&t)
                .ok_or_else(|| serde::de::Error::custom(format!("`{t}` is not a hex CRC-32"))),
        }
    }
}

/// `0x1234abcd` or `1234abcd` as a number.
pub fn parse_crc(text: &str) -> Option<u32> {
    let digits = text.trim().trim_start_matches("0x");
    u32::from_str_radix(digits, 16).ok()
}

/// Per-axis sample noise while still: the square root of the median per-pose variance (the
/// median keeps one disturbed pose from counting).
fn still_noise(poses: &[CapturedPose]) -> BTreeMap<String, f64> {
    let mut out = BTreeMap::new();
    type Variance = fn(&imucal_protocol::PoseStats) -> [f32; 3];
    let sensors: [(&str, Variance); 3] = [
        ("accel", |s| s.accel_var),
        ("gyro", |s| s.gyro_var),
        ("mag", |s| s.mag_var),
    ];
    for (name, variance) in sensors {
        for (i, axis) in AXES.iter().enumerate() {
            let mut v: Vec<f64> = poses
                .iter()
                .map(|p| f64::from(variance(&p.stats)[i]))
                .filter(|v| v.is_finite() && *v > 0.0)
                .collect();
            if let Some(median) = super::stats::median(&mut v) {
                out.insert(format!("{name}.noise.{axis}"), median.sqrt());
            }
        }
    }
    out
}

fn temperature_span(poses: &[CapturedPose]) -> Option<TemperatureSpan> {
    let temps: Vec<&imucal_protocol::PoseStats> = poses
        .iter()
        .map(|p| &p.stats)
        .filter(|s| s.temp_mean_c.is_finite())
        .collect();
    if temps.is_empty() {
        return None;
    }
    let n = temps.len() as f64;
    Some(TemperatureSpan {
        min_c: temps
            .iter()
            .map(|s| f64::from(s.temp_min_c))
            .fold(f64::INFINITY, f64::min),
        mean_c: temps.iter().map(|s| f64::from(s.temp_mean_c)).sum::<f64>() / n,
        max_c: temps
            .iter()
            .map(|s| f64::from(s.temp_max_c))
            .fold(f64::NEG_INFINITY, f64::max),
    })
}

/// The session's verdict as recorded.
fn record_verdict(verdict: &crate::session::Verdict) -> Option<RecordVerdict> {
    serde_json::to_value(verdict)
        .ok()
        .and_then(|v| serde_json::from_value(v).ok())
}
