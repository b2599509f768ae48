//! Which sensor chip the simulated board carries, and the real driver reading it: the LSM9DS1
//! (Nano 33 BLE Sense) or the BMI270 + BMM150 (Nano 33 BLE Sense Rev2), both emulated at
//! register level and shared between the board (which sets what they sense) and the driver.

use std::sync::{Arc, Mutex, MutexGuard, PoisonError};

use embedded_hal::delay::DelayNs;
use embedded_hal::i2c::{ErrorType, I2c, Operation};
use imucal_firmware::bmi270::{self, Bmi270Bmm150};
use imucal_firmware::imu::{Imu, RawSample, Reading, SensorScales};
use imucal_firmware::lsm9ds1::{self, Lsm9ds1};

use super::parts::SharedChip;
use crate::bmi270_chip::{Bmi270Chip, Bmi270ChipError, CONFIG_IMAGE_LEN};
use crate::lsm9ds1_chip::{Lsm9ds1Chip, Lsm9ds1ChipError, NonFinitePhysicalValue};

/// The sensor chip of a simulated board.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum SensorChip {
    /// ST LSM9DS1 (Arduino Nano 33 BLE Sense).
    #[default]
    Lsm9ds1,
    /// Bosch BMI270 + BMM150 (Arduino Nano 33 BLE Sense Rev2).
    Bmi270,
}

/// The configuration image the emulated BMI270 accepts: a stand-in for Bosch's file (which is
/// not shipped), so the simulated driver performs the full upload and status check.
pub static SIM_BMI270_CONFIG: [u8; CONFIG_IMAGE_LEN] = stand_in_image();

const fn stand_in_image() -> [u8; CONFIG_IMAGE_LEN] {
    let mut image = [0u8; CONFIG_IMAGE_LEN];
    let mut i = 0;
    while i < CONFIG_IMAGE_LEN {
        image[i] = (i.wrapping_mul(31) ^ (i >> 8)) as u8;
        i += 1;
    }
    image
}

fn lock<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The emulated BMI270/BMM150, shared between the board and the driver.
#[derive(Debug, Clone)]
pub struct SharedBmi270(Arc<Mutex<Bmi270Chip>>);

impl ErrorType for SharedBmi270 {
    type Error = Bmi270ChipError;
}

impl I2c for SharedBmi270 {
    fn transaction(
        &mut self,
        address: u8,
        operations: &mut [Operation<'_>],
    ) -> Result<(), Self::Error> {
        lock(&self.0).transaction(address, operations)
    }
}

/// Simulated time stands still while the driver waits.
#[derive(Debug, Clone, Copy, Default)]
pub struct SimDelay;

impl DelayNs for SimDelay {
    fn delay_ns(&mut self, _ns: u32) {}
}

/// The emulated chip of a board.
#[derive(Debug, Clone)]
pub enum BoardChip {
    /// LSM9DS1.
    Lsm9ds1(SharedChip),
    /// BMI270 + BMM150.
    Bmi270(SharedBmi270),
}

impl BoardChip {
    /// A chip just after power-on; an LSM9DS1 converts on its own clock when `lsm_odr_error`
    /// is given ([`Lsm9ds1Chip::run_on_own_clock`]).
    pub fn new(kind: SensorChip, lsm_odr_error: Option<f64>) -> Self {
        match kind {
            SensorChip::Lsm9ds1 => Self::Lsm9ds1(SharedChip::new(lsm9ds1_chip(lsm_odr_error))),
            SensorChip::Bmi270 => Self::Bmi270(SharedBmi270(Arc::new(Mutex::new(
                Bmi270Chip::new(&SIM_BMI270_CONFIG),
            )))),
        }
    }

    /// Powers the chip off and on (registers back to their defaults).
    pub fn power_cycle(&self) {
        match self {
            Self::Lsm9ds1(chip) => chip.with(|c| *c = lsm9ds1_chip(c.odr_error())),
            Self::Bmi270(chip) => *lock(&chip.0) = Bmi270Chip::new(&SIM_BMI270_CONFIG),
        }
    }

    /// Sets what the chip senses (m/s², rad/s, µT, °C).
    pub fn set_physical(
        &self,
        accel: [f64; 3],
        gyro: [f64; 3],
        mag: [f64; 3],
        temp_c: f64,
    ) -> Result<(), NonFinitePhysicalValue> {
        match self {
            Self::Lsm9ds1(chip) => chip.with(|c| c.set_physical(accel, gyro, mag, temp_c)),
            Self::Bmi270(chip) => lock(&chip.0).set_physical(accel, gyro, mag, temp_c),
        }
    }

    /// Moves the chip's own clock to `t_s` (only an LSM9DS1 on its own clock has one).
    pub fn set_time(&self, t_s: f64) {
        if let Self::Lsm9ds1(chip) = self {
            chip.with(|c| c.advance_time(t_s));
        }
    }

    /// The real driver for this chip, initialised (`lsm` configures an LSM9DS1).
    pub fn driver(&self, lsm: lsm9ds1::Config) -> Result<BoardImu, BoardImuError> {
        match self {
            Self::Lsm9ds1(chip) => {
                let mut driver = Lsm9ds1::new(chip.clone(), lsm);
                driver.init().map_err(BoardImuError::Lsm9ds1)?;
                Ok(BoardImu::Lsm9ds1(driver))
            }
            Self::Bmi270(chip) => {
                let config = bmi270::Config {
                    config_file: &SIM_BMI270_CONFIG,
                    max_burst: bmi270::MAX_BURST,
                };
                let mut driver = Bmi270Bmm150::new(chip.clone(), SimDelay, config);
                driver.init().map_err(BoardImuError::Bmi270)?;
                Ok(BoardImu::Bmi270(driver))
            }
        }
    }
}

/// An LSM9DS1 just after power-on, on its own clock when `odr_error` is given.
fn lsm9ds1_chip(odr_error: Option<f64>) -> Lsm9ds1Chip {
    let mut chip = Lsm9ds1Chip::default();
    if let Some(error) = odr_error {
        chip.run_on_own_clock(error);
    }
    chip
}

/// A driver error of either chip.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum BoardImuError {
    /// From the LSM9DS1 driver.
    Lsm9ds1(lsm9ds1::Error<Lsm9ds1ChipError>),
    /// From the BMI270/BMM150 driver.
    Bmi270(bmi270::Error<Bmi270ChipError>),
}

impl std::fmt::Display for BoardImuError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Lsm9ds1(e) => write!(f, "LSM9DS1 driver: {e}"),
            Self::Bmi270(e) => write!(f, "BMI270/BMM150 driver: {e}"),
        }
    }
}

/// The firmware's IMU on the simulated board.
pub enum BoardImu {
    /// LSM9DS1 driver.
    Lsm9ds1(Lsm9ds1<SharedChip>),
    /// BMI270 + BMM150 driver.
    Bmi270(Bmi270Bmm150<SharedBmi270, SimDelay>),
}

impl Imu for BoardImu {
    type Error = BoardImuError;

    fn scales(&self) -> SensorScales {
        match self {
            Self::Lsm9ds1(d) => d.scales(),
            Self::Bmi270(d) => d.scales(),
        }
    }

    fn read(&mut self) -> Result<RawSample, Self::Error> {
        match self {
            Self::Lsm9ds1(d) => d.read().map_err(BoardImuError::Lsm9ds1),
            Self::Bmi270(d) => d.read().map_err(BoardImuError::Bmi270),
        }
    }

    fn read_with_status(&mut self) -> Result<Reading, Self::Error> {
        match self {
            Self::Lsm9ds1(d) => d.read_with_status().map_err(BoardImuError::Lsm9ds1),
            Self::Bmi270(d) => d.read_with_status().map_err(BoardImuError::Bmi270),
        }
    }
}
