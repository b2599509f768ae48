//! `imucal analyze`: residual analysis of a recording (see `imucal::analysis`), printed as text
//! or as the stable JSON document, optionally with a report directory of plots. A session
//! directory of `imucal calibrate` without a `recording.csv` is analysed from its `poses.json`
//! (`imucal::session::analyse_poses`), and `--write-params` writes its parameter set with the
//! accepted effects added, for `imucal flash`.

use anyhow::{bail, Context};
use imucal::analysis::{analyse_recording, report, AnalysisError, AnalysisOptions};
use imucal::device::ParamsFile;
use imucal::geomag::local_field_today;
use imucal::pipeline::check_input;
use imucal::pipeline::gyro::{gyro_unit_scale, moot_gyro_scale};
use imucal::session::{analyse_poses, extend_set, load_poses};

use super::args::{AnalyzeArgs, InputArgs};
use super::write_policy::{check_outputs, Output};

/// Analyse a session directory from its poses; optionally write the extended set.
fn run_session_dir(args: &AnalyzeArgs, dir: &std::path::Path) -> anyhow::Result<()> {
    let poses = load_poses(&dir.join("poses.json"))?;
    let analysis = analyse_poses(&poses, args.reference.gravity);
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
        let base_file = ParamsFile::load(&base_path)?;
        let base = base_file.to_calibration_set(&base_path.display().to_string())?;
        let extended = extend_set(&base, &analysis);
        // The extended set stays the base file's: bound to its board, with its provenance, its
        // sensors left unfitted and their input units, so `flash` refuses it on another board
        // and keeps the board's own calibration of a sensor the session did not fit.
        let mut file = ParamsFile::from(&extended.set);
        file.device = base_file.device;
        file.provenance = base_file.provenance;
        file.not_fitted = base_file.not_fitted;
        file.absent_sensors = base_file.absent_sensors;
        file.accel.input_unit = base_file.accel.input_unit;
        file.gyro.input_unit = base_file.gyro.input_unit;
        file.mag.input_unit = base_file.mag.input_unit;
        std::fs::write(out, file.to_json())
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

/// Run the command.
pub fn run(args: &AnalyzeArgs) -> anyhow::Result<()> {
    let outputs: Vec<Output> = [
        args.report.as_deref().map(Output::Dir),
        args.write_params.as_deref().map(Output::File),
    ]
    .into_iter()
    .flatten()
    .collect();
    check_outputs(&outputs, &super::input_paths(&args.input), args.force)?;
    let references = super::references(&args.reference)?;
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
    let input = InputArgs {
        recording: super::recording_file(&args.input.recording)?,
        ..args.input.clone()
    };
    let recording = super::load(&input)?;
    let sensors = recording.sensors();
    // The same checks as `imucal fit`: a unit mix-up or unusable holds refuse the analysis.
    let checked = check_input(
        recording,
        &sensors,
        &super::input_options(&args.input, &args.reference),
        references.field_ut,
    );
    if !checked.unit_refusals.is_empty() {
        bail!(
            "the recording was refused: {}",
            checked.unit_refusal_sentences().join("; ")
        );
    }
    for warning in &checked.warnings {
        eprintln!("imucal: warning: {warning}");
    }
    let Some(still) = &checked.still else {
        let why = [
            imucal::recording::Sensor::Accel,
            imucal::recording::Sensor::Gyro,
        ]
        .into_iter()
        .find_map(|s| checked.refusal(s))
        .unwrap_or("no still intervals were found");
        bail!("{why}; there is nothing to analyse");
    };
    let recording = &checked.recording;
    let (gyro_scale, gyro_unit) = gyro_unit_scale(recording, references.gyro_scale);
    if let Some(moot) = moot_gyro_scale(recording, references.gyro_scale) {
        eprintln!("imucal: warning: {moot}");
    }
    let options = AnalysisOptions {
        gravity: references.gravity_mps2,
        field_ut: match (references.field_ut, &args.reference.location) {
            (Some(h), _) => Some(h),
            (None, Some(location)) => Some(
                local_field_today(location)
                    .context("the field at --location could not be modelled")?
                    .total_ut,
            ),
            (None, None) => None,
        },
        gyro_scale,
        gyro_scale_known: gyro_unit == "rad/s",
        latitude_deg: args.reference.location.map(|l| l.latitude_deg),
        ..AnalysisOptions::default()
    };
    let mut analysis = analyse_recording(recording, still, &options);
    for (sensor, result) in &mut analysis.sensors {
        if let Some(reason) = checked.refusal(*sensor) {
            *result = Err(AnalysisError::Refused(reason.to_string()));
        }
    }
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
