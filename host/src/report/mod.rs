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

pub mod gain;
pub mod plots;
pub mod recording;

use std::path::{Path, PathBuf};

use serde_json::Value;

use crate::device::ParamsFile;
use crate::fit::{CalibrationStd, Mat3, Vec3};
use crate::session::coverage::{sphere_centre, Coverage, REGIONS};
use crate::session::rest::REST_QUANTITIES;
use imucal_protocol::apply_sensor;

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
    #[error("the input has neither accelerometer poses nor magnetometer samples to report on")]
    NoData,
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
    /// Time of each sample, s.
    pub time_s: Vec<f64>,
    /// Temperature of each sample, °C, when known.
    pub temp_c: Option<Vec<f64>>,
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

fn read(path: &Path) -> Result<String, ReportError> {
    std::fs::read_to_string(path).map_err(|cause| ReportError::Read {
        path: path.display().to_string(),
        cause,
    })
}

fn format_error(path: &Path, detail: impl Into<String>) -> ReportError {
    ReportError::Format {
        path: path.display().to_string(),
        detail: detail.into(),
    }
}

fn vec3_of(value: &Value) -> Option<Vec3> {
    let array = value.as_array()?;
    match array.as_slice() {
        [x, y, z] => Some(Vec3::new(x.as_f64()?, y.as_f64()?, z.as_f64()?)),
        _ => None,
    }
}

fn mat3_of(rows: &[[f64; 3]; 3]) -> Mat3 {
    Mat3::from_fn(|r, c| rows[r][c])
}

/// The columns of a session's `mag_samples.csv`.
struct MagColumns {
    time_s: Vec<f64>,
    raw: Vec<Vec3>,
    temp_c: Vec<f64>,
    /// Samples of the positions and tumble phases (every sample without a phase column).
    counted: Vec<Vec3>,
}

/// Reads `mag_samples.csv` (`t_s,mx,my,mz,temp_c,phase`): the tumble samples if there are
/// any, otherwise every sample; and apart, the samples the session's coverage counted.
fn read_mag_csv(path: &Path) -> Result<MagColumns, ReportError> {
    let text = read(path)?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines
        .next()
        .unwrap_or_default()
        .split(',')
        .map(str::trim)
        .collect();
    let column = |name: &str| {
        header
            .iter()
            .position(|h| *h == name)
            .ok_or_else(|| format_error(path, format!("the header has no `{name}` column")))
    };
    let [t, mx, my, mz, temp] = [
        column("t_s")?,
        column("mx")?,
        column("my")?,
        column("mz")?,
        column("temp_c")?,
    ];
    let phase = header.iter().position(|h| *h == "phase");
    let mut rows: Vec<(bool, f64, Vec3, f64)> = Vec::new();
    let mut counted = Vec::new();
    for (index, line) in lines.enumerate().filter(|(_, l)| !l.trim().is_empty()) {
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        let number = |k: usize| {
            fields
                .get(k)
                .and_then(|f| f.parse::<f64>().ok())
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    format_error(
                        path,
                        format!("line {} is not five numbers and a phase", index + 2),
                    )
                })
        };
        let phase_name = phase.and_then(|p| fields.get(p)).copied();
        let tumble = phase_name == Some("tumble");
        let reading = Vec3::new(number(mx)?, number(my)?, number(mz)?);
        if phase_name != Some("rest") {
            counted.push(reading);
        }
        rows.push((
            tumble,
            number(t)?,
            Vec3::new(number(mx)?, number(my)?, number(mz)?),
            number(temp)?,
        ));
    }
    if rows.iter().any(|r| r.0) {
        rows.retain(|r| r.0);
    }
    Ok(MagColumns {
        time_s: rows.iter().map(|r| r.1).collect(),
        raw: rows.iter().map(|r| r.2).collect(),
        temp_c: rows.iter().map(|r| r.3).collect(),
        counted,
    })
}

/// Builds a report from a session directory written by `imucal calibrate`.
pub fn from_session_dir(dir: &Path) -> Result<ReportData, ReportError> {
    let params_path = dir.join("params.json");
    let params = ParamsFile::load(&params_path)?;
    let set = params.to_calibration_set(&params_path.display().to_string())?;
    let gravity = params.reference.gravity_mps2;
    let field = params.reference.field_ut;

    let poses_path = dir.join("poses.json");
    let poses: Value = serde_json::from_str(&read(&poses_path)?)
        .map_err(|e| format_error(&poses_path, e.to_string()))?;
    let mut raw = Vec::new();
    let mut temp = Vec::new();
    let mut labels = Vec::new();
    let mut gyro_raw = Vec::new();
    for pose in poses.as_array().into_iter().flatten() {
        let stats = &pose["stats"];
        let mean = vec3_of(&stats["accel_mean"])
            .ok_or_else(|| format_error(&poses_path, "a pose has no `stats.accel_mean` triple"))?;
        let t = stats["temp_mean_c"].as_f64();
        labels.push(pose["target"].as_str().map_or_else(
            || up_label(&vec3_of(&pose["target_up"]).unwrap_or(mean)),
            str::to_string,
        ));
        gyro_raw.push(vec3_of(&stats["gyro_mean"]).map(|g| (g, t.unwrap_or(25.0))));
        raw.push(mean);
        temp.push(t);
    }
    let labels = numbered(labels);
    let gyro = gyro_raw.iter().all(Option::is_some).then(|| GyroPoses {
        raw_dps: gyro_raw.iter().flatten().map(|(g, _)| degrees(g)).collect(),
        calibrated_dps: gyro_raw
            .iter()
            .flatten()
            .map(|(g, t)| degrees(&Vec3::from(apply_sensor(&set.gyro, (*g).into(), *t))))
            .collect(),
        labels: labels.clone(),
        scale_fit: Vec::new(),
    });
    let calibrated = raw
        .iter()
        .zip(&temp)
        .map(|(x, t)| Vec3::from(apply_sensor(&set.accel, (*x).into(), t.unwrap_or(25.0))))
        .collect();
    let accel = (!raw.is_empty()).then_some(AccelPoses {
        raw_mps2: raw,
        calibrated,
        temp_c: temp,
        gravity,
        labels,
    });

    let MagColumns {
        time_s,
        raw: mag_raw,
        temp_c: mag_temp,
        counted,
    } = read_mag_csv(&dir.join("mag_samples.csv"))?;
    let mag_calibrated = mag_raw
        .iter()
        .zip(&mag_temp)
        .map(|(x, t)| Vec3::from(apply_sensor(&set.mag, (*x).into(), *t)))
        .collect();
    let mag_a = mat3_of(&params.mag.a);
    let mag = (!mag_raw.is_empty()).then(|| MagSamples {
        raw: mag_raw,
        calibrated: mag_calibrated,
        time_s,
        temp_c: Some(mag_temp),
        field,
        raw_unit: "µT".to_string(),
        calibrated_unit: "µT".to_string(),
        ellipsoid: ellipsoid_shape(&mag_a, field).map(|s| (Vec3::from(params.mag.b), s)),
        counted,
    });

    let mut data = ReportData {
        source: dir.display().to_string(),
        accel,
        gyro: gyro.filter(|g| !g.raw_dps.is_empty()),
        mag,
        extended_terms: extended_terms(&params),
        parameters: [
            ("accelerometer", "m/s²", &params.accel),
            ("gyroscope", "rad/s", &params.gyro),
            ("magnetometer", "µT", &params.mag),
        ]
        .into_iter()
        .map(|(name, unit, s)| SensorParameters {
            name: name.to_string(),
            unit_in: unit.to_string(),
            unit_out: unit.to_string(),
            a: mat3_of(&s.a),
            b: Vec3::from(s.b),
            std: None,
            to_nominal: Some(1.0),
        })
        .collect(),
        analysis: std::fs::read_to_string(dir.join(ANALYSIS_TEXT_FILE)).ok(),
        session_regions_covered: std::fs::read_to_string(dir.join("summary.json"))
            .ok()
            .and_then(|text| serde_json::from_str::<Value>(&text).ok())
            .and_then(|summary| summary["mag_regions_covered"].as_u64()),
        ..ReportData::default()
    };
    let summary_path = dir.join("summary.json");
    if let Ok(text) = std::fs::read_to_string(&summary_path) {
        let summary: Value =
            serde_json::from_str(&text).map_err(|e| format_error(&summary_path, e.to_string()))?;
        data.verdict_level = summary["verdict"]["level"]
            .as_str()
            .unwrap_or("unknown")
            .to_string();
        data.verdict = summary["verdict"]["reasons"]
            .as_array()
            .into_iter()
            .flatten()
            .filter_map(|r| r.as_str().map(str::to_string))
            .collect();
        if let Some(map) = summary["uncertainties"].as_object() {
            data.uncertainty_notes = map
                .iter()
                .map(|(key, value)| uncertainty_in_words(key, value))
                .collect();
        }
        // With `--analyze` the extended set replaced the base set on the board: both checks.
        let extended =
            summary["on_board_after"].is_object() && summary["on_board_after"] != summary["after"];
        let mut columns = vec![("before (raw)", "before")];
        if extended {
            columns.push(("after, base set", "after"));
            columns.push(("after, extended set (on the board)", "on_board_after"));
        } else {
            columns.push(("after (on the board)", "after"));
        }
        for (label, key) in columns {
            if let Some(check) = RestCheck::of(&summary[key]) {
                data.rest_checks.push((label.to_string(), check));
            }
        }
        if data.rest_checks.is_empty() {
            // Summaries without the before/after objects carry the after-values alone.
            let check = RestCheck {
                accel_mg: summary["accel_rest_error_mg"].as_f64(),
                mag_pct: summary["mag_rest_error_pct"].as_f64(),
                gyro_dps: summary["gyro_rest_error_dps"].as_f64(),
            };
            if check
                .accel_mg
                .or(check.mag_pct)
                .or(check.gyro_dps)
                .is_some()
            {
                data.rest_checks.push(("after".to_string(), check));
            }
        }
        if let Some(gyro) = data.gyro.as_mut() {
            gyro.scale_fit = gyro_scale_rows(&summary["gyro_scale"]);
        }
    } else {
        data.verdict_level = "unknown".to_string();
        data.notes
            .push("summary.json is missing: no verdict from the session".to_string());
    }
    Ok(data)
}

/// Text for a value that was not estimated (NaN, infinite or absent in the input).
pub const NOT_ESTIMATED: &str = "unknown / not estimated";

/// Rates in rad/s as °/s per axis.
fn degrees(v: &Vec3) -> [f64; 3] {
    [v.x, v.y, v.z].map(f64::to_degrees)
}

/// A pose's name from its up direction, e.g. `+X-Y up`.
pub fn up_label(up: &Vec3) -> String {
    match up.try_normalize(0.0) {
        Some(u) => format!("{} up", crate::session::targets::direction_name(&u)),
        None => "pose".to_string(),
    }
}

/// Labels made distinct: a repeated name gets its occurrence (`+Z up`, `+Z up #2`).
pub fn numbered(labels: Vec<String>) -> Vec<String> {
    let mut seen = std::collections::HashMap::<String, usize>::new();
    labels
        .into_iter()
        .map(|label| {
            let count = seen.entry(label.clone()).or_insert(0);
            *count += 1;
            if *count == 1 {
                label
            } else {
                format!("{label} #{count}")
            }
        })
        .collect()
}

/// A summary's uncertainty entry in words: what it is, per axis or worst direction, its unit
/// and that it is one standard deviation.
fn uncertainty_in_words(key: &str, value: &Value) -> (String, String) {
    let (name, unit) = match key {
        "accel_bias_mg" => ("accelerometer offset, per axis x, y, z", "mg"),
        "accel_scale_ppm" => ("accelerometer scale factor, per axis x, y, z", "ppm"),
        "accel_norm_mg" => ("expected error of |a| in the worst direction", "mg"),
        "gyro_bias_dps" => ("gyroscope bias, per axis x, y, z", "°/s"),
        "mag_bias_ut" => ("magnetometer offset, per axis x, y, z", "µT"),
        "mag_norm_pct" => (
            "expected error of |m| in the worst direction",
            "% of the field",
        ),
        "alignment_deg" => (
            "angle between the magnetometer's and the accelerometer's frames (RMS of the axes)",
            "°",
        ),
        other => (other, ""),
    };
    let values: Vec<Option<f64>> = match value {
        Value::Array(items) => items.iter().map(Value::as_f64).collect(),
        other => vec![other.as_f64()],
    };
    let known = |v: &Option<f64>| v.is_some_and(f64::is_finite);
    // One "not estimated" for the row rather than one per axis.
    let text = if values.iter().any(known) {
        values
            .iter()
            .map(|v| match v.filter(|v| v.is_finite()) {
                Some(_) => format!("± {}", with_unit(*v, unit)),
                None => NOT_ESTIMATED.to_string(),
            })
            .collect::<Vec<_>>()
            .join(", ")
    } else {
        NOT_ESTIMATED.to_string()
    };
    (name.to_string(), text)
}

/// `value unit` to 3 significant digits, or [`NOT_ESTIMATED`].
fn with_unit(value: Option<f64>, unit: &str) -> String {
    match value.filter(|v| v.is_finite()) {
        // Degrees are written against the number (1.2°), other units after a space.
        Some(v) if unit == "°" => format!("{}°", significant(v, 3)),
        Some(v) => format!("{} {unit}", significant(v, 3))
            .trim_end()
            .to_string(),
        None => NOT_ESTIMATED.to_string(),
    }
}

/// `value` to `digits` significant digits in plain notation (scientific below 1e-4).
fn significant(value: f64, digits: usize) -> String {
    if value == 0.0 {
        return "0".to_string();
    }
    let magnitude = value.abs().log10().floor() as i32;
    if !(-4..6).contains(&magnitude) {
        return format!("{value:.prec$e}", prec = digits.saturating_sub(1));
    }
    let decimals = (digits as i32 - 1 - magnitude).max(0) as usize;
    format!("{value:.decimals$}")
}

/// The summary's gyroscope scale fit (`gyro_scale`) as rows for the report.
fn gyro_scale_rows(value: &Value) -> Vec<(String, String)> {
    let number = |key: &str| value[key].as_f64();
    let triple = |key: &str| -> Option<[f64; 3]> {
        let a = value[key].as_array()?;
        Some([
            a.first()?.as_f64()?,
            a.get(1)?.as_f64()?,
            a.get(2)?.as_f64()?,
        ])
    };
    let Some(scale) = triple("scale") else {
        return Vec::new();
    };
    let sigma = triple("scale_sigma_pct").unwrap_or([f64::NAN; 3]);
    // `scale` is the correction (diagonal of A); the sensor reads high by its inverse, as the
    // parameter table's scale error says.
    let mut rows = vec![(
        "scale error of x, y, z (how far the sensor reads from nominal, ± one standard \
         deviation)"
            .to_string(),
        (0..3)
            .map(|i| {
                format!(
                    "{:+.3} % ± {}",
                    (1.0 / scale[i] - 1.0) * 100.0,
                    with_unit(Some(sigma[i]), "%")
                )
            })
            .collect::<Vec<_>>()
            .join(", "),
    )];
    rows.push((
        "largest misalignment between axes (± one standard deviation)".to_string(),
        format!(
            "{} ± {}",
            with_unit(number("misalignment_deg"), "°"),
            with_unit(number("misalignment_sigma_deg"), "°")
        ),
    ));
    if let (Some(used), Some(recorded)) = (number("moves_used"), number("moves_recorded")) {
        rows.push((
            "moves between holds used for the fit".to_string(),
            format!("{used:.0} of {recorded:.0}"),
        ));
    }
    rows.push((
        "angle mismatch of the moves after the fit (RMS)".to_string(),
        with_unit(number("rms_deg"), "°"),
    ));
    if let Some(tilt) = triple("tilt_deg") {
        rows.push((
            "rotation about x, y, z over all moves".to_string(),
            tilt.map(|t| format!("{t:.0}°")).join(", "),
        ));
    }
    rows
}

/// The set's terms beyond `A` and `b` as (sensor, term, values) rows.
fn extended_terms(params: &ParamsFile) -> Vec<(String, String, String)> {
    let mut rows = Vec::new();
    for (name, unit, sensor) in [
        ("accelerometer", "m/s²", &params.accel),
        ("gyroscope", "rad/s", &params.gyro),
        ("magnetometer", "µT", &params.mag),
    ] {
        let t_ref = sensor
            .t_ref_c
            .map_or(String::new(), |t| format!(" (T − {t:.2} °C)"));
        if let Some(bias) = &sensor.bias_temp {
            for (k, coeffs) in bias.coeffs.iter().enumerate() {
                if coeffs.iter().any(|c| *c != 0.0) {
                    rows.push((
                        name.to_string(),
                        format!(
                            "offset per {}{t_ref}",
                            crate::analysis::effects::celsius_power(k + 1)
                        ),
                        axes_text(
                            coeffs,
                            &format!("{unit}/{}", crate::analysis::effects::celsius_power(k + 1)),
                        ),
                    ));
                }
            }
        }
        if let Some(scale) = sensor.scale_temp.filter(|s| s.iter().any(|c| *c != 0.0)) {
            rows.push((
                name.to_string(),
                format!("scale change per °C{t_ref}"),
                axes_text(&scale.map(|v| v * 1e6), "ppm/°C"),
            ));
        }
        if let Some(nl) = &sensor.nonlinearity {
            rows.push((
                name.to_string(),
                "quadratic non-linearity".to_string(),
                axes_text(&nl.quadratic, &format!("1/({unit})")),
            ));
            rows.push((
                name.to_string(),
                "cubic non-linearity".to_string(),
                axes_text(&nl.cubic, &format!("1/({unit})²")),
            ));
        }
    }
    if let Some(k) = &params.gyro_g_sensitivity {
        for (r, row) in k.iter().enumerate() {
            rows.push((
                "gyroscope".to_string(),
                format!("g-sensitivity, row {}", ["x", "y", "z"][r]),
                axes_text(&row.map(f64::to_degrees), "°/s per m/s²"),
            ));
        }
    }
    rows
}

/// `x …, y …, z … unit` in one number format.
fn axes_text(values: &[f64; 3], unit: &str) -> String {
    let parts: Vec<String> = ["x", "y", "z"]
        .iter()
        .zip(values)
        .map(|(axis, v)| format!("{axis} {v:+.3e}"))
        .collect();
    format!("{} {unit}", parts.join(", "))
}

/// Text made safe for HTML.
pub fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// Error of `|v|` against `reference`, in mg of `reference` (so 1 g = 1000 mg).
fn norm_error_mg(v: &Vec3, reference: f64) -> f64 {
    (v.norm() / reference - 1.0) * 1000.0
}

/// Error of `|v|` against `reference`, percent.
fn norm_error_pct(v: &Vec3, reference: f64) -> f64 {
    (v.norm() / reference - 1.0) * 100.0
}

fn rms(values: &[f64]) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    (values.iter().map(|v| v * v).sum::<f64>() / values.len() as f64).sqrt()
}

/// How one table column writes its numbers: fixed with six decimals when every value of the
/// column is between 1e-4 and 1e5 (or zero), otherwise scientific with four, so a column never
/// mixes the two.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ColumnFormat {
    /// `1.234567`
    Fixed,
    /// `1.2346e-7`
    Scientific,
}

impl ColumnFormat {
    /// The format that suits every finite value of `column`.
    pub fn for_column(column: &[f64]) -> Self {
        // Six decimals keep at least three significant digits down to 1e-4.
        let fits = |v: &f64| *v == 0.0 || (1e-4..1e5).contains(&v.abs());
        if column.iter().filter(|v| v.is_finite()).all(fits) {
            ColumnFormat::Fixed
        } else {
            ColumnFormat::Scientific
        }
    }

    /// `value` in this format, or [`NOT_ESTIMATED`].
    pub fn show(self, value: f64) -> String {
        if !value.is_finite() {
            return NOT_ESTIMATED.to_string();
        }
        match self {
            ColumnFormat::Fixed => format!("{value:.6}"),
            ColumnFormat::Scientific => format!("{value:.4e}"),
        }
    }
}

fn parameter_table(p: &SensorParameters) -> String {
    let cell = |format: ColumnFormat, value: f64, std: Option<f64>| match std {
        Some(s) if s > 0.0 && s.is_finite() => format!(
            "<td>{}<span class=std> ± {s:.2e}</span></td>",
            format.show(value)
        ),
        _ => format!("<td>{}</td>", format.show(value)),
    };
    let columns: [Vec<f64>; 4] = [0, 1, 2, 3].map(|c| {
        (0..3)
            .map(|r| if c < 3 { p.a[(r, c)] } else { p.b[r] })
            .collect()
    });
    let formats = columns.each_ref().map(|c| ColumnFormat::for_column(c));
    let mut rows = String::new();
    for r in 0..3 {
        rows.push_str("<tr>");
        rows.push_str(&format!("<th>row {}</th>", r + 1));
        for (c, format) in formats.iter().enumerate().take(3) {
            rows.push_str(&cell(*format, p.a[(r, c)], p.std.map(|s| s.a[(r, c)])));
        }
        rows.push_str(&cell(formats[3], p.b[r], p.std.map(|s| s.b[r])));
        rows.push_str("</tr>");
    }
    let readable = p
        .to_nominal
        .and_then(|k| gain::gain(&p.a, k).map(|g| (k, g)))
        .map_or(String::new(), |(k, g)| {
            gain_table(&g, k, &p.unit_in, &p.unit_out)
        });
    format!(
        "<h3>{}</h3><p class=small>y = A·(x − b); x in {}, y in {}</p><table><tr><th></th><th colspan=3>A</th><th>b</th></tr>{rows}</table>{readable}",
        escape(&p.name),
        escape(&p.unit_in),
        escape(&p.unit_out)
    )
}

/// The matrix read as a person reads it: scale factor and scale error per axis and the angles
/// between the axes, with the unit conversion (`to_nominal` output units per input unit) apart.
fn gain_table(g: &gain::Gain, to_nominal: f64, unit_in: &str, unit_out: &str) -> String {
    let mut rows = String::from(
        "<tr><th></th><th>x</th><th>y</th><th>z</th></tr><tr><th>scale factor against nominal</th>",
    );
    for s in g.scale {
        rows.push_str(&format!("<td>{s:.5}</td>"));
    }
    rows.push_str("</tr><tr><th>scale error</th>");
    for s in g.scale {
        rows.push_str(&format!("<td>{:+.3} %</td>", (s - 1.0) * 100.0));
    }
    rows.push_str(
        "</tr><tr><th></th><th>yz</th><th>xz</th><th>xy</th></tr><tr><th>axes off 90° by</th>",
    );
    for d in g.skew_deg {
        rows.push_str(&format!("<td>{d:+.3}°</td>"));
    }
    rows.push_str("</tr>");
    let conversion = if (to_nominal - 1.0).abs() < 1e-12 {
        String::new()
    } else {
        format!(
            " The unit conversion, 1 {} = {} {}, is taken out: A alone would hide these \
             errors in it.",
            escape(unit_in),
            significant(to_nominal, 6),
            escape(unit_out)
        )
    };
    format!(
        "<p class=small>Read as scale factors and angles between the sensing axes.{conversion}</p><table>{rows}</table>"
    )
}

/// Samples a region needs to count as reached: the session's own minimum.
fn region_min_samples() -> usize {
    crate::session::SessionOptions::default().mag_min_per_region
}

/// Coverage of `mag` in the 26 regions of the session's screen: the samples it counted, their
/// sphere centre and the same region cells ([`crate::session::coverage`]); `None` when the
/// samples fix no centre.
pub fn region_coverage(mag: &MagSamples) -> Option<Coverage> {
    let centre = sphere_centre(&mag.counted)?;
    Some(Coverage::of(&mag.counted, &centre))
}

/// The coverage in words, with the count the session's summary recorded when it differs
/// (a summary written by an older version counted regions with a single sample).
fn session_regions_text(cover: Option<&Coverage>, on_screen: Option<u64>) -> String {
    let min = region_min_samples();
    let Some(cover) = cover else {
        return "the samples' directions are not countable (no sphere centre)".to_string();
    };
    let covered = cover.covered(min);
    let empty = cover.empty_regions(min);
    let mut text = format!(
        "{covered} of {REGIONS} directions with at least {min} samples, as the session's \
         screen counts them (moves between positions included)"
    );
    if !empty.is_empty() {
        text.push_str(&format!("; empty: {}", empty.join(" ")));
    }
    if let Some(n) = on_screen.filter(|n| usize::try_from(*n).ok() != Some(covered)) {
        text.push_str(&format!("; the session's summary recorded {n}"));
    }
    text
}

/// Smallest temperature span worth an axis, °C: below it a plot against temperature is a
/// vertical stripe. Die temperature sensors of consumer IMUs resolve 0.003–0.06 °C, and a
/// temperature coefficient only shows over a span many times that.
const MIN_TEMPERATURE_SPAN_C: f64 = 0.5;

/// Whether `temps` span enough to plot against.
fn temperature_varies(temps: &[f64]) -> bool {
    let (lo, hi) = temperature_span(temps);
    hi - lo >= MIN_TEMPERATURE_SPAN_C
}

fn temperature_span(temps: &[f64]) -> (f64, f64) {
    temps
        .iter()
        .filter(|t| t.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), t| {
            (lo.min(*t), hi.max(*t))
        })
}

/// Why there is no plot against temperature: it stayed within [`MIN_TEMPERATURE_SPAN_C`].
fn constant_temperature_text(what: &str, temps: &[f64]) -> String {
    let (lo, hi) = temperature_span(temps);
    if !lo.is_finite() {
        return format!(
            "No temperature was recorded with the {what}, so there is no plot against it."
        );
    }
    format!(
        "Temperature constant at {:.1} °C during the {what} (span {:.2} °C, under {MIN_TEMPERATURE_SPAN_C} °C), so there is no plot against it.",
        (lo + hi) / 2.0,
        hi - lo
    )
}

fn figure(svg: &str) -> String {
    format!("<div class=fig>{svg}</div>")
}

/// Renders the report page.
pub fn render_html(data: &ReportData) -> Result<String, ReportError> {
    if data.accel.is_none() && data.mag.is_none() {
        return Err(ReportError::NoData);
    }
    let mut summary_rows = Vec::new();
    let mut body = String::new();

    if let Some(mag) = &data.mag {
        body.push_str("<h2>Magnetometer</h2><p>Raw samples with the outline of the fitted ellipsoid (top) and calibrated samples with the reference sphere (bottom).</p><div class=row>");
        for axes in plots::PROJECTIONS {
            let outline = mag
                .ellipsoid
                .map(|(centre, shape)| plots::ellipse_outline(&centre, &shape, axes.0, axes.1))
                .unwrap_or_default();
            body.push_str(&figure(&plots::projection(
                &format!("raw {}{}", axes.2, axes.3),
                &mag.raw_unit,
                &mag.raw,
                (&outline, "fitted ellipsoid"),
                axes,
                false,
            )?));
        }
        body.push_str("</div><div class=row>");
        let sphere = plots::ellipse_outline(&Vec3::zeros(), &(Mat3::identity() * mag.field), 0, 1);
        for axes in plots::PROJECTIONS {
            body.push_str(&figure(&plots::projection(
                &format!("calibrated {}{}", axes.2, axes.3),
                &mag.calibrated_unit,
                &mag.calibrated,
                (&sphere, "reference sphere"),
                axes,
                true,
            )?));
        }
        body.push_str("</div>");
        // Raw norms are compared with their own mean: the raw unit or scale may differ from the
        // reference, and the spread is what calibration removes.
        let raw_mean = mag.raw.iter().map(|v| v.norm()).sum::<f64>() / mag.raw.len() as f64;
        let before: Vec<f64> = mag
            .raw
            .iter()
            .map(|v| norm_error_pct(v, raw_mean))
            .collect();
        let after: Vec<f64> = mag
            .calibrated
            .iter()
            .map(|v| norm_error_pct(v, mag.field))
            .collect();
        summary_rows.push((
            "magnetometer |m| error RMS".to_string(),
            format!(
                "{:.2} % before, {:.3} % after ({} samples)",
                rms(&before),
                rms(&after),
                after.len()
            ),
        ));
        body.push_str("<h3>Norm error</h3><div class=row>");
        body.push_str(&figure(&plots::histogram(
            "before: |m| / mean raw |m| − 1",
            "norm error (%)",
            &before,
            false,
        )?));
        body.push_str(&figure(&plots::histogram(
            "after: |m| / reference − 1",
            "norm error (%)",
            &after,
            true,
        )?));
        body.push_str("</div><h3>Residual against time and temperature</h3><div class=row>");
        let pairs = |x: &[f64], y: &[f64]| -> Vec<(f64, f64)> {
            x.iter().copied().zip(y.iter().copied()).collect()
        };
        body.push_str(&figure(&plots::residual_against(
            "magnetometer norm error against time",
            "time (s)",
            "norm error (%)",
            &pairs(&mag.time_s, &before),
            &pairs(&mag.time_s, &after),
        )?));
        let mut constant = None;
        match mag.temp_c.as_ref() {
            Some(temp) if temperature_varies(temp) => {
                body.push_str(&figure(&plots::residual_against(
                    "magnetometer norm error against temperature",
                    "temperature (°C)",
                    "norm error (%)",
                    &pairs(temp, &before),
                    &pairs(temp, &after),
                )?));
            }
            Some(temp) => constant = Some(constant_temperature_text("magnetometer samples", temp)),
            None => constant = Some(constant_temperature_text("magnetometer samples", &[])),
        }
        body.push_str("</div>");
        if let Some(text) = constant {
            body.push_str(&format!("<p class=small>{}</p>", escape(&text)));
        }
        body.push_str("<h3>Sphere coverage</h3>");
        let cover = region_coverage(mag);
        if let Some(cover) = &cover {
            body.push_str(&figure(&plots::coverage_map(cover, region_min_samples())?));
        }
        summary_rows.push((
            "sphere coverage".to_string(),
            session_regions_text(cover.as_ref(), data.session_regions_covered),
        ));
    }

    if let Some(accel) = &data.accel {
        let before: Vec<f64> = accel
            .raw_mps2
            .iter()
            .map(|v| norm_error_mg(v, accel.gravity))
            .collect();
        let after: Vec<f64> = accel
            .calibrated
            .iter()
            .map(|v| norm_error_mg(v, accel.gravity))
            .collect();
        summary_rows.push((
            "accelerometer |a| error RMS".to_string(),
            format!(
                "{:.2} mg before, {:.3} mg after ({} poses)",
                rms(&before),
                rms(&after),
                after.len()
            ),
        ));
        body.push_str("<h2>Accelerometer</h2><p>Error of |a| against local gravity per pose, before and after calibration, each on its own scale.</p>");
        let labels = &accel.labels;
        body.push_str(&figure(&plots::pose_bars(
            "accelerometer before calibration: |a| − g per pose",
            "error of |a| (mg)",
            &before,
            labels,
            false,
        )?));
        body.push_str(&figure(&plots::pose_bars(
            "accelerometer after calibration: |a| − g per pose (own scale)",
            "error of |a| (mg)",
            &after,
            labels,
            true,
        )?));
        let with_temp: Vec<(f64, f64, f64)> = accel
            .temp_c
            .iter()
            .zip(before.iter().zip(&after))
            .filter_map(|(t, (b, a))| t.map(|t| (t, *b, *a)))
            .collect();
        let temps: Vec<f64> = with_temp.iter().map(|p| p.0).collect();
        if temperature_varies(&temps) {
            body.push_str(&figure(&plots::residual_against(
                "accelerometer |a| error against pose temperature",
                "temperature (°C)",
                "error of |a| (mg)",
                &with_temp.iter().map(|p| (p.0, p.1)).collect::<Vec<_>>(),
                &with_temp.iter().map(|p| (p.0, p.2)).collect::<Vec<_>>(),
            )?));
        } else {
            body.push_str(&format!(
                "<p class=small>{}</p>",
                escape(&constant_temperature_text("accelerometer poses", &temps))
            ));
        }
    }

    if let Some(gyro) = &data.gyro {
        body.push_str(&gyro_section(gyro, &mut summary_rows)?);
    }

    let mut parameters = String::new();
    for p in &data.parameters {
        parameters.push_str(&parameter_table(p));
    }
    if !data.extended_terms.is_empty() {
        parameters.push_str(
            "<h3>Extended terms on the board</h3><p class=small>Terms beyond A and b that the \
             firmware applies (written by the residual analysis).</p><table><tr><th>sensor</th>\
             <th>term</th><th>values</th></tr>",
        );
        for (sensor, term, values) in &data.extended_terms {
            parameters.push_str(&format!(
                "<tr><td>{}</td><td>{}</td><td>{}</td></tr>",
                escape(sensor),
                escape(term),
                escape(values)
            ));
        }
        parameters.push_str("</table>");
    }
    if !data.uncertainty_notes.is_empty() {
        parameters.push_str(
            "<h3>How well the parameters are known</h3><p class=small>Each figure is one \
             standard deviation (±): the true value lies within it about two times in three, \
             and within three times it almost always.</p><table class=text>",
        );
        for (name, value) in &data.uncertainty_notes {
            parameters.push_str(&format!(
                "<tr><th>{}</th><td>{}</td></tr>",
                escape(name),
                escape(value)
            ));
        }
        parameters.push_str("</table>");
    }

    let level_class = badge_class(&data.verdict_level);
    let mut verdict = format!(
        "<p class=\"verdict {level_class}\">Verdict: {}</p>",
        escape(&data.verdict_level)
    );
    if !data.verdict.is_empty() {
        verdict.push_str("<ul>");
        for reason in &data.verdict {
            verdict.push_str(&format!("<li>{}</li>", escape(reason)));
        }
        verdict.push_str("</ul>");
    }
    let mut summary = String::from("<table class=text>");
    for (name, value) in &summary_rows {
        summary.push_str(&format!(
            "<tr><th>{}</th><td>{}</td></tr>",
            escape(name),
            escape(value)
        ));
    }
    summary.push_str("</table>");
    summary.push_str(&rest_check_table(&data.rest_checks));
    let notes: String = data
        .notes
        .iter()
        .map(|n| format!("<li>{}</li>", escape(n)))
        .collect();
    let notes = if notes.is_empty() {
        String::new()
    } else {
        format!("<h3>Notes</h3><ul>{notes}</ul>")
    };
    if let Some(analysis) = &data.analysis {
        body.push_str(&format!(
            "<h2>Residual analysis and extended terms</h2><p>What the residuals of the poses \
             show beyond the base model, and the terms written for it (the parameter tables \
             below are the set on the board).</p><pre>{}</pre>",
            escape(analysis)
        ));
    }
    if !data.history.is_empty() {
        body.push_str("<h2>Calibration history</h2><p>This board's parameters in every recorded calibration.</p><div class=row>");
        for (_, svg) in &data.history {
            body.push_str(&figure(svg));
        }
        body.push_str("</div>");
    }
    Ok(format!(
        "<!DOCTYPE html>\n<html lang=en><head><meta charset=utf-8><title>imucal report: {title}</title><style>{STYLE}</style></head><body>\n<h1>IMU calibration report</h1><p class=small>{title}</p>\n{verdict}{summary}{notes}\n{body}\n<h2>Parameters</h2>{parameters}\n</body></html>\n",
        title = escape(&data.source)
    ))
}

const STYLE: &str = "body{font-family:sans-serif;margin:24px;color:#222;max-width:1100px}\
h1{font-size:24px;margin-bottom:4px}h2{border-bottom:1px solid #ccc;padding-bottom:4px;margin-top:32px}\
table{border-collapse:collapse;margin:8px 0}th,td{border:1px solid #ddd;padding:4px 8px;text-align:right;font-size:13px}\
th{background:#f4f4f4;text-align:left}.std{color:#777}.small{color:#666;font-size:13px}\
.row{display:flex;flex-wrap:wrap;gap:8px}.fig{display:inline-block}\
.verdict{font-size:18px;font-weight:bold;padding:8px 12px;display:inline-block;border-radius:4px}\
.good{background:#d9f0d3}.marginal{background:#fee8c8}.poor{background:#f4c7c3}.neutral{background:#e8e8e8}\
pre{white-space:pre-wrap;overflow-wrap:anywhere;font-size:12px;background:#fafafa;padding:8px}\
table.text td{text-align:left}";

/// The badge's colour class for a verdict: green, orange and red only for the session's own
/// levels; anything else (`fitted`: no held-out check) is neutral grey.
pub fn badge_class(level: &str) -> &'static str {
    match level {
        "good" => "good",
        "marginal" => "marginal",
        "poor" => "poor",
        _ => "neutral",
    }
}

/// The errors at rest on the board, one column per set.
fn rest_check_table(checks: &[(String, RestCheck)]) -> String {
    if checks.is_empty() {
        return String::new();
    }
    let mut text = String::from("<h3>Checks at rest on the board</h3><table><tr><th></th>");
    for (name, _) in checks {
        text.push_str(&format!("<th>{}</th>", escape(name)));
    }
    text.push_str("<th>target</th></tr>");
    for (k, quantity) in REST_QUANTITIES.iter().enumerate() {
        text.push_str(&format!("<tr><th>{}</th>", quantity.label));
        for (_, check) in checks {
            let (digits, unit) = (quantity.digits, quantity.unit);
            let cell = check.values()[k]
                .filter(|v| v.is_finite())
                .map_or(NOT_ESTIMATED.to_string(), |v| {
                    format!("{v:.digits$} {unit}")
                });
            text.push_str(&format!("<td>{}</td>", escape(&cell)));
        }
        text.push_str(&format!("<td>{}</td></tr>", escape(quantity.target)));
    }
    text.push_str("</table>");
    text
}

/// RMS over poses of each axis.
fn axis_rms(values: &[[f64; 3]]) -> [f64; 3] {
    [0, 1, 2].map(|i| rms(&values.iter().map(|v| v[i]).collect::<Vec<_>>()))
}

/// The gyroscope's section: rate at rest per pose and axis before and after (each on its own
/// scale), the per-axis RMS, and the scale fit from the moves.
fn gyro_section(
    gyro: &GyroPoses,
    summary_rows: &mut Vec<(String, String)>,
) -> Result<String, ReportError> {
    let before = axis_rms(&gyro.raw_dps);
    let after = axis_rms(&gyro.calibrated_dps);
    let per_axis = |v: [f64; 3]| {
        v.iter()
            .map(|r| format!("{r:.4}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    summary_rows.push((
        "gyroscope rate at rest, RMS over poses, x, y, z".to_string(),
        format!(
            "{} °/s before, {} °/s after ({} poses)",
            per_axis(before),
            per_axis(after),
            gyro.raw_dps.len()
        ),
    ));
    let mut body = String::from(
        "<h2>Gyroscope</h2><p>Mean rate in each still pose, per axis, before and after \
         calibration, each on its own scale. Held still the true rate is the Earth's rotation \
         (0.004 °/s at most) plus whatever the hands turned the board during the hold, so what \
         remains after calibration is the bias the fit left and that sway.</p>",
    );
    body.push_str(&figure(&plots::axis_bars(
        "gyroscope before calibration: rate at rest per pose",
        "rate (°/s)",
        &gyro.raw_dps,
        &gyro.labels,
    )?));
    body.push_str(&figure(&plots::axis_bars(
        "gyroscope after calibration: residual rate at rest per pose (own scale)",
        "rate (°/s)",
        &gyro.calibrated_dps,
        &gyro.labels,
    )?));
    body.push_str("<table><tr><th>RMS over poses</th><th>x</th><th>y</th><th>z</th></tr>");
    for (name, values) in [("before, °/s", before), ("after, °/s", after)] {
        body.push_str(&format!("<tr><th>{name}</th>"));
        for v in values {
            body.push_str(&format!("<td>{v:.4}</td>"));
        }
        body.push_str("</tr>");
    }
    body.push_str("</table>");
    if gyro.scale_fit.is_empty() {
        body.push_str(
            "<p class=small>Scale and misalignment: not estimated (only the bias was \
             calibrated).</p>",
        );
    } else {
        body.push_str("<h3>Scale and misalignment from the moves between holds</h3><table>");
        for (name, value) in &gyro.scale_fit {
            body.push_str(&format!(
                "<tr><th>{}</th><td>{}</td></tr>",
                escape(name),
                escape(value)
            ));
        }
        body.push_str("</table>");
    }
    Ok(body)
}

/// The name of the report file in its directory.
pub const REPORT_FILE: &str = "report.html";

/// Writes [`REPORT_FILE`] into `dir` (created if missing) and returns its path.
pub fn write_report(data: &ReportData, dir: &Path) -> Result<PathBuf, ReportError> {
    let html = render_html(data)?;
    std::fs::create_dir_all(dir).map_err(|cause| ReportError::Write {
        path: dir.display().to_string(),
        cause,
    })?;
    let path = dir.join(REPORT_FILE);
    std::fs::write(&path, html).map_err(|cause| ReportError::Write {
        path: path.display().to_string(),
        cause,
    })?;
    Ok(path)
}
