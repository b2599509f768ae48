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

/// How to turn a [`RawSample`] into nominal units, and the chip's limits.
///
/// Nominal units: accelerometer m/s², gyroscope rad/s, magnetometer µT, temperature °C
/// (`temp_c = temp_offset_c + temp * temp_c_per_count`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SensorScales {
    /// Accelerometer sensitivity, m/s² per count.
    pub accel_mps2_per_count: f32,
    /// Gyroscope sensitivity, rad/s per count.
    pub gyro_rads_per_count: f32,
    /// Magnetometer sensitivity, µT per count.
    pub mag_ut_per_count: f32,
    /// Temperature sensitivity, °C per count.
    pub temp_c_per_count: f32,
    /// Temperature at zero counts, °C.
    pub temp_offset_c: f32,
    /// Accelerometer full scale (±), m/s².
    pub accel_range_mps2: f32,
    /// Gyroscope full scale (±), rad/s.
    pub gyro_range_rads: f32,
    /// Magnetometer full scale (±), µT.
    pub mag_range_ut: f32,
    /// Output data rate of the sample stream, Hz.
    pub sample_rate_hz: f32,
}
