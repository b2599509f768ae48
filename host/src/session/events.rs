//! What a running session tells its user interface ([`SessionEvent`] through a
//! [`SessionObserver`]), and the magnetometer samples it keeps with the phase they were taken in.

use imucal_protocol::{ParamStatus, StreamKind};
use serde::Serialize;

use super::mag_guidance::MagGuidance;
use super::motion::MotionState;
use super::solve::SessionFit;
use super::targets::Target;
use crate::device::PoseProgress;

/// Which part of the session a magnetometer sample was taken in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Phase {
    /// Moving between and holding the positions.
    Positions,
    /// Turning the board in all directions.
    Tumble,
    /// Waiting for the board to lie still.
    Rest,
}

impl Phase {
    /// Name as written to files.
    pub fn name(self) -> &'static str {
        match self {
            Phase::Positions => "positions",
            Phase::Tumble => "tumble",
            Phase::Rest => "rest",
        }
    }

    /// The phase written as `name` ([`Phase::name`]).
    pub fn from_name(name: &str) -> Option<Self> {
        [Phase::Positions, Phase::Tumble, Phase::Rest]
            .into_iter()
            .find(|p| p.name() == name)
    }
}

/// One raw magnetometer reading of the stream.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MagSample {
    /// Board time, s.
    pub t_s: f64,
    /// Reading, µT (nominal units).
    pub mag: [f64; 3],
    /// Die temperature, °C.
    pub temp_c: f64,
    /// When it was taken.
    pub phase: Phase,
}

/// What the session reports while it runs.
#[derive(Debug, Clone)]
pub enum SessionEvent<'a> {
    /// The next orientation to hold.
    Prompt {
        /// The orientation.
        target: &'a Target,
        /// Poses captured so far.
        captured: usize,
        /// Poses wanted in this phase.
        total: usize,
    },
    /// The latest stillness window while watching for a position.
    Motion {
        /// Stillness and up direction.
        state: MotionState,
        /// The position the board is in, if any.
        at: Option<&'a Target>,
        /// Whether that position is still needed.
        needed: bool,
        /// Stillness needed before the capture starts, s.
        settle_s: f64,
    },
    /// The board is averaging a pose.
    Capturing {
        /// The position.
        target: &'a Target,
        /// Progress reported by the device client.
        progress: PoseProgress,
        /// Still data this capture averages, s (the adaptive hold length).
        hold_s: f64,
    },
    /// A pose was captured.
    Captured {
        /// The position.
        target: &'a Target,
        /// Samples averaged.
        samples: u32,
        /// Poses captured so far.
        captured: usize,
        /// Poses wanted in this phase.
        total: usize,
    },
    /// A capture did not succeed; the session keeps watching.
    CaptureFailed {
        /// The position.
        target: &'a Target,
        /// What happened, as a sentence.
        reason: String,
    },
    /// A sentence worth showing (extra positions decided, phase accepted with less data, …).
    Note(String),
    /// The magnetometer phase begins.
    MagPrompt,
    /// Magnetometer coverage so far.
    MagCoverage {
        /// Regions with enough samples.
        covered: usize,
        /// All regions.
        regions: usize,
        /// Samples so far in this phase.
        samples: usize,
        /// Names of the regions still short of samples.
        empty: Vec<String>,
        /// How to turn the board towards the nearest of them, from the current attitude (`None`
        /// once all are full or before the attitude is known).
        guidance: Option<MagGuidance>,
    },
    /// The board should be put down.
    RestPrompt,
    /// Stillness while waiting for rest.
    Resting {
        /// Still time so far, s.
        still_for_s: f64,
        /// Still time needed, s.
        needed_s: f64,
    },
    /// A rest measurement is being taken.
    Measuring {
        /// Raw ("before") or calibrated ("after").
        kind: StreamKind,
    },
    /// The fit is done (shown before writing).
    Fitted(&'a SessionFit),
    /// The set is written, committed, read back and matches.
    Verified(ParamStatus),
}

/// The caller's user interface of a session.
pub trait SessionObserver {
    /// Something happened.
    fn event(&mut self, event: &SessionEvent<'_>);

    /// Whether to write `fit` to the board (default: yes, for unattended use).
    fn confirm_write(&mut self, fit: &SessionFit) -> bool {
        let _ = fit;
        true
    }
}

/// An observer that ignores every event and always writes.
#[derive(Debug, Clone, Copy, Default)]
pub struct Unattended;

impl SessionObserver for Unattended {
    fn event(&mut self, _event: &SessionEvent<'_>) {}
}

/// An observer that also hands every event to `tap`: e.g. what the screen shows, passed on to
/// a simulated person who reads it.
pub struct Tapped<'a, O: ?Sized, F> {
    /// The observer that handles the events and decides the write.
    pub observer: &'a mut O,
    /// Sees every event first.
    pub tap: F,
}

impl<O: SessionObserver + ?Sized, F: FnMut(&SessionEvent<'_>)> SessionObserver
    for Tapped<'_, O, F>
{
    fn event(&mut self, event: &SessionEvent<'_>) {
        (self.tap)(event);
        self.observer.event(event);
    }

    fn confirm_write(&mut self, fit: &SessionFit) -> bool {
        self.observer.confirm_write(fit)
    }
}
