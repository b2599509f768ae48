//! The host link over USB CDC-ACM: embedded-io `Read + ReadReady + Write` over a
//! `usbd_serial::SerialPort`, polling the USB device on every access.
//!
//! USB needs servicing every few milliseconds (enumeration, and moving packets between the
//! endpoints and the serial port's buffers); the firmware core calls `read_ready()` once per main
//! loop turn and that is where the device is polled.
//!
//! Writing must never hang the core when nobody reads: while the device is not configured (cable
//! only on a charger, host not enumerated) written bytes are discarded, as a UART discards them
//! with nothing attached. When the host stops reading (port closed, program stopped) the endpoint
//! fills; a write that makes no progress for [`WRITE_STALL_CYCLES`] returns
//! [`UsbLinkError::HostNotReading`] and later writes are discarded at once until the host sends a
//! byte or raises DTR (opens the port) again, so one stall costs one timeout, not one per message.

use embedded_io::{ErrorKind, ErrorType, Read, ReadReady, Write};
use usb_device::bus::UsbBus;
use usb_device::device::{UsbDevice, UsbDeviceState};
use usb_device::UsbError;
use usbd_serial::SerialPort;

/// CPU cycles a write may wait for the host to take data: 20 ms at 64 MHz, above the 1 ms USB
/// frame and a busy host's scheduling delay, and short against a sample period's budget of
/// several frames.
pub const WRITE_STALL_CYCLES: u32 = 64_000 * 20;

/// Why a USB link operation failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum UsbLinkError {
    /// The host has not taken data for 20 ms: it has closed the port or stopped reading. Data is
    /// dropped until it opens the port or sends again.
    HostNotReading,
    /// The USB stack reported an error other than "would block".
    Usb,
}

impl core::fmt::Display for UsbLinkError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::HostNotReading => write!(
                f,
                "the USB host took no data for 20 ms; open the serial port on the host and keep \
                 reading it"
            ),
            Self::Usb => write!(
                f,
                "the USB stack reported an error; unplug and re-plug the board"
            ),
        }
    }
}

impl embedded_io::Error for UsbLinkError {
    fn kind(&self) -> ErrorKind {
        match self {
            Self::HostNotReading => ErrorKind::TimedOut,
            Self::Usb => ErrorKind::Other,
        }
    }
}

/// A source of elapsed CPU cycles for the write timeout (the DWT cycle counter on the board).
pub trait CycleCounter {
    /// Current cycle count; wraps.
    fn cycles(&self) -> u32;
}

/// The DWT cycle counter of the Cortex-M4; it must have been enabled at start-up
/// (`DCB::enable_trace`, `DWT::enable_cycle_counter`).
#[derive(Debug, Clone, Copy, Default)]
pub struct DwtCycles;

impl CycleCounter for DwtCycles {
    fn cycles(&self) -> u32 {
        cortex_m::peripheral::DWT::cycle_count()
    }
}

/// Size of the link's own receive buffer: one full-speed bulk packet.
const RX_CHUNK: usize = 64;

/// The USB CDC-ACM host link; see the module documentation.
pub struct UsbSerialLink<'a, B: UsbBus, T: CycleCounter> {
    device: UsbDevice<'a, B>,
    serial: SerialPort<'a, B>,
    cycles: T,
    rx: [u8; RX_CHUNK],
    rx_start: usize,
    rx_end: usize,
    host_reading: bool,
    last_dtr: bool,
}

impl<'a, B: UsbBus, T: CycleCounter> UsbSerialLink<'a, B, T> {
    /// A link over `device` and its CDC-ACM class `serial`; `cycles` times write stalls.
    pub fn new(device: UsbDevice<'a, B>, serial: SerialPort<'a, B>, cycles: T) -> Self {
        Self {
            device,
            serial,
            cycles,
            rx: [0; RX_CHUNK],
            rx_start: 0,
            rx_end: 0,
            host_reading: true,
            last_dtr: false,
        }
    }

    /// Whether the host has enumerated and configured the device.
    pub fn configured(&self) -> bool {
        self.device.state() == UsbDeviceState::Configured
    }

    /// Services the USB device and notices the host opening the port (DTR rising).
    pub fn poll(&mut self) {
        self.device.poll(&mut [&mut self.serial]);
        let dtr = self.serial.dtr();
        if dtr && !self.last_dtr {
            self.host_reading = true;
        }
        self.last_dtr = dtr;
    }

    /// Moves received bytes into the link's buffer when it is empty; returns whether any wait.
    fn fill(&mut self) -> Result<bool, UsbLinkError> {
        if self.rx_start < self.rx_end {
            return Ok(true);
        }
        match self.serial.read(&mut self.rx) {
            Ok(n) => {
                self.rx_start = 0;
                self.rx_end = n.min(RX_CHUNK);
                if n > 0 {
                    // The host is talking, so it is also reading.
                    self.host_reading = true;
                }
                Ok(n > 0)
            }
            Err(UsbError::WouldBlock) => Ok(false),
            Err(_) => Err(UsbLinkError::Usb),
        }
    }
}

impl<B: UsbBus, T: CycleCounter> ErrorType for UsbSerialLink<'_, B, T> {
    type Error = UsbLinkError;
}

impl<B: UsbBus, T: CycleCounter> ReadReady for UsbSerialLink<'_, B, T> {
    fn read_ready(&mut self) -> Result<bool, UsbLinkError> {
        self.poll();
        self.fill()
    }
}

impl<B: UsbBus, T: CycleCounter> Read for UsbSerialLink<'_, B, T> {
    /// Waits (polling USB) for the first byte, then returns what is buffered.
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, UsbLinkError> {
        if buf.is_empty() {
            return Ok(0);
        }
        while !self.fill()? {
            self.poll();
        }
        let waiting = self.rx.get(self.rx_start..self.rx_end).unwrap_or(&[]);
        let n = waiting.len().min(buf.len());
        if let (Some(dst), Some(src)) = (buf.get_mut(..n), waiting.get(..n)) {
            dst.copy_from_slice(src);
        }
        self.rx_start += n;
        Ok(n)
    }
}

impl<B: UsbBus, T: CycleCounter> Write for UsbSerialLink<'_, B, T> {
    /// Queues at least one byte, polling USB while the endpoint is full; see the module
    /// documentation for what happens when nobody reads.
    fn write(&mut self, buf: &[u8]) -> Result<usize, UsbLinkError> {
        if buf.is_empty() {
            return Ok(0);
        }
        self.poll();
        if !self.configured() || !self.host_reading {
            return Ok(buf.len());
        }
        let started = self.cycles.cycles();
        loop {
            match self.serial.write(buf) {
                Ok(n) if n > 0 => return Ok(n),
                Ok(_) | Err(UsbError::WouldBlock) => {}
                Err(_) => return Err(UsbLinkError::Usb),
            }
            if self.cycles.cycles().wrapping_sub(started) > WRITE_STALL_CYCLES {
                self.host_reading = false;
                return Err(UsbLinkError::HostNotReading);
            }
            self.poll();
        }
    }

    /// Waits until the serial port's buffer has gone to the USB endpoint, with the same timeout.
    fn flush(&mut self) -> Result<(), UsbLinkError> {
        if !self.configured() || !self.host_reading {
            return Ok(());
        }
        let started = self.cycles.cycles();
        loop {
            self.poll();
            match self.serial.flush() {
                Ok(()) => return Ok(()),
                Err(UsbError::WouldBlock) => {}
                Err(_) => return Err(UsbLinkError::Usb),
            }
            if self.cycles.cycles().wrapping_sub(started) > WRITE_STALL_CYCLES {
                self.host_reading = false;
                return Err(UsbLinkError::HostNotReading);
            }
        }
    }
}
