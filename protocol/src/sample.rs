//! Sample value types: raw counts, scale factors, and the batches that carry streams.
//!
//! Raw batches pack each sample as fixed-width little-endian bytes, because postcard would
//! varint-encode each `i16` into up to 3 bytes; see the crate docs for the wire-size budget.

use heapless::Vec;
use serde::{Deserialize, Serialize};

use crate::error::BatchError;

/// One raw reading of the IMU in the chip's integer counts.
///
/// Scale factors to nominal units are announced by the device in its `Welcome`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct RawSample {
    /// Accelerometer, counts per axis.
    pub accel: [i16; 3],
    /// Gyroscope, counts per axis.
    pub gyro: [i16; 3],
    /// Magnetometer, counts per axis.
    pub mag: [i16; 3],
    /// Die temperature, counts.
    pub temp: i16,
}

/// How to turn a [`RawSample`] into nominal units, and the chip's limits.
///
/// Nominal units: accelerometer m/s², gyroscope rad/s, magnetometer µT, temperature °C
/// (`temp_c = temp_offset_c + temp * temp_c_per_count`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SensorScales {
    /// Accelerometer sensitivity, m/s² per count.
    pub accel_mps2_per_count: f32,
    /// Gyroscope sensitivity, rad/s per count.
    pub gyro_rads_per_count: f32,
    /// Magnetometer sensitivity, µT per count.
    pub mag_ut_per_count: f32,
    /// Temperature sensitivity, °C per count.
    pub temp_c_per_count: f32,
    /// Temperature at zero counts, °C.
    pub temp_offset_c: f32,
    /// Accelerometer full scale (±), m/s².
    pub accel_range_mps2: f32,
    /// Gyroscope full scale (±), rad/s.
    pub gyro_range_rads: f32,
    /// Magnetometer full scale (±), µT.
    pub mag_range_ut: f32,
    /// Output data rate of the sample stream, Hz.
    pub sample_rate_hz: f32,
}

impl SensorScales {
    /// The scales of an LSM9DS1-class part at ±2 g, ±245 °/s, ±4 gauss and 100 Hz, 16 counts
    /// per °C about 25 °C: an example for documentation and tests (a board reports its own).
    pub const EXAMPLE_LSM9DS1: Self = Self {
        accel_mps2_per_count: 0.000_598_5,
        gyro_rads_per_count: 0.000_152_7,
        mag_ut_per_count: 0.014,
        temp_c_per_count: 1.0 / 16.0,
        temp_offset_c: 25.0,
        accel_range_mps2: 19.6,
        gyro_range_rads: 4.36,
        mag_range_ut: 400.0,
        sample_rate_hz: 100.0,
    };
}

/// Which sensors a board has fitted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
pub struct SensorSet {
    /// Accelerometer present.
    pub accel: bool,
    /// Gyroscope present.
    pub gyro: bool,
    /// Magnetometer present.
    pub mag: bool,
    /// Die temperature sensor present.
    pub temp: bool,
}

/// Maximum number of samples in a [`SampleBatch`]; a full batch fits [`crate::MAX_FRAME`].
pub const RAW_BATCH_CAPACITY: usize = 20;
/// Maximum number of samples in a [`CalibratedBatch`]; a full batch fits [`crate::MAX_FRAME`].
pub const CALIBRATED_BATCH_CAPACITY: usize = 10;
/// Bytes of one packed raw sample on the wire: 10 × `i16` plus a `u16` time offset.
pub const PACKED_SAMPLE_BYTES: usize = 22;

/// Timing shared by all samples of a batch.
///
/// A sample's time is `t0_us + offset_ticks * tick_us`, where `offset_ticks` is a `u16` stored
/// with the sample; times are therefore quantised down to whole ticks after `t0_us`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
pub struct BatchHeader {
    /// Index of the first sample in the stream, counting emitted (post-decimation) samples,
    /// so a gap between consecutive batches shows lost samples.
    pub first_index: u32,
    /// Time of the batch's start on the device's monotonic clock, µs.
    pub t0_us: u64,
    /// Resolution of the per-sample time offsets, µs (must be non-zero).
    pub tick_us: u32,
}

impl BatchHeader {
    /// The time offset of a sample at `t_us`, in ticks after `t0_us` (rounded down).
    pub fn offset_ticks(&self, t_us: u64) -> Result<u16, BatchError> {
        if self.tick_us == 0 {
            return Err(BatchError::ZeroTick);
        }
        let elapsed = t_us
            .checked_sub(self.t0_us)
            .ok_or(BatchError::BeforeStart)?;
        u16::try_from(elapsed / u64::from(self.tick_us)).map_err(|_| BatchError::SpanExceeded)
    }

    /// The absolute time of a sample stored with `offset_ticks`, µs (saturating).
    pub fn time_us(&self, offset_ticks: u16) -> u64 {
        self.t0_us
            .saturating_add(u64::from(offset_ticks) * u64::from(self.tick_us))
    }
}

/// How a sample type is stored in a [`Batch`]: a fixed wire layout that holds the sample and
/// its time offset in ticks after the batch's start.
pub trait BatchEntry: Sized {
    /// The sample as producers and consumers see it.
    type Sample;
    /// The stored entry for `sample` taken `offset_ticks` after the batch's start.
    fn pack(sample: &Self::Sample, offset_ticks: u16) -> Self;
    /// The sample and its offset in ticks.
    fn unpack(&self) -> (Self::Sample, u16);
}

/// One raw sample packed as fixed-width little-endian bytes (accel, gyro, mag, temp, offset),
/// [`PACKED_SAMPLE_BYTES`] on the wire whatever the values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct PackedSample([u8; PACKED_SAMPLE_BYTES]);

impl BatchEntry for PackedSample {
    type Sample = RawSample;

    fn pack(sample: &RawSample, offset_ticks: u16) -> Self {
        let mut bytes = [0u8; PACKED_SAMPLE_BYTES];
        let values = sample
            .accel
            .iter()
            .chain(&sample.gyro)
            .chain(&sample.mag)
            .chain(core::iter::once(&sample.temp))
            .map(|v| v.to_le_bytes())
            .chain(core::iter::once(offset_ticks.to_le_bytes()));
        for (slot, value) in bytes.chunks_exact_mut(2).zip(values) {
            slot.copy_from_slice(&value);
        }
        Self(bytes)
    }

    fn unpack(&self) -> (RawSample, u16) {
        let mut words = [0u16; PACKED_SAMPLE_BYTES / 2];
        for (word, pair) in words.iter_mut().zip(self.0.chunks_exact(2)) {
            *word = u16::from_le_bytes([pair[0], pair[1]]);
        }
        let [ax, ay, az, gx, gy, gz, mx, my, mz, temp, offset] = words;
        let s = |w: u16| w as i16;
        let sample = RawSample {
            accel: [s(ax), s(ay), s(az)],
            gyro: [s(gx), s(gy), s(gz)],
            mag: [s(mx), s(my), s(mz)],
            temp: s(temp),
        };
        (sample, offset)
    }
}

/// One calibrated sample with its time offset in ticks (4 fixed bytes per value, varint offset).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TimedCalibrated(CalibratedSample, u16);

impl BatchEntry for TimedCalibrated {
    type Sample = CalibratedSample;

    fn pack(sample: &CalibratedSample, offset_ticks: u16) -> Self {
        Self(*sample, offset_ticks)
    }

    fn unpack(&self) -> (CalibratedSample, u16) {
        (self.0, self.1)
    }
}

/// A batch of up to `N` samples sharing one [`BatchHeader`], each stored as an entry `E`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Batch<E, const N: usize> {
    header: BatchHeader,
    samples: Vec<E, N>,
}

/// A batch of raw samples, as streamed by `StartStream { kind: Raw, .. }`.
pub type SampleBatch = Batch<PackedSample, RAW_BATCH_CAPACITY>;

/// A batch of calibrated samples, as streamed by `StartStream { kind: Calibrated, .. }`.
pub type CalibratedBatch = Batch<TimedCalibrated, CALIBRATED_BATCH_CAPACITY>;

impl<E: BatchEntry, const N: usize> Batch<E, N> {
    /// An empty batch with the given timing.
    pub fn new(header: BatchHeader) -> Self {
        Self {
            header,
            samples: Vec::new(),
        }
    }

    /// The batch's timing.
    pub fn header(&self) -> &BatchHeader {
        &self.header
    }

    /// Appends a sample taken at `t_us` (device clock, µs).
    pub fn push(&mut self, sample: &E::Sample, t_us: u64) -> Result<(), BatchError> {
        if self.samples.is_full() {
            return Err(BatchError::Full);
        }
        let offset = self.header.offset_ticks(t_us)?;
        self.samples
            .push(E::pack(sample, offset))
            .map_err(|_| BatchError::Full)
    }

    /// Number of samples held.
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    /// Whether the batch holds no samples.
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// Whether the batch holds its capacity `N` of samples.
    pub fn is_full(&self) -> bool {
        self.samples.is_full()
    }

    /// Removes all samples and sets new timing, for reuse without a new allocation.
    pub fn reset(&mut self, header: BatchHeader) {
        self.header = header;
        self.samples.clear();
    }

    /// The sample at `index` and its time in µs.
    pub fn get(&self, index: usize) -> Option<(E::Sample, u64)> {
        self.samples.get(index).map(|e| self.unpack(e))
    }

    /// All samples in order, each with its time in µs.
    pub fn iter(&self) -> impl Iterator<Item = (E::Sample, u64)> + '_ {
        self.samples.iter().map(|e| self.unpack(e))
    }

    fn unpack(&self, entry: &E) -> (E::Sample, u64) {
        let (sample, offset) = entry.unpack();
        (sample, self.header.time_us(offset))
    }
}

/// One sample after the device's calibration, in nominal units.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct CalibratedSample {
    /// Specific force, m/s².
    pub accel: [f32; 3],
    /// Angular rate, rad/s.
    pub gyro: [f32; 3],
    /// Magnetic field, µT.
    pub mag: [f32; 3],
    /// Die temperature, °C.
    pub temp_c: f32,
}
