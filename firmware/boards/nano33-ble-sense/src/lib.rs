//! Board support for imucal on the Arduino Nano 33 BLE Sense (rev 1: nRF52840 + ST LSM9DS1).
//!
//! - [`usb_link`]: the host link, USB CDC-ACM (a virtual serial port) carrying the imucal protocol.
//! - [`clock`]: the core's monotonic microsecond clock from TIMER1, extended to 64 bits by
//!   [`wrap`].
//! - [`param_flash`]: the two flash pages at the top of the nRF52840's flash, as embedded-storage
//!   `NorFlash`, for the core's parameter store.
//! - [`pins`]: what the firmware relies on from the board schematic.
//!
//! The LSM9DS1 is driven by the firmware core's `lsm9ds1` driver over the HAL's TWIM, which
//! implements embedded-hal 1.0 `I2c` directly.
//!
//! `unsafe` is confined to [`param_flash`], which turns the linker-reserved flash region into the
//! `&'static mut [u8]` the HAL's flash controller driver takes.
#![no_std]
#![deny(unsafe_code)]
#![deny(unsafe_op_in_unsafe_fn)]
#![warn(missing_docs)]

pub mod clock;
pub mod param_flash;
pub mod usb_link;
pub mod wrap;

/// Pins of the Nano 33 BLE Sense rev 1 used by this firmware (Arduino schematic
/// ABX00031, variant file of Arduino's mbed nRF52840 core).
pub mod pins {
    /// P0.14: SDA of the internal I²C bus (LSM9DS1, and the other on-board sensors).
    pub const I2C_SDA_P0: u8 = 14;
    /// P0.15: SCL of the internal I²C bus.
    pub const I2C_SCL_P0: u8 = 15;
    /// P0.22: VDD_ENV, the switched 3.3 V supply of the on-board sensors; driven high with high
    /// drive strength because it sources the sensors' current.
    pub const SENSOR_POWER_P0: u8 = 22;
    /// P1.00: R_PULLUP, supplies the 4.7 kΩ pull-ups of the internal I²C bus.
    pub const I2C_PULLUP_P1: u8 = 0;
    /// P0.13: the orange LED "L" (active high), lit once the firmware runs.
    pub const LED_P0: u8 = 13;
}

/// USB vendor id reported by the firmware.
///
/// By default Arduino's (0x2341), which `imucal ports` lists as a likely IMU board; with the
/// `pid-codes-test-ids` feature pid.codes' (0x1209). See the README for the licensing note.
pub const USB_VID: u16 = if cfg!(feature = "pid-codes-test-ids") {
    0x1209
} else {
    0x2341
};

/// USB product id reported by the firmware.
///
/// By default 0x805A, the id the Arduino core gives a running Nano 33 BLE sketch (0x005A is its
/// bootloader); with the `pid-codes-test-ids` feature 0x0001, pid.codes' test id.
pub const USB_PID: u16 = if cfg!(feature = "pid-codes-test-ids") {
    0x0001
} else {
    0x805A
};

/// USB manufacturer string.
pub const USB_MANUFACTURER: &str = "imucal";
/// USB product string; `imucal ports` shows it next to the port.
pub const USB_PRODUCT: &str = "imucal Nano 33 BLE Sense";

/// Writes `id` as 16 upper-case hex digits, most significant first, for the USB serial number.
pub fn hex_u64(id: u64, out: &mut [u8; 16]) -> &str {
    const DIGITS: &[u8; 16] = b"0123456789ABCDEF";
    for (i, slot) in out.iter_mut().enumerate() {
        // i < 16, so the shift is at most 60 and the nibble indexes DIGITS in range.
        let nibble = (id >> (60 - 4 * i)) & 0xF;
        *slot = DIGITS.get(nibble as usize).copied().unwrap_or(b'0');
    }
    // Only ASCII digits were written.
    core::str::from_utf8(out).unwrap_or("0000000000000000")
}
