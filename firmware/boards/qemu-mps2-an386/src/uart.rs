//! Poll-mode driver for the Arm CMSDK APB UART (as on the MPS2 boards and in QEMU's model).
//!
//! Registers (CMSDK technical reference, "APB UART"): DATA 0x00, STATE 0x04 (bit 0 TX buffer full,
//! bit 1 RX buffer full, bits 2/3 TX/RX overrun, write 1 to clear), CTRL 0x08 (bit 0 TX enable,
//! bit 1 RX enable), BAUDDIV 0x10 (PCLK divided by the baud rate, at least 16).

use core::convert::Infallible;
use core::ptr::{read_volatile, write_volatile};
use core::sync::atomic::{AtomicBool, Ordering};

const DATA: usize = 0x00;
const STATE: usize = 0x04;
const CTRL: usize = 0x08;
const BAUDDIV: usize = 0x10;

const STATE_TX_FULL: u32 = 1 << 0;
const STATE_RX_FULL: u32 = 1 << 1;
const STATE_RX_OVERRUN: u32 = 1 << 3;
const CTRL_TX_RX_ENABLE: u32 = 0b11;

/// APB clock of the MPS2 FPGA images, Hz.
pub const PCLK_HZ: u32 = 25_000_000;

/// The UARTs of the MPS2 AN386 image used by this board.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UartPort {
    /// UART0 at 0x4000_4000: the host link.
    Uart0,
    /// UART1 at 0x4000_5000: the sensor feed.
    Uart1,
}

impl UartPort {
    const fn base(self) -> usize {
        match self {
            UartPort::Uart0 => 0x4000_4000,
            UartPort::Uart1 => 0x4000_5000,
        }
    }

    fn claimed(self) -> &'static AtomicBool {
        static UART0: AtomicBool = AtomicBool::new(false);
        static UART1: AtomicBool = AtomicBool::new(false);
        match self {
            UartPort::Uart0 => &UART0,
            UartPort::Uart1 => &UART1,
        }
    }
}

/// Exclusive handle to one CMSDK UART, enabled for transmit and receive.
#[derive(Debug)]
pub struct CmsdkUart {
    base: usize,
    rx_overruns: u32,
}

impl CmsdkUart {
    /// Claims `port` and enables it at `baud`; `None` when the port was already claimed.
    ///
    /// Baud rates too high for the 25 MHz APB clock are clamped to the fastest the divider allows.
    pub fn take(port: UartPort, baud: u32) -> Option<Self> {
        if port.claimed().swap(true, Ordering::AcqRel) {
            return None;
        }
        let mut uart = CmsdkUart {
            base: port.base(),
            rx_overruns: 0,
        };
        let divider = (PCLK_HZ / baud.max(1)).max(16);
        uart.write_reg(BAUDDIV, divider);
        uart.write_reg(CTRL, CTRL_TX_RX_ENABLE);
        Some(uart)
    }

    fn read_reg(&self, offset: usize) -> u32 {
        // SAFETY: `base` is one of the UART blocks of this memory map and is owned exclusively by
        // `self` (see `take`); the offsets are word-aligned registers of that block.
        unsafe { read_volatile((self.base + offset) as *const u32) }
    }

    fn write_reg(&mut self, offset: usize, value: u32) {
        // SAFETY: as in `read_reg`.
        unsafe { write_volatile((self.base + offset) as *mut u32, value) }
    }

    /// The received byte, if one is waiting.
    pub fn try_read_byte(&mut self) -> Option<u8> {
        let state = self.read_reg(STATE);
        if state & STATE_RX_OVERRUN != 0 {
            // A byte was lost; the frame CRC upstream rejects the damaged frame.
            self.rx_overruns = self.rx_overruns.wrapping_add(1);
            self.write_reg(STATE, STATE_RX_OVERRUN);
        }
        (state & STATE_RX_FULL != 0).then(|| self.read_reg(DATA) as u8)
    }

    /// Sends one byte, waiting while the transmit buffer is full.
    pub fn write_byte(&mut self, byte: u8) {
        while self.read_reg(STATE) & STATE_TX_FULL != 0 {}
        self.write_reg(DATA, u32::from(byte));
    }

    /// Number of receive overruns seen so far (bytes lost because they were not read in time).
    pub fn rx_overruns(&self) -> u32 {
        self.rx_overruns
    }
}

impl embedded_io::ErrorType for CmsdkUart {
    type Error = Infallible;
}

impl embedded_io::ReadReady for CmsdkUart {
    fn read_ready(&mut self) -> Result<bool, Infallible> {
        Ok(self.read_reg(STATE) & STATE_RX_FULL != 0)
    }
}

impl embedded_io::Read for CmsdkUart {
    /// Waits for the first byte, then returns what is available without waiting further.
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Infallible> {
        let mut n = 0;
        for slot in buf.iter_mut() {
            let byte = loop {
                match self.try_read_byte() {
                    Some(byte) => break Some(byte),
                    None if n == 0 => continue,
                    None => break None,
                }
            };
            match byte {
                Some(byte) => {
                    *slot = byte;
                    n += 1;
                }
                None => break,
            }
        }
        Ok(n)
    }
}

impl embedded_io::WriteReady for CmsdkUart {
    fn write_ready(&mut self) -> Result<bool, Infallible> {
        Ok(self.read_reg(STATE) & STATE_TX_FULL == 0)
    }
}

impl embedded_io::Write for CmsdkUart {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        for &byte in buf {
            self.write_byte(byte);
        }
        Ok(buf.len())
    }

    fn flush(&mut self) -> Result<(), Infallible> {
        while self.read_reg(STATE) & STATE_TX_FULL != 0 {}
        Ok(())
    }
}
