//! The calibration report: one self-contained HTML page (inline CSS and SVG, no network
//! resources) showing the data before and after calibration, the fitted parameters with their
//! uncertainties, and the verdict.
//!
//! Figures: magnetometer samples in the xy, xz and yz projections, raw with the outline of the
//! fitted ellipsoid and calibrated with the reference sphere; the accelerometer's error of `|a|`
//! per pose; the gyroscope's rate at rest per pose and axis; histograms of the magnetometer's
//! norm error; the residual against time and temperature (or a sentence when the temperature
//! was constant); a map of the sphere's coverage. Poses are named by the side that points up. A report is built from a session directory
//! ([`from_session_dir`]) or from any recording and its fits ([`ReportData`] filled by the
//! caller), then rendered with [`render_html`].
//!
//! Files: the data (`mod.rs`), reading a session directory (`session_dir.rs`), numbers and words
//! (`format.rs`), the page (`html.rs`), the figures (`plots.rs`), a recording's fits as report
//! data (`recording.rs`), the gain in the report's units (`gain.rs`).

mod format;
pub mod gain;
mod html;
pub mod plots;
pub mod recording;
mod session_dir;

pub use format::{escape, numbered, region_coverage, up_label, ColumnFormat, NOT_ESTIMATED};
pub use html::{badge_class, render_html};
pub use session_dir::from_session_dir;

use std::path::{Path, PathBuf};

use serde_json::Value;

use crate::fit::{CalibrationStd, Mat3, Vec3};

/// File of a session directory holding the `--analyze` residual analysis as text, with the
/// extended terms it added; the report shows it when present.
pub const ANALYSIS_TEXT_FILE: &str = "analysis.txt";

/// Why a report could not be built or written.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// A file of the input could not be read.
    #[error("cannot read `{path}`: {cause}; a session directory holds params.json, poses.json, mag_samples.csv and summary.json")]
    Read {
        /// The file.
        path: String,
        /// The operating system's error.
        cause: std::io::Error,
    },
    /// A file of the input is not in the expected format.
    #[error("`{path}` is not as `imucal calibrate` writes it: {detail}")]
    Format {
        /// The file.
        path: String,
        /// What is wrong.
        detail: String,
    },
    /// The parameter file was refused.
    #[error(transparent)]
    Params(#[from] crate::device::ParamsFileError),
    /// A figure could not be drawn.
    #[error(transparent)]
    Plot(#[from] plots::PlotError),
    /// There is nothing to show.
    #[error(
        "the input has no accelerometer or gyroscope poses and no magnetometer samples to report on{because}"
    )]
    NoData {
        /// Why no sensor could be fitted (`": accel not fitted: …"`), or empty.
        because: String,
    },
    /// The report could not be written.
    #[error("cannot write `{path}`: {cause}; check that the directory is writable")]
    Write {
        /// The file.
        path: String,
        /// The operating system's error.
        cause: std::io::Error,
    },
}

/// A sensor's fitted parameters for the table.
#[derive(Debug, Clone)]
pub struct SensorParameters {
    /// Sensor name.
    pub name: String,
    /// Unit of the readings the calibration takes.
    pub unit_in: String,
    /// Unit of the calibrated output.
    pub unit_out: String,
    /// Correction matrix.
    pub a: Mat3,
    /// Offset.
    pub b: Vec3,
    /// One-sigma uncertainties of each entry, where the fit gives them.
    pub std: Option<CalibrationStd>,
    /// Output units per input unit at nominal sensitivity, when known: with it the table shows
    /// the scale errors and axis angles with the unit conversion taken out ([`gain::gain`]).
    pub to_nominal: Option<f64>,
}

/// Accelerometer still poses.
#[derive(Debug, Clone)]
pub struct AccelPoses {
    /// Pose means as read, converted to m/s² (scaled to `gravity` when the unit is counts).
    pub raw_mps2: Vec<Vec3>,
    /// Calibrated pose means, m/s².
    pub calibrated: Vec<Vec3>,
    /// Mean temperature of each pose, °C, when known.
    pub temp_c: Vec<Option<f64>>,
    /// Local gravity, m/s².
    pub gravity: f64,
    /// Name of each pose (the side that points up, or the recording's label).
    pub labels: Vec<String>,
}

/// The gyroscope's mean rate in each still pose, before and after calibration: at rest the
/// calibrated rate is what the bias fit leaves (the Earth's rotation is 0.004 °/s at most).
#[derive(Debug, Clone)]
pub struct GyroPoses {
    /// Mean rate per pose and axis as read, °/s.
    pub raw_dps: Vec<[f64; 3]>,
    /// Calibrated mean rate per pose and axis, °/s.
    pub calibrated_dps: Vec<[f64; 3]>,
    /// Name of each pose.
    pub labels: Vec<String>,
    /// The scale and misalignment fit from the moves between holds, as (what, value) rows;
    /// empty when only the bias was calibrated.
    pub scale_fit: Vec<(String, String)>,
}

/// The errors at rest of one parameter set, as the session measured them on the board.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RestCheck {
    /// `| |ā| − g |`, mg.
    pub accel_mg: Option<f64>,
    /// `| |m̄| − H |`, % of the field.
    pub mag_pct: Option<f64>,
    /// `|ω̄|`, °/s.
    pub gyro_dps: Option<f64>,
}

impl RestCheck {
    /// The values in the order of [`REST_QUANTITIES`].
    fn values(&self) -> [Option<f64>; 3] {
        [self.accel_mg, self.mag_pct, self.gyro_dps]
    }

    fn of(value: &Value) -> Option<Self> {
        value.is_object().then(|| Self {
            accel_mg: value["accel_error_mg"].as_f64(),
            mag_pct: value["mag_error_pct"].as_f64(),
            gyro_dps: value["gyro_rate_dps"].as_f64(),
        })
    }
}

/// Magnetometer samples over many orientations.
#[derive(Debug, Clone)]
pub struct MagSamples {
    /// Samples as read.
    pub raw: Vec<Vec3>,
    /// Calibrated samples.
    pub calibrated: Vec<Vec3>,
    /// Time of each sample, s; its number when the recording has no times (`time_is_index`).
    pub time_s: Vec<f64>,
    /// Whether `time_s` holds sample numbers: a recording without a time column or `--rate`.
    pub time_is_index: bool,
    /// Temperature of each sample, °C, when known.
    pub temp_c: Option<Vec<f64>>,
    /// Where the temperature came from, when not from the magnetometer's own rows.
    pub temp_note: Option<String>,
    /// Reference field magnitude of the calibrated output.
    pub field: f64,
    /// Unit of the raw samples.
    pub raw_unit: String,
    /// Unit of the calibrated samples.
    pub calibrated_unit: String,
    /// The fitted ellipsoid of the raw samples: centre `b` and shape `field·A⁻¹`.
    pub ellipsoid: Option<(Vec3, Mat3)>,
    /// Raw samples whose directions the coverage counts: for a session, those its screen counted
    /// (the moves between positions and the tumble, not the final rest); for a recording, `raw`.
    pub counted: Vec<Vec3>,
}

/// Everything one report shows.
#[derive(Debug, Clone, Default)]
pub struct ReportData {
    /// What was calibrated (a session directory or a recording).
    pub source: String,
    /// Accelerometer poses, if any.
    pub accel: Option<AccelPoses>,
    /// Magnetometer samples, if any.
    pub mag: Option<MagSamples>,
    /// Gyroscope rate at rest per pose, if any.
    pub gyro: Option<GyroPoses>,
    /// Fitted parameters per sensor.
    pub parameters: Vec<SensorParameters>,
    /// Terms beyond `A` and `b` in the set (temperature, non-linearity, g-sensitivity), as
    /// (sensor, term, values with unit) rows.
    pub extended_terms: Vec<(String, String, String)>,
    /// The checks at rest on the board, one column per set: `before` (raw), and after the base
    /// set and, with `--analyze`, after the extended set on the board.
    pub rest_checks: Vec<(String, RestCheck)>,
    /// Further uncertainty figures as (name, value with unit).
    pub uncertainty_notes: Vec<(String, String)>,
    /// Overall verdict: `good`, `marginal`, `poor` or a short phrase (`fitted` when nothing
    /// was checked on held-out data: the badge is then neutral).
    pub verdict_level: String,
    /// Reasons and remarks behind the verdict, one sentence each.
    pub verdict: Vec<String>,
    /// Other remarks (local field check, thinning, method choices).
    pub notes: Vec<String>,
    /// Directions (of the 26 regions) the session's screen counted as reached, when the input
    /// is a session directory: it includes the field seen during the moves between positions.
    pub session_regions_covered: Option<u64>,
    /// The residual analysis and the extended terms it added (`calibrate --analyze`), as text.
    pub analysis: Option<String>,
    /// The board's parameters over time from the calibration history, `(title, SVG)` per
    /// figure (see `history::plot::parameters_over_time`); empty when there is no history.
    pub history: Vec<(String, String)>,
}

/// The ellipsoid shape `field·A⁻¹` of a calibration `y = A·(x − b)` with `|y| = field`.
pub fn ellipsoid_shape(a: &Mat3, field: f64) -> Option<Mat3> {
    a.try_inverse().map(|inv| inv * field)
}

/// The name of the report file in its directory.
pub const REPORT_FILE: &str = "report.html";

/// Writes [`REPORT_FILE`] into `dir` (created if missing) and returns its path.
pub fn write_report(data: &ReportData, dir: &Path) -> Result<PathBuf, ReportError> {
    let path = dir.join(REPORT_FILE);
    write_report_file(data, &path)?;
    Ok(path)
}

/// Writes the report to the file `path`, creating its directory if missing.
pub fn write_report_file(data: &ReportData, path: &Path) -> Result<(), ReportError> {
    let html = render_html(data)?;
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|cause| ReportError::Write {
            path: dir.display().to_string(),
            cause,
        })?;
    }
    std::fs::write(path, html).map_err(|cause| ReportError::Write {
        path: path.display().to_string(),
        cause,
    })
}
