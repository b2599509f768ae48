//! `imucal report`: an HTML report of a session directory (as `imucal calibrate` writes it) or
//! of a recording, fitted through the same pipeline, checks and default chain as `imucal fit`.

use std::path::{Path, PathBuf};

use anyhow::bail;
use imucal::fit::Vec3;
use imucal::geomag::{local_field_today, LocalField, RadiusCheck};
use imucal::history::fleet::count_boards;
use imucal::pipeline::{calibrate, check_input, FitOptions};
use imucal::report::recording::from_calibration;
use imucal::report::{from_session_dir, write_report_file, ReportData, REPORT_FILE};
use indicatif::{ProgressBar, ProgressStyle};

use super::args::ReportArgs;
use super::write_policy::{check_outputs, Output};

fn progress(steps: u64) -> ProgressBar {
    let bar = ProgressBar::new(steps);
    if let Ok(style) = ProgressStyle::with_template("{bar:30} {pos}/{len} {msg}") {
        bar.set_style(style);
    }
    bar
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

/// Fits a recording through the pipeline and gathers what the report shows. Refuses, as `fit`
/// does, when an input check refuses a sensor.
/// The report of a recording, and the sentences of the sensors refused for their units (the
/// page leaves them out; the command then fails, as `fit` does).
fn from_recording(
    args: &ReportArgs,
    field: Option<&LocalField>,
    bar: &ProgressBar,
) -> anyhow::Result<(ReportData, Vec<String>)> {
    let references = super::references(&args.reference)?;
    let recording = super::load(&args.input, args.reference.gyro_scale, None)?;
    bar.inc(1);
    bar.set_message("checking the recording and finding still intervals");
    let sensors = recording.sensors();
    let options = super::input_options(&args.input, &args.reference);
    let input = check_input(recording, &sensors, &options, args.reference.field_ut);
    // As `fit` does, a sensor refused (its unit, its holds) is left out with its reason, which
    // the report shows; the others are reported.
    let refused = input.unit_refusal_sentences();
    if input.still.is_none() && input.mag_points().is_empty() {
        // Nothing left to report on: say why the holds were refused.
        if let Some(why) = [
            imucal::recording::Sensor::Accel,
            imucal::recording::Sensor::Gyro,
        ]
        .into_iter()
        .find_map(|s| input.refusal(s))
        {
            bail!("{why}; no report was written");
        }
    }
    bar.inc(1);
    bar.set_message("fitting");
    let calibration = calibrate(
        &input,
        &FitOptions {
            references: Some(references),
            location: args.reference.location,
            ..FitOptions::default()
        },
    )?;
    bar.inc(1);
    Ok((from_calibration(&input, &calibration, field), refused))
}

fn default_out(path: &Path, is_session: bool) -> PathBuf {
    if is_session {
        return path.to_path_buf();
    }
    if path == Path::new("-") {
        // Standard input has no name to derive one from.
        return PathBuf::from("recording_report");
    }
    let stem = path
        .file_stem()
        .map_or("recording".into(), |s| s.to_string_lossy().into_owned());
    path.with_file_name(format!("{stem}_report"))
}

/// The report file `-o` names: `out` itself when it names a file (its name ends in `.html` or
/// `.htm`, or it exists and is no directory, e.g. `/dev/stdout`), else `report.html` in the
/// directory `out`.
fn report_file(out: &Path) -> PathBuf {
    let html_name = out
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("html") || e.eq_ignore_ascii_case("htm"));
    let other_than_dir = std::fs::metadata(out).is_ok_and(|m| !m.is_dir());
    if (html_name && !out.is_dir()) || other_than_dir {
        out.to_path_buf()
    } else {
        out.join(REPORT_FILE)
    }
}

/// Whether `dir` holds what a session's report is made from.
fn is_session_dir(dir: &Path) -> bool {
    dir.is_dir() && dir.join("params.json").is_file() && dir.join("poses.json").is_file()
}

/// The session directories directly inside `dir`, by name: the boards of a batch
/// (`calibrate --sim-boards N` or several ports writes one per device id).
fn batch_sessions(dir: &Path) -> Vec<PathBuf> {
    let mut sessions: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|entries| {
            entries
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| is_session_dir(p))
                .collect()
        })
        .unwrap_or_default();
    sessions.sort();
    sessions
}

/// Why the directory `path` cannot be reported: what it lacks, for a batch which of its boards'
/// sessions to report instead, and for a session `calibrate` stopped before its fit, how to
/// finish it.
fn not_a_session(path: &Path) -> anyhow::Error {
    let sessions = batch_sessions(path);
    if !sessions.is_empty() {
        // One report is of one board, as `calibrate --resume` resumes one board of a batch.
        let commands: Vec<String> = sessions
            .iter()
            .map(|s| format!("`imucal report {}`", s.display()))
            .collect();
        // The command line names the wrong directory: a usage error, exit status 2.
        return super::UsageError(format!(
            "`{}` is the directory of a batch of `imucal calibrate`, with the sessions of {}; a \
             report is of one board's session, so report each: {}",
            path.display(),
            count_boards(sessions.len()),
            commands.join(", ")
        ))
        .into();
    }
    let missing: Vec<&str> = ["params.json", "poses.json"]
        .into_iter()
        .filter(|name| !path.join(name).is_file())
        .collect();
    if let Ok(progress) = imucal::session::load_progress(path) {
        return anyhow::anyhow!(
            "`{}` is a session of `imucal calibrate` that stopped before its calibration was \
             fitted ({}), so it has no {} to report; continue it with `imucal calibrate --resume \
             {}` (with the options printed when it stopped) and report it once it has finished",
            path.display(),
            if progress.stopped_because.is_empty() {
                format!("stage `{}`", progress.stage)
            } else {
                progress.stopped_because
            },
            missing.join(" or "),
            path.display()
        );
    }
    anyhow::anyhow!(
        "`{}` is not a session directory of `imucal calibrate`: it has no {}, nor a \
         recording.csv{}; pass a session directory or a recording file",
        path.display(),
        missing.join(" or "),
        if path.join(REPORT_FILE).is_file() {
            format!(" (its {REPORT_FILE} is the output of `imucal report`)")
        } else {
            String::new()
        }
    )
}

/// Run the command.
pub fn run(args: &ReportArgs) -> anyhow::Result<()> {
    let path = &args.input.recording;
    // A session directory with its parameters and poses is reported from them; one with only
    // its recording (as `fit` and `analyze` read it), from the recording.
    let is_session = is_session_dir(path);
    if path.is_dir() && !is_session && super::directory_recording(path).is_none() {
        return Err(not_a_session(path));
    }
    let out = report_file(
        &args
            .out
            .clone()
            .unwrap_or_else(|| default_out(path, is_session)),
    );
    check_outputs(
        &[Output::FileInNewDir(&out)],
        &super::input_paths(&args.input),
        args.force,
    )?;
    super::references(&args.reference)?;
    let field = args
        .reference
        .location
        .as_ref()
        .map(local_field_today)
        .transpose()?;
    let bar = progress(4);
    let (mut data, refused) = if is_session {
        bar.set_message("reading the session directory");
        let data = from_session_dir(path)?;
        bar.inc(3);
        (data, Vec::new())
    } else {
        bar.set_message("reading the recording");
        from_recording(args, field.as_ref(), &bar)?
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
    write_report_file(&data, &out)?;
    bar.inc(1);
    bar.finish_and_clear();
    println!("report written to {}", out.display());
    anyhow::ensure!(
        refused.is_empty(),
        "the report leaves out what was refused: {}",
        refused.join("; ")
    );
    Ok(())
}
