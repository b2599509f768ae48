//! imucal host library: fitting calibration models to IMU data, reading recordings,
//! talking to a board, guided calibration, residual analysis and reports.
#![forbid(unsafe_code)]

pub mod analysis;
pub mod compat;
pub mod device;
pub mod export;
pub mod fit;
pub mod geomag;
pub mod history;
pub mod input_checks;
pub mod pipeline;
pub mod recording;
pub mod report;
pub mod session;
pub mod still;
pub mod synthetic;
