//! imucal firmware core: sampling, stillness detection, pose capture, applying the calibration,
//! the parameter store and the protocol dispatch of an IMU board, independent of any chip or MCU.
#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]

pub mod apply;
pub mod bmi270;
pub mod bmm150;
pub mod device;
pub mod imu;
mod log;
pub mod lsm9ds1;
pub mod pose;
pub mod ram_flash;
pub mod sampling;
pub mod stillness;
pub mod store;
