//! `imucal calibrate`: the guided calibration on a board (`--port`) or on the simulated board
//! started in-process behind a pseudo-terminal (`--sim`), which the host then opens with the
//! same serial-port code as real hardware. The session itself is `imucal::session`; this file
//! is its user interface: pictures and prompts, indicatif bars for stillness, hold progress and
//! coverage (plain lines with `--yes` or when stderr is not a terminal), the result, the
//! before/after table, and the session directory. With `--analyze` the residual analysis of the
//! session's poses follows, and the effects it accepts are written as the firmware's extended
//! terms (`imucal::session::extend`). The screen is `calibrate_view.rs`, the `--analyze` step
//! `calibrate_extend.rs`, the simulated board `calibrate_sim.rs`, boards that run a MotionCal
//! sketch `calibrate_motioncal.rs`, several boards on one fixture `calibrate_batch.rs` (both
//! chosen where commands are dispatched).

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use anyhow::Context;
use imucal::device::{DeviceClient, ParamsFile, UnitSample};
use imucal::pipeline::References;
use imucal::session::{
    load_mag_samples, load_moves, load_poses, load_progress, run_session_with, save_session,
    summary, CapturedPose, FieldSource, MagSample, SessionControl, SessionEvent, SessionOptions,
    Tapped, MOVES_FILE,
};
use imucal_protocol::Welcome;

use super::args::CalibrateArgs;
use super::board::given_or_only_board;
use super::calibrate_extend::{close_the_loop, Closed};
use super::calibrate_sim::Simulated;
use super::calibrate_view::{before_after_table, Terminal};
use super::write_policy::{
    check_outputs, not_asked, refused_poor, Output, WriteDecision, WritePolicy,
};

fn duration_arg(name: &str, seconds: f64) -> anyhow::Result<Duration> {
    anyhow::ensure!(
        seconds.is_finite() && seconds > 0.0,
        "{name} is {seconds}, but it must be a number of seconds greater than zero"
    );
    Ok(Duration::from_secs_f64(seconds))
}

pub(super) fn unix_now() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs())
}

/// What an unfinished session in `dir` measured, refused when it was started on another board.
struct Resumed {
    poses: Vec<CapturedPose>,
    mag: Vec<MagSample>,
    moves: Vec<Vec<UnitSample>>,
}

/// Read what the unfinished session in `dir` measured: its poses, magnetometer samples and the
/// moves between its holds.
fn resumed_session(dir: &Path, device_id: &str) -> anyhow::Result<Resumed> {
    let progress = load_progress(dir)?;
    anyhow::ensure!(
        progress.device_id == device_id,
        "{} was measured on device {}, but this board is device {device_id}; resume it on its \
         own board, or start a new session without --resume",
        dir.display(),
        progress.device_id
    );
    // A session stopped before its first pose has no poses.json, and possibly no samples; one
    // saved before moves were kept has no moves.csv.
    let poses_path = dir.join("poses.json");
    let poses = if poses_path.exists() {
        load_poses(&poses_path)?
    } else {
        Vec::new()
    };
    let mag_path = dir.join("mag_samples.csv");
    let mag = if mag_path.exists() {
        load_mag_samples(&mag_path)?
    } else {
        Vec::new()
    };
    let moves_path = dir.join(MOVES_FILE);
    let moves = if moves_path.exists() {
        load_moves(&moves_path)?
    } else {
        Vec::new()
    };
    let names: Vec<&str> = poses.iter().map(|p| p.target.name.as_str()).collect();
    say!(
        "Resuming {} (stopped: {}): {} positions already captured ({}); they are not asked for \
         again. The {} magnetometer samples and the {} moves between positions saved are kept.",
        dir.display(),
        progress.stopped_because,
        poses.len(),
        names.join(", "),
        mag.len(),
        moves.len()
    );
    Ok(Resumed { poses, mag, moves })
}

/// `word` as one shell word: as it is when it needs no quoting, otherwise in single quotes.
fn shell_word(word: &str) -> String {
    let plain = |c: char| c.is_ascii_alphanumeric() || "/._,:=+-@%".contains(c);
    if !word.is_empty() && word.chars().all(plain) {
        word.to_string()
    } else {
        format!("'{}'", word.replace('\'', r"'\''"))
    }
}

/// The command that continues the session saved in `dir` as `args` started it: the board (the
/// port, or every simulator option that makes the simulated board and its person the same),
/// the references, limits and history, so that it works as pasted.
pub(super) fn resume_command(args: &CalibrateArgs, dir: &Path) -> String {
    use super::args::{
        SimTemperature, DEFAULT_GRAVITY, DEFAULT_HOLD_S, DEFAULT_MAG_TIMEOUT_S,
        DEFAULT_POSE_TIMEOUT_S, DEFAULT_REST_TIMEOUT_S, DEFAULT_SPEED,
    };
    let mut words = vec![
        "imucal calibrate --resume".to_string(),
        shell_word(&dir.display().to_string()),
    ];
    if args.sim {
        words.push("--sim".to_string());
    }
    let mut option = |name: &str, value: String| {
        let value = shell_word(&value);
        // A negative number after a space would be read as an option.
        words.push(if value.starts_with('-') {
            format!("--{name}={value}")
        } else {
            format!("--{name} {value}")
        });
    };
    if args.sim {
        option("sim-seed", args.sim_seed.to_string());
        if args.sim_chip != imucal_hil_sim::board::SensorChip::default() {
            if let Some(chip) = clap::ValueEnum::to_possible_value(&args.sim_chip) {
                option("sim-chip", chip.get_name().to_string());
            }
        }
        if let Some(error) = args.sim_odr_error {
            option("sim-odr-error", error.to_string());
        }
        if args.sim_temperature != SimTemperature::Constant {
            option("sim-temperature", args.sim_temperature.to_string());
        }
        for effect in &args.sim_effects {
            option("sim-effect", effect.clone());
        }
        if args.speed != DEFAULT_SPEED {
            option("speed", args.speed.to_string());
        }
    }
    for port in &args.port {
        option("port", port.clone());
    }
    if args.rounds > 1 {
        option("rounds", args.rounds.to_string());
    }
    if args.gravity != DEFAULT_GRAVITY {
        option("gravity", args.gravity.to_string());
    }
    if let Some(field) = args.field_ut {
        option("field-ut", field.to_string());
    }
    if let Some(at) = &args.location {
        option(
            "location",
            format!("{},{},{}", at.latitude_deg, at.longitude_deg, at.altitude_m),
        );
    }
    for (name, value, default) in [
        ("hold", args.hold, DEFAULT_HOLD_S),
        ("pose-timeout", args.pose_timeout, DEFAULT_POSE_TIMEOUT_S),
        ("mag-timeout", args.mag_timeout, DEFAULT_MAG_TIMEOUT_S),
        ("rest-timeout", args.rest_timeout, DEFAULT_REST_TIMEOUT_S),
    ] {
        if value != default {
            option(name, value.to_string());
        }
    }
    let history = &args.history;
    for (name, value) in [
        ("db", &history.db),
        ("operator", &history.operator),
        ("station", &history.station),
    ] {
        if let Some(value) = value {
            option(name, value.clone());
        }
    }
    let flags = [
        ("--no-history", history.no_history),
        ("--analyze", args.analyze),
        ("--accept-poor", args.accept_poor),
        ("--json", args.json),
        ("--yes", args.yes),
    ];
    words.extend(
        flags
            .iter()
            .filter(|(_, given)| *given)
            .map(|(flag, _)| flag.to_string()),
    );
    words.join(" ")
}

/// A second SIGINT within this time of the first is the same Ctrl-C: `timeout` and `kill` on a
/// process group deliver one interrupt to the process and again to its group.
const SAME_CTRL_C: Duration = Duration::from_millis(500);

/// A flag set by the first Ctrl-C (or SIGTERM, SIGHUP: a `timeout`, a closed terminal), which
/// the session notices at its next batch of samples or stage (it then stops the stream and
/// saves); a second one ends the program at once.
pub(super) fn interrupt_flag() -> anyhow::Result<Arc<AtomicBool>> {
    let flag = Arc::new(AtomicBool::new(false));
    let handler_flag = Arc::clone(&flag);
    let mut first: Option<Instant> = None;
    ctrlc::set_handler(move || match first {
        None => {
            first = Some(Instant::now());
            handler_flag.store(true, Ordering::SeqCst);
            say!("\nInterrupted: stopping the session and saving what was measured (Ctrl-C again to quit at once)");
        }
        Some(at) if at.elapsed() < SAME_CTRL_C => {}
        Some(_) => std::process::exit(130),
    })
    .context("the Ctrl-C handler could not be installed")?;
    Ok(flag)
}

/// Binds the saved parameter file to the board it was measured on, so that `flash` can tell
/// it from another board's.
fn bind_saved_params(path: &std::path::Path, welcome: &Welcome) -> anyhow::Result<()> {
    let file = ParamsFile::load(path)?.bound_to(welcome);
    std::fs::write(path, file.to_json())
        .with_context(|| format!("could not write {}", path.display()))
}

/// The magnetometer's reference from `--field-ut`, or the World Magnetic Model at
/// `--location` (announced), or `None`.
pub(super) fn field_reference(args: &CalibrateArgs) -> anyhow::Result<Option<f64>> {
    checked_references(args)?;
    let modelled = args
        .location
        .as_ref()
        .map(imucal::geomag::local_field_today)
        .transpose()
        .context("the field at --location could not be modelled")?;
    if let (Some(model), None) = (&modelled, args.field_ut) {
        say!(
            "Reference field from the World Magnetic Model at --location: {:.2} µT, dip {:.1}°",
            model.total_ut,
            model.inclination_deg
        );
    }
    Ok(args.field_ut.or(modelled.as_ref().map(|m| m.total_ut)))
}

/// The session's reference field and where it came from: the one given (`--field-ut`, or the
/// model at `--location`), else a simulated board's site field, else none (the fit keeps the
/// sensor's mean radius).
pub(super) fn session_field(
    given: Option<f64>,
    simulated_site: Option<f64>,
) -> (Option<f64>, FieldSource) {
    match (given, simulated_site) {
        (Some(field), _) => (Some(field), FieldSource::Given),
        (None, Some(site)) => (Some(site), FieldSource::SimulatedSite),
        (None, None) => (None, FieldSource::Given),
    }
}

/// `--gravity` and `--field-ut` checked as `fit`, `analyze` and `report` check them (gravity on
/// the Earth's surface, fields a magnetometer can measure).
fn checked_references(args: &CalibrateArgs) -> anyhow::Result<References> {
    let checked = References::checked(args.gravity, args.field_ut, None);
    Ok(checked.map_err(super::UsageError::from)?)
}

/// The session's options from the command line.
pub(super) fn session_options(
    args: &CalibrateArgs,
    (field_ut, field_source): (Option<f64>, FieldSource),
) -> anyhow::Result<SessionOptions> {
    checked_references(args)?;
    Ok(SessionOptions {
        gravity_mps2: args.gravity,
        field_ut,
        field_source,
        hold: duration_arg("--hold", args.hold)?,
        pose_timeout: duration_arg("--pose-timeout", args.pose_timeout)?,
        mag_timeout: duration_arg("--mag-timeout", args.mag_timeout)?,
        rest_timeout: duration_arg("--rest-timeout", args.rest_timeout)?,
        rounds: usize::from(args.rounds),
        accept_outlier: args.accept_outlier,
        ..SessionOptions::default()
    })
}

/// The session directory (`--resume`, `-o`, or a new `imucal-session-<unix time>`), refused
/// before the board is opened when a new session would write into an earlier one's files.
pub(super) fn checked_session_dir(args: &CalibrateArgs) -> anyhow::Result<PathBuf> {
    if let Some(dir) = &args.resume {
        // What cannot be resumed is said before a board is opened.
        if !dir.join(imucal::session::PROGRESS_FILE).is_file() {
            anyhow::ensure!(
                !dir.join("summary.json").is_file(),
                "{} is a finished session (it has summary.json and no progress.json): there is \
                 nothing to resume; `imucal flash {}` writes its set, and a new session needs \
                 a new -o directory",
                dir.display(),
                dir.join("params.json").display()
            );
            anyhow::bail!(
                "{} holds no progress.json, so it is not a session `imucal calibrate` left \
                 unfinished; pass the directory a stopped session saved (its error message \
                 names it)",
                dir.display()
            );
        }
        return Ok(dir.clone());
    }
    let dir = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("imucal-session-{}", unix_now())));
    // A stopped session there is continued with --resume; --force starts over and says what
    // it replaces.
    if let Ok(progress) = imucal::session::load_progress(&dir) {
        let held = imucal::words::counted(progress.poses, "position");
        anyhow::ensure!(
            args.force,
            "`{}` holds a stopped session ({held} measured, {}); continue it with `imucal \
             calibrate --resume {}` (and the board's --port or --sim options), choose another \
             directory, or pass --force to start over there, replacing what it measured",
            dir.display(),
            if progress.stopped_because.is_empty() {
                format!("stage `{}`", progress.stage)
            } else {
                progress.stopped_because.clone()
            },
            dir.display()
        );
        say!(
            "imucal: warning: --force: starting over in {}, replacing the stopped session's \
             {held} there",
            dir.display()
        );
    }
    check_outputs(&[Output::Dir(&dir)], &[], args.force)?;
    Ok(dir)
}

/// Run `imucal calibrate`.
pub fn run(args: &CalibrateArgs) -> anyhow::Result<()> {
    let dir = checked_session_dir(args)?;
    // Refused before a simulated board starts or a port opens.
    let given_field = field_reference(args)?;
    let simulated = if args.sim {
        Some(Simulated::start(args)?)
    } else {
        None
    };
    let port = match &simulated {
        Some(sim) => sim.port(),
        None => given_or_only_board(args.port.first().map(String::as_str))?,
    };
    let field = session_field(given_field, simulated.as_ref().map(Simulated::field_ut));
    if simulated.is_some() {
        say!(
            "Simulated board (seed {}, {}× real time) on {port}; field {:.2} µT{}",
            args.sim_seed,
            args.speed,
            field.0.unwrap_or_default(),
            if field.1 == FieldSource::SimulatedSite {
                " (the simulated site's, as if looked up for the location)"
            } else {
                " (given)"
            }
        );
    }

    let options = session_options(args, field)?;
    let mut client = DeviceClient::open(&port)?;
    let welcome = *client.welcome();
    say!(
        "Connected to {port}: device {}, firmware {}.{}.{}, {} Hz",
        welcome.device_id,
        welcome.firmware_version.major,
        welcome.firmware_version.minor,
        welcome.firmware_version.patch,
        welcome.scales.sample_rate_hz
    );
    let resumed = match &args.resume {
        Some(dir) => resumed_session(dir, &welcome.device_id.to_string())?,
        None => Resumed {
            poses: Vec::new(),
            mag: Vec::new(),
            moves: Vec::new(),
        },
    };
    if let Some(sim) = &simulated {
        sim.resumed(&resumed.poses);
    }
    let control = SessionControl {
        resume: resumed.poses,
        resume_mag: resumed.mag,
        resume_moves: resumed.moves,
        save_dir: Some(dir.clone()),
        interrupt: Some(interrupt_flag()?),
    };
    let plain = args.yes || !std::io::stderr().is_terminal();
    let policy = WritePolicy {
        yes: args.yes,
        accept_poor: args.accept_poor,
    };
    let mut terminal = Terminal::new(plain, policy, port.clone()).with_json_events(args.json);
    let result = match &simulated {
        // The simulated person reads the prompts off the screen, as a person would.
        Some(sim) => {
            let mut shown = Tapped {
                observer: &mut terminal,
                tap: |event: &SessionEvent<'_>| sim.show(event),
            };
            run_session_with(&mut client, &options, &mut shown, &control)
        }
        None => run_session_with(&mut client, &options, &mut terminal, &control),
    };
    terminal.bar.finish_and_clear();
    let mut outcome = result.map_err(|error| {
        anyhow::anyhow!("{error}\nContinue with `{}`", resume_command(args, &dir))
    })?;
    if !outcome.written && outcome.not_written_because.is_none() {
        outcome.not_written_because = Some(
            match terminal.decision {
                Some(WriteDecision::RefusedPoor) => "poor verdict",
                Some(WriteDecision::NoOneToAsk) => "no --yes, and no terminal to ask",
                _ => "declined at the prompt",
            }
            .to_string(),
        );
    }
    save_session(&outcome, &dir)?;
    bind_saved_params(&dir.join("params.json"), &welcome)?;
    if let Some(sim) = &simulated {
        sim.save_truth(&dir.join("truth.json"))?;
    }
    let closed = if args.analyze {
        Some(close_the_loop(
            &mut client,
            &options,
            &outcome,
            &dir,
            args.json,
            policy,
        ))
    } else {
        None
    };
    // The summary and the history name the set on the board now: the extended one when
    // `--analyze` wrote it over the base set.
    let mut final_summary = summary(&outcome);
    let mut rest_failure = None;
    if let Some(Ok(Closed::SavedNotWritten(set, uncertainties))) = closed.as_ref() {
        // Nothing is on the board: the summary and the history name the saved set, the one
        // params.json holds and `flash` would write, as a written session does.
        final_summary.base_params_crc = Some(final_summary.params_crc.clone());
        final_summary.params = ParamsFile::from(&**set);
        final_summary.params_crc = format!("{:#010x}", set.crc32());
        final_summary.base_uncertainties = Some(final_summary.uncertainties);
        final_summary.uncertainties = **uncertainties;
        write_summary(&dir, &final_summary)?;
    }
    if let Some(Ok(Closed::RevertedAtRest {
        worse,
        extended_path,
    })) = closed.as_ref()
    {
        final_summary.notes.push(format!(
            "the extended set ({}) checked worse at rest than the base set ({}) and the base \
             set was written back",
            extended_path.display(),
            worse.join("; ")
        ));
        write_summary(&dir, &final_summary)?;
    }
    if let Some(Ok(Closed::Written {
        set,
        uncertainties,
        note,
        verdict,
        status,
        rest,
    })) = closed.as_ref()
    {
        final_summary.notes.extend(note.iter().cloned());
        // The verdict is the written set's; the set is on the board even when the base set
        // was refused for its verdict and the terms explained why.
        final_summary.verdict = verdict.clone();
        final_summary.written = true;
        final_summary.verified = true;
        final_summary.not_written_because = None;
        final_summary.base_params_crc = Some(final_summary.params_crc.clone());
        final_summary.params = ParamsFile::from(&**set);
        final_summary.params_crc = format!("{:#010x}", status.active_crc);
        final_summary.base_uncertainties = Some(final_summary.uncertainties);
        final_summary.uncertainties = **uncertainties;
        final_summary.on_board_after = rest.as_ref().ok().copied();
        // The scalar figures describe the set on the board; unknown when its check failed.
        let on_board = rest.as_ref().ok();
        final_summary.missed_targets = on_board
            .map(|a| a.missed_targets(outcome.fit.budgets))
            .unwrap_or_default();
        final_summary.verdict = imucal::session::verdict_with_missed_targets(
            &final_summary.verdict,
            &final_summary.missed_targets,
        );
        final_summary.accel_rest_error_mg = on_board.map(|a| a.accel_error_mg);
        final_summary.mag_rest_error_pct = on_board.map(|a| a.mag_error_pct);
        final_summary.gyro_rest_error_dps = on_board.map(|a| a.gyro_rate_dps);
        rest_failure = rest.as_ref().err().map(|e| format!("{e:#}"));
        write_summary(&dir, &final_summary)?;
    }
    // Recorded only once the session directory holds the calibration, and also when the
    // analysis failed: the board holds a set either way.
    let mut record =
        imucal::history::CalibrationRecord::from_session(&final_summary, &outcome.poses);
    record.firmware_version = Some(super::history::firmware_text(&welcome.firmware_version));
    // A failed write is returned after the summary is printed, so nothing is hidden.
    let recorded = super::history::record(&args.history, record);
    let closed = closed.transpose()?;
    let on_board_after = match &closed {
        Some(Closed::Written {
            rest: Ok(errors), ..
        }) => Some(errors),
        _ => None,
    };

    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&final_summary)
                .context("the summary could not be encoded")?
        );
    } else {
        println!();
        print!("{}", before_after_table(&outcome, on_board_after));
        if !final_summary.missed_targets.is_empty() {
            let next = if args.analyze {
                "the residual analysis found no further term the firmware can apply; see \
                 analysis.txt"
            } else {
                "the model lacks an effect this board shows (temperature, drift, …): \
                 `--analyze` looks for it and writes what the firmware can apply"
            };
            println!(
                "The set on the board misses its targets at rest: {}; {next}.",
                final_summary.missed_targets.join("; ")
            );
        }
        // The stream's measured rate: a sensor off its nominal rate shows here first.
        let lost = match outcome.lost_samples {
            0 => "no sample lost".to_string(),
            1 => "1 sample lost in transit".to_string(),
            n => format!(
                "{n} samples lost in transit ({:.1} % of the stream)",
                100.0 * outcome.sample_loss_rate
            ),
        };
        let stream = match outcome.stream_rate_hz {
            rate if rate > 0.0 => format!(", stream {rate:.1} Hz with {lost}"),
            _ if outcome.lost_samples > 0 => format!(", {lost}"),
            _ => String::new(),
        };
        println!(
            "Session{}: {:.1} s {} ({:.1} s wall), {} positions, {} of 26 magnetometer \
             directions{stream}; verified: {}",
            // The time of the run before the stop is not known (the board's clock may have
            // restarted); the positions and directions are the whole session's.
            if args.resume.is_some() {
                " (this run's time; the positions and directions include the resumed run's)"
            } else {
                ""
            },
            outcome.session_seconds,
            if args.sim {
                "simulated"
            } else {
                "on the board's clock"
            },
            outcome.wall_seconds,
            outcome.poses.len(),
            outcome.coverage.covered(options.mag_min_per_region),
            if final_summary.verified {
                "yes"
            } else {
                "no (not written)"
            }
        );
        let flash = match &final_summary.not_written_because {
            None => "writes the parameters again".to_string(),
            Some(why) => format!("writes them; they are not on the board: {why}"),
        };
        if let Some(note) = &outcome.link_note {
            println!(
                "Link: {note}; what the session lost (samples, the gyroscope's moves) is the \
                 link's doing, not the handling"
            );
        }
        println!(
            "Saved {} (`imucal flash {}` {flash})",
            dir.display(),
            dir.join("params.json").display()
        );
    }
    // A Ctrl-C during the last check at rest, after the set was verified, finds nothing left
    // to stop: the session finished, and the message printed at the Ctrl-C is corrected.
    if control
        .interrupt
        .as_ref()
        .is_some_and(|flag| flag.load(Ordering::SeqCst))
    {
        say!(
            "The Ctrl-C came after the last stage had begun: the session finished and is saved \
             in {}",
            dir.display()
        );
    }
    recorded?;
    if let Some(why) = rest_failure {
        anyhow::bail!(
            "the extended set is on the board, but its check at rest failed: {why}; check the \
             board with `imucal stream --calibrated`"
        );
    }
    // A set on the board that misses its own target at rest fails the command, as a failed
    // check at rest does: the board holds it, the summary and the history say what it missed.
    if final_summary.written && !final_summary.missed_targets.is_empty() {
        anyhow::bail!(
            "the set is written and verified on the board, but misses its targets at rest: {}; \
             the verdict and the history record it (the set stays on the board: calibrate \
             again, or with --analyze to look for the effect the model lacks)",
            final_summary.missed_targets.join("; ")
        );
    }
    // Nothing written because of the verdict is a failure for scripts, after all is saved.
    if terminal.decision == Some(WriteDecision::RefusedPoor) && !final_summary.written {
        return Err(refused_poor("The calibration", &dir.join("params.json")));
    }
    if let Some(why) = final_summary
        .not_written_because
        .as_deref()
        .filter(|why| why.starts_with(imucal::history::part_limits::PART_LIMITS_REFUSAL))
    {
        anyhow::bail!(
            "The calibration is not written: {why}. It is saved in {}; check the board, or write \
             it anyway with `imucal flash {} --accept-outlier`",
            dir.display(),
            dir.join("params.json").display()
        );
    }
    if terminal.decision == Some(WriteDecision::NoOneToAsk) {
        return Err(not_asked(
            "The calibration",
            &format!(
                "write the saved file with `imucal flash {} --yes`",
                dir.join("params.json").display()
            ),
        ));
    }
    if let Some(Closed::RefusedPoor(params)) = closed {
        return Err(refused_poor("The extended set", &params));
    }
    Ok(())
}

/// Write `summary.json` of the session in `dir` again (the set on the board changed).
fn write_summary(dir: &Path, summary: &impl serde::Serialize) -> anyhow::Result<()> {
    let path = dir.join("summary.json");
    let text = serde_json::to_string_pretty(summary).context("the summary could not be encoded")?;
    std::fs::write(&path, text + "\n")
        .with_context(|| format!("could not write {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cli::args::{Cli, Command};
    use clap::Parser;

    fn calibrate_args(words: &[&str]) -> CalibrateArgs {
        let cli = Cli::try_parse_from(words).unwrap_or_else(|e| panic!("{words:?}: {e}"));
        match cli.command {
            Command::Calibrate(args) => args,
            other => panic!("not calibrate: {other:?}"),
        }
    }

    #[test]
    fn the_resume_command_names_the_simulated_board_and_reads_back_as_the_same() {
        let args = calibrate_args(&[
            "imucal",
            "calibrate",
            "--sim",
            "--sim-seed",
            "3",
            "--sim-odr-error",
            "-0.004",
            "--sim-effect",
            "accel.bias_temperature=2",
            "--rounds",
            "2",
            "--yes",
            "-o",
            "my session",
        ]);
        let command = resume_command(&args, Path::new("my session"));
        assert!(
            command.starts_with("imucal calibrate --resume 'my session' --sim --sim-seed 3"),
            "{command}"
        );
        // The words a shell would pass, read back by the same parser.
        let words: Vec<String> = command
            .replace("'my session'", "my_session")
            .split_whitespace()
            .map(|w| w.replace("my_session", "my session"))
            .collect();
        let words: Vec<&str> = words.iter().map(String::as_str).collect();
        let again = calibrate_args(&words);
        assert_eq!(again.resume.as_deref(), Some(Path::new("my session")));
        assert_eq!(again.sim_seed, 3);
        assert_eq!(again.sim_odr_error, Some(-0.004));
        assert_eq!(again.sim_effects, args.sim_effects);
        assert_eq!((again.rounds, again.yes, again.sim), (2, true, true));
    }

    #[test]
    fn the_resume_command_of_a_board_names_its_port() {
        let args = calibrate_args(&["imucal", "calibrate", "--port", "/dev/ttyACM0"]);
        assert_eq!(
            resume_command(&args, Path::new("s1")),
            "imucal calibrate --resume s1 --port /dev/ttyACM0"
        );
    }
}
