//! `imucal report`: an HTML report of a session directory (as `imucal calibrate` writes it) or
//! of a recording, fitted here with the same default methods as `imucal fit`.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use clap::Args;
use imucal::fit::{Fit, Method, Vec3};
use imucal::geomag::{local_field_today, LocalField, Location, RadiusCheck};
use imucal::recording::{Recording, Sensor, STANDARD_GRAVITY};
use imucal::report::{
    ellipsoid_shape, from_session_dir, write_report, AccelPoses, MagSamples, ReportData,
    SensorParameters,
};
use imucal::still::find_still;
use indicatif::{ProgressBar, ProgressStyle};

use super::args::InputArgs;
use super::methods;

/// Examples shown by `imucal report --help`.
pub const EXAMPLES: &str = "Examples:\n  \
    imucal report session-2025-11-21/                      (a directory written by `imucal calibrate -o`)\n  \
    imucal report data/real/sf_mpu6050_hmc5883l_full_sphere.csv --mag-unit gauss --location 46.05,14.51 -o report/\n  \
    imucal report motioncal_log.txt --format motioncal --rate 100 -o report/";

/// Arguments of `imucal report`.
#[derive(Debug, Args)]
pub struct ReportArgs {
    /// The recording (or session directory, given as the positional path) and how to read it.
    #[command(flatten)]
    pub input: InputArgs,
    /// Directory for `report.html` (default: the session directory, or `<recording>_report`).
    #[arg(long, short = 'o')]
    pub out: Option<PathBuf>,
    /// Where the data was taken, `LAT,LON[,ALT_M]`: the World Magnetic Model's field there is
    /// the magnetometer reference (unless --field-ut) and checks the fitted radius.
    #[arg(long)]
    pub location: Option<String>,
    /// Local gravity in m/s².
    #[arg(long, default_value_t = STANDARD_GRAVITY)]
    pub gravity: f64,
    /// Local field magnitude in µT (default: from --location, else the output is normalised to 1).
    #[arg(long)]
    pub field_ut: Option<f64>,
    /// Magnetometer fits use at most this many samples, evenly thinned (0 = all).
    #[arg(long, default_value_t = 2000)]
    pub max_mag_samples: usize,
    /// History database whose records of the session's board are plotted over time
    /// (default: `$IMUCAL_DB`, else the default file when it exists).
    #[arg(long, value_name = "URL")]
    pub db: Option<String>,
}

fn progress(steps: u64) -> ProgressBar {
    let bar = ProgressBar::new(steps);
    if let Ok(style) = ProgressStyle::with_template("{bar:30} {pos}/{len} {msg}") {
        bar.set_style(style);
    }
    bar
}

fn location_field(args: &ReportArgs) -> anyhow::Result<Option<LocalField>> {
    let Some(text) = &args.location else {
        return Ok(None);
    };
    let location: Location = text.parse()?;
    let field = local_field_today(&location)?;
    Ok(Some(field))
}

fn field_note(field: &LocalField) -> String {
    format!(
        "{}: F = {:.2} ± {:.2} µT, dip {:.2}°, declination {:.2}°",
        field.model,
        field.total_ut,
        field.total_uncertainty_ut,
        field.inclination_deg,
        field.declination_deg
    )
}

/// Mean distance of samples (µT) from a centre.
fn mean_radius(samples: &[Vec3], centre: &Vec3) -> f64 {
    samples.iter().map(|s| (s - centre).norm()).sum::<f64>() / samples.len().max(1) as f64
}

fn parameters(name: &str, unit_in: &str, unit_out: &str, fit: &Fit) -> SensorParameters {
    SensorParameters {
        name: format!("{name} ({})", fit.method.name()),
        unit_in: unit_in.to_string(),
        unit_out: unit_out.to_string(),
        a: fit.cal.a,
        b: fit.cal.b,
        std: fit.std,
    }
}

/// Fits a recording and gathers what the report shows.
fn from_recording(
    args: &ReportArgs,
    recording: &Recording,
    field: Option<&LocalField>,
    bar: &ProgressBar,
) -> anyhow::Result<ReportData> {
    let mut data = ReportData {
        source: recording.source.display().to_string(),
        verdict_level: "fitted".to_string(),
        ..ReportData::default()
    };
    if recording.has(Sensor::Accel) || recording.has(Sensor::Gyro) {
        bar.set_message("finding still intervals");
        let still = find_still(recording, &super::still_options(&args.input))
            .context("still intervals could not be found")?;
        bar.inc(1);
        bar.set_message("fitting the accelerometer and gyroscope");
        if recording.has(Sensor::Accel) {
            let poses = still.poses(Sensor::Accel);
            let (fit, note) =
                methods::default_accel_fit(&poses, args.gravity, still.directions.len());
            if let Some(note) = note {
                data.notes.push(format!("accelerometer: {note}"));
            }
            match fit {
                Ok(fit) => {
                    let means: Vec<Vec3> = poses.iter().map(|p| p.mean).collect();
                    // Raw readings in m/s²; counts are scaled so that their mean norm is g.
                    let scale = recording.units.to_si(Sensor::Accel).unwrap_or_else(|| {
                        args.gravity
                            / (means.iter().map(|m| m.norm()).sum::<f64>() / means.len() as f64)
                    });
                    let temp_c = still
                        .intervals
                        .iter()
                        .filter(|i| i.accel.is_some())
                        .map(|i| i.temp.map(|t| t.mean))
                        .collect();
                    data.accel = Some(AccelPoses {
                        raw_mps2: means.iter().map(|m| m * scale).collect(),
                        calibrated: means.iter().map(|m| fit.cal.apply(m)).collect(),
                        temp_c,
                        gravity: args.gravity,
                    });
                    data.verdict.push(format!(
                        "accelerometer: residual RMS {:.2e} of g over {} poses",
                        fit.rms,
                        poses.len()
                    ));
                    data.parameters.push(parameters(
                        "accelerometer",
                        recording.units.symbol(Sensor::Accel),
                        "m/s²",
                        &fit,
                    ));
                }
                Err(e) => data.verdict.push(format!("accelerometer not fitted: {e}")),
            }
        }
        if recording.has(Sensor::Gyro) {
            let poses = still.poses(Sensor::Gyro);
            let (scale, unit) = match recording.units.to_si(Sensor::Gyro) {
                Some(s) => (s, "rad/s"),
                None => (1.0, "counts"),
            };
            match methods::fit_gyro(Method::GyroBias, &poses, scale) {
                Ok(fit) => data.parameters.push(parameters(
                    "gyroscope",
                    recording.units.symbol(Sensor::Gyro),
                    unit,
                    &fit,
                )),
                Err(e) => data.verdict.push(format!("gyroscope not fitted: {e}")),
            }
        }
        bar.inc(1);
    } else {
        bar.inc(2);
    }
    if let Some(mag) = &recording.mag {
        bar.set_message("fitting the magnetometer");
        let reference = args.field_ut.or(field.map(|f| f.total_ut));
        let points = methods::thin(&mag.samples, args.max_mag_samples);
        match methods::fit_mag(methods::MAG_METHODS[0], &points, reference.unwrap_or(1.0)) {
            Ok(fit) => {
                let keep = methods::thin(
                    &(0..mag.samples.len())
                        .map(|i| Vec3::new(i as f64, 0.0, 0.0))
                        .collect::<Vec<_>>(),
                    args.max_mag_samples,
                );
                let index: Vec<usize> = keep.iter().map(|v| v.x as usize).collect();
                let rows_match = recording
                    .temp_c
                    .as_ref()
                    .filter(|t| t.len() == mag.samples.len());
                let field_value = fit.reference;
                data.mag = Some(MagSamples {
                    raw: points.clone(),
                    calibrated: points.iter().map(|p| fit.cal.apply(p)).collect(),
                    time_s: index
                        .iter()
                        .filter_map(|i| mag.time.get(*i).copied())
                        .collect(),
                    temp_c: rows_match
                        .map(|t| index.iter().filter_map(|i| t.get(*i).copied()).collect()),
                    field: field_value,
                    raw_unit: recording.units.symbol(Sensor::Mag).to_string(),
                    calibrated_unit: if reference.is_some() {
                        "µT"
                    } else {
                        "field = 1"
                    }
                    .to_string(),
                    ellipsoid: ellipsoid_shape(&fit.cal.a, field_value).map(|s| (fit.cal.b, s)),
                });
                data.verdict.push(format!(
                    "magnetometer: residual RMS {:.2e} of the field over {} samples",
                    fit.rms,
                    points.len()
                ));
                if let (Some(field), Some(to_ut)) = (field, recording.units.to_si(Sensor::Mag)) {
                    let check = RadiusCheck::new(mean_radius(&points, &fit.cal.b) * to_ut, field);
                    data.notes.push(check.sentence());
                }
                data.parameters.push(parameters(
                    "magnetometer",
                    recording.units.symbol(Sensor::Mag),
                    if reference.is_some() {
                        "µT"
                    } else {
                        "field = 1"
                    },
                    &fit,
                ));
            }
            Err(e) => data.verdict.push(format!("magnetometer not fitted: {e}")),
        }
    }
    bar.inc(1);
    Ok(data)
}

fn default_out(path: &Path, is_session: bool) -> PathBuf {
    if is_session {
        return path.to_path_buf();
    }
    let stem = path
        .file_stem()
        .map_or("recording".into(), |s| s.to_string_lossy().into_owned());
    path.with_file_name(format!("{stem}_report"))
}

/// Run the command.
pub fn run(args: &ReportArgs) -> anyhow::Result<()> {
    if !(args.gravity.is_finite() && args.gravity > 0.0) {
        bail!(
            "--gravity {} is not a positive number of m/s²",
            args.gravity
        );
    }
    if let Some(h) = args.field_ut {
        if !(h.is_finite() && h > 0.0) {
            bail!("--field-ut {h} is not a positive field magnitude");
        }
    }
    let field = location_field(args)?;
    let path = &args.input.recording;
    let is_session = path.is_dir();
    let bar = progress(4);
    let mut data = if is_session {
        bar.set_message("reading the session directory");
        let data = from_session_dir(path)?;
        bar.inc(3);
        data
    } else {
        bar.set_message("reading the recording");
        let recording = super::load(&args.input)?;
        bar.inc(1);
        from_recording(args, &recording, field.as_ref(), &bar)?
    };
    if let Some(field) = &field {
        data.notes.push(field_note(field));
        if is_session {
            if let Some(mag) = &data.mag {
                let centre = mag.ellipsoid.map_or(Vec3::zeros(), |(b, _)| b);
                data.notes
                    .push(RadiusCheck::new(mean_radius(&mag.raw, &centre), field).sentence());
            }
        }
    }
    if is_session {
        match super::history::report_figures(args.db.as_deref(), path) {
            Ok(figures) => data.history = figures,
            Err(note) => data.notes.push(note),
        }
    }
    bar.set_message("drawing the plots");
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| default_out(path, is_session));
    let written = write_report(&data, &out)?;
    bar.inc(1);
    bar.finish_and_clear();
    println!("report written to {}", written.display());
    Ok(())
}
