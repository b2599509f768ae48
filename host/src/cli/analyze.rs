//! `imucal analyze`: residual analysis of a recording (see `imucal::analysis`), printed as text
//! or as the stable JSON document, optionally with a report directory of plots. The base fits
//! are the pipeline's, as `imucal fit` prints them for the same options, and the analysis starts
//! from them; like `fit`, the command fails when any sensor could not be fitted or analysed. A session
//! directory of `imucal calibrate` without a `recording.csv` is analysed from its `poses.json`
//! (`imucal::session::analyse_poses`), and `--write-params` writes its parameter set with the
//! accepted effects added, for `imucal flash`.

use anyhow::{bail, Context};
use imucal::analysis::{analyse_calibration, report, AnalysisOptions};
use imucal::device::ParamsFile;
use imucal::geomag::local_field_today;
use imucal::pipeline::calibration::once_per_reason;
use imucal::pipeline::gyro::{gyro_unit_scale, moot_gyro_scale};
use imucal::pipeline::{check_and_calibrate, FitOptions};
use imucal::session::{analyse_poses, extend_set, load_poses};
use serde_json::Value;

use super::args::{AnalyzeArgs, InputArgs};
use super::write_policy::{check_outputs, Output};
use super::UsageError;

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
        say!(
            "Wrote {} from {}; extended terms added: {added}. `imucal flash {}` writes it to the board.",
            out.display(),
            base_path.display(),
            out.display()
        );
        for effect in &extended.left_out {
            say!("Note: {effect} was accepted but the firmware has no term for it; not written");
        }
    }
    fail_on_any(&analysis)
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
    let session = is_pose_session(&args.input.recording);
    // An option the input cannot take is a usage error, told before anything is read or
    // written.
    if args.write_params.is_some() && !session {
        return Err(UsageError(format!(
            "--write-params needs a session directory of `imucal calibrate` (with poses.json and \
             params.json); `{}` is not one",
            args.input.recording.display()
        ))
        .into());
    }
    check_outputs(&outputs, &super::input_paths(&args.input), args.force)?;
    let references = super::references(&args.reference)?;
    if session {
        return run_session_dir(args, &args.input.recording);
    }
    let input = InputArgs {
        recording: super::recording_file(&args.input.recording)?,
        ..args.input.clone()
    };
    let recording = super::load(&input, args.reference.gyro_scale, None)?;
    let sensors = recording.sensors();
    // The pipeline `imucal fit` runs, with the same options: the base fits printed here are
    // its result, and the analysis builds on them.
    let fit_options = FitOptions {
        references: Some(references),
        location: args.reference.location,
        methods: Vec::new(),
        device_id: None,
    };
    let (checked, calibration) = check_and_calibrate(
        recording,
        &sensors,
        &super::input_options(&args.input, &args.reference),
        args.reference.field_ut,
        &fit_options,
    )?;
    // The same checks as `imucal fit`, per sensor: a sensor refused (a unit mix-up, no holds)
    // is "not fitted" below with its reason, and the others are analysed, as `fit` fits them.
    for warning in &checked.warnings {
        say!("imucal: warning: {warning}");
    }
    // Without holds the accelerometer and gyroscope are refused by the pipeline already; the
    // magnetometer's analysis works on windows of its stream and needs none.
    let no_holds = imucal::still::StillReport {
        intervals: Vec::new(),
        directions: Vec::new(),
        noise: Vec::new(),
        window: 0,
        from_pose_column: false,
        rate_bound_applied: false,
    };
    let still = checked.still.as_ref().unwrap_or(&no_holds);
    let recording = &checked.recording;
    let (gyro_scale, gyro_unit) = gyro_unit_scale(recording, references.gyro_scale);
    if let Some(moot) = moot_gyro_scale(recording, references.gyro_scale) {
        say!("imucal: warning: {moot}");
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
    let analysis = analyse_calibration(recording, still, &options, &calibration);
    // One document and one text, printed and written alike.
    let mut document = report::to_json(&analysis);
    // Each sensor's base fit as `imucal fit --json` gives it.
    if let Some(sensors) = document["sensors"].as_object_mut() {
        for outcome in &calibration.sensors {
            if let Some(Value::Object(entry)) = sensors.get_mut(outcome.sensor.name()) {
                entry.insert("base_fit".into(), super::fit::to_json(outcome));
            }
        }
    }
    let text = format!(
        "{}\nresidual analysis (on each hold less one detection window at either end, so its \
         RMS is not the fit's above)\n\n{}",
        super::fit::table_text(&calibration),
        report::to_text(&analysis)
    );
    let output = if args.json {
        format!("{}\n", serde_json::to_string_pretty(&document)?)
    } else {
        text.clone()
    };
    // A closed pipe (e.g. `| head`) is not an error of the analysis.
    if let Err(e) = std::io::Write::write_all(&mut std::io::stdout(), output.as_bytes()) {
        if e.kind() != std::io::ErrorKind::BrokenPipe {
            return Err(e).context("could not write the analysis to standard output");
        }
    }
    if let Some(dir) = &args.report {
        let files = report::write_report_as(&analysis, dir, &document, &text)?;
        if !args.json {
            println!("report: {} files in {}", files.len(), dir.display());
        }
    }
    fail_on_any(&analysis)
}

/// As `imucal fit` does: the command fails when any sensor could not be analysed, after
/// everything that could be done was printed and written; the error names each sensor and why.
fn fail_on_any(analysis: &imucal::analysis::RecordingAnalysis) -> anyhow::Result<()> {
    let reasons: Vec<(&str, String)> = analysis
        .sensors
        .iter()
        .filter_map(|(sensor, r)| {
            let e = r.as_ref().err()?;
            Some((sensor.name(), format!("not analysed: {e}")))
        })
        .collect();
    if reasons.is_empty() {
        return Ok(());
    }
    bail!("{}", once_per_reason(&reasons).join("; "))
}
