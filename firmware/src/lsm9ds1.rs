//! Register-level driver for the ST LSM9DS1 9-axis IMU over an embedded-hal 1.0 I²C bus.
//!
//! The chip is two I²C devices in one package: the accelerometer + gyroscope (with the die
//! thermometer) at 0x6B (0x6A with SDO_A/G low) and the magnetometer at 0x1E (0x1C with SDO_M low);
//! this is the IMU of the Arduino Nano 33 BLE Sense. Register addresses, bit fields and the
//! sensitivity table are from the ST LSM9DS1 datasheet (DocID025715), sections 7–8 and table 3.
//!
//! Every sensor is read in counts ([`RawSample`]); [`Config::scales`] turns the configured full
//! scales into SI sensitivities ([`SensorScales`]: m/s², rad/s, µT, °C).
//!
//! Magnetometer axes: on the package the magnetometer's X axis points opposite to the
//! accelerometer/gyroscope X axis, while Y and Z agree (datasheet figure 1, "Pin connections").
//! The raw magnetometer frame is therefore a *reflection* of the A/G frame, which no rotation in a
//! calibration can undo. By default ([`MagAxes::AlignedToAccelGyro`]) the driver negates the
//! magnetometer X count so that all three sensors report in the A/G frame; [`MagAxes::Raw`] keeps
//! the chip's own magnetometer axes.

use embedded_hal::i2c::I2c;

use crate::imu::{Imu, NewData, RawSample, Reading, SensorScales};

/// Standard gravity, m/s² per g (the datasheet's accelerometer unit).
const STANDARD_GRAVITY_MPS2: f32 = 9.806_65;
/// µT per gauss.
const MICROTESLA_PER_GAUSS: f32 = 100.0;
/// rad per degree.
const RAD_PER_DEG: f32 = core::f32::consts::PI / 180.0;

/// Accelerometer/gyroscope I²C address with SDO_A/G high (Arduino Nano 33 BLE Sense).
pub const ACCEL_GYRO_ADDRESS_SDO_HIGH: u8 = 0x6B;
/// Accelerometer/gyroscope I²C address with SDO_A/G low.
pub const ACCEL_GYRO_ADDRESS_SDO_LOW: u8 = 0x6A;
/// Magnetometer I²C address with SDO_M high (Arduino Nano 33 BLE Sense).
pub const MAG_ADDRESS_SDO_HIGH: u8 = 0x1E;
/// Magnetometer I²C address with SDO_M low.
pub const MAG_ADDRESS_SDO_LOW: u8 = 0x1C;

/// WHO_AM_I value of the accelerometer/gyroscope.
pub const ACCEL_GYRO_WHO_AM_I: u8 = 0x68;
/// WHO_AM_I value of the magnetometer.
pub const MAG_WHO_AM_I: u8 = 0x3D;

/// Register addresses of the accelerometer/gyroscope device (datasheet table 21).
pub mod accel_gyro_reg {
    /// Identification, reads 0x68.
    pub const WHO_AM_I: u8 = 0x0F;
    /// Gyroscope output data rate (bits 7:5), full scale (bits 4:3), bandwidth (bits 1:0).
    pub const CTRL_REG1_G: u8 = 0x10;
    /// Gyroscope interrupt/output filter selection.
    pub const CTRL_REG2_G: u8 = 0x11;
    /// Gyroscope low-power mode and high-pass filter.
    pub const CTRL_REG3_G: u8 = 0x12;
    /// Temperature output, low byte (high byte at 0x16), 12-bit two's complement.
    pub const OUT_TEMP_L: u8 = 0x15;
    /// Gyroscope X output, low byte; Y and Z follow up to 0x1D.
    pub const OUT_X_L_G: u8 = 0x18;
    /// Gyroscope axis enables (bits 5:3).
    pub const CTRL_REG4: u8 = 0x1E;
    /// Accelerometer decimation and axis enables (bits 5:3).
    pub const CTRL_REG5_XL: u8 = 0x1F;
    /// Accelerometer output data rate (bits 7:5), full scale (bits 4:3), bandwidth.
    pub const CTRL_REG6_XL: u8 = 0x20;
    /// Accelerometer high-resolution mode and internal filter selection.
    pub const CTRL_REG7_XL: u8 = 0x21;
    /// BOOT, BDU (bit 6), interrupt pin mode, SIM, IF_ADD_INC (bit 2), BLE, SW_RESET.
    pub const CTRL_REG8: u8 = 0x22;
    /// Gyroscope sleep, FIFO enables, I²C disable.
    pub const CTRL_REG9: u8 = 0x23;
    /// Accelerometer X output, low byte; Y and Z follow up to 0x2D.
    pub const OUT_X_L_XL: u8 = 0x28;
}

/// Register addresses of the magnetometer device (datasheet table 21).
pub mod mag_reg {
    /// Identification, reads 0x3D.
    pub const WHO_AM_I_M: u8 = 0x0F;
    /// TEMP_COMP (bit 7), X/Y operating mode OM (bits 6:5), data rate DO (bits 4:2).
    pub const CTRL_REG1_M: u8 = 0x20;
    /// Full scale FS (bits 6:5), reboot, soft reset.
    pub const CTRL_REG2_M: u8 = 0x21;
    /// I²C disable, low power, SPI mode, operating mode MD (bits 1:0).
    pub const CTRL_REG3_M: u8 = 0x22;
    /// Z operating mode OMZ (bits 3:2), endianness.
    pub const CTRL_REG4_M: u8 = 0x23;
    /// FAST_READ, BDU (bit 6).
    pub const CTRL_REG5_M: u8 = 0x24;
    /// ZYXOR (bit 7, a conversion overwritten unread) and ZYXDA (bit 3, new X, Y and Z data).
    pub const STATUS_REG_M: u8 = 0x27;
    /// Magnetometer X output, low byte; Y and Z follow up to 0x2D.
    pub const OUT_X_L_M: u8 = 0x28;
    /// Set in a magnetometer sub-address to make a multi-byte access advance the address.
    pub const AUTO_INCREMENT: u8 = 0x80;
}

/// STATUS_REG (0x17): accelerometer new data available.
const STATUS_XLDA: u8 = 1 << 0;
/// STATUS_REG (0x17): gyroscope new data available.
const STATUS_GDA: u8 = 1 << 1;
/// STATUS_REG_M: new X, Y and Z magnetometer data available.
const STATUS_M_ZYXDA: u8 = 1 << 3;
/// STATUS_REG_M: a magnetometer conversion overwrote one that was not read.
const STATUS_M_ZYXOR: u8 = 1 << 7;
/// CTRL_REG8: block data update, so a multi-byte read never mixes two samples.
const CTRL_REG8_BDU: u8 = 1 << 6;
/// CTRL_REG8: advance the register address during multi-byte accesses.
const CTRL_REG8_IF_ADD_INC: u8 = 1 << 2;
/// CTRL_REG4 / CTRL_REG5_XL: X, Y and Z enabled.
const XYZ_ENABLED: u8 = 0b0011_1000;
/// CTRL_REG1_M: on-chip temperature compensation of the magnetometer (recommended by ST).
const CTRL_REG1_M_TEMP_COMP: u8 = 1 << 7;
/// CTRL_REG3_M: MD = 00, continuous conversion; I²C stays enabled.
const CTRL_REG3_M_CONTINUOUS: u8 = 0x00;
/// CTRL_REG5_M: block data update.
const CTRL_REG5_M_BDU: u8 = 1 << 6;
/// Temperature sensitivity, counts per °C (datasheet table 5).
const TEMP_COUNTS_PER_DEG_C: f32 = 16.0;
/// Temperature at zero counts, °C (datasheet table 5).
const TEMP_AT_ZERO_COUNTS_C: f32 = 25.0;

/// Level of an SDO pin, which selects one of the two I²C addresses of a device.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SdoLevel {
    /// Pin high (pulled up, as on the Arduino Nano 33 BLE Sense).
    #[default]
    High,
    /// Pin low.
    Low,
}

/// Accelerometer full scale (FS_XL in CTRL_REG6_XL).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum AccelRange {
    /// ±2 g, 0.061 mg/count.
    G2,
    /// ±4 g, 0.122 mg/count.
    #[default]
    G4,
    /// ±8 g, 0.244 mg/count.
    G8,
    /// ±16 g, 0.732 mg/count.
    G16,
}

impl AccelRange {
    /// Every accelerometer full scale, smallest first.
    pub const ALL: [AccelRange; 4] = [Self::G2, Self::G4, Self::G8, Self::G16];

    /// FS_XL field value. The datasheet's encoding is not monotonic: 00 = 2 g, 01 = 16 g,
    /// 10 = 4 g, 11 = 8 g.
    const fn fs_bits(self) -> u8 {
        match self {
            Self::G2 => 0b00,
            Self::G16 => 0b01,
            Self::G4 => 0b10,
            Self::G8 => 0b11,
        }
    }

    /// Full scale (±), g.
    pub const fn full_scale_g(self) -> f32 {
        match self {
            Self::G2 => 2.0,
            Self::G4 => 4.0,
            Self::G8 => 8.0,
            Self::G16 => 16.0,
        }
    }

    /// Sensitivity, mg per count (datasheet table 3, LA_So).
    pub const fn mg_per_count(self) -> f32 {
        match self {
            Self::G2 => 0.061,
            Self::G4 => 0.122,
            Self::G8 => 0.244,
            Self::G16 => 0.732,
        }
    }
}

/// Gyroscope full scale (FS_G in CTRL_REG1_G).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum GyroRange {
    /// ±245 °/s, 8.75 m°/s per count.
    Dps245,
    /// ±500 °/s, 17.50 m°/s per count.
    #[default]
    Dps500,
    /// ±2000 °/s, 70 m°/s per count.
    Dps2000,
}

impl GyroRange {
    /// Every gyroscope full scale, smallest first.
    pub const ALL: [GyroRange; 3] = [Self::Dps245, Self::Dps500, Self::Dps2000];

    /// FS_G field value (10 is not available).
    const fn fs_bits(self) -> u8 {
        match self {
            Self::Dps245 => 0b00,
            Self::Dps500 => 0b01,
            Self::Dps2000 => 0b11,
        }
    }

    /// Full scale (±), degrees per second.
    pub const fn full_scale_dps(self) -> f32 {
        match self {
            Self::Dps245 => 245.0,
            Self::Dps500 => 500.0,
            Self::Dps2000 => 2000.0,
        }
    }

    /// Sensitivity, millidegrees per second per count (datasheet table 3, G_So).
    pub const fn mdps_per_count(self) -> f32 {
        match self {
            Self::Dps245 => 8.75,
            Self::Dps500 => 17.50,
            Self::Dps2000 => 70.0,
        }
    }
}

/// Magnetometer full scale (FS in CTRL_REG2_M).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MagRange {
    /// ±4 gauss (±400 µT), 0.14 mgauss/count.
    #[default]
    Gauss4,
    /// ±8 gauss, 0.29 mgauss/count.
    Gauss8,
    /// ±12 gauss, 0.43 mgauss/count.
    Gauss12,
    /// ±16 gauss, 0.58 mgauss/count.
    Gauss16,
}

impl MagRange {
    /// Every magnetometer full scale, smallest first.
    pub const ALL: [MagRange; 4] = [Self::Gauss4, Self::Gauss8, Self::Gauss12, Self::Gauss16];

    /// FS field value.
    const fn fs_bits(self) -> u8 {
        match self {
            Self::Gauss4 => 0b00,
            Self::Gauss8 => 0b01,
            Self::Gauss12 => 0b10,
            Self::Gauss16 => 0b11,
        }
    }

    /// Full scale (±), gauss.
    pub const fn full_scale_gauss(self) -> f32 {
        match self {
            Self::Gauss4 => 4.0,
            Self::Gauss8 => 8.0,
            Self::Gauss12 => 12.0,
            Self::Gauss16 => 16.0,
        }
    }

    /// Sensitivity, milligauss per count (datasheet table 3, M_GN).
    pub const fn mgauss_per_count(self) -> f32 {
        match self {
            Self::Gauss4 => 0.14,
            Self::Gauss8 => 0.29,
            Self::Gauss12 => 0.43,
            Self::Gauss16 => 0.58,
        }
    }
}

/// Output data rate of the accelerometer and gyroscope together.
///
/// With the gyroscope on, the accelerometer runs at the gyroscope's rate (ODR_G); the driver
/// writes the same code to ODR_XL so both fields agree.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum AccelGyroDataRate {
    /// 14.9 Hz.
    Hz14_9,
    /// 59.5 Hz.
    Hz59_5,
    /// 119 Hz.
    #[default]
    Hz119,
    /// 238 Hz.
    Hz238,
    /// 476 Hz.
    Hz476,
    /// 952 Hz.
    Hz952,
}

impl AccelGyroDataRate {
    /// ODR_G field value (000 is power-down and never used here).
    const fn odr_bits(self) -> u8 {
        match self {
            Self::Hz14_9 => 0b001,
            Self::Hz59_5 => 0b010,
            Self::Hz119 => 0b011,
            Self::Hz238 => 0b100,
            Self::Hz476 => 0b101,
            Self::Hz952 => 0b110,
        }
    }

    /// Rate, Hz.
    pub const fn hz(self) -> f32 {
        match self {
            Self::Hz14_9 => 14.9,
            Self::Hz59_5 => 59.5,
            Self::Hz119 => 119.0,
            Self::Hz238 => 238.0,
            Self::Hz476 => 476.0,
            Self::Hz952 => 952.0,
        }
    }
}

/// Output data rate of the magnetometer (DO in CTRL_REG1_M).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MagDataRate {
    /// 0.625 Hz.
    Hz0_625,
    /// 1.25 Hz.
    Hz1_25,
    /// 2.5 Hz.
    Hz2_5,
    /// 5 Hz.
    Hz5,
    /// 10 Hz.
    Hz10,
    /// 20 Hz.
    Hz20,
    /// 40 Hz.
    Hz40,
    /// 80 Hz.
    #[default]
    Hz80,
}

impl MagDataRate {
    /// DO field value.
    const fn do_bits(self) -> u8 {
        match self {
            Self::Hz0_625 => 0b000,
            Self::Hz1_25 => 0b001,
            Self::Hz2_5 => 0b010,
            Self::Hz5 => 0b011,
            Self::Hz10 => 0b100,
            Self::Hz20 => 0b101,
            Self::Hz40 => 0b110,
            Self::Hz80 => 0b111,
        }
    }
}

/// Magnetometer operating mode (OM for X/Y, OMZ for Z): lower noise costs current.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MagPerformance {
    /// Low-power mode.
    LowPower,
    /// Medium-performance mode.
    Medium,
    /// High-performance mode.
    High,
    /// Ultra-high-performance mode (lowest noise).
    #[default]
    UltraHigh,
}

impl MagPerformance {
    /// OM / OMZ field value.
    const fn om_bits(self) -> u8 {
        match self {
            Self::LowPower => 0b00,
            Self::Medium => 0b01,
            Self::High => 0b10,
            Self::UltraHigh => 0b11,
        }
    }
}

/// Frame of the magnetometer counts returned by [`Lsm9ds1`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MagAxes {
    /// The chip's own magnetometer axes (X opposite to the accelerometer/gyroscope X).
    Raw,
    /// Accelerometer/gyroscope axes: the magnetometer X count is negated (saturating, so
    /// −32768 reads as +32767).
    #[default]
    AlignedToAccelGyro,
}

/// Chip configuration applied by [`Lsm9ds1::init`].
///
/// The default suits calibration by hand on an Arduino Nano 33 BLE Sense: ±4 g (gravity with
/// margin for handling), ±500 °/s (slow turns by hand), ±4 gauss (the Earth's field is below
/// 0.7 gauss), 119 Hz accelerometer/gyroscope, 80 Hz magnetometer in ultra-high performance, and
/// magnetometer counts in the accelerometer/gyroscope frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Config {
    /// Accelerometer full scale.
    pub accel_range: AccelRange,
    /// Gyroscope full scale.
    pub gyro_range: GyroRange,
    /// Magnetometer full scale.
    pub mag_range: MagRange,
    /// Accelerometer and gyroscope output data rate; this is the sample rate of [`Imu::read`].
    pub accel_gyro_rate: AccelGyroDataRate,
    /// Magnetometer output data rate. Below the A/G rate, consecutive reads repeat the latest
    /// magnetometer sample.
    pub mag_rate: MagDataRate,
    /// Magnetometer operating mode.
    pub mag_performance: MagPerformance,
    /// Frame of the magnetometer counts.
    pub mag_axes: MagAxes,
    /// Level of the SDO_A/G pin.
    pub sdo_accel_gyro: SdoLevel,
    /// Level of the SDO_M pin.
    pub sdo_mag: SdoLevel,
}

impl Config {
    /// I²C address of the accelerometer/gyroscope device.
    pub const fn accel_gyro_address(&self) -> u8 {
        match self.sdo_accel_gyro {
            SdoLevel::High => ACCEL_GYRO_ADDRESS_SDO_HIGH,
            SdoLevel::Low => ACCEL_GYRO_ADDRESS_SDO_LOW,
        }
    }

    /// I²C address of the magnetometer device.
    pub const fn mag_address(&self) -> u8 {
        match self.sdo_mag {
            SdoLevel::High => MAG_ADDRESS_SDO_HIGH,
            SdoLevel::Low => MAG_ADDRESS_SDO_LOW,
        }
    }

    /// SI sensitivities and ranges of this configuration (datasheet table 3 and table 5).
    pub fn scales(&self) -> SensorScales {
        SensorScales {
            accel_mps2_per_count: self.accel_range.mg_per_count() * 1e-3 * STANDARD_GRAVITY_MPS2,
            gyro_rads_per_count: self.gyro_range.mdps_per_count() * 1e-3 * RAD_PER_DEG,
            mag_ut_per_count: self.mag_range.mgauss_per_count() * 1e-3 * MICROTESLA_PER_GAUSS,
            temp_c_per_count: 1.0 / TEMP_COUNTS_PER_DEG_C,
            temp_offset_c: TEMP_AT_ZERO_COUNTS_C,
            accel_range_mps2: self.accel_range.full_scale_g() * STANDARD_GRAVITY_MPS2,
            gyro_range_rads: self.gyro_range.full_scale_dps() * RAD_PER_DEG,
            mag_range_ut: self.mag_range.full_scale_gauss() * MICROTESLA_PER_GAUSS,
            sample_rate_hz: self.accel_gyro_rate.hz(),
        }
    }

    /// Register writes that bring the accelerometer/gyroscope device into this configuration,
    /// in order. CTRL_REG1_G comes last: setting ODR_G starts both sensors together.
    pub fn accel_gyro_writes(&self) -> [(u8, u8); 9] {
        let odr = self.accel_gyro_rate.odr_bits() << 5;
        [
            (
                accel_gyro_reg::CTRL_REG8,
                CTRL_REG8_BDU | CTRL_REG8_IF_ADD_INC,
            ),
            // FIFO off, I²C on, gyroscope not asleep.
            (accel_gyro_reg::CTRL_REG9, 0x00),
            // Gyroscope output straight from the LPF1 path, no high-pass filter.
            (accel_gyro_reg::CTRL_REG2_G, 0x00),
            // Normal (not low-power) gyroscope mode, high-pass filter off.
            (accel_gyro_reg::CTRL_REG3_G, 0x00),
            (accel_gyro_reg::CTRL_REG4, XYZ_ENABLED),
            (accel_gyro_reg::CTRL_REG5_XL, XYZ_ENABLED),
            (
                accel_gyro_reg::CTRL_REG6_XL,
                odr | (self.accel_range.fs_bits() << 3),
            ),
            // Accelerometer internal filter bypassed.
            (accel_gyro_reg::CTRL_REG7_XL, 0x00),
            (
                accel_gyro_reg::CTRL_REG1_G,
                odr | (self.gyro_range.fs_bits() << 3),
            ),
        ]
    }

    /// Register writes that bring the magnetometer device into this configuration, in order.
    pub fn mag_writes(&self) -> [(u8, u8); 5] {
        let om = self.mag_performance.om_bits();
        [
            (
                mag_reg::CTRL_REG1_M,
                CTRL_REG1_M_TEMP_COMP | (om << 5) | (self.mag_rate.do_bits() << 2),
            ),
            (mag_reg::CTRL_REG2_M, self.mag_range.fs_bits() << 5),
            (mag_reg::CTRL_REG3_M, CTRL_REG3_M_CONTINUOUS),
            (mag_reg::CTRL_REG4_M, om << 2),
            (mag_reg::CTRL_REG5_M, CTRL_REG5_M_BDU),
        ]
    }
}

/// Failure of an LSM9DS1 operation; `E` is the I²C bus error.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Error<E> {
    /// The I²C transfer failed.
    Bus(E),
    /// The accelerometer/gyroscope answered with a WHO_AM_I other than 0x68.
    WrongAccelGyroId {
        /// I²C address that was asked.
        address: u8,
        /// Value read.
        found: u8,
    },
    /// The magnetometer answered with a WHO_AM_I other than 0x3D.
    WrongMagId {
        /// I²C address that was asked.
        address: u8,
        /// Value read.
        found: u8,
    },
    /// A sample was requested before [`Lsm9ds1::init`] succeeded.
    NotInitialised,
}

impl<E: core::fmt::Debug> core::fmt::Display for Error<E> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Bus(e) => write!(
                f,
                "the I2C transfer to the LSM9DS1 failed ({e:?}); check wiring, pull-ups and power"
            ),
            Self::WrongAccelGyroId { address, found } => write!(
                f,
                "the device at I2C address {address:#04x} reports WHO_AM_I {found:#04x}, not the \
                 LSM9DS1 accelerometer/gyroscope's 0x68; check the chip and the SDO_A/G level"
            ),
            Self::WrongMagId { address, found } => write!(
                f,
                "the device at I2C address {address:#04x} reports WHO_AM_I {found:#04x}, not the \
                 LSM9DS1 magnetometer's 0x3d; check the chip and the SDO_M level"
            ),
            Self::NotInitialised => write!(
                f,
                "the LSM9DS1 was read before it was configured; call init() first and check that \
                 it succeeded"
            ),
        }
    }
}

impl<E: core::fmt::Debug> core::error::Error for Error<E> {}

/// LSM9DS1 on an I²C bus.
#[derive(Debug)]
pub struct Lsm9ds1<I2C> {
    i2c: I2C,
    config: Config,
    initialised: bool,
}

impl<I2C: I2c> Lsm9ds1<I2C> {
    /// Take the bus; nothing is sent until [`Self::init`].
    pub fn new(i2c: I2C, config: Config) -> Self {
        Self {
            i2c,
            config,
            initialised: false,
        }
    }

    /// Check both WHO_AM_I registers, then write the configuration
    /// ([`Config::accel_gyro_writes`], then [`Config::mag_writes`]).
    pub fn init(&mut self) -> Result<(), Error<I2C::Error>> {
        self.initialised = false;
        let ag = self.config.accel_gyro_address();
        let mag = self.config.mag_address();
        let found = self.read_register(ag, accel_gyro_reg::WHO_AM_I)?;
        if found != ACCEL_GYRO_WHO_AM_I {
            return Err(Error::WrongAccelGyroId { address: ag, found });
        }
        let found = self.read_register(mag, mag_reg::WHO_AM_I_M)?;
        if found != MAG_WHO_AM_I {
            return Err(Error::WrongMagId {
                address: mag,
                found,
            });
        }
        for (register, value) in self.config.accel_gyro_writes() {
            self.write_register(ag, register, value)?;
        }
        for (register, value) in self.config.mag_writes() {
            self.write_register(mag, register, value)?;
        }
        self.initialised = true;
        Ok(())
    }

    /// The configuration this driver applies.
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// Give the bus back.
    pub fn release(self) -> I2C {
        self.i2c
    }

    fn read_register(&mut self, address: u8, register: u8) -> Result<u8, Error<I2C::Error>> {
        let mut value = [0u8; 1];
        self.i2c
            .write_read(address, &[register], &mut value)
            .map_err(Error::Bus)?;
        let [value] = value;
        Ok(value)
    }

    fn write_register(
        &mut self,
        address: u8,
        register: u8,
        value: u8,
    ) -> Result<(), Error<I2C::Error>> {
        self.i2c
            .write(address, &[register, value])
            .map_err(Error::Bus)
    }
}

/// Three little-endian 16-bit values.
fn vector_from_le(bytes: [u8; 6]) -> [i16; 3] {
    let [xl, xh, yl, yh, zl, zh] = bytes;
    [
        i16::from_le_bytes([xl, xh]),
        i16::from_le_bytes([yl, yh]),
        i16::from_le_bytes([zl, zh]),
    ]
}

impl<I2C: I2c> Imu for Lsm9ds1<I2C> {
    type Error = Error<I2C::Error>;

    fn scales(&self) -> SensorScales {
        self.config.scales()
    }

    fn read(&mut self) -> Result<RawSample, Self::Error> {
        self.read_with_status().map(|reading| reading.sample)
    }

    /// Three bursts: temperature, STATUS_REG and gyroscope (0x15..0x1D), accelerometer
    /// (0x28..0x2D), STATUS_REG_M and magnetometer (0x27..0x2D with the auto-increment bit).
    /// Each status byte is read before the outputs it describes, so a conversion landing during
    /// the read shows as new on the next read instead of being lost.
    fn read_with_status(&mut self) -> Result<Reading, Self::Error> {
        if !self.initialised {
            return Err(Error::NotInitialised);
        }
        let ag = self.config.accel_gyro_address();
        let mut temp_status_gyro = [0u8; 9];
        self.i2c
            .write_read(ag, &[accel_gyro_reg::OUT_TEMP_L], &mut temp_status_gyro)
            .map_err(Error::Bus)?;
        let mut accel = [0u8; 6];
        self.i2c
            .write_read(ag, &[accel_gyro_reg::OUT_X_L_XL], &mut accel)
            .map_err(Error::Bus)?;
        let mut status_mag = [0u8; 7];
        self.i2c
            .write_read(
                self.config.mag_address(),
                &[mag_reg::STATUS_REG_M | mag_reg::AUTO_INCREMENT],
                &mut status_mag,
            )
            .map_err(Error::Bus)?;

        let [tl, th, status, gxl, gxh, gyl, gyh, gzl, gzh] = temp_status_gyro;
        let [status_m, mxl, mxh, myl, myh, mzl, mzh] = status_mag;
        let mut mag = vector_from_le([mxl, mxh, myl, myh, mzl, mzh]);
        if self.config.mag_axes == MagAxes::AlignedToAccelGyro {
            let [x, _, _] = &mut mag;
            *x = x.saturating_neg();
        }
        Ok(Reading {
            sample: RawSample {
                accel: vector_from_le(accel),
                gyro: vector_from_le([gxl, gxh, gyl, gyh, gzl, gzh]),
                mag,
                temp: i16::from_le_bytes([tl, th]),
            },
            // Both flags: the accelerometer and gyroscope convert together when both run.
            new_data: NewData {
                accel_gyro: status & (STATUS_XLDA | STATUS_GDA) != 0,
                mag: status_m & STATUS_M_ZYXDA != 0,
                mag_overrun: status_m & STATUS_M_ZYXOR != 0,
            },
        })
    }
}
