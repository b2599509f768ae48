//! The state a running session carries between its phases: the device, the options, the user
//! interface, the stillness monitor, and what the stream delivered (magnetometer samples for the
//! sphere fit, and the raw stream of each move between two holds for the gyroscope's scale).

use std::io::{Read, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{SystemTime, UNIX_EPOCH};

use imucal_protocol::StreamKind;

use super::error::SessionError;
use super::events::{MagSample, Phase, SessionEvent, SessionObserver};
use super::journal::Journal;
use super::motion::MotionMonitor;
use super::options::SessionOptions;
use super::solve::CapturedPose;
use super::targets::Target;
use crate::device::{DeviceClient, SampleChunk, UnitSample};

/// A session in progress.
pub(super) struct Runner<'a, L: Read + Write> {
    pub(super) client: &'a mut DeviceClient<L>,
    pub(super) options: &'a SessionOptions,
    pub(super) observer: &'a mut dyn SessionObserver,
    pub(super) monitor: MotionMonitor,
    pub(super) mag: Vec<MagSample>,
    /// The raw stream since watching for a position last started (the move in progress).
    pub(super) current_move: Vec<UnitSample>,
    /// Whether samples of the move in progress were lost on the way (a gap in the stream
    /// index): its integration would miss their rotation, so it is not kept.
    pub(super) current_move_lost: bool,
    /// Finished moves, each from the end of one hold to the start of the next capture.
    pub(super) moves: Vec<Vec<UnitSample>>,
    /// The axis the moves were last said to lack rotation about.
    pub(super) lacking_axis: Option<usize>,
    /// The session directory, written as the session goes.
    pub(super) journal: Journal,
    /// Set (by a Ctrl-C handler) to stop the session at the next batch of samples.
    pub(super) interrupt: Option<Arc<AtomicBool>>,
    /// The CRC of the set once its write started: from then on the board may hold it.
    pub(super) write_started: Option<u32>,
    /// Added to every streamed sample's board time: non-zero when a resumed session's board
    /// restarted its clock, so that the session's times keep increasing
    /// ([`Runner::continue_clock_after`]).
    pub(super) time_offset_s: f64,
}

/// Nominal gap between a resumed session's saved data and its new samples when the board's
/// clock restarted in between, s.
pub(super) const RESUME_GAP_S: f64 = 1.0;

/// Seconds since the Unix epoch (0 if the clock is before it).
pub(super) fn unix_now() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs())
}

/// The targets' names, comma separated.
pub(super) fn names(targets: &[&Target]) -> String {
    targets
        .iter()
        .map(|t| t.name.as_str())
        .collect::<Vec<_>>()
        .join(", ")
}

impl<'a, L: Read + Write> Runner<'a, L> {
    pub(super) fn new(
        client: &'a mut DeviceClient<L>,
        options: &'a SessionOptions,
        observer: &'a mut dyn SessionObserver,
        journal: Journal,
        interrupt: Option<Arc<AtomicBool>>,
    ) -> Self {
        Self {
            journal,
            interrupt,
            write_started: None,
            time_offset_s: 0.0,
            monitor: MotionMonitor::new(options.window_s, options.thresholds),
            client,
            options,
            observer,
            mag: Vec::new(),
            current_move: Vec::new(),
            current_move_lost: false,
            moves: Vec::new(),
            lacking_axis: None,
        }
    }

    /// Stop if the session was interrupted.
    pub(super) fn check_interrupt(&self) -> Result<(), SessionError> {
        if self
            .interrupt
            .as_ref()
            .is_some_and(|flag| flag.load(Ordering::SeqCst))
        {
            return Err(SessionError::Interrupted);
        }
        Ok(())
    }

    /// Begin `stage` (saving the samples so far). An interrupt that came while no samples were
    /// read (during a fit, a capture, a write) stops the session here, before the stage starts.
    pub(super) fn stage(&mut self, stage: &str) -> Result<(), SessionError> {
        self.check_interrupt()?;
        self.journal.stage(stage, &self.mag, &self.moves)
    }

    pub(super) fn read_chunk(&mut self) -> Result<SampleChunk, SessionError> {
        self.check_interrupt()?;
        match self.client.next_samples(self.options.read_timeout)? {
            Some(mut chunk) => {
                if self.time_offset_s != 0.0 {
                    for sample in &mut chunk.samples {
                        sample.t_s += self.time_offset_s;
                    }
                }
                Ok(chunk)
            }
            None => Err(SessionError::NoSamples {
                port: self.client.port_name().to_string(),
                waited_s: self.options.read_timeout.as_secs_f64(),
            }),
        }
    }

    /// A resumed session whose board now reads `board_now_s`: when that is not past the saved
    /// data's last time (the board restarted), this run's samples are shifted to start
    /// [`RESUME_GAP_S`] after it, and a note says so. The time between the runs is unknown to
    /// the board, so the gap is nominal.
    pub(super) fn continue_clock_after(&mut self, resumed: &[CapturedPose], board_now_s: f64) {
        let last = resumed
            .iter()
            .map(|p| p.t_s)
            .chain(self.mag.iter().map(|m| m.t_s))
            .chain(self.moves.iter().flatten().map(|s| s.t_s))
            .filter(|t| t.is_finite())
            .fold(f64::NEG_INFINITY, f64::max);
        if last.is_finite() && board_now_s <= last {
            self.time_offset_s = last + RESUME_GAP_S - board_now_s;
            self.observer.event(&SessionEvent::Note(format!(
                "the board's clock reads {board_now_s:.1} s, before the saved run's last time \
                 ({last:.1} s): it restarted, so this run's times continue from {:.1} s (the \
                 time between the runs is not known)",
                last + RESUME_GAP_S
            )));
        }
    }

    pub(super) fn record_mag(&mut self, sample: &UnitSample, phase: Phase) {
        self.mag.push(MagSample {
            t_s: sample.t_s,
            mag: sample.mag,
            temp_c: sample.temp_c,
            phase,
        });
    }

    /// Start the raw stream and a fresh stillness window (and a fresh move recording).
    pub(super) fn start_watching(&mut self) -> Result<(), SessionError> {
        self.monitor.reset();
        self.current_move.clear();
        self.current_move_lost = false;
        self.client
            .start_stream(StreamKind::Raw, self.options.decimation)?;
        Ok(())
    }

    /// Keep the move in progress as finished (the stream stops for a capture), unless samples
    /// of it were lost on the way.
    pub(super) fn finish_move(&mut self) {
        let samples = std::mem::take(&mut self.current_move);
        let lost = std::mem::take(&mut self.current_move_lost);
        if samples.len() >= 2 && !lost {
            self.moves.push(samples);
        }
    }

    pub(super) fn board_time_s(&mut self) -> Result<f64, SessionError> {
        Ok(self.client.status()?.uptime_ms as f64 * 1e-3)
    }

    /// End a session stopped by `cause`: stop the stream (the board may be gone), say what the
    /// board holds, save what was measured.
    pub(super) fn stop(&mut self, cause: SessionError) -> SessionError {
        let _ = self.client.stop_stream();
        let board_holds = self.board_holds();
        let saved = self
            .journal
            .stopped(&cause.to_string(), &board_holds, &self.mag, &self.moves);
        SessionError::Stopped {
            cause: Box::new(cause),
            board_holds,
            saved,
        }
    }

    /// What the board holds, read back from it once a write has started.
    fn board_holds(&mut self) -> String {
        let Some(written) = self.write_started else {
            return "its earlier calibration: nothing was written".to_string();
        };
        match self.client.status() {
            Ok(status) if status.active_crc == written => {
                format!("the new set (active CRC {written:#010x}, read back from the board)")
            }
            Ok(status) => format!(
                "its earlier set, not the new one (active CRC {:#010x} read back; the new set's \
                 is {written:#010x})",
                status.active_crc
            ),
            Err(error) => format!(
                "a set that could not be read back ({error}); the new set's CRC is \
                 {written:#010x}: compare it with `imucal info --port {}` once the board answers",
                self.client.port_name()
            ),
        }
    }
}
