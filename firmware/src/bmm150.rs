//! Register-level driver for the Bosch BMM150 magnetometer over an embedded-hal 1.0 I²C bus
//! (the magnetometer of the Arduino Nano 33 BLE Sense Rev2, at 0x10 on the sensor bus).
//!
//! Registers and data format from the Bosch BMM150 datasheet (BST-BMM150-DS001), section 5:
//! CHIP_ID 0x40 reads 0x32 once the power-control bit (0x4B bit 0) is set; DATA_X/Y are 13-bit
//! and DATA_Z 15-bit two's complement, left-aligned in 0x42–0x47 (3 and 1 flag bits below);
//! RHALL 0x48–0x49 carries the data-ready bit (bit 0 of 0x48); OP_MODE 0x4C selects the data rate
//! (bits 5:3) and the mode (bits 2:1, 00 = normal); REPXY 0x51 and REPZ 0x52 the repetitions.
//!
//! Counts are returned uncompensated: Bosch's trim-register compensation (a non-linear function
//! of RHALL) is not applied. imucal's fit absorbs the linear gain and offset per axis; the
//! nominal sensitivity used is the datasheet's 0.3 µT per count for all axes.

use embedded_hal::i2c::I2c;

/// I²C address with CSB low and SDO low (Nano 33 BLE Sense Rev2).
pub const ADDRESS: u8 = 0x10;
/// CHIP_ID value.
pub const CHIP_ID: u8 = 0x32;
/// Nominal sensitivity, µT per count (datasheet table 2, typical resolution).
pub const UT_PER_COUNT: f32 = 0.3;

/// Register addresses (datasheet table 21).
pub mod reg {
    /// Chip identification, 0x32.
    pub const CHIP_ID: u8 = 0x40;
    /// DATA_X LSB; DATA_X MSB, DATA_Y, DATA_Z and RHALL follow up to 0x49.
    pub const DATA_X_LSB: u8 = 0x42;
    /// Power control (bit 0) and soft reset (bits 7 and 1).
    pub const POWER_CTRL: u8 = 0x4B;
    /// Data rate (bits 5:3), operation mode (bits 2:1), self test (bit 0).
    pub const OP_MODE: u8 = 0x4C;
    /// Repetitions of the X/Y measurement: 1 + 2·value.
    pub const REPXY: u8 = 0x51;
    /// Repetitions of the Z measurement: 1 + value.
    pub const REPZ: u8 = 0x52;
}

/// OP_MODE: normal mode at 20 Hz (data rate code 0b101).
pub const OP_MODE_NORMAL_20HZ: u8 = 0b101 << 3;
/// REPXY of the datasheet's "regular" preset (9 repetitions).
pub const REPXY_REGULAR: u8 = 4;
/// REPZ of the datasheet's "regular" preset (15 repetitions).
pub const REPZ_REGULAR: u8 = 14;

/// One reading: counts per axis and whether it is new.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MagReading {
    /// X, Y (13-bit) and Z (15-bit) counts.
    pub counts: [i16; 3],
    /// The data-ready bit was set.
    pub ready: bool,
}

/// Decodes the eight data bytes 0x42–0x49.
pub fn decode(data: [u8; 8]) -> MagReading {
    // Left-aligned: an arithmetic shift of the 16-bit word drops the flag bits and keeps the sign.
    let word = |lo: u8, hi: u8| i16::from_le_bytes([lo, hi]);
    MagReading {
        counts: [
            word(data[0], data[1]) >> 3,
            word(data[2], data[3]) >> 3,
            word(data[4], data[5]) >> 1,
        ],
        ready: data[6] & 1 == 1,
    }
}

/// Why the BMM150 could not be started.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Error<E> {
    /// The bus failed.
    Bus(E),
    /// CHIP_ID did not read 0x32.
    WrongId {
        /// Value read.
        found: u8,
    },
}

/// Powers the chip, checks its id and starts normal mode; `wait_ms` pauses the caller's clock
/// (the datasheet asks for 3 ms from power-on to the first register access).
pub fn init<I2C: I2c>(
    i2c: &mut I2C,
    mut wait_ms: impl FnMut(u32),
) -> Result<(), Error<I2C::Error>> {
    i2c.write(ADDRESS, &[reg::POWER_CTRL, 0x01])
        .map_err(Error::Bus)?;
    wait_ms(3);
    let mut id = [0u8];
    i2c.write_read(ADDRESS, &[reg::CHIP_ID], &mut id)
        .map_err(Error::Bus)?;
    if id[0] != CHIP_ID {
        return Err(Error::WrongId { found: id[0] });
    }
    for (register, value) in [
        (reg::REPXY, REPXY_REGULAR),
        (reg::REPZ, REPZ_REGULAR),
        (reg::OP_MODE, OP_MODE_NORMAL_20HZ),
    ] {
        i2c.write(ADDRESS, &[register, value]).map_err(Error::Bus)?;
    }
    Ok(())
}

/// Reads the data registers.
pub fn read<I2C: I2c>(i2c: &mut I2C) -> Result<MagReading, I2C::Error> {
    let mut data = [0u8; 8];
    i2c.write_read(ADDRESS, &[reg::DATA_X_LSB], &mut data)?;
    Ok(decode(data))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn left_aligned_data_decodes_with_sign() {
        // X = −1 (13-bit) with flag bits set, Y = 4095, Z = −16384 (15-bit minimum), ready.
        let x = ((-1i16) << 3) | 0b111;
        let y = 4095i16 << 3;
        let z = i16::MIN | 1;
        let [xl, xh] = x.to_le_bytes();
        let [yl, yh] = y.to_le_bytes();
        let [zl, zh] = z.to_le_bytes();
        let r = decode([xl, xh, yl, yh, zl, zh, 0x01, 0x00]);
        assert_eq!(r.counts, [-1, 4095, -16384]);
        assert!(r.ready);
    }
}
