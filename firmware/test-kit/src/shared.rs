//! Doubles whose state the test shares with the device under test (reference-counted).

use core::cell::{Cell, RefCell};
use core::convert::Infallible;
use std::collections::VecDeque;
use std::rc::Rc;
use std::vec::Vec;

use imucal_firmware::device::Clock;
use imucal_firmware::imu::{Imu, RawSample, SensorScales};

/// An IMU that returns whatever sample the test put in its cell.
pub struct FixedImu {
    /// The sample every read returns.
    pub sample: Rc<Cell<RawSample>>,
    /// The scales it announces.
    pub scales: SensorScales,
}

impl Imu for FixedImu {
    type Error = Infallible;

    fn scales(&self) -> SensorScales {
        self.scales
    }

    fn read(&mut self) -> Result<RawSample, Infallible> {
        Ok(self.sample.get())
    }
}

/// Both directions of the serial link, shared between the device and the test.
#[derive(Clone, Default)]
pub struct MemoryLink {
    /// Bytes waiting for the device.
    pub to_device: Rc<RefCell<VecDeque<u8>>>,
    /// Bytes the device wrote.
    pub from_device: Rc<RefCell<Vec<u8>>>,
}

impl embedded_io::ErrorType for MemoryLink {
    type Error = Infallible;
}

impl embedded_io::Read for MemoryLink {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Infallible> {
        let mut queue = self.to_device.borrow_mut();
        let count = buf.len().min(queue.len());
        for (slot, byte) in buf.iter_mut().zip(queue.drain(..count)) {
            *slot = byte;
        }
        Ok(count)
    }
}

impl embedded_io::ReadReady for MemoryLink {
    fn read_ready(&mut self) -> Result<bool, Infallible> {
        Ok(!self.to_device.borrow().is_empty())
    }
}

impl embedded_io::Write for MemoryLink {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        self.from_device.borrow_mut().extend_from_slice(buf);
        Ok(buf.len())
    }

    fn flush(&mut self) -> Result<(), Infallible> {
        Ok(())
    }
}

/// A clock the test advances.
pub struct StepClock(pub Rc<Cell<u64>>);

impl Clock for StepClock {
    fn now_us(&mut self) -> u64 {
        self.0.get()
    }
}
