//! imucal host library: fitting calibration models to IMU data, reading recordings,
//! talking to a board, guided calibration, residual analysis and reports.
#![forbid(unsafe_code)]

pub mod analysis;
pub mod compat;
/// Coverage of reported uncertainties over simulated recordings (needs `synthetic`).
#[cfg(feature = "synthetic")]
pub mod coverage;
pub mod device;
pub mod export;
pub mod fit;
pub mod geomag;
pub mod history;
pub mod input_checks;
/// The residual analysis on simulated recordings with hidden effects (needs `synthetic`, `sim`).
#[cfg(all(feature = "synthetic", feature = "sim"))]
pub mod open_world;
pub mod pipeline;
pub mod recording;
pub mod report;
pub mod session;
pub mod stats;
pub mod still;
#[cfg(feature = "synthetic")]
pub mod synthetic;
pub mod words;
