//! Why a guided session stopped. Every message names the port where it matters, says what
//! happened and what to try.

use crate::device::DeviceError;
use crate::fit::FitError;

/// What to try when no orientation was captured on a sound link.
const NO_PROGRESS_ADVICE: &str = "Hold the board still in one of them as pictured (within \
     20°), or allow more time with --pose-timeout";

/// Why a guided calibration session failed.
#[derive(Debug, thiserror::Error)]
pub enum SessionError {
    /// Talking to the board failed (the message names the port and what to try).
    #[error(transparent)]
    Device(#[from] DeviceError),
    /// The stream went quiet.
    #[error(
        "no samples arrived from {port} for {waited_s:.1} s while streaming; check the cable and \
         that the board is powered, then run the calibration again"
    )]
    NoSamples {
        /// The port.
        port: String,
        /// How long the session waited, s.
        waited_s: f64,
    },
    /// No new orientation was captured for too long.
    #[error(
        "no new orientation was captured on {port} for {waited_s:.0} s; still needed: {missing}. \
         {}", .link_note.as_ref().map_or_else(|| NO_PROGRESS_ADVICE.to_string(), |note| format!("Not the hold: {note}"))
    )]
    NoProgress {
        /// The port.
        port: String,
        /// How long the session waited, s.
        waited_s: f64,
        /// Names of the orientations still needed.
        missing: String,
        /// The link's loss when it is noisy enough to explain the stall
        /// ([`crate::device::LinkStats::noisy_link_note`]).
        link_note: Option<String>,
    },
    /// The magnetometer phase ended without enough directions.
    #[error(
        "the magnetometer phase timed out after {waited_s:.0} s with {covered} of {regions} \
         directions covered (at least {needed} are needed); still empty: {empty}. Turn the board \
         slowly through all directions, away from steel and cables, or allow more time with \
         --mag-timeout"
    )]
    MagCoverage {
        /// How long the phase ran, s.
        waited_s: f64,
        /// Regions with enough samples.
        covered: usize,
        /// Regions needed.
        needed: usize,
        /// All regions.
        regions: usize,
        /// Names of the empty regions.
        empty: String,
    },
    /// The board never came to rest for the final check.
    #[error(
        "the board on {port} did not lie still for {needed_s:.1} s within {waited_s:.0} s; put it \
         down on a steady surface and do not touch it, or allow more time with --rest-timeout"
    )]
    NotAtRest {
        /// The port.
        port: String,
        /// Stillness needed, s.
        needed_s: f64,
        /// How long the session waited, s.
        waited_s: f64,
    },
    /// The data could not be fitted.
    #[error("the calibration could not be fitted: {0}; run the session again")]
    Fit(#[from] FitError),
    /// A sensor's data could not be fitted.
    #[error("the calibration could not be fitted: {0}; run the session again")]
    SensorFit(#[from] super::solve::SensorFitError),
    /// An option is out of range.
    #[error("{name} is {value}, but it must be {requirement}; change that option")]
    InvalidOption {
        /// The option.
        name: &'static str,
        /// The rejected value.
        value: f64,
        /// The allowed range in words.
        requirement: &'static str,
    },
    /// A session file could not be read.
    #[error(
        "could not read the session file {path} ({reason}); pass the directory `imucal calibrate` \
         saved, with its poses.json intact"
    )]
    Load {
        /// The file.
        path: String,
        /// What went wrong.
        reason: String,
    },
    /// A session file could not be written.
    #[error(
        "could not write the session file {path} ({cause}); check that the directory is \
         writable and has space, or choose another with --out"
    )]
    Save {
        /// The file.
        path: String,
        /// The operating system's error.
        cause: std::io::Error,
    },
    /// The user stopped the session (Ctrl-C).
    #[error("the session was stopped by the user (Ctrl-C, or a termination signal)")]
    Interrupted,
    /// The session stopped early; says what the board holds and where the measurements are.
    #[error("{cause}\nThe board holds {board_holds}.\nSession: {saved}.")]
    Stopped {
        /// Why the session stopped.
        cause: Box<SessionError>,
        /// What the board holds now, in words (read back from the board when a write started).
        board_holds: String,
        /// Where what was measured is saved, or why it is not.
        saved: String,
    },
}
