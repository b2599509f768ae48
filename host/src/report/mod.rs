//! The calibration report: one self-contained HTML page (inline CSS and SVG, no network
//! resources) showing the data before and after calibration, the fitted parameters with their
//! uncertainties, and the verdict.
//!
//! Figures: magnetometer samples in the xy, xz and yz projections, raw with the outline of the
//! fitted ellipsoid and calibrated with the reference sphere; the accelerometer's error of `|a|`
//! per pose; histograms of the magnetometer's norm error; the residual against time and
//! temperature; a map of the sphere's coverage. A report is built from a session directory
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
    /// Fitted parameters per sensor.
    pub parameters: Vec<SensorParameters>,
    /// Further uncertainty figures as (name, value with unit).
    pub uncertainty_notes: Vec<(String, String)>,
    /// Overall verdict: `good`, `marginal`, `poor` or a short phrase.
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
    for pose in poses.as_array().into_iter().flatten() {
        let stats = &pose["stats"];
        let mean = vec3_of(&stats["accel_mean"])
            .ok_or_else(|| format_error(&poses_path, "a pose has no `stats.accel_mean` triple"))?;
        let t = stats["temp_mean_c"].as_f64();
        raw.push(mean);
        temp.push(t);
    }
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
        mag,
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
                .map(|(key, value)| (key.clone(), compact(value)))
                .collect();
        }
        for (key, label) in [
            ("accel_rest_error_mg", "|a| error at rest after writing, mg"),
            (
                "mag_rest_error_pct",
                "|m| error at rest after writing, % of the field",
            ),
            ("gyro_rest_error_dps", "|ω| at rest after writing, °/s"),
        ] {
            if let Some(v) = summary[key].as_f64() {
                data.uncertainty_notes
                    .push((label.to_string(), format!("{v:.3}")));
            }
        }
    } else {
        data.verdict_level = "unknown".to_string();
        data.notes
            .push("summary.json is missing: no verdict from the session".to_string());
    }
    Ok(data)
}

/// A JSON value as short text (numbers to 4 significant digits).
fn compact(value: &Value) -> String {
    match value {
        Value::Number(n) => n.as_f64().map_or(n.to_string(), |v| format!("{v:.4}")),
        Value::Array(items) => format!(
            "[{}]",
            items.iter().map(compact).collect::<Vec<_>>().join(", ")
        ),
        other => other.to_string(),
    }
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

fn number(value: f64) -> String {
    let magnitude = value.abs();
    if value == 0.0 || (1e-2..1e5).contains(&magnitude) {
        format!("{value:.6}")
    } else {
        format!("{value:.4e}")
    }
}

fn parameter_table(p: &SensorParameters) -> String {
    let cell = |value: f64, std: Option<f64>| match std {
        Some(s) if s > 0.0 => format!(
            "<td>{}<span class=std> ± {s:.2e}</span></td>",
            number(value)
        ),
        _ => format!("<td>{}</td>", number(value)),
    };
    let mut rows = String::new();
    for r in 0..3 {
        rows.push_str("<tr>");
        rows.push_str(&format!("<th>row {}</th>", r + 1));
        for c in 0..3 {
            rows.push_str(&cell(p.a[(r, c)], p.std.map(|s| s.a[(r, c)])));
        }
        rows.push_str(&cell(p.b[r], p.std.map(|s| s.b[r])));
        rows.push_str("</tr>");
    }
    let readable = p
        .to_nominal
        .and_then(|k| gain::gain(&p.a, k))
        .map_or(String::new(), |g| {
            format!("<p>{}</p>", escape(&gain::gain_text(&g, 3)))
        });
    format!(
        "<h3>{}</h3><p class=small>y = A·(x − b); x in {}, y in {}</p><table><tr><th></th><th colspan=3>A</th><th>b</th></tr>{rows}</table>{readable}",
        escape(&p.name),
        escape(&p.unit_in),
        escape(&p.unit_out)
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
    let (lo, hi) = temps
        .iter()
        .filter(|t| t.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), t| {
            (lo.min(*t), hi.max(*t))
        });
    hi - lo >= MIN_TEMPERATURE_SPAN_C
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
                &outline,
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
                &sphere,
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
        if let Some(temp) = mag.temp_c.as_ref().filter(|t| temperature_varies(t)) {
            body.push_str(&figure(&plots::residual_against(
                "magnetometer norm error against temperature",
                "temperature (°C)",
                "norm error (%)",
                &pairs(temp, &before),
                &pairs(temp, &after),
            )?));
        }
        body.push_str("</div><h3>Sphere coverage</h3>");
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
        let labels: Vec<String> = accel
            .calibrated
            .iter()
            .map(|v| crate::session::targets::direction_name(&v.normalize()))
            .collect();
        body.push_str(&figure(&plots::pose_bars(
            "accelerometer before calibration: |a| − g per pose",
            &before,
            &labels,
            false,
        )?));
        body.push_str(&figure(&plots::pose_bars(
            "accelerometer after calibration: |a| − g per pose",
            &after,
            &labels,
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
        }
    }

    let mut parameters = String::new();
    for p in &data.parameters {
        parameters.push_str(&parameter_table(p));
    }
    if !data.uncertainty_notes.is_empty() {
        parameters.push_str("<h3>Uncertainties (one sigma) and checks</h3><table>");
        for (name, value) in &data.uncertainty_notes {
            parameters.push_str(&format!(
                "<tr><th>{}</th><td>{}</td></tr>",
                escape(name),
                escape(value)
            ));
        }
        parameters.push_str("</table>");
    }

    let level_class = match data.verdict_level.as_str() {
        "good" => "good",
        "poor" => "poor",
        _ => "marginal",
    };
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
    let mut summary = String::from("<table>");
    for (name, value) in &summary_rows {
        summary.push_str(&format!(
            "<tr><th>{}</th><td>{}</td></tr>",
            escape(name),
            escape(value)
        ));
    }
    summary.push_str("</table>");
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
.good{background:#d9f0d3}.marginal{background:#fee8c8}.poor{background:#f4c7c3}";

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
