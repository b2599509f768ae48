//! The pipeline every command goes through, as a library:
//!
//! ```text
//! recording ─▶ input (units, sanity, still intervals, magnetometer samples)   input.rs
//!           ─▶ fit: accelerometer by the default chain (chain.rs) or a method (methods.rs),
//!                   gyroscope (gyro.rs), magnetometer, then mag → accel frame (align.rs)
//!           ─▶ each residual tested against the noise of the means it rests on
//!                   (pose or window observations)                         observations.rs
//!           ─▶ RecordingCalibration (units, references, provenance)        calibration.rs
//!           ─▶ parameter file (params_file.rs) ─▶ export / flash / report
//! ```
//!
//! Reference values (`--gravity`, `--field-ut`, `--gyro-scale`) are range-checked once
//! (`references.rs`). The command line maps its flags onto [`InputOptions`] and [`FitOptions`]
//! and prints what comes back.

pub mod align;
pub mod calibrate;
pub mod calibration;
pub mod chain;
pub mod gyro;
pub mod input;
pub mod methods;
pub mod observations;
pub mod params_file;
pub mod references;

pub use calibrate::{calibrate, check_and_calibrate, FitOptions};
pub use calibration::{RecordingCalibration, SensorOutcome};
pub use chain::{default_accel_chain, ChainChoice};
pub use input::{check_input, check_input_then, still_intervals, CheckedInput, InputOptions};
pub use params_file::{parameter_sigma, params_file};
pub use references::{ReferenceError, References};

/// Why the pipeline stopped before fitting.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PipelineError {
    /// A reference value is out of range.
    #[error(transparent)]
    Reference(#[from] ReferenceError),
    /// The field at the given location could not be modelled.
    #[error("the field at --location could not be modelled: {0}")]
    FieldModel(String),
}
