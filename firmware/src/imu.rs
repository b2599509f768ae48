//! The sensor seen by the firmware core: anything that yields raw counts and their scales, and
//! whether each sensor's value is a new conversion (the chip's data-ready bits).

pub use imucal_protocol::{RawSample, SensorScales};

/// Which parts of a [`Reading`] are new conversions since the previous read.
///
/// A sensor whose clock runs slower than the read timer (or whose rate is below it, like the
/// LSM9DS1 magnetometer at 80 Hz under 119 Hz) hands back the value already read; averaging it
/// again would count one measurement twice.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NewData {
    /// The accelerometer and gyroscope hold a new conversion.
    pub accel_gyro: bool,
    /// The magnetometer holds a new conversion.
    pub mag: bool,
    /// At least one magnetometer conversion was overwritten before it was read.
    pub mag_overrun: bool,
}

impl NewData {
    /// Every sensor new, nothing lost: what a chip without data-ready flags is taken to give.
    pub const ALL: Self = Self {
        accel_gyro: true,
        mag: true,
        mag_overrun: false,
    };
}

/// One read of every sensor with its data-ready state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Reading {
    /// The sensors' output registers, in counts.
    pub sample: RawSample,
    /// Which of them are new conversions.
    pub new_data: NewData,
}

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

    /// Read the latest sample with the chip's data-ready state. The core samples through this.
    ///
    /// The default, for chips whose driver does not read data-ready, reports every sensor new.
    fn read_with_status(&mut self) -> Result<Reading, Self::Error> {
        self.read().map(|sample| Reading {
            sample,
            new_data: NewData::ALL,
        })
    }
}
