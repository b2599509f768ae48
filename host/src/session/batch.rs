//! The batch session of a production line: several boards mounted together on one fixture,
//! guided through the positions together, each captured on its own thread, then fitted, tested
//! against the fleet ([`super::batch_gate`]), written, verified, saved and recorded on its own.
//! A board that fails (disconnects, poor verdict, refused as an outlier) does not stop the
//! others; every attempt that reached a fit is recorded in the history, refused ones marked as
//! not written, with the reason.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Instant;

use imucal_protocol::Welcome;
use serde::Serialize;

use super::batch_gate::{GateOptions, OutlierCheck, WriteGate};
use super::{
    run_session_with, save_session, summary, SessionControl, SessionEvent, SessionFit,
    SessionObserver, SessionOptions, SessionSummary, VerdictLevel,
};
use crate::device::{DeviceClient, ParamsFile};
use crate::history::part_limits::beyond_part_limits;
use crate::history::{record_calibration, CalibrationRecord, RecordId};

/// Settings of a batch.
#[derive(Debug, Clone)]
pub struct BatchOptions {
    /// The session's settings, the same for every board.
    pub session: SessionOptions,
    /// Write a board's parameters even when it is an outlier.
    pub accept_outlier: bool,
    /// Write a board's parameters even when its verdict is poor.
    pub accept_poor: bool,
    /// The outlier test before writing, and the history database.
    pub gate: GateOptions,
    /// Each board's session directory is `out_dir/<device id>`.
    pub out_dir: PathBuf,
    /// Record every attempt in the history (`gate.db`).
    pub record_history: bool,
    /// Who calibrated, kept in the history.
    pub operator: Option<String>,
    /// Which station, kept in the history.
    pub station: Option<String>,
    /// Set (by a Ctrl-C handler) to stop every board's session at its next batch of samples;
    /// each saves what was measured, as a single session does.
    pub interrupt: Option<Arc<AtomicBool>>,
}

/// How one board's attempt ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum BoardStatus {
    /// Written, read back and matching.
    Verified,
    /// Not written: an outlier against its fleet or batch.
    RefusedOutlier,
    /// Not written: the fit's verdict is poor.
    RefusedPoorVerdict,
    /// The session failed before a fit (the error says why).
    Failed,
}

/// One board's result.
#[derive(Debug, Clone, Serialize)]
pub struct BoardResult {
    /// The port.
    pub port: String,
    /// The board's id, once connected.
    pub device_id: Option<String>,
    /// How the attempt ended.
    pub status: BoardStatus,
    /// Whether the board is an outlier (also when `--accept-outlier` wrote it).
    pub outlier: bool,
    /// The outlier test before writing.
    pub outlier_check: Option<OutlierCheck>,
    /// Why the session failed.
    pub error: Option<String>,
    /// The session directory.
    pub session_dir: Option<PathBuf>,
    /// The history record of this attempt.
    pub recorded_as: Option<RecordId>,
    /// Why the attempt could not be recorded.
    pub history_error: Option<String>,
    /// Wall time of the history write (open the store, insert, commit), s.
    pub history_write_seconds: Option<f64>,
    /// The session's summary (fit, verdict, errors at rest).
    pub summary: Option<SessionSummary>,
    /// Wall time of this board's session, s (also of a failed one; `None` when its thread
    /// stopped unexpectedly).
    pub wall_seconds: Option<f64>,
    /// CPU time of this board's host thread, s (None where the platform cannot tell).
    pub host_cpu_seconds: Option<f64>,
}

/// What a whole batch produced.
#[derive(Debug, Clone, Serialize)]
pub struct BatchReport {
    /// Every board, in the order of the ports.
    pub boards: Vec<BoardResult>,
    /// Boards written and verified.
    pub verified: usize,
    /// Wall time of the batch, s.
    pub wall_seconds: f64,
}

/// CPU time of the calling thread, s.
fn thread_cpu_seconds() -> Option<f64> {
    #[cfg(unix)]
    {
        use nix::time::{clock_gettime, ClockId};
        clock_gettime(ClockId::CLOCK_THREAD_CPUTIME_ID)
            .ok()
            .map(|t| t.tv_sec() as f64 + t.tv_nsec() as f64 * 1e-9)
    }
    #[cfg(not(unix))]
    {
        None
    }
}

/// Progress lines of one board, passed to the caller's `log(port, line)`.
struct BoardObserver<'a> {
    port: &'a str,
    index: usize,
    device_id: String,
    gate: &'a WriteGate,
    options: &'a BatchOptions,
    log: &'a (dyn Fn(&str, &str) + Sync),
    show: &'a (dyn Fn(&str, &SessionEvent<'_>) + Sync),
    /// The test's result and the decision, once the fit reached the gate.
    decision: Option<(OutlierCheck, BoardStatus)>,
}

impl SessionObserver for BoardObserver<'_> {
    fn event(&mut self, event: &SessionEvent<'_>) {
        (self.show)(self.port, event);
        let line = match event {
            SessionEvent::Captured {
                target,
                captured,
                total,
                ..
            } => format!("captured {} ({captured}/{total})", target.name),
            SessionEvent::CaptureFailed { target, reason } => {
                format!("capture of {} failed: {reason}", target.name)
            }
            SessionEvent::Note(note) => note.clone(),
            SessionEvent::MagPrompt => "magnetometer: turning".into(),
            SessionEvent::RestPrompt => "at rest".into(),
            SessionEvent::Fitted(fit) => format!("fitted, verdict {}", fit.verdict.level.name()),
            SessionEvent::Verified(status) => format!(
                "written and verified: CRC {:#010x}, store sequence {}",
                status.active_crc, status.active_seq
            ),
            _ => return,
        };
        (self.log)(self.port, &line);
    }

    fn confirm_write(&mut self, fit: &SessionFit) -> bool {
        let record = CalibrationRecord::from_fit(&self.device_id, fit);
        // The bounds every path that writes a set applies, whatever the comparison was with.
        let past_part_limits =
            crate::history::part_limits::refusal_phrase(&beyond_part_limits(&record)).is_some();
        let check = self.gate.arrive(self.index, record);
        let status = if (check.check.outlier || past_part_limits) && !self.options.accept_outlier {
            BoardStatus::RefusedOutlier
        } else if fit.verdict.level == VerdictLevel::Poor && !self.options.accept_poor {
            BoardStatus::RefusedPoorVerdict
        } else {
            BoardStatus::Verified
        };
        if check.check.outlier {
            let causes: Vec<&str> = check
                .check
                .findings
                .iter()
                .map(|f| f.likely_cause.as_str())
                .collect();
            (self.log)(
                self.port,
                &format!("OUTLIER ({:?}): {}", check.basis, causes.join("; ")),
            );
        }
        self.decision = Some((check, status));
        status == BoardStatus::Verified
    }
}

/// Calibrate the boards on `ports` together (see the module documentation); `log(port, line)`
/// receives each board's progress, `show(port, event)` every event of its session (what its
/// screen would show).
pub fn run_batch(
    ports: &[String],
    options: &BatchOptions,
    log: &(dyn Fn(&str, &str) + Sync),
    show: &(dyn Fn(&str, &SessionEvent<'_>) + Sync),
) -> BatchReport {
    let start = Instant::now();
    let gate = Arc::new(WriteGate::new(ports.len(), options.gate.clone()));
    let boards: Vec<BoardResult> = std::thread::scope(|scope| {
        let handles: Vec<_> = ports
            .iter()
            .enumerate()
            .map(|(index, port)| {
                let gate = Arc::clone(&gate);
                scope.spawn(move || {
                    let result = run_board(index, port, &gate, options, log, show);
                    // Boards that never reached the gate must not hold the others.
                    gate.depart(index);
                    result
                })
            })
            .collect();
        handles
            .into_iter()
            .zip(ports)
            .map(|(handle, port)| {
                handle.join().unwrap_or_else(|_| {
                    failed(port, None, "the board's thread stopped unexpectedly".into())
                })
            })
            .collect()
    });
    BatchReport {
        verified: boards
            .iter()
            .filter(|b| b.status == BoardStatus::Verified)
            .count(),
        boards,
        wall_seconds: start.elapsed().as_secs_f64(),
    }
}

fn failed(port: &str, device_id: Option<String>, error: String) -> BoardResult {
    BoardResult {
        port: port.to_string(),
        device_id,
        status: BoardStatus::Failed,
        outlier: false,
        outlier_check: None,
        error: Some(error),
        session_dir: None,
        recorded_as: None,
        history_error: None,
        history_write_seconds: None,
        summary: None,
        wall_seconds: None,
        host_cpu_seconds: None,
    }
}

/// [`board_session`] with its wall and CPU time, failed or not.
fn run_board(
    index: usize,
    port: &str,
    gate: &WriteGate,
    options: &BatchOptions,
    log: &(dyn Fn(&str, &str) + Sync),
    show: &(dyn Fn(&str, &SessionEvent<'_>) + Sync),
) -> BoardResult {
    let start = Instant::now();
    let cpu_start = thread_cpu_seconds();
    let mut result = board_session(index, port, gate, options, log, show);
    result.wall_seconds = Some(start.elapsed().as_secs_f64());
    result.host_cpu_seconds = thread_cpu_seconds()
        .zip(cpu_start)
        .map(|(end, begin)| end - begin);
    result
}

fn board_session(
    index: usize,
    port: &str,
    gate: &WriteGate,
    options: &BatchOptions,
    log: &(dyn Fn(&str, &str) + Sync),
    show: &(dyn Fn(&str, &SessionEvent<'_>) + Sync),
) -> BoardResult {
    let mut client = match DeviceClient::open(port) {
        Ok(client) => client,
        Err(e) => return failed(port, None, e.to_string()),
    };
    let device_id = client.welcome().device_id.to_string();
    log(port, &format!("connected: device {device_id}"));
    let mut observer = BoardObserver {
        port,
        index,
        device_id: device_id.clone(),
        gate,
        options,
        log,
        show,
        decision: None,
    };
    let dir = options.out_dir.join(&device_id);
    // Saved as it goes, so a board lost mid-session keeps what was measured.
    let control = SessionControl {
        save_dir: Some(dir.clone()),
        interrupt: options.interrupt.clone(),
        ..SessionControl::default()
    };
    let outcome = match run_session_with(&mut client, &options.session, &mut observer, &control) {
        Ok(outcome) => outcome,
        Err(e) => {
            gate.depart(index);
            log(port, &format!("failed: {e}"));
            return failed(port, Some(device_id), e.to_string());
        }
    };
    let (check, status) = match observer.decision {
        Some(decision) => decision,
        None => {
            return failed(
                port,
                Some(device_id),
                "the session ended without a fit".into(),
            )
        }
    };
    let mut outcome = outcome;
    // The session's own reason (past the part limits) is the more precise one.
    if outcome.not_written_because.is_none() || status != BoardStatus::RefusedOutlier {
        outcome.not_written_because = refusal_reason(status, &check);
    }
    let saved = save_session(&outcome, &dir)
        .map_err(|e| e.to_string())
        .and_then(|_| bind_saved_params(&dir.join("params.json"), client.welcome()));
    let summary = summary(&outcome);
    let mut result = BoardResult {
        port: port.to_string(),
        device_id: Some(device_id),
        status,
        outlier: check.check.outlier,
        outlier_check: Some(check),
        error: saved.as_ref().err().cloned(),
        session_dir: saved.is_ok().then_some(dir),
        recorded_as: None,
        history_error: None,
        history_write_seconds: None,
        summary: Some(summary),
        wall_seconds: None,
        host_cpu_seconds: None,
    };
    if options.record_history {
        record_attempt(&mut result, &outcome.poses, options, &client);
    }
    result
}

/// Why a board's set was not written, in words, for its summary and its history record;
/// `None` for a written set.
fn refusal_reason(status: BoardStatus, check: &OutlierCheck) -> Option<String> {
    match status {
        BoardStatus::RefusedOutlier => Some(
            match check.basis {
                super::batch_gate::OutlierBasis::Batch => {
                    "outlier against the other boards of the batch"
                }
                super::batch_gate::OutlierBasis::PartLimits => {
                    "beyond the bounds of every common part's datasheet"
                }
                _ => "outlier against the fleet",
            }
            .to_string(),
        ),
        BoardStatus::RefusedPoorVerdict => Some("poor verdict".into()),
        _ => None,
    }
}

/// Binds the saved parameter file to the board it was measured on, so that `flash` can tell it
/// from another board's.
fn bind_saved_params(path: &std::path::Path, welcome: &Welcome) -> Result<(), String> {
    let file = ParamsFile::load(path)
        .map_err(|e| e.to_string())?
        .bound_to(welcome);
    std::fs::write(path, file.to_json())
        .map_err(|e| format!("could not write {}: {e}", path.display()))
}

/// Record the attempt (refused ones marked as not written, with the reason).
fn record_attempt<L>(
    result: &mut BoardResult,
    poses: &[super::CapturedPose],
    options: &BatchOptions,
    client: &DeviceClient<L>,
) where
    L: std::io::Read + std::io::Write,
{
    let Some(summary) = &result.summary else {
        return;
    };
    let mut record = CalibrationRecord::from_session(summary, poses);
    let version = client.welcome().firmware_version;
    record.firmware_version = Some(format!(
        "{}.{}.{}",
        version.major, version.minor, version.patch
    ));
    record.operator.clone_from(&options.operator);
    record.station.clone_from(&options.station);
    let start = Instant::now();
    let written = record_calibration(options.gate.db.as_deref(), &record);
    result.history_write_seconds = Some(start.elapsed().as_secs_f64());
    match written {
        Ok((id, _)) => result.recorded_as = Some(id),
        Err(e) => result.history_error = Some(e.to_string()),
    }
}
