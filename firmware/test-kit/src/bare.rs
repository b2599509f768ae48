//! Allocation-free doubles, for harnesses without a heap.

use core::convert::Infallible;

use imucal_firmware::device::Clock;
use imucal_firmware::imu::{Imu, RawSample, SensorScales};

/// An IMU that returns `sample(n)` on its n-th read, so no two consecutive reads are equal.
/// Generic over the function so that a bench inlines it rather than calling through a pointer.
pub struct CountingImu<S> {
    /// Reads so far.
    pub count: u32,
    /// The scales it announces.
    pub scales: SensorScales,
    /// The sample of the n-th read.
    pub sample: S,
}

impl<S: Fn(u32) -> RawSample> Imu for CountingImu<S> {
    type Error = Infallible;

    fn scales(&self) -> SensorScales {
        self.scales
    }

    fn read(&mut self) -> Result<RawSample, Infallible> {
        self.count = self.count.wrapping_add(1);
        Ok((self.sample)(self.count))
    }
}

/// A clock that advances `step_us` on every reading, so every `poll()` takes a sample.
pub struct SteppingClock {
    /// The last time read, µs.
    pub now_us: u64,
    /// The advance per reading, µs.
    pub step_us: u64,
}

impl Clock for SteppingClock {
    fn now_us(&mut self) -> u64 {
        self.now_us += self.step_us;
        self.now_us
    }
}

/// A link whose input is one pre-encoded request (up to `N` bytes) and whose output is
/// counted, not kept.
pub struct SinkLink<const N: usize> {
    input: [u8; N],
    input_len: usize,
    read_at: usize,
    /// Bytes the device has written (wrapping).
    pub bytes_out: u32,
}

impl<const N: usize> SinkLink<N> {
    /// A link that will deliver `input` (truncated to `N` bytes) and then nothing.
    pub fn new(input: &[u8]) -> Self {
        let mut buffer = [0u8; N];
        let len = input.len().min(N);
        for (slot, byte) in buffer.iter_mut().zip(input) {
            *slot = *byte;
        }
        Self {
            input: buffer,
            input_len: len,
            read_at: 0,
            bytes_out: 0,
        }
    }
}

impl<const N: usize> embedded_io::ErrorType for SinkLink<N> {
    type Error = Infallible;
}

impl<const N: usize> embedded_io::ReadReady for SinkLink<N> {
    fn read_ready(&mut self) -> Result<bool, Infallible> {
        Ok(self.read_at < self.input_len)
    }
}

impl<const N: usize> embedded_io::Read for SinkLink<N> {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Infallible> {
        let rest = self.input.get(self.read_at..self.input_len).unwrap_or(&[]);
        let n = rest.len().min(buf.len());
        for (slot, byte) in buf.iter_mut().zip(rest) {
            *slot = *byte;
        }
        self.read_at += n;
        Ok(n)
    }
}

impl<const N: usize> embedded_io::Write for SinkLink<N> {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        self.bytes_out = self.bytes_out.wrapping_add(buf.len() as u32);
        Ok(buf.len())
    }

    fn flush(&mut self) -> Result<(), Infallible> {
        Ok(())
    }
}
