//! Register-level driver for the Bosch BMI270 accelerometer/gyroscope with a BMM150
//! magnetometer on the same I²C bus (Arduino Nano 33 BLE Sense Rev2: BMI270 at 0x68, BMM150 at
//! 0x10), over embedded-hal 1.0, as one [`Imu`].
//!
//! Registers and the initialisation sequence are from the Bosch BMI270 datasheet
//! (BST-BMI270-DS000), sections 4.3 ("Initialization") and 5: CHIP_ID 0x00 reads 0x24; PWR_CONF
//! 0x7C = 0 (advanced power save off), wait 450 µs; INIT_CTRL 0x59 = 0; the configuration file is
//! written to INIT_DATA 0x5E in bursts, each preceded by its word offset in INIT_ADDR_0/1
//! (0x5B: bits 3:0, 0x5C: bits 11:4); INIT_CTRL = 1; after about 20 ms INTERNAL_STATUS 0x21
//! (bits 3:0) reads 1 ("init ok"). Data: STATUS 0x03 (bit 7 accel ready, bit 6 gyro ready),
//! ACC 0x0C–0x11, GYR 0x12–0x17 (16-bit little-endian), TEMPERATURE 0x22–0x23 (0 = 23 °C,
//! 1/512 K per count).
//!
//! Why not the `bmi2` crate (0.1.x, no_std, embedded-hal 1.0, uploads the configuration file):
//! it owns the bus, so the BMM150 on the same bus would need a bus-sharing layer; it is marked
//! work-in-progress with a single maintainer; and it adds a heap-free vector crate for its burst
//! buffer. The part imucal needs — init with the config upload, ranges, raw reads — is about a
//! hundred lines, so the driver is written here and tested against the register-level emulation
//! in the simulator.
//!
//! The configuration file is Bosch's (`bmi270_config_file` of the BMI270 Sensor API); it is not
//! part of this crate: the board passes it in [`Config::config_file`] (the Nano 33 BLE Sense
//! Rev2 build takes it from the `bmi2` crate, using nothing else of that crate).

use embedded_hal::delay::DelayNs;
use embedded_hal::i2c::I2c;

use crate::bmm150;
use crate::imu::{Imu, RawSample, SensorScales};

/// Standard gravity, m/s² per g.
const STANDARD_GRAVITY_MPS2: f32 = 9.806_65;
/// rad per degree.
const RAD_PER_DEG: f32 = core::f32::consts::PI / 180.0;

/// I²C address with SDO low (Nano 33 BLE Sense Rev2).
pub const ADDRESS: u8 = 0x68;
/// CHIP_ID value.
pub const CHIP_ID: u8 = 0x24;
/// INTERNAL_STATUS message "initialisation ok".
pub const STATUS_INIT_OK: u8 = 0x01;

/// Register addresses (datasheet section 5.2).
pub mod reg {
    /// Chip identification, 0x24.
    pub const CHIP_ID: u8 = 0x00;
    /// Data-ready flags: bit 7 accelerometer, bit 6 gyroscope, bit 5 auxiliary.
    pub const STATUS: u8 = 0x03;
    /// Accelerometer X LSB; Y, Z and the gyroscope follow up to 0x17.
    pub const ACC_X_LSB: u8 = 0x0C;
    /// Initialisation status, message in bits 3:0.
    pub const INTERNAL_STATUS: u8 = 0x21;
    /// Temperature LSB (MSB at 0x23).
    pub const TEMPERATURE_0: u8 = 0x22;
    /// Accelerometer filter (bit 7), averaging (6:4), data rate (3:0).
    pub const ACC_CONF: u8 = 0x40;
    /// Accelerometer range (1:0).
    pub const ACC_RANGE: u8 = 0x41;
    /// Gyroscope filter/noise modes (7:6), bandwidth (5:4), data rate (3:0).
    pub const GYR_CONF: u8 = 0x42;
    /// Gyroscope range (2:0).
    pub const GYR_RANGE: u8 = 0x43;
    /// Start (1) or stop (0) of the configuration load.
    pub const INIT_CTRL: u8 = 0x59;
    /// Configuration word offset, bits 3:0.
    pub const INIT_ADDR_0: u8 = 0x5B;
    /// Configuration word offset, bits 11:4.
    pub const INIT_ADDR_1: u8 = 0x5C;
    /// Configuration data port.
    pub const INIT_DATA: u8 = 0x5E;
    /// Power configuration: advanced power save (bit 0).
    pub const PWR_CONF: u8 = 0x7C;
    /// Sensor enables: aux (bit 0), gyro (1), accel (2), temperature (3).
    pub const PWR_CTRL: u8 = 0x7D;
    /// Commands (0xB6 soft reset).
    pub const CMD: u8 = 0x7E;
}

/// ACC_CONF: performance filter, average of 4, 100 Hz.
pub const ACC_CONF_100HZ: u8 = 0xA8;
/// ACC_RANGE code for ±4 g.
pub const ACC_RANGE_4G: u8 = 0x01;
/// GYR_CONF: performance modes, normal bandwidth, 100 Hz.
pub const GYR_CONF_100HZ: u8 = 0xE8;
/// GYR_RANGE code for ±1000 °/s.
pub const GYR_RANGE_1000DPS: u8 = 0x01;
/// PWR_CTRL: accelerometer, gyroscope and thermometer on.
pub const PWR_CTRL_ACC_GYR_TEMP: u8 = 0b1110;

/// Largest configuration burst sent at once, bytes (one RAM frame on the stack).
pub const MAX_BURST: usize = 128;

/// Accelerometer counts per g at ±4 g.
const ACC_COUNTS_PER_G: f32 = 8192.0;
/// Gyroscope counts per °/s at ±1000 °/s.
const GYR_COUNTS_PER_DPS: f32 = 32.768;

/// What the driver needs from the board.
#[derive(Debug, Clone, Copy)]
pub struct Config {
    /// Bosch's BMI270 configuration file (8192 bytes in the Sensor API).
    pub config_file: &'static [u8],
    /// Largest I²C write the bus takes at once, bytes (the config is sent in bursts of this
    /// size, at most [`MAX_BURST`], rounded down to even).
    pub max_burst: usize,
}

/// Driver errors.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Error<E> {
    /// The bus failed.
    Bus(E),
    /// CHIP_ID did not read 0x24.
    WrongChipId {
        /// Value read.
        found: u8,
    },
    /// The BMM150's CHIP_ID did not read 0x32.
    WrongMagId {
        /// Value read.
        found: u8,
    },
    /// The configuration file is empty, of odd length, or the burst size is below 2.
    BadConfigFile,
    /// INTERNAL_STATUS never reported "init ok" after the configuration load.
    ConfigLoadFailed {
        /// Last INTERNAL_STATUS message.
        status: u8,
    },
    /// `read` before a successful `init`.
    NotInitialised,
}

impl<E: core::fmt::Debug> core::fmt::Display for Error<E> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Bus(e) => write!(
                f,
                "I²C bus error {e:?}; check the sensor bus wiring and power"
            ),
            Self::WrongChipId { found } => write!(
                f,
                "BMI270 CHIP_ID reads {found:#04x}, expected 0x24; is this a Rev2 board?"
            ),
            Self::WrongMagId { found } => write!(
                f,
                "BMM150 CHIP_ID reads {found:#04x}, expected 0x32; is this a Rev2 board?"
            ),
            Self::BadConfigFile => write!(
                f,
                "the BMI270 configuration file is empty or of odd length, or the burst size is \
                 below 2; pass Bosch's bmi270_config_file"
            ),
            Self::ConfigLoadFailed { status } => write!(
                f,
                "the BMI270 refused its configuration file (INTERNAL_STATUS {status:#04x}); \
                 pass the file matching this chip"
            ),
            Self::NotInitialised => write!(f, "the BMI270 was read before init succeeded"),
        }
    }
}

/// BMI270 + BMM150 on one bus.
pub struct Bmi270Bmm150<I2C, D> {
    i2c: I2C,
    delay: D,
    config: Config,
    initialised: bool,
}

impl<I2C: I2c, D: DelayNs> Bmi270Bmm150<I2C, D> {
    /// Takes the bus and a delay; nothing is sent until [`Self::init`].
    pub fn new(i2c: I2C, delay: D, config: Config) -> Self {
        Self {
            i2c,
            delay,
            config,
            initialised: false,
        }
    }

    /// Checks the chip ids, loads the configuration file, configures and powers the sensors.
    pub fn init(&mut self) -> Result<(), Error<I2C::Error>> {
        self.initialised = false;
        let file = self.config.config_file;
        let burst = self.config.max_burst.min(MAX_BURST) & !1;
        if file.is_empty() || file.len() & 1 == 1 || burst < 2 {
            return Err(Error::BadConfigFile);
        }
        let found = self.read_u8(reg::CHIP_ID)?;
        if found != CHIP_ID {
            return Err(Error::WrongChipId { found });
        }
        self.write(reg::PWR_CONF, 0x00)?;
        self.delay.delay_us(450);
        self.write(reg::INIT_CTRL, 0x00)?;
        for (index, chunk) in file.chunks(burst).enumerate() {
            let word = (index * burst / 2) as u16;
            self.write(reg::INIT_ADDR_0, (word & 0x0F) as u8)?;
            self.write(reg::INIT_ADDR_1, (word >> 4) as u8)?;
            // Copied to RAM: DMA bus masters (nRF TWIM) cannot send straight from flash.
            let mut frame = [0u8; 1 + MAX_BURST];
            frame[0] = reg::INIT_DATA;
            frame[1..=chunk.len()].copy_from_slice(chunk);
            self.i2c
                .write(ADDRESS, &frame[..=chunk.len()])
                .map_err(Error::Bus)?;
        }
        self.write(reg::INIT_CTRL, 0x01)?;
        let mut status = 0;
        // The datasheet gives 20 ms; allow 150 ms as Bosch's API does before giving up.
        for _ in 0..150 {
            self.delay.delay_ms(1);
            status = self.read_u8(reg::INTERNAL_STATUS)? & 0x0F;
            if status == STATUS_INIT_OK {
                break;
            }
        }
        if status != STATUS_INIT_OK {
            return Err(Error::ConfigLoadFailed { status });
        }
        for (register, value) in [
            (reg::PWR_CTRL, PWR_CTRL_ACC_GYR_TEMP),
            (reg::ACC_CONF, ACC_CONF_100HZ),
            (reg::ACC_RANGE, ACC_RANGE_4G),
            (reg::GYR_CONF, GYR_CONF_100HZ),
            (reg::GYR_RANGE, GYR_RANGE_1000DPS),
        ] {
            self.write(register, value)?;
        }
        let delay = &mut self.delay;
        bmm150::init(&mut self.i2c, |ms| delay.delay_ms(ms)).map_err(|e| match e {
            bmm150::Error::Bus(e) => Error::Bus(e),
            bmm150::Error::WrongId { found } => Error::WrongMagId { found },
        })?;
        self.initialised = true;
        Ok(())
    }

    /// Gives the bus and the delay back.
    pub fn release(self) -> (I2C, D) {
        (self.i2c, self.delay)
    }

    fn read_u8(&mut self, register: u8) -> Result<u8, Error<I2C::Error>> {
        let mut value = [0u8];
        self.i2c
            .write_read(ADDRESS, &[register], &mut value)
            .map_err(Error::Bus)?;
        Ok(value[0])
    }

    fn write(&mut self, register: u8, value: u8) -> Result<(), Error<I2C::Error>> {
        self.i2c
            .write(ADDRESS, &[register, value])
            .map_err(Error::Bus)
    }
}

/// The scales of the configuration [`Bmi270Bmm150::init`] writes.
pub fn scales() -> SensorScales {
    SensorScales {
        accel_mps2_per_count: STANDARD_GRAVITY_MPS2 / ACC_COUNTS_PER_G,
        gyro_rads_per_count: RAD_PER_DEG / GYR_COUNTS_PER_DPS,
        mag_ut_per_count: bmm150::UT_PER_COUNT,
        temp_c_per_count: 1.0 / 512.0,
        temp_offset_c: 23.0,
        accel_range_mps2: 4.0 * STANDARD_GRAVITY_MPS2,
        gyro_range_rads: 1000.0 * RAD_PER_DEG,
        mag_range_ut: 1300.0,
        sample_rate_hz: 100.0,
    }
}

impl<I2C: I2c, D: DelayNs> Imu for Bmi270Bmm150<I2C, D> {
    type Error = Error<I2C::Error>;

    fn scales(&self) -> SensorScales {
        scales()
    }

    /// Two BMI270 bursts (accel + gyro 0x0C–0x17, temperature 0x22–0x23) and one BMM150 burst.
    fn read(&mut self) -> Result<RawSample, Self::Error> {
        if !self.initialised {
            return Err(Error::NotInitialised);
        }
        let mut data = [0u8; 12];
        self.i2c
            .write_read(ADDRESS, &[reg::ACC_X_LSB], &mut data)
            .map_err(Error::Bus)?;
        let mut temp = [0u8; 2];
        self.i2c
            .write_read(ADDRESS, &[reg::TEMPERATURE_0], &mut temp)
            .map_err(Error::Bus)?;
        let mag = bmm150::read(&mut self.i2c).map_err(Error::Bus)?;
        let word = |i: usize| i16::from_le_bytes([data[2 * i], data[2 * i + 1]]);
        Ok(RawSample {
            accel: [word(0), word(1), word(2)],
            gyro: [word(3), word(4), word(5)],
            mag: mag.counts,
            temp: i16::from_le_bytes(temp),
        })
    }
}
