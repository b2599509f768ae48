//! `imucal analyze`: residual analysis of a recording (see `imucal::analysis`), printed as text
//! or as the stable JSON document, optionally with a report directory of plots. A session
//! directory of `imucal calibrate` without a `recording.csv` is analysed from its `poses.json`
//! (`imucal::session::analyse_poses`), and `--write-params` writes its parameter set with the
//! accepted effects added, for `imucal flash`.

use std::path::PathBuf;

use anyhow::{bail, Context};
use clap::Args;
use imucal::analysis::{analyse_recording, report, AnalysisOptions};
use imucal::device::ParamsFile;
use imucal::recording::Sensor;
use imucal::session::{analyse_poses, extend_set, load_poses};
use imucal::still::find_still;

use super::args::InputArgs;

/// Arguments of `imucal analyze`.
#[derive(Debug, Args)]
pub struct AnalyzeArgs {
    /// How to read the recording (a recording file or a session directory's recording).
    #[command(flatten)]
    pub input: InputArgs,
    /// Local gravity in m/s².
    #[arg(long, default_value_t = imucal::recording::STANDARD_GRAVITY)]
    pub gravity: f64,
    /// Local field magnitude in µT (without it the magnetometer is normalised to 1).
    #[arg(long)]
    pub field_ut: Option<f64>,
    /// Where the data was recorded (latitude, longitude in degrees, optional altitude in m): the
    /// World Magnetic Model's field there today is the reference unless --field-ut is given.
    #[arg(long, value_name = "LAT,LON[,ALT_M]", allow_hyphen_values = true)]
    pub location: Option<imucal::geomag::Location>,
    /// Gyroscope scale in rad/s per count, for `--gyro-unit counts`.
    #[arg(long)]
    pub gyro_scale: Option<f64>,
    /// Print the JSON document instead of text.
    #[arg(long)]
    pub json: bool,
    /// Write analysis.json, analysis.txt and SVG plots of each accepted effect into this directory.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Session directories only: write the session's parameter set (params-base.json, else
    /// params.json) with the accepted effects added as extended terms to this file.
    ///
    /// Example: imucal analyze imucal-session-1700000000 --write-params extended.json
    ///          imucal flash extended.json
    #[arg(long, verbatim_doc_comment)]
    pub write_params: Option<PathBuf>,
}

/// Analyse a session directory from its poses; optionally write the extended set.
fn run_session_dir(args: &AnalyzeArgs, dir: &std::path::Path) -> anyhow::Result<()> {
    let poses = load_poses(&dir.join("poses.json"))?;
    let analysis = analyse_poses(&poses, args.gravity);
    let output = if args.json {
        format!(
            "{}\n",
            serde_json::to_string_pretty(&report::to_json(&analysis))?
        )
    } else {
        format!(
            "{} ({} poses)\n\n{}",
            dir.display(),
            poses.len(),
            report::to_text(&analysis)
        )
    };
    if let Err(e) = std::io::Write::write_all(&mut std::io::stdout(), output.as_bytes()) {
        if e.kind() != std::io::ErrorKind::BrokenPipe {
            return Err(e).context("could not write the analysis to standard output");
        }
    }
    if let Some(report_dir) = &args.report {
        let files = report::write_report(&analysis, report_dir)?;
        if !args.json {
            println!("report: {} files in {}", files.len(), report_dir.display());
        }
    }
    if let Some(out) = &args.write_params {
        let base_path = [dir.join("params-base.json"), dir.join("params.json")]
            .into_iter()
            .find(|p| p.is_file())
            .with_context(|| {
                format!(
                    "`{}` has neither params-base.json nor params.json to extend; pass the \
                     directory `imucal calibrate` saved",
                    dir.display()
                )
            })?;
        let base =
            ParamsFile::load(&base_path)?.to_calibration_set(&base_path.display().to_string())?;
        let extended = extend_set(&base, &analysis);
        std::fs::write(out, ParamsFile::from(&extended.set).to_json())
            .with_context(|| format!("could not write {}", out.display()))?;
        let added = if extended.extended() {
            extended.added.join(", ")
        } else {
            "none (the set is unchanged)".to_string()
        };
        eprintln!(
            "Wrote {} from {}; extended terms added: {added}. `imucal flash {}` writes it to the board.",
            out.display(),
            base_path.display(),
            out.display()
        );
        for effect in &extended.left_out {
            eprintln!(
                "Note: {effect} was accepted but the firmware has no term for it; not written"
            );
        }
    }
    if analysis.sensors.iter().all(|(_, r)| r.is_err()) {
        bail!("no sensor could be analysed (see the messages above)");
    }
    Ok(())
}

/// A session directory without a recording but with its poses.
fn is_pose_session(path: &std::path::Path) -> bool {
    path.is_dir() && !path.join("recording.csv").is_file() && path.join("poses.json").is_file()
}

/// A session directory holds its recording as `recording.csv`; a file is used as it is.
fn resolve_input(path: &std::path::Path) -> anyhow::Result<PathBuf> {
    if path.is_dir() {
        let candidate = path.join("recording.csv");
        if candidate.is_file() {
            return Ok(candidate);
        }
        bail!(
            "`{}` is a directory without a recording.csv or poses.json; pass the recording file \
             itself or a session directory of `imucal calibrate`",
            path.display()
        );
    }
    Ok(path.to_path_buf())
}

/// Run the command.
pub fn run(args: &AnalyzeArgs) -> anyhow::Result<()> {
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
    if let Some(s) = args.gyro_scale {
        if !(s.is_finite() && s > 0.0) {
            bail!("--gyro-scale {s} is not a positive number of rad/s per count");
        }
    }
    if is_pose_session(&args.input.recording) {
        return run_session_dir(args, &args.input.recording);
    }
    if args.write_params.is_some() {
        bail!(
            "--write-params needs a session directory of `imucal calibrate` (with poses.json and \
             params.json); `{}` is not one",
            args.input.recording.display()
        );
    }
    let mut input_path = args.input.recording.clone();
    input_path = resolve_input(&input_path)?;
    let recording = {
        let input = InputArgs {
            recording: input_path,
            ..clone_input(&args.input)
        };
        super::load(&input)?
    };
    let still = find_still(&recording, &super::still_options(&args.input))
        .context("still intervals could not be found")?;
    let gyro_scale = match (recording.units.to_si(Sensor::Gyro), args.gyro_scale) {
        (Some(s), _) => s,
        (None, Some(s)) => s,
        (None, None) => 1.0,
    };
    let options = AnalysisOptions {
        gravity: args.gravity,
        field_ut: match (args.field_ut, &args.location) {
            (Some(h), _) => Some(h),
            (None, Some(location)) => Some(
                imucal::geomag::local_field_today(location)
                    .context("the field at --location could not be modelled")?
                    .total_ut,
            ),
            (None, None) => None,
        },
        gyro_scale,
        ..AnalysisOptions::default()
    };
    let analysis = analyse_recording(&recording, &still, &options);
    let output = if args.json {
        format!(
            "{}\n",
            serde_json::to_string_pretty(&report::to_json(&analysis))?
        )
    } else {
        format!(
            "{}\n  {}\n\n{}",
            recording.source.display(),
            still.summary(),
            report::to_text(&analysis)
        )
    };
    // A closed pipe (e.g. `| head`) is not an error of the analysis.
    if let Err(e) = std::io::Write::write_all(&mut std::io::stdout(), output.as_bytes()) {
        if e.kind() != std::io::ErrorKind::BrokenPipe {
            return Err(e).context("could not write the analysis to standard output");
        }
    }
    if let Some(dir) = &args.report {
        let files = report::write_report(&analysis, dir)?;
        if !args.json {
            println!("report: {} files in {}", files.len(), dir.display());
        }
    }
    if analysis.sensors.iter().all(|(_, r)| r.is_err()) {
        bail!("no sensor could be analysed (see the messages above)");
    }
    Ok(())
}

fn clone_input(i: &InputArgs) -> InputArgs {
    InputArgs {
        recording: i.recording.clone(),
        accel_unit: i.accel_unit,
        gyro_unit: i.gyro_unit,
        mag_unit: i.mag_unit,
        rate: i.rate,
        mag_file: i.mag_file.clone(),
        no_mag_sibling: i.no_mag_sibling,
        format: i.format,
        columns: i.columns.clone(),
        gyro_file: i.gyro_file.clone(),
        imutk_time_unit: i.imutk_time_unit,
        window: i.window,
        min_hold: i.min_hold,
        still_margin: i.still_margin,
        direction_angle: i.direction_angle,
    }
}
