//! Errors of the simulator: every message names the bad input and how to fix it.

use thiserror::Error;

/// Why a simulation could not be set up or written.
#[derive(Debug, Error)]
pub enum SimError {
    /// A numeric setting is NaN, infinite or outside its allowed range.
    #[error("{name} is {value}, but it must be {requirement}; change that setting")]
    InvalidSetting {
        /// Name of the setting as the user knows it.
        name: &'static str,
        /// The rejected value.
        value: f64,
        /// The allowed range in words.
        requirement: &'static str,
    },
    /// An `--effect` argument could not be understood.
    #[error("effect `{text}` is not understood: {reason}")]
    InvalidEffect {
        /// The argument as given.
        text: String,
        /// What is wrong and what is accepted instead.
        reason: String,
    },
    /// A schedule name is not one of the known schedules.
    #[error("schedule `{0}` is unknown; use one of twelve, tumble, sweep")]
    UnknownSchedule(String),
    /// A trajectory has no segments to evaluate.
    #[error("the trajectory is empty; add at least one hold or turn before sampling it")]
    EmptyTrajectory,
    /// The output file could not be written.
    #[error("could not write {path}: {source}; check that the directory exists and is writable")]
    Write {
        /// File that failed.
        path: String,
        /// Underlying I/O error.
        source: std::io::Error,
    },
    /// The truth could not be encoded as JSON.
    #[error("could not encode the truth as JSON: {0}")]
    Json(#[from] serde_json::Error),
}

/// Check that `value` is finite and strictly positive.
pub(crate) fn require_positive(name: &'static str, value: f64) -> Result<f64, SimError> {
    if value.is_finite() && value > 0.0 {
        Ok(value)
    } else {
        Err(SimError::InvalidSetting {
            name,
            value,
            requirement: "a finite number greater than zero",
        })
    }
}

/// Check that `value` is finite and not negative.
pub(crate) fn require_non_negative(name: &'static str, value: f64) -> Result<f64, SimError> {
    if value.is_finite() && value >= 0.0 {
        Ok(value)
    } else {
        Err(SimError::InvalidSetting {
            name,
            value,
            requirement: "a finite number of zero or more",
        })
    }
}

/// Check that `value` is finite.
pub(crate) fn require_finite(name: &'static str, value: f64) -> Result<f64, SimError> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(SimError::InvalidSetting {
            name,
            value,
            requirement: "a finite number",
        })
    }
}
