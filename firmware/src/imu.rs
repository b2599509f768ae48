//! The sensor seen by the firmware core: anything that yields raw counts and their scales.

pub use imucal_protocol::{RawSample, SensorScales};

/// A 9-axis IMU with a die thermometer.
///
/// Implemented by chip drivers (e.g. [`crate::lsm9ds1`]) and by test doubles. The core never
/// touches a bus itself.
pub trait Imu {
    /// Bus or chip error.
    type Error: core::fmt::Debug;

    /// Scale factors and ranges of the current configuration.
    fn scales(&self) -> SensorScales;

    /// Read the latest sample of every sensor, in counts.
    fn read(&mut self) -> Result<RawSample, Self::Error>;
}
