//! imucal host library: fitting calibration models to IMU data, reading recordings,
//! and (in later modules) talking to a board.
#![forbid(unsafe_code)]

pub mod fit;
