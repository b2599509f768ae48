//! The guided calibration session: which orientations are still needed, live stillness, the
//! magnetometer's sphere coverage, when enough data is in, fitting, writing, verifying, and the
//! before/after check at rest. The user interface is the caller's: it receives
//! [`SessionEvent`]s through a [`SessionObserver`] and is asked before the parameters are written.
//!
//! Sequence ([`run_session`]):
//! 1. Positions ([`capture`]): a raw stream gives the up direction and stillness
//!    ([`motion::MotionMonitor`]); when the board is still in one of the twelve positions of
//!    seed 003 ([`targets::twelve_positions`]) that is still needed, the stream stops and the
//!    board averages a pose (`CapturePose`) for as long as its mean needs ([`hold`]). Poses may
//!    come in any order; the prompt names the one that helps the fit most ([`plan`]). The stream
//!    of every move between holds is kept for the gyroscope ([`gyro_moves`]). With
//!    [`SessionOptions::rounds`] above 1 the twelve are captured that many times over. Afterwards, if the
//!    covariance of the accelerometer fit says the expected `|a|` error exceeds a quarter of the
//!    budget, corner positions are asked for as well ([`targets::corner_positions`]), until it
//!    meets that target or four are in. Then, while a fit of the moves against gravity says an
//!    entry of the gyroscope's `A` is over a third of its budget, up to four corners whose turn
//!    tilts the board about the axis that entry needs ([`gyro_phase`]).
//! 2. Magnetometer ([`mag_phase`]): raw samples while the user turns the board, until every one
//!    of 26 direction regions holds enough samples ([`coverage`]); the moves between the
//!    positions count, so this only fills in what they left empty.
//! 3. Rest: once the board lies still, raw samples give the "before" errors (taken again if the
//!    board moved during them).
//! 4. Fit with the library's default methods ([`solve::fit_session`]), the gyroscope's scale and
//!    misalignment from the moves ([`gyro_fit::complete_gyro`]; against gravity and, with an
//!    aligned magnetometer, the field direction, [`gyro_field`]), show the result with its
//!    uncertainties and verdict, write the set, commit, read it back and compare (CRC and every
//!    value), then stream calibrated samples at rest for the "after" errors.
//!
//! Afterwards [`extend`] can run the residual analysis on the poses and add the effects it
//! accepts (temperature polynomial of the bias, …) to the set as the firmware's extended terms.
//!
//! Every request has the device client's timeouts and retries; each phase has its own wall-clock
//! limit, and every failure is a [`SessionError`] sentence.

pub mod batch;
pub mod batch_gate;
mod capture;
pub mod coverage;
mod error;
pub mod events;
pub mod extend;
pub mod gyro_field;
pub mod gyro_fit;
pub mod gyro_moves;
mod gyro_nuisance;
mod gyro_phase;
pub mod hold;
pub mod journal;
mod mag_alignment;
pub mod mag_guidance;
mod mag_phase;
pub mod motion;
pub mod motioncal;
pub mod options;
pub mod plan;
pub mod rest;
mod rest_phase;
mod runner;
pub mod save;
#[cfg(feature = "sim")]
pub mod sim_screen;
pub mod solve;
pub mod targets;

use std::io::{Read, Write};
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Instant;

use imucal_protocol::{ParamStatus, StreamKind};

use crate::device::{DeviceClient, UnitSample};
use crate::fit::Vec3;
use capture::CaptureGoal;
use journal::Journal;
use runner::{unix_now, Runner};

pub use coverage::{Coverage, REGIONS};
pub use error::SessionError;
pub use events::{MagSample, Phase, SessionEvent, SessionObserver, Tapped, Unattended};
pub use extend::{analyse_poses, extend_set, ExtendedSet};
pub use gyro_fit::{GyroBudgets, GyroScale};
pub use journal::{load_progress, Progress};
pub use motion::{MotionMonitor, MotionState};
pub use options::SessionOptions;
pub use rest::{rest_errors, RestErrors};
pub use rest_phase::stream_for;
pub use save::{
    load_mag_samples, load_moves, load_poses, save_session, summary, verdict_with_missed_targets,
    SessionSummary,
};
pub use save::{MOVES_FILE, PROGRESS_FILE};
pub use solve::{
    fit_session, Budgets, CapturedPose, FieldSource, SessionFit, Uncertainties, Verdict,
    VerdictLevel,
};
pub use targets::{Target, MATCH_ANGLE_DEG};

/// Everything a session produced.
#[derive(Debug, Clone)]
pub struct SessionOutcome {
    /// The port.
    pub port: String,
    /// The board's id.
    pub device_id: String,
    /// Every captured pose, in capture order.
    pub poses: Vec<CapturedPose>,
    /// Why extra positions were or were not asked for.
    pub extra_positions_note: String,
    /// Every raw magnetometer sample streamed.
    pub mag_samples: Vec<MagSample>,
    /// Every move between holds kept for the gyroscope's scale fit (those of an earlier run
    /// first), in nominal units.
    pub moves: Vec<Vec<UnitSample>>,
    /// Coverage of the magnetometer phase.
    pub coverage: Coverage,
    /// Samples a region needed to count as covered ([`SessionOptions::mag_min_per_region`]).
    pub mag_min_per_region: usize,
    /// The fit.
    pub fit: SessionFit,
    /// The gyroscope's scale and misalignment, `None` when they could not be fitted (the
    /// verdict says why; the set then carries the bias only).
    pub gyro_scale: Option<GyroScale>,
    /// Whether the set was written (false when the write was declined).
    pub written: bool,
    /// Why the set was not written, in words (`poor verdict`, `outlier against the fleet`, …),
    /// set by whoever declined it before the session is saved; `None` when it was written.
    pub not_written_because: Option<String>,
    /// Whether the set read back from the board matched (CRC and every value).
    pub verified: bool,
    /// The store's state after the commit.
    pub param_status: Option<ParamStatus>,
    /// Errors at rest before calibration (raw readings).
    pub before: RestErrors,
    /// Errors at rest after calibration (the board's calibrated stream).
    pub after: Option<RestErrors>,
    /// Board time from the first prompt to the verified write, s (simulated time on a
    /// simulated board).
    pub session_seconds: f64,
    /// Wall time of the same span, s.
    pub wall_seconds: f64,
    /// Wall time the host spent fitting (the board waits meanwhile), s. A simulated board
    /// running `k`× faster than real time counts it `k` times in `session_seconds`.
    pub fit_wall_seconds: f64,
    /// Calibrated samples per second of board time during the "after" measurement.
    pub stream_rate_hz: f64,
    /// Samples lost in transit over the whole session.
    pub lost_samples: u64,
    /// Fraction of the stream's samples lost in transit.
    pub sample_loss_rate: f64,
    /// A noisy link's measured loss and what to check, when the link was noisy enough to
    /// matter ([`crate::device::LinkStats::noisy_link_note`]).
    pub link_note: Option<String>,
}

/// How a session runs beyond its options: where it is saved as it goes, poses of an earlier
/// run to continue from, and a flag that stops it.
#[derive(Debug, Clone, Default)]
pub struct SessionControl {
    /// The session directory, written after every pose and phase ([`journal`]); when the
    /// session stops early it holds what was measured and `progress.json` says why.
    pub save_dir: Option<PathBuf>,
    /// Poses of an earlier run of this session ([`load_poses`]); their positions are not asked
    /// for again.
    pub resume: Vec<CapturedPose>,
    /// Magnetometer samples of that earlier run (`mag_samples.csv`, [`load_mag_samples`]):
    /// kept, saved again with the new ones and fitted with them.
    pub resume_mag: Vec<MagSample>,
    /// Moves between the holds of that earlier run (`moves.csv`, [`load_moves`]): kept, saved
    /// again with the new ones and fitted with them.
    pub resume_moves: Vec<Vec<UnitSample>>,
    /// Set (by a Ctrl-C handler) to stop the session at the next batch of samples.
    pub interrupt: Option<Arc<AtomicBool>>,
}

/// Run a whole guided session on a connected board (see the module documentation).
pub fn run_session<L: Read + Write>(
    client: &mut DeviceClient<L>,
    options: &SessionOptions,
    observer: &mut dyn SessionObserver,
) -> Result<SessionOutcome, SessionError> {
    run_session_with(client, options, observer, &SessionControl::default())
}

/// Run a whole guided session under `control`. A session that stops early (a lost board, a
/// lost reply, a timeout, `control.interrupt`) stops the stream, saves what was measured, and
/// returns [`SessionError::Stopped`], which says what the board holds: its earlier set when no
/// write started, otherwise the active CRC read back (or that it could not be read).
pub fn run_session_with<L: Read + Write>(
    client: &mut DeviceClient<L>,
    options: &SessionOptions,
    observer: &mut dyn SessionObserver,
    control: &SessionControl,
) -> Result<SessionOutcome, SessionError> {
    options.validate()?;
    let device_id = client.welcome().device_id.to_string();
    let mut journal = Journal::new(control.save_dir.as_deref(), device_id)?;
    journal.resume_with(&control.resume, &control.resume_mag, &control.resume_moves)?;
    let mut runner = Runner::new(
        client,
        options,
        observer,
        journal,
        control.interrupt.clone(),
    );
    runner.mag = control.resume_mag.clone();
    runner.moves = control.resume_moves.clone();
    match run_phases(&mut runner, &control.resume) {
        Ok(outcome) => Ok(outcome),
        Err(cause) => Err(runner.stop(cause)),
    }
}

/// Holds `fit`'s set to the bounds of every common part's datasheet
/// ([`crate::history::part_limits`]), the check every path that writes a set applies: a bound
/// that only warns (a magnet by the magnetometer) becomes a reason of the verdict, which is then
/// at best marginal; one that refuses becomes a reason too and, without `accept_outlier`, is
/// returned as why the set is not written.
fn hold_to_part_limits(
    fit: &mut SessionFit,
    device_id: &str,
    options: &SessionOptions,
) -> Option<String> {
    use crate::history::part_limits::{beyond_part_limits, refusal_phrase, warning_phrases};
    let record = crate::history::CalibrationRecord::from_fit(device_id, fit);
    let findings = beyond_part_limits(&record);
    for warning in warning_phrases(&findings) {
        fit.verdict.reasons.push(format!(
            "{warning}; move the board away from magnets and steel, or remove them, and \
             calibrate again"
        ));
        if fit.verdict.level == VerdictLevel::Good {
            fit.verdict.level = VerdictLevel::Marginal;
        }
    }
    let refusal = refusal_phrase(&findings)?;
    fit.verdict.reasons.push(if options.accept_outlier {
        format!("{refusal} (written anyway: --accept-outlier)")
    } else {
        format!("{refusal}; not written (--accept-outlier writes it anyway)")
    });
    if fit.verdict.level == VerdictLevel::Good {
        fit.verdict.level = VerdictLevel::Marginal;
    }
    (!options.accept_outlier).then(|| {
        format!(
            "{}: {refusal}",
            crate::history::part_limits::PART_LIMITS_REFUSAL
        )
    })
}

fn run_phases<L: Read + Write>(
    runner: &mut Runner<'_, L>,
    resumed: &[CapturedPose],
) -> Result<SessionOutcome, SessionError> {
    let options = runner.options;
    // A stream left running by an earlier program would mix into the replies' timing.
    runner.client.stop_stream()?;
    let board_start_s = runner.board_time_s()?;
    runner.continue_clock_after(resumed, board_start_s);
    let wall_start = Instant::now();

    let mut captured = Vec::new();
    let twelve = targets::twelve_positions();
    // A resumed session's poses go back to the rounds they were captured in.
    let indices: Vec<usize> = resumed.iter().map(|p| p.target.index).collect();
    let mut resumed_rounds = vec![Vec::new(); options.rounds.max(1)];
    for (pose, round) in resumed
        .iter()
        .zip(targets::round_of_each(&indices, options.rounds))
    {
        resumed_rounds[round].push(pose.clone());
    }
    for round in 1..=options.rounds {
        if options.rounds > 1 {
            runner.observer.event(&SessionEvent::Note(format!(
                "round {round} of {}: the twelve positions again",
                options.rounds
            )));
        }
        // Each round captures every position once more; poses of earlier rounds do not count.
        let mut this_round = std::mem::take(&mut resumed_rounds[round - 1]);
        runner.capture_targets(
            &twelve,
            &mut this_round,
            options.pose_timeout,
            false,
            &CaptureGoal::up_to(twelve.len()),
        )?;
        runner.client.stop_stream()?;
        captured.append(&mut this_round);
    }
    let extra_positions_note = runner.extra_positions(&mut captured)?;
    runner
        .observer
        .event(&SessionEvent::Note(extra_positions_note.clone()));
    let gyro_turns_note = runner.gyro_turns(&mut captured)?;
    runner.observer.event(&SessionEvent::Note(gyro_turns_note));

    runner.stage("magnetometer")?;
    let coverage = runner.magnetometer()?;
    runner.stage("rest")?;
    let raw_rest = runner.measure_at_rest()?;
    runner.stage("fitting")?;

    // Every moving sample shows a field direction: those of the moves between the positions and
    // of the tumble.
    let turning: Vec<Vec3> = runner
        .mag
        .iter()
        .filter(|m| m.phase != Phase::Rest)
        .map(|m| Vec3::from(m.mag))
        .collect();
    let fit_start = Instant::now();
    let mut fit = fit_session(
        &captured,
        &crate::pipeline::methods::thin_redundant(&turning, options.mag_max_fit_samples),
        options.gravity_mps2,
        options.field_ut,
        options.budgets,
        unix_now(),
    )?;
    fit.name_field_source(options.field_source);
    let no_samples = || SessionError::NoSamples {
        port: runner.client.port_name().to_string(),
        waited_s: options.read_timeout.as_secs_f64(),
    };
    let before = rest_errors(&raw_rest, fit.gravity_mps2, fit.field_ut).ok_or_else(no_samples)?;
    let gyro_scale = gyro_fit::complete_gyro(
        &mut fit,
        &runner.moves,
        &raw_rest,
        f64::from(options.thresholds.gyro_std_rads),
        options.gyro_budgets,
        options.budgets.mag_pct,
    )
    .ok();
    let fit_wall_seconds = fit_start.elapsed().as_secs_f64();
    runner.journal.fitted(&fit.set)?;
    let device_id = runner.client.welcome().device_id.to_string();
    let past_part_limits = hold_to_part_limits(&mut fit, &device_id, options);
    runner.observer.event(&SessionEvent::Fitted(&fit));

    let mut outcome = SessionOutcome {
        port: runner.client.port_name().to_string(),
        device_id: runner.client.welcome().device_id.to_string(),
        poses: captured,
        extra_positions_note,
        mag_samples: Vec::new(),
        moves: runner.moves.clone(),
        coverage,
        mag_min_per_region: options.mag_min_per_region,
        written: false,
        not_written_because: None,
        verified: false,
        param_status: None,
        before,
        after: None,
        session_seconds: 0.0,
        wall_seconds: 0.0,
        fit_wall_seconds,
        stream_rate_hz: 0.0,
        lost_samples: 0,
        sample_loss_rate: 0.0,
        link_note: None,
        fit,
        gyro_scale,
    };
    // An interrupt during the fit stops the session before the write is offered or started.
    runner.check_interrupt()?;
    let confirmed = runner.observer.confirm_write(&outcome.fit);
    if let (true, Some(why)) = (confirmed, &past_part_limits) {
        outcome.not_written_because = Some(why.clone());
    }
    if confirmed && past_part_limits.is_none() {
        runner.check_interrupt()?;
        runner.write_started = Some(outcome.fit.set.crc32());
        runner
            .journal
            .stage("writing", &runner.mag, &runner.moves)?;
        let status = runner.client.write_params_verified(&outcome.fit.set)?;
        runner.stage("after")?;
        outcome.written = true;
        outcome.verified = true;
        outcome.param_status = Some(status);
        runner.observer.event(&SessionEvent::Verified(status));
        let board_end_s = runner.board_time_s()?;
        outcome.wall_seconds = wall_start.elapsed().as_secs_f64();
        // A board that restarted in between has a younger clock; fall back to wall time.
        outcome.session_seconds = if board_end_s >= board_start_s {
            board_end_s - board_start_s
        } else {
            outcome.wall_seconds
        };
        let calibrated = runner.measure(StreamKind::Calibrated)?;
        let after = rest_errors(&calibrated, outcome.fit.gravity_mps2, outcome.fit.field_ut)
            .ok_or_else(|| SessionError::NoSamples {
                port: outcome.port.clone(),
                waited_s: options.read_timeout.as_secs_f64(),
            })?;
        outcome.stream_rate_hz = if after.duration_s > 0.0 {
            (after.samples.saturating_sub(1)) as f64 / after.duration_s
        } else {
            0.0
        };
        outcome.after = Some(after);
    } else {
        outcome.wall_seconds = wall_start.elapsed().as_secs_f64();
        outcome.session_seconds = runner.board_time_s()? - board_start_s;
    }
    let stats = runner.client.stats();
    outcome.lost_samples = stats.lost_samples;
    outcome.sample_loss_rate = stats.sample_loss_rate();
    outcome.link_note = stats.noisy_link_note();
    outcome.mag_samples = std::mem::take(&mut runner.mag);
    Ok(outcome)
}
