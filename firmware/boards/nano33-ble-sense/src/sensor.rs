//! The board's IMU on the internal I²C bus: the LSM9DS1 of the Nano 33 BLE Sense (rev 1, the
//! default build) or, with the `rev2` feature, the BMI270 + BMM150 of the Rev2. A sensor that
//! cannot be configured is logged and the firmware runs on, so the host sees sensor errors.

use imucal_firmware::imu::Imu;
use nrf52840_hal::pac::TWIM0;
use nrf52840_hal::twim::{self, Twim};

/// Attempts at configuring the sensor before running without it.
const SENSOR_INIT_ATTEMPTS: u32 = 3;

/// Name of a TWIM error for the log (the HAL type has no defmt support).
fn twim_error_name(error: &twim::Error) -> &'static str {
    match error {
        twim::Error::TxBufferTooLong => "transmit buffer too long",
        twim::Error::RxBufferTooLong => "receive buffer too long",
        twim::Error::TxBufferZeroLength => "empty transmit buffer",
        twim::Error::RxBufferZeroLength => "empty receive buffer",
        twim::Error::Transmit => "transmit incomplete",
        twim::Error::Receive => "receive incomplete",
        twim::Error::DMABufferNotInDataMemory => "buffer not in RAM",
        twim::Error::AddressNack => "address not acknowledged",
        twim::Error::DataNack => "data not acknowledged",
        twim::Error::Overrun => "receive overrun",
    }
}

/// Runs `init` up to [`SENSOR_INIT_ATTEMPTS`] times, waiting for the sensor's boot between tries;
/// logs the last failure with `log`.
fn configure_with_retries<E>(mut init: impl FnMut() -> Result<(), E>, log: impl Fn(&E)) {
    for attempt in 1..=SENSOR_INIT_ATTEMPTS {
        match init() {
            Ok(()) => {
                defmt::info!("{=str} configured", SENSOR_NAME);
                return;
            }
            Err(error) if attempt == SENSOR_INIT_ATTEMPTS => log(&error),
            Err(_) => {
                cortex_m::asm::delay(crate::SENSOR_POWER_UP_MS * (crate::CPU_HZ / 1000));
            }
        }
    }
    // The host link still comes up, so the host sees the failure as sensor errors.
    defmt::warn!(
        "running without the {=str}; every sample counts as a sensor error",
        SENSOR_NAME
    );
}

#[cfg(not(feature = "rev2"))]
mod chip {
    use super::*;
    use imucal_firmware::lsm9ds1::{self, Config, Lsm9ds1};

    /// The sensor's name in the log.
    pub const SENSOR_NAME: &str = "LSM9DS1";

    /// Logs why the LSM9DS1 could not be configured, as a sentence naming cause and fix.
    fn log_sensor_error(error: &lsm9ds1::Error<twim::Error>) {
        match error {
            lsm9ds1::Error::Bus(twim::Error::AddressNack) => defmt::error!(
                "LSM9DS1: no answer at its I2C address; this build needs a Nano 33 BLE Sense rev 1 \
                 (for the Rev2's BMI270/BMM150 build with --features rev2), with VDD_ENV (P0.22) \
                 and the pull-ups (P1.00) on"
            ),
            lsm9ds1::Error::Bus(other) => defmt::error!(
                "LSM9DS1: I2C transfer failed ({=str}); check the sensor supply and the bus pull-ups",
                twim_error_name(other)
            ),
            lsm9ds1::Error::WrongAccelGyroId { address, found } => defmt::error!(
                "LSM9DS1: device at {=u8:#x} reports WHO_AM_I {=u8:#x}, not 0x68; this is not an LSM9DS1",
                address,
                found
            ),
            lsm9ds1::Error::WrongMagId { address, found } => defmt::error!(
                "LSM9DS1 magnetometer at {=u8:#x} reports WHO_AM_I {=u8:#x}, not 0x3d; this is not an LSM9DS1",
                address,
                found
            ),
            lsm9ds1::Error::NotInitialised => {
                defmt::error!("LSM9DS1: read before configuration; configure it first")
            }
        }
    }

    /// The LSM9DS1 with its default configuration.
    pub fn configure(i2c: Twim<TWIM0>) -> impl Imu {
        let mut imu = Lsm9ds1::new(i2c, Config::default());
        configure_with_retries(|| imu.init(), log_sensor_error);
        imu
    }
}

#[cfg(feature = "rev2")]
mod chip {
    use super::*;
    use embedded_hal::delay::DelayNs;
    use imucal_firmware::bmi270::{self, Bmi270Bmm150, Config};

    /// The sensor's name in the log.
    pub const SENSOR_NAME: &str = "BMI270/BMM150";

    /// Busy-waits on the core clock (only used during configuration).
    struct CycleDelay;

    impl DelayNs for CycleDelay {
        fn delay_ns(&mut self, ns: u32) {
            // 64 cycles per µs; at least one cycle.
            cortex_m::asm::delay((ns / 1000).max(1) * (crate::CPU_HZ / 1_000_000));
        }
    }

    /// Logs why the BMI270/BMM150 could not be configured, as a sentence naming cause and fix.
    fn log_sensor_error(error: &bmi270::Error<twim::Error>) {
        match error {
            bmi270::Error::Bus(twim::Error::AddressNack) => defmt::error!(
                "BMI270/BMM150: no answer at 0x68/0x10; this build needs a Nano 33 BLE Sense Rev2 \
                 (build without --features rev2 for rev 1)"
            ),
            bmi270::Error::Bus(other) => defmt::error!(
                "BMI270/BMM150: I2C transfer failed ({=str}); check the sensor supply and pull-ups",
                twim_error_name(other)
            ),
            bmi270::Error::WrongChipId { found } => {
                defmt::error!("BMI270: CHIP_ID {=u8:#x}, not 0x24", found)
            }
            bmi270::Error::WrongMagId { found } => {
                defmt::error!("BMM150: CHIP_ID {=u8:#x}, not 0x32", found)
            }
            bmi270::Error::BadConfigFile => {
                defmt::error!("BMI270: the configuration file is empty or of odd length")
            }
            bmi270::Error::ConfigLoadFailed { status } => defmt::error!(
                "BMI270: INTERNAL_STATUS {=u8:#x} after the configuration load; the file does not \
                 match the chip",
                status
            ),
            bmi270::Error::NotInitialised => {
                defmt::error!("BMI270: read before configuration; configure it first")
            }
        }
    }

    /// The BMI270 with Bosch's configuration file (from the `bmi2` crate) and the BMM150.
    pub fn configure(i2c: Twim<TWIM0>) -> impl Imu {
        let config = Config {
            config_file: &bmi2::config::BMI270_CONFIG_FILE,
            max_burst: bmi270::MAX_BURST,
        };
        let mut imu = Bmi270Bmm150::new(i2c, CycleDelay, config);
        configure_with_retries(|| imu.init(), log_sensor_error);
        imu
    }
}

pub use chip::{configure, SENSOR_NAME};
