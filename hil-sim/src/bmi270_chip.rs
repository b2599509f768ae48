//! Register-level emulation of the Bosch BMI270 (0x68) and the BMM150 (0x10) on one I²C bus, as
//! on the Arduino Nano 33 BLE Sense Rev2, for running the real driver in simulation.
//!
//! BMI270 (datasheet BST-BMI270-DS000): CHIP_ID 0x24; power-on defaults of the registers the
//! driver touches; auto-incrementing register pointer; the configuration load — bursts to
//! INIT_DATA (0x5E) land at the word offset set in INIT_ADDR_0/1 and are refused while advanced
//! power save (PWR_CONF bit 0) is on or INIT_CTRL is 1; INIT_CTRL = 1 checks the loaded image
//! against the expected file and sets INTERNAL_STATUS to 1 ("init ok") or 2 ("init err");
//! until then, and for sensors off in PWR_CTRL, data registers read 0; ACC_RANGE/GYR_RANGE set
//! the sensitivities (32768 counts per full scale); STATUS bits 7/6 are set by each new sample
//! and cleared by reading the accelerometer data; temperature 512 counts/K around 23 °C;
//! CMD 0xB6 soft reset.
//!
//! BMM150 (datasheet BST-BMM150-DS001): suspended after power-on (only POWER_CTRL 0x4B answers,
//! CHIP_ID reads 0); with the power bit set CHIP_ID reads 0x32; in normal mode (OP_MODE bits
//! 2:1 = 00) the data registers hold X/Y 13-bit and Z 15-bit left-aligned counts of 0.3 µT (an
//! ideal part: Bosch's trim compensation is the identity here) with the data-ready bit set.
//!
//! Not modelled: the configuration file's features (the image is only compared), FIFO,
//! interrupts, the auxiliary interface (the BMM150 sits on the main bus, as on the Rev2),
//! filters, self-test, data-rate timing. Both chips sense in the same frame.

use embedded_hal::i2c::{self, ErrorKind, NoAcknowledgeSource, Operation};
use imucal_firmware::bmi270::{self as driver, reg};
use imucal_firmware::bmm150::{self as mag_driver, reg as mag_reg};

/// Standard gravity, m/s² per g.
const STANDARD_GRAVITY_MPS2: f64 = 9.806_65;
/// Register count of each device.
const REGISTERS: usize = 0x80;

/// Why the emulated bus refused a transfer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Bmi270ChipError {
    /// No device answers at this address.
    NoDeviceAtAddress(u8),
    /// A configuration burst arrived while the chip cannot take it (advanced power save on, or
    /// INIT_CTRL = 1): the datasheet's load sequence was not followed.
    ConfigWriteRefused,
    /// A configuration burst runs past the chip's 8 KiB image.
    ConfigOverflow,
}

impl std::fmt::Display for Bmi270ChipError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::NoDeviceAtAddress(a) => write!(f, "no device answers at I²C address {a:#04x}"),
            Self::ConfigWriteRefused => write!(
                f,
                "INIT_DATA written with advanced power save on or INIT_CTRL = 1; the driver must \
                 clear PWR_CONF and INIT_CTRL before loading the configuration"
            ),
            Self::ConfigOverflow => write!(f, "configuration burst past the 8 KiB image"),
        }
    }
}

impl std::error::Error for Bmi270ChipError {}

impl i2c::Error for Bmi270ChipError {
    fn kind(&self) -> ErrorKind {
        match self {
            Self::NoDeviceAtAddress(_) => ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address),
            _ => ErrorKind::NoAcknowledge(NoAcknowledgeSource::Data),
        }
    }
}

/// Size of the BMI270's configuration image, bytes.
pub const CONFIG_IMAGE_LEN: usize = 8192;

/// The emulated pair of chips.
#[derive(Debug, Clone)]
pub struct Bmi270Chip {
    regs: [u8; REGISTERS],
    mag_regs: [u8; REGISTERS],
    pointer: u8,
    mag_pointer: u8,
    burst_offset: usize,
    image: Vec<u8>,
    expected_image: Vec<u8>,
    accel_mps2: [f64; 3],
    gyro_rads: [f64; 3],
    mag_ut: [f64; 3],
    temp_c: f64,
}

fn bmi270_defaults() -> [u8; REGISTERS] {
    let mut r = [0u8; REGISTERS];
    r[usize::from(reg::CHIP_ID)] = driver::CHIP_ID;
    r[usize::from(reg::ACC_CONF)] = 0xA8;
    r[usize::from(reg::ACC_RANGE)] = 0x02;
    r[usize::from(reg::GYR_CONF)] = 0xA9;
    r[usize::from(reg::PWR_CONF)] = 0x03;
    r
}

fn bmm150_defaults() -> [u8; REGISTERS] {
    let mut r = [0u8; REGISTERS];
    r[usize::from(mag_reg::OP_MODE)] = 0x06;
    r
}

/// Rounds `value / per_count` to a count within `[-limit, limit − 1]`.
fn counts(value: f64, per_count: f64, limit: f64) -> i16 {
    (value / per_count).round().clamp(-limit, limit - 1.0) as i16
}

impl Bmi270Chip {
    /// Chips just after power-on that accept `config_file` as the valid configuration image.
    pub fn new(config_file: &[u8]) -> Self {
        Self {
            regs: bmi270_defaults(),
            mag_regs: bmm150_defaults(),
            pointer: 0,
            mag_pointer: 0,
            burst_offset: 0,
            image: vec![0; CONFIG_IMAGE_LEN],
            expected_image: config_file.to_vec(),
            accel_mps2: [0.0; 3],
            gyro_rads: [0.0; 3],
            mag_ut: [0.0; 3],
            temp_c: 23.0,
        }
    }

    /// Sets what the chips sense (m/s², rad/s, µT, °C) and marks a new sample ready.
    /// Non-finite inputs are a bug of the world model and are refused.
    pub fn set_physical(
        &mut self,
        accel_mps2: [f64; 3],
        gyro_rads: [f64; 3],
        mag_ut: [f64; 3],
        temp_c: f64,
    ) -> Result<(), crate::lsm9ds1_chip::NonFinitePhysicalValue> {
        let all = accel_mps2.iter().chain(&gyro_rads).chain(&mag_ut);
        if !all.chain(std::iter::once(&temp_c)).all(|v| v.is_finite()) {
            return Err(crate::lsm9ds1_chip::NonFinitePhysicalValue {
                quantity: "BMI270/BMM150",
            });
        }
        (self.accel_mps2, self.gyro_rads, self.mag_ut, self.temp_c) =
            (accel_mps2, gyro_rads, mag_ut, temp_c);
        self.regs[usize::from(reg::STATUS)] |= 0xC0;
        Ok(())
    }

    /// INTERNAL_STATUS message (1 = init ok).
    pub fn internal_status(&self) -> u8 {
        self.regs[usize::from(reg::INTERNAL_STATUS)] & 0x0F
    }

    /// A BMI270 register as last written or reset.
    pub fn register(&self, register: u8) -> u8 {
        self.regs[usize::from(register & 0x7F)]
    }

    fn operational(&self) -> bool {
        self.internal_status() == driver::STATUS_INIT_OK
    }

    fn data_byte(&self, register: u8) -> u8 {
        let pwr = self.regs[usize::from(reg::PWR_CTRL)];
        let acc_fs_g = f64::from(2u8 << (self.regs[usize::from(reg::ACC_RANGE)] & 0x03));
        let gyr_fs_dps =
            2000.0 / f64::from(1u8 << (self.regs[usize::from(reg::GYR_RANGE)] & 0x07).min(4));
        let word = |value: i16, high: bool| value.to_le_bytes()[usize::from(high)];
        let on = |bit: u8| self.operational() && pwr & (1 << bit) != 0;
        match register {
            0x0C..=0x11 if on(2) => {
                let i = usize::from((register - 0x0C) / 2);
                let per = acc_fs_g * STANDARD_GRAVITY_MPS2 / 32768.0;
                word(counts(self.accel_mps2[i], per, 32768.0), register % 2 == 1)
            }
            0x12..=0x17 if on(1) => {
                let i = usize::from((register - 0x12) / 2);
                let per = gyr_fs_dps.to_radians() / 32768.0;
                word(counts(self.gyro_rads[i], per, 32768.0), register % 2 == 1)
            }
            0x22 | 0x23 => {
                // 0x8000 means "no valid temperature".
                let value = if on(3) {
                    counts(self.temp_c - 23.0, 1.0 / 512.0, 32767.0)
                } else {
                    i16::MIN
                };
                word(value, register == 0x23)
            }
            0x0C..=0x17 => 0,
            _ => self.regs[usize::from(register & 0x7F)],
        }
    }

    fn read_bmi270(&mut self) -> u8 {
        let register = self.pointer;
        let value = self.data_byte(register);
        if register == reg::ACC_X_LSB {
            self.regs[usize::from(reg::STATUS)] &= !0xC0;
        }
        if register != reg::INIT_DATA {
            self.pointer = (register + 1) & 0x7F;
        }
        value
    }

    fn write_bmi270(&mut self, value: u8) -> Result<(), Bmi270ChipError> {
        let register = self.pointer;
        match register {
            reg::INIT_DATA => {
                if self.regs[usize::from(reg::PWR_CONF)] & 1 != 0
                    || self.regs[usize::from(reg::INIT_CTRL)] != 0
                {
                    return Err(Bmi270ChipError::ConfigWriteRefused);
                }
                let word = usize::from(self.regs[usize::from(reg::INIT_ADDR_0)] & 0x0F)
                    | (usize::from(self.regs[usize::from(reg::INIT_ADDR_1)]) << 4);
                // The byte offset advances within a burst; INIT_ADDR keeps the burst's start.
                let offset = 2 * word + self.burst_offset;
                *self
                    .image
                    .get_mut(offset)
                    .ok_or(Bmi270ChipError::ConfigOverflow)? = value;
                self.burst_offset += 1;
                return Ok(());
            }
            reg::INIT_CTRL if value == 1 => {
                let loaded = &self.image[..self.expected_image.len().min(CONFIG_IMAGE_LEN)];
                let ok = !self.expected_image.is_empty() && loaded == self.expected_image;
                self.regs[usize::from(reg::INTERNAL_STATUS)] = if ok { 0x01 } else { 0x02 };
            }
            reg::CMD if value == 0xB6 => {
                let expected = std::mem::take(&mut self.expected_image);
                *self = Self::new(&expected);
                return Ok(());
            }
            _ => {}
        }
        self.regs[usize::from(register)] = value;
        self.pointer = (register + 1) & 0x7F;
        Ok(())
    }

    fn mag_byte(&self, register: u8) -> u8 {
        let powered = self.mag_regs[usize::from(mag_reg::POWER_CTRL)] & 1 == 1;
        if !powered && register != mag_reg::POWER_CTRL {
            return 0;
        }
        let normal = (self.mag_regs[usize::from(mag_reg::OP_MODE)] >> 1) & 0x03 == 0;
        let per = f64::from(mag_driver::UT_PER_COUNT);
        let left = |i: usize, bits: u32, flags: u8| {
            let limit = f64::from(1u32 << (bits - 1));
            let c = counts(self.mag_ut[i], per, limit);
            ((c << (16 - bits)) as u16 | u16::from(flags)).to_le_bytes()
        };
        match register {
            mag_reg::CHIP_ID => mag_driver::CHIP_ID,
            0x42..=0x49 if normal => {
                let bytes = [left(0, 13, 0), left(1, 13, 0), left(2, 15, 0), [0x01, 0x00]];
                let k = usize::from(register - 0x42);
                bytes[k / 2][k % 2]
            }
            0x42..=0x49 => 0,
            _ => self.mag_regs[usize::from(register & 0x7F)],
        }
    }
}

impl i2c::ErrorType for Bmi270Chip {
    type Error = Bmi270ChipError;
}

impl i2c::I2c for Bmi270Chip {
    /// The first byte written after a start is the register; further bytes go to consecutive
    /// registers (INIT_DATA keeps the pointer). Reads return registers from the pointer.
    fn transaction(
        &mut self,
        address: u8,
        operations: &mut [Operation<'_>],
    ) -> Result<(), Self::Error> {
        let is_mag = match address {
            driver::ADDRESS => false,
            mag_driver::ADDRESS => true,
            other => return Err(Bmi270ChipError::NoDeviceAtAddress(other)),
        };
        let mut expecting_register = true;
        for operation in operations {
            match operation {
                Operation::Write(bytes) => {
                    for &byte in bytes.iter() {
                        if expecting_register {
                            if is_mag {
                                self.mag_pointer = byte & 0x7F;
                            } else {
                                self.pointer = byte & 0x7F;
                                self.burst_offset = 0;
                            }
                            expecting_register = false;
                        } else if is_mag {
                            self.mag_regs[usize::from(self.mag_pointer)] = byte;
                            self.mag_pointer = (self.mag_pointer + 1) & 0x7F;
                        } else {
                            self.write_bmi270(byte)?;
                        }
                    }
                }
                Operation::Read(buffer) => {
                    for byte in buffer.iter_mut() {
                        *byte = if is_mag {
                            let value = self.mag_byte(self.mag_pointer);
                            self.mag_pointer = (self.mag_pointer + 1) & 0x7F;
                            value
                        } else {
                            self.read_bmi270()
                        };
                    }
                    expecting_register = true;
                }
            }
        }
        Ok(())
    }
}
