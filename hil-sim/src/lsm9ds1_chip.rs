//! Register-level emulation of the ST LSM9DS1 on I²C, for running the real driver in simulation.
//!
//! Two devices answer, as on the chip: the accelerometer/gyroscope (0x6B, or 0x6A with SDO_A/G
//! low) and the magnetometer (0x1E, or 0x1C with SDO_M low). Modelled, from the ST LSM9DS1
//! datasheet (DocID025715): WHO_AM_I (0x68 / 0x3D); power-on register defaults; the register
//! pointer and its advance (A/G: IF_ADD_INC in CTRL_REG8; M: bit 7 of the sub-address); full
//! scales (FS_XL, FS_G, FS) with the sensitivities of datasheet table 3; power-down (ODR = 0,
//! MD = 1x) reading as zero; the magnetometer hard-iron offset registers; software reset.
//! Output registers are derived on every read from the physical state set by
//! [`Lsm9ds1Chip::set_physical`]: divided by the sensitivity, rounded to the nearest count and
//! clamped to the nominal full scale and the 16-bit range (temperature: 16 counts/°C around
//! 25 °C, 12-bit).
//!
//! Conversion timing is optional ([`Lsm9ds1Chip::run_on_own_clock`], [`conversion`]): the chip
//! converts at its output data rate off by a relative error, latches its outputs at each
//! conversion and raises the data-ready flags (XLDA/GDA/TDA, ZYXDA, and ZYXOR on a magnetometer
//! overrun), which reading the outputs clears. Without it, outputs follow the physical state on
//! every read and data is always ready.
//!
//! Not modelled (stored, without effect): filters and bandwidths, FIFO, interrupts, self-test,
//! single-conversion mode (treated as continuous). Block data update is implicit: the state
//! never changes during a transaction. A powered-down sensor reads 0 where the real chip holds
//! its last sample.
//!
//! Writes to reserved or read-only registers, and the unavailable gyroscope full-scale code 10,
//! are refused with an error: ST warns that writing reserved registers can damage the device, so a
//! driver that does it is wrong even though the real chip would acknowledge.

mod conversion;

use embedded_hal::i2c::{self, ErrorKind, NoAcknowledgeSource, Operation};
use imucal_firmware::lsm9ds1::SdoLevel;

use conversion::ChipClock;

/// Standard gravity, m/s² per g.
const STANDARD_GRAVITY_MPS2: f64 = 9.806_65;
/// rad/s per °/s.
const RAD_PER_DEG: f64 = std::f64::consts::PI / 180.0;
/// µT per gauss.
const MICROTESLA_PER_GAUSS: f64 = 100.0;
/// Temperature sensitivity, counts per °C, and the temperature at zero counts.
const TEMP_COUNTS_PER_DEG_C: f64 = 16.0;
const TEMP_AT_ZERO_COUNTS_C: f64 = 25.0;
/// The temperature output is 12-bit two's complement, sign-extended to 16 bits.
const TEMP_COUNT_MIN: f64 = -2048.0;
const TEMP_COUNT_MAX: f64 = 2047.0;

/// Number of register addresses of each device (7-bit sub-address).
const REGISTER_COUNT: usize = 0x80;

// Accelerometer/gyroscope registers.
const AG_WHO_AM_I: u8 = 0x0F;
const CTRL_REG1_G: u8 = 0x10;
const OUT_TEMP_L: u8 = 0x15;
const OUT_TEMP_H: u8 = 0x16;
const AG_STATUS_REG: u8 = 0x17;
const OUT_X_L_G: u8 = 0x18;
const CTRL_REG4: u8 = 0x1E;
const CTRL_REG5_XL: u8 = 0x1F;
const CTRL_REG6_XL: u8 = 0x20;
const CTRL_REG8: u8 = 0x22;
const AG_STATUS_REG_2: u8 = 0x27;
const OUT_X_L_XL: u8 = 0x28;
const CTRL_REG8_IF_ADD_INC: u8 = 1 << 2;
const CTRL_REG8_SW_RESET: u8 = 1 << 0;

// Magnetometer registers.
const OFFSET_X_REG_L_M: u8 = 0x05;
const M_WHO_AM_I: u8 = 0x0F;
const CTRL_REG1_M: u8 = 0x20;
const CTRL_REG2_M: u8 = 0x21;
const CTRL_REG3_M: u8 = 0x22;
const STATUS_REG_M: u8 = 0x27;
const OUT_X_L_M: u8 = 0x28;
const CTRL_REG2_M_SOFT_RST: u8 = 1 << 2;
const M_AUTO_INCREMENT: u8 = 0x80;

/// What a register address of a device is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Access {
    ReadWrite,
    ReadOnly,
    Reserved,
}

/// Register map of the accelerometer/gyroscope (datasheet table 21).
fn accel_gyro_access(register: u8) -> Access {
    match register {
        0x04..=0x0D | 0x10..=0x13 | 0x1E..=0x24 | 0x2E | 0x30..=0x37 => Access::ReadWrite,
        0x0F | 0x14..=0x1D | 0x26..=0x2D | 0x2F => Access::ReadOnly,
        _ => Access::Reserved,
    }
}

/// Register map of the magnetometer (datasheet table 21).
fn mag_access(register: u8) -> Access {
    match register {
        0x05..=0x0A | 0x20..=0x24 | 0x30 | 0x32..=0x33 => Access::ReadWrite,
        0x0F | 0x27..=0x2D | 0x31 => Access::ReadOnly,
        _ => Access::Reserved,
    }
}

/// Power-on contents of the accelerometer/gyroscope registers (datasheet section 7).
fn accel_gyro_defaults() -> [u8; REGISTER_COUNT] {
    let mut registers = [0u8; REGISTER_COUNT];
    registers[usize::from(AG_WHO_AM_I)] = 0x68;
    registers[usize::from(CTRL_REG4)] = 0x38;
    registers[usize::from(CTRL_REG5_XL)] = 0x38;
    registers[usize::from(CTRL_REG8)] = CTRL_REG8_IF_ADD_INC;
    registers
}

/// Power-on contents of the magnetometer registers (datasheet section 8): 10 Hz, ±4 gauss,
/// powered down.
fn mag_defaults() -> [u8; REGISTER_COUNT] {
    let mut registers = [0u8; REGISTER_COUNT];
    registers[usize::from(M_WHO_AM_I)] = 0x3D;
    registers[usize::from(CTRL_REG1_M)] = 0x10;
    registers[usize::from(CTRL_REG3_M)] = 0x03;
    registers
}

/// Which device of the package a transfer addresses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Device {
    AccelGyro,
    Mag,
}

/// Why the emulated chip refused a transfer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Lsm9ds1ChipError {
    /// No device answers at this I²C address.
    NoDeviceAtAddress {
        /// The 7-bit address used.
        address: u8,
    },
    /// A write touched a register the datasheet marks reserved.
    ReservedRegisterWrite {
        /// Device address.
        address: u8,
        /// Register address.
        register: u8,
    },
    /// A write touched a read-only register.
    ReadOnlyRegisterWrite {
        /// Device address.
        address: u8,
        /// Register address.
        register: u8,
    },
    /// A control register was given a field code the datasheet lists as not available.
    UnavailableSetting {
        /// Device address.
        address: u8,
        /// Register address.
        register: u8,
        /// Value written.
        value: u8,
    },
}

impl std::fmt::Display for Lsm9ds1ChipError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::NoDeviceAtAddress { address } => write!(
                f,
                "no LSM9DS1 device acknowledges I2C address {address:#04x}; use 0x6b/0x6a for the \
                 accelerometer/gyroscope or 0x1e/0x1c for the magnetometer, matching the SDO pins"
            ),
            Self::ReservedRegisterWrite { address, register } => write!(
                f,
                "write to reserved register {register:#04x} of device {address:#04x}; reserved \
                 registers must not be written (datasheet table 21)"
            ),
            Self::ReadOnlyRegisterWrite { address, register } => write!(
                f,
                "write to read-only register {register:#04x} of device {address:#04x}; only \
                 control registers can be written"
            ),
            Self::UnavailableSetting {
                address,
                register,
                value,
            } => write!(
                f,
                "value {value:#04x} written to register {register:#04x} of device {address:#04x} \
                 selects a full scale the datasheet lists as not available; use FS_G 00, 01 or 11"
            ),
        }
    }
}

impl std::error::Error for Lsm9ds1ChipError {}

impl i2c::Error for Lsm9ds1ChipError {
    fn kind(&self) -> ErrorKind {
        match self {
            Self::NoDeviceAtAddress { .. } => {
                ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address)
            }
            _ => ErrorKind::Other,
        }
    }
}

/// A physical input the chip cannot represent.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NonFinitePhysicalValue {
    /// Which input: "accelerometer", "gyroscope", "magnetometer" or "temperature".
    pub quantity: &'static str,
}

impl std::fmt::Display for NonFinitePhysicalValue {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "the {} input to the LSM9DS1 emulation is not finite; the world model produced \
             NaN or infinity and must be fixed",
            self.quantity
        )
    }
}

impl std::error::Error for NonFinitePhysicalValue {}

/// Physical quantities seen by the chip, all in the accelerometer/gyroscope frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct Physical {
    accel_mps2: [f64; 3],
    gyro_rads: [f64; 3],
    mag_ut: [f64; 3],
    temp_c: f64,
}

/// An emulated LSM9DS1 on an I²C bus.
///
/// Use it directly or through `&mut` as the bus of a driver; set what the chip senses with
/// [`Self::set_physical`].
#[derive(Debug, Clone)]
pub struct Lsm9ds1Chip {
    accel_gyro_address: u8,
    mag_address: u8,
    accel_gyro_registers: [u8; REGISTER_COUNT],
    mag_registers: [u8; REGISTER_COUNT],
    accel_gyro_pointer: u8,
    mag_pointer: u8,
    mag_auto_increment: bool,
    physical: Physical,
    /// The chip's own conversion timebase, when modelled.
    clock: Option<ChipClock>,
}

impl Default for Lsm9ds1Chip {
    /// Both SDO pins high, as on the Arduino Nano 33 BLE Sense (0x6B and 0x1E).
    fn default() -> Self {
        Self::new(SdoLevel::High, SdoLevel::High)
    }
}

impl Lsm9ds1Chip {
    /// A chip just after power-on, with the given SDO pin levels, sensing nothing at 25 °C.
    pub fn new(sdo_accel_gyro: SdoLevel, sdo_mag: SdoLevel) -> Self {
        Self {
            accel_gyro_address: match sdo_accel_gyro {
                SdoLevel::High => 0x6B,
                SdoLevel::Low => 0x6A,
            },
            mag_address: match sdo_mag {
                SdoLevel::High => 0x1E,
                SdoLevel::Low => 0x1C,
            },
            accel_gyro_registers: accel_gyro_defaults(),
            mag_registers: mag_defaults(),
            accel_gyro_pointer: 0,
            mag_pointer: 0,
            mag_auto_increment: false,
            physical: Physical {
                temp_c: TEMP_AT_ZERO_COUNTS_C,
                ..Physical::default()
            },
            clock: None,
        }
    }

    /// Convert on the chip's own oscillator from now on: output data rates are the nominal ones
    /// times `1 + odr_error` (e.g. ±0.005 for ±0.5 %), outputs change only at conversions, and
    /// the data-ready flags say whether a read gets a new one. Time starts at 0 s and moves with
    /// [`Self::advance_time`].
    pub fn run_on_own_clock(&mut self, odr_error: f64) {
        self.clock = Some(ChipClock::new(odr_error));
    }

    /// The relative output data rate error of a chip on its own clock; `None` when conversion
    /// timing is not modelled.
    pub fn odr_error(&self) -> Option<f64> {
        self.clock.as_ref().map(ChipClock::odr_error)
    }

    /// Move the chip's time to `t_s`, latching the current physical state into the outputs of
    /// every sensor that converted since the previous call. No effect without
    /// [`Self::run_on_own_clock`].
    pub fn advance_time(&mut self, t_s: f64) {
        let (accel_gyro_hz, mag_hz) = (self.accel_gyro_rate_hz(), self.mag_rate_hz());
        let Some(clock) = self.clock.as_mut() else {
            return;
        };
        let converted = clock.advance(t_s, accel_gyro_hz, mag_hz);
        let (accel, gyro, temp, mag) = (
            self.accel_counts(),
            self.gyro_counts(),
            self.temp_counts(),
            self.mag_counts(),
        );
        if let Some(clock) = self.clock.as_mut() {
            if converted.accel_gyro {
                clock.outputs.accel = accel;
                clock.outputs.gyro = gyro;
                clock.outputs.temp = temp;
            }
            if converted.mag {
                clock.outputs.mag = mag;
            }
        }
    }

    /// Reading an output register consumes the conversion it holds: the sensor's data-ready
    /// (and for the magnetometer, overrun) flags clear. Accelerometer and gyroscope share one
    /// flag here (they convert together); reading the temperature leaves it set, as XLDA/GDA
    /// are on the chip.
    fn clear_on_output_read(&mut self, device: Device, register: u8) {
        let Some(clock) = self.clock.as_mut() else {
            return;
        };
        match (device, register) {
            (Device::AccelGyro, OUT_X_L_G..=0x1D | OUT_X_L_XL..=0x2D) => {
                clock.outputs.accel_gyro_ready = false;
            }
            (Device::Mag, OUT_X_L_M..=0x2D) => {
                clock.outputs.mag_ready = false;
                clock.outputs.mag_overrun = false;
            }
            _ => {}
        }
    }

    /// Set what the chip senses: specific force (m/s²), angular rate (rad/s) and magnetic field
    /// (µT), all along the accelerometer/gyroscope axes of the package, and die temperature (°C).
    ///
    /// The magnetometer element's X axis is opposite to the A/G X axis (datasheet figure 1), so
    /// its X output register holds the negated field X.
    pub fn set_physical(
        &mut self,
        accel_mps2: [f64; 3],
        gyro_rads: [f64; 3],
        mag_ut: [f64; 3],
        temp_c: f64,
    ) -> Result<(), NonFinitePhysicalValue> {
        let check = |values: &[f64], quantity| {
            if values.iter().all(|v| v.is_finite()) {
                Ok(())
            } else {
                Err(NonFinitePhysicalValue { quantity })
            }
        };
        check(&accel_mps2, "accelerometer")?;
        check(&gyro_rads, "gyroscope")?;
        check(&mag_ut, "magnetometer")?;
        check(&[temp_c], "temperature")?;
        self.physical = Physical {
            accel_mps2,
            gyro_rads,
            mag_ut,
            temp_c,
        };
        Ok(())
    }

    /// I²C address of the accelerometer/gyroscope device.
    pub fn accel_gyro_address(&self) -> u8 {
        self.accel_gyro_address
    }

    /// I²C address of the magnetometer device.
    pub fn mag_address(&self) -> u8 {
        self.mag_address
    }

    /// Accelerometer/gyroscope output data rate in Hz as configured, or `None` when powered
    /// down or set to the unlisted code 111. With the gyroscope on, ODR_G sets both sensors' rate.
    pub fn accel_gyro_rate_hz(&self) -> Option<f64> {
        const GYRO_HZ: [f64; 6] = [14.9, 59.5, 119.0, 238.0, 476.0, 952.0];
        const ACCEL_ONLY_HZ: [f64; 6] = [10.0, 50.0, 119.0, 238.0, 476.0, 952.0];
        let odr_g = self.ag(CTRL_REG1_G) >> 5;
        let odr_xl = self.ag(CTRL_REG6_XL) >> 5;
        match (odr_g, odr_xl) {
            (0, 0) => None,
            (0, code) => ACCEL_ONLY_HZ.get(usize::from(code - 1)).copied(),
            (code, _) => GYRO_HZ.get(usize::from(code - 1)).copied(),
        }
    }

    /// Magnetometer output data rate in Hz as configured, or `None` when powered down.
    pub fn mag_rate_hz(&self) -> Option<f64> {
        const DO_HZ: [f64; 8] = [0.625, 1.25, 2.5, 5.0, 10.0, 20.0, 40.0, 80.0];
        if !self.mag_converting() {
            return None;
        }
        DO_HZ
            .get(usize::from((self.m(CTRL_REG1_M) >> 2) & 0b111))
            .copied()
    }

    /// Current content of a register of the device at `address` (outputs as they would read
    /// now), or `None` for an address no device answers to.
    pub fn register(&self, address: u8, register: u8) -> Option<u8> {
        let device = self.device(address).ok()?;
        Some(self.read_register(device, register & 0x7F))
    }

    fn ag(&self, register: u8) -> u8 {
        self.accel_gyro_registers
            .get(usize::from(register))
            .copied()
            .unwrap_or(0)
    }

    fn m(&self, register: u8) -> u8 {
        self.mag_registers
            .get(usize::from(register))
            .copied()
            .unwrap_or(0)
    }

    fn gyro_on(&self) -> bool {
        self.ag(CTRL_REG1_G) >> 5 != 0
    }

    fn accel_on(&self) -> bool {
        self.gyro_on() || self.ag(CTRL_REG6_XL) >> 5 != 0
    }

    fn mag_converting(&self) -> bool {
        // MD: 00 continuous, 01 single conversion (treated as continuous), 1x power-down.
        self.m(CTRL_REG3_M) & 0b10 == 0
    }

    /// Accelerometer sensitivity (m/s² per count) and full scale (m/s²) from FS_XL.
    fn accel_scale(&self) -> (f64, f64) {
        let (mg_per_count, full_scale_g) = match (self.ag(CTRL_REG6_XL) >> 3) & 0b11 {
            0b00 => (0.061, 2.0),
            0b01 => (0.732, 16.0),
            0b10 => (0.122, 4.0),
            _ => (0.244, 8.0),
        };
        (
            mg_per_count * 1e-3 * STANDARD_GRAVITY_MPS2,
            full_scale_g * STANDARD_GRAVITY_MPS2,
        )
    }

    /// Gyroscope sensitivity (rad/s per count) and full scale (rad/s) from FS_G. The code 10 is
    /// refused on write and never stored.
    fn gyro_scale(&self) -> (f64, f64) {
        let (mdps_per_count, full_scale_dps) = match (self.ag(CTRL_REG1_G) >> 3) & 0b11 {
            0b00 => (8.75, 245.0),
            0b01 => (17.50, 500.0),
            _ => (70.0, 2000.0),
        };
        (
            mdps_per_count * 1e-3 * RAD_PER_DEG,
            full_scale_dps * RAD_PER_DEG,
        )
    }

    /// Magnetometer sensitivity (µT per count) and full scale (µT) from FS.
    fn mag_scale(&self) -> (f64, f64) {
        let (mgauss_per_count, full_scale_gauss) = match (self.m(CTRL_REG2_M) >> 5) & 0b11 {
            0b00 => (0.14, 4.0),
            0b01 => (0.29, 8.0),
            0b10 => (0.43, 12.0),
            _ => (0.58, 16.0),
        };
        (
            mgauss_per_count * 1e-3 * MICROTESLA_PER_GAUSS,
            full_scale_gauss * MICROTESLA_PER_GAUSS,
        )
    }

    /// Output counts of one sensor axis: quantised to the nearest count, then clamped to the
    /// nominal full scale and to the 16-bit range.
    fn counts(value: f64, (per_count, full_scale): (f64, f64)) -> i16 {
        let limit = (full_scale / per_count).round();
        let upper = limit.min(f64::from(i16::MAX));
        let lower = (-limit).max(f64::from(i16::MIN));
        // In range after the clamp, so the cast is exact.
        (value / per_count).round().clamp(lower, upper) as i16
    }

    fn accel_counts(&self) -> [i16; 3] {
        if !self.accel_on() {
            return [0; 3];
        }
        let scale = self.accel_scale();
        self.physical.accel_mps2.map(|v| Self::counts(v, scale))
    }

    fn gyro_counts(&self) -> [i16; 3] {
        if !self.gyro_on() {
            return [0; 3];
        }
        let scale = self.gyro_scale();
        self.physical.gyro_rads.map(|v| Self::counts(v, scale))
    }

    /// Magnetometer counts on the element's own axes, less the hard-iron offset registers.
    fn mag_counts(&self) -> [i16; 3] {
        if !self.mag_converting() {
            return [0; 3];
        }
        let scale = self.mag_scale();
        let [x, y, z] = self.physical.mag_ut;
        let mut out = [0i16; 3];
        for ((slot, field), axis) in out.iter_mut().zip([-x, y, z]).zip(0u8..) {
            let offset_register = OFFSET_X_REG_L_M + 2 * axis;
            let offset = i16::from_le_bytes([self.m(offset_register), self.m(offset_register + 1)]);
            let (per_count, _) = scale;
            *slot = Self::counts(field - f64::from(offset) * per_count, scale);
        }
        out
    }

    fn temp_counts(&self) -> i16 {
        if !self.accel_on() {
            return 0;
        }
        let counts = ((self.physical.temp_c - TEMP_AT_ZERO_COUNTS_C) * TEMP_COUNTS_PER_DEG_C)
            .round()
            .clamp(TEMP_COUNT_MIN, TEMP_COUNT_MAX);
        counts as i16
    }

    /// Low (even offset) or high byte of the little-endian vector output at `offset` 0..6.
    fn vector_byte(vector: [i16; 3], offset: u8) -> u8 {
        let value = vector.get(usize::from(offset / 2)).copied().unwrap_or(0);
        let [low, high] = value.to_le_bytes();
        if offset & 1 == 0 {
            low
        } else {
            high
        }
    }

    fn read_register(&self, device: Device, register: u8) -> u8 {
        if let Some(clock) = &self.clock {
            if let Some(value) = self.latched_register(clock, device, register) {
                return value;
            }
        }
        match device {
            Device::AccelGyro => match register {
                OUT_TEMP_L => self.temp_counts().to_le_bytes()[0],
                OUT_TEMP_H => self.temp_counts().to_le_bytes()[1],
                AG_STATUS_REG | AG_STATUS_REG_2 => {
                    // TDA | GDA | XLDA: new data always available.
                    (u8::from(self.accel_on()) * 0b101) | (u8::from(self.gyro_on()) << 1)
                }
                r @ OUT_X_L_G..=0x1D => Self::vector_byte(self.gyro_counts(), r - OUT_X_L_G),
                r @ OUT_X_L_XL..=0x2D => Self::vector_byte(self.accel_counts(), r - OUT_X_L_XL),
                r => self.ag(r),
            },
            Device::Mag => match register {
                // ZYXDA | ZDA | YDA | XDA when converting.
                STATUS_REG_M => u8::from(self.mag_converting()) * 0x0F,
                r @ OUT_X_L_M..=0x2D => Self::vector_byte(self.mag_counts(), r - OUT_X_L_M),
                r => self.m(r),
            },
        }
    }

    /// Status and output registers of a chip on its own clock; `None` for the others.
    fn latched_register(&self, clock: &ChipClock, device: Device, register: u8) -> Option<u8> {
        let out = &clock.outputs;
        let value = match (device, register) {
            (Device::AccelGyro, OUT_TEMP_L) => out.temp.to_le_bytes()[0],
            (Device::AccelGyro, OUT_TEMP_H) => out.temp.to_le_bytes()[1],
            (Device::AccelGyro, AG_STATUS_REG | AG_STATUS_REG_2) => {
                let ready = u8::from(out.accel_gyro_ready);
                // TDA | GDA | XLDA, for the sensors that run.
                (ready * u8::from(self.accel_on()) * 0b101)
                    | ((ready * u8::from(self.gyro_on())) << 1)
            }
            (Device::AccelGyro, r @ OUT_X_L_G..=0x1D) => Self::vector_byte(out.gyro, r - OUT_X_L_G),
            (Device::AccelGyro, r @ OUT_X_L_XL..=0x2D) => {
                Self::vector_byte(out.accel, r - OUT_X_L_XL)
            }
            (Device::Mag, STATUS_REG_M) => {
                // ZYXOR | ZOR | YOR | XOR, ZYXDA | ZDA | YDA | XDA.
                (u8::from(out.mag_overrun) * 0xF0) | (u8::from(out.mag_ready) * 0x0F)
            }
            (Device::Mag, r @ OUT_X_L_M..=0x2D) => Self::vector_byte(out.mag, r - OUT_X_L_M),
            _ => return None,
        };
        Some(value)
    }

    fn write_register(
        &mut self,
        device: Device,
        register: u8,
        value: u8,
    ) -> Result<(), Lsm9ds1ChipError> {
        let (address, access) = match device {
            Device::AccelGyro => (self.accel_gyro_address, accel_gyro_access(register)),
            Device::Mag => (self.mag_address, mag_access(register)),
        };
        match access {
            Access::Reserved => {
                return Err(Lsm9ds1ChipError::ReservedRegisterWrite { address, register })
            }
            Access::ReadOnly => {
                return Err(Lsm9ds1ChipError::ReadOnlyRegisterWrite { address, register })
            }
            Access::ReadWrite => {}
        }
        match (device, register) {
            (Device::AccelGyro, CTRL_REG1_G) if (value >> 3) & 0b11 == 0b10 => {
                Err(Lsm9ds1ChipError::UnavailableSetting {
                    address,
                    register,
                    value,
                })
            }
            (Device::AccelGyro, CTRL_REG8) if value & CTRL_REG8_SW_RESET != 0 => {
                self.accel_gyro_registers = accel_gyro_defaults();
                Ok(())
            }
            (Device::Mag, CTRL_REG2_M) if value & CTRL_REG2_M_SOFT_RST != 0 => {
                self.mag_registers = mag_defaults();
                Ok(())
            }
            (Device::AccelGyro, r) => {
                if let Some(slot) = self.accel_gyro_registers.get_mut(usize::from(r)) {
                    *slot = value;
                }
                Ok(())
            }
            (Device::Mag, r) => {
                if let Some(slot) = self.mag_registers.get_mut(usize::from(r)) {
                    *slot = value;
                }
                Ok(())
            }
        }
    }

    fn device(&self, address: u8) -> Result<Device, Lsm9ds1ChipError> {
        if address == self.accel_gyro_address {
            Ok(Device::AccelGyro)
        } else if address == self.mag_address {
            Ok(Device::Mag)
        } else {
            Err(Lsm9ds1ChipError::NoDeviceAtAddress { address })
        }
    }

    /// Register pointer after one byte: A/G advances when IF_ADD_INC is set, M when the
    /// sub-address carried bit 7. The pointer wraps within the 7-bit register space.
    fn advance(&mut self, device: Device) {
        match device {
            Device::AccelGyro => {
                if self.ag(CTRL_REG8) & CTRL_REG8_IF_ADD_INC != 0 {
                    self.accel_gyro_pointer = (self.accel_gyro_pointer + 1) & 0x7F;
                }
            }
            Device::Mag => {
                if self.mag_auto_increment {
                    self.mag_pointer = (self.mag_pointer + 1) & 0x7F;
                }
            }
        }
    }

    fn pointer(&self, device: Device) -> u8 {
        match device {
            Device::AccelGyro => self.accel_gyro_pointer,
            Device::Mag => self.mag_pointer,
        }
    }

    fn set_sub_address(&mut self, device: Device, sub_address: u8) {
        match device {
            Device::AccelGyro => self.accel_gyro_pointer = sub_address & 0x7F,
            Device::Mag => {
                self.mag_pointer = sub_address & 0x7F;
                self.mag_auto_increment = sub_address & M_AUTO_INCREMENT != 0;
            }
        }
    }
}

impl i2c::ErrorType for Lsm9ds1Chip {
    type Error = Lsm9ds1ChipError;
}

impl i2c::I2c for Lsm9ds1Chip {
    /// Writes after a (repeated) start begin with the sub-address; further bytes go to
    /// consecutive registers. Reads return registers from the pointer. The pointer persists
    /// between transactions, as on the chip.
    fn transaction(
        &mut self,
        address: u8,
        operations: &mut [Operation<'_>],
    ) -> Result<(), Self::Error> {
        let device = self.device(address)?;
        // Adjacent writes are one write on the wire: only the first byte after a start is the
        // sub-address.
        let mut expecting_sub_address = true;
        for operation in operations {
            match operation {
                Operation::Write(bytes) => {
                    for &byte in bytes.iter() {
                        if expecting_sub_address {
                            self.set_sub_address(device, byte);
                            expecting_sub_address = false;
                        } else {
                            self.write_register(device, self.pointer(device), byte)?;
                            self.advance(device);
                        }
                    }
                }
                Operation::Read(buffer) => {
                    for byte in buffer.iter_mut() {
                        let register = self.pointer(device);
                        *byte = self.read_register(device, register);
                        self.clear_on_output_read(device, register);
                        self.advance(device);
                    }
                    expecting_sub_address = true;
                }
            }
        }
        Ok(())
    }
}
