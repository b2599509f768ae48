//! Simulated imucal board: the world the board moves in, the true sensor physics with effects the
//! host is not told about, the schedules a person would follow, and recordings with their truth.
//!
//! `x = A⁻¹·y + b` per sensor (so the correct calibration is `y = A·(x − b)`, as the host fits
//! it); see [`physics`] for the full reading model and [`effects`] for the hidden effects.
#![forbid(unsafe_code)]

pub mod bmi270_chip;
pub mod board;
pub mod effects;
pub mod error;
pub mod faults;
pub mod feed;
pub mod link_faults;
pub mod lsm9ds1_chip;
pub mod motioncal_board;
pub mod motioncal_serve;
pub mod out_of_family;
pub mod physics;
pub mod poser;
pub mod recording;
pub mod sensor_kind;
pub mod serve;
pub mod world;

pub use error::SimError;
pub use recording::{simulate_recording, write_csv, Recording, SimConfig, Truth};
