//! imucal wire protocol (work in progress).
#![no_std]
#![forbid(unsafe_code)]

use serde::{Deserialize, Serialize};

/// One raw reading of the IMU in the chip's integer counts.
///
/// Scale factors to nominal units are announced by the device in its `Welcome`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct RawSample {
    /// Accelerometer, counts per axis.
    pub accel: [i16; 3],
    /// Gyroscope, counts per axis.
    pub gyro: [i16; 3],
    /// Magnetometer, counts per axis.
    pub mag: [i16; 3],
    /// Die temperature, counts.
    pub temp: i16,
}
