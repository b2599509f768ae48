//! The three vector sensors and the LSM9DS1's nominal scale of each.

use serde::{Deserialize, Serialize};

use crate::world::STANDARD_GRAVITY_MPS2;

/// Accelerometer sensitivity at ±4 g: 0.122 mg/LSB, in m/s² per count.
pub const ACCEL_MPS2_PER_COUNT: f64 = 0.122e-3 * STANDARD_GRAVITY_MPS2;
/// Gyroscope sensitivity at ±500 °/s: 17.5 m°/s per LSB, in rad/s per count.
pub const GYRO_RADS_PER_COUNT: f64 = 17.5e-3 * std::f64::consts::PI / 180.0;
/// Magnetometer sensitivity at ±4 gauss: 0.14 mgauss/LSB, in µT per count.
pub const MAG_UT_PER_COUNT: f64 = 0.014;

/// One of the three vector sensors.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SensorKind {
    /// Accelerometer (m/s²).
    Accel,
    /// Gyroscope (rad/s).
    Gyro,
    /// Magnetometer (µT).
    Mag,
}

impl SensorKind {
    /// All sensors in the fixed order accel, gyro, mag.
    pub const ALL: [SensorKind; 3] = [SensorKind::Accel, SensorKind::Gyro, SensorKind::Mag];

    /// Name as used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            SensorKind::Accel => "accel",
            SensorKind::Gyro => "gyro",
            SensorKind::Mag => "mag",
        }
    }

    /// Parse `accel`, `gyro` or `mag`.
    pub fn from_name(name: &str) -> Option<Self> {
        SensorKind::ALL.into_iter().find(|s| s.name() == name)
    }

    /// Position in [`SensorKind::ALL`].
    pub fn index(self) -> usize {
        match self {
            SensorKind::Accel => 0,
            SensorKind::Gyro => 1,
            SensorKind::Mag => 2,
        }
    }

    /// Nominal units per count of the LSM9DS1.
    pub fn units_per_count(self) -> f64 {
        match self {
            SensorKind::Accel => ACCEL_MPS2_PER_COUNT,
            SensorKind::Gyro => GYRO_RADS_PER_COUNT,
            SensorKind::Mag => MAG_UT_PER_COUNT,
        }
    }
}
