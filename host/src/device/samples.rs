//! Streamed samples in physical units, and writing them in the recording CSV format of
//! `ARCHITECTURE.md` ("Recording format": `t_s,ax,ay,az,gx,gy,gz,mx,my,mz,temp_c` in s, m/s²,
//! rad/s, µT, °C). Raw counts become units by the `SensorScales` of the board's `Welcome`.

use std::io::Write;

use imucal_protocol::{
    BatchHeader, CalibratedBatch, RawSample, SampleBatch, SensorScales, SensorSet, StreamKind,
};

/// One sample in physical units: m/s², rad/s, µT, °C; time on the board's clock, s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UnitSample {
    /// Board time, seconds since its power-up.
    pub t_s: f64,
    /// Accelerometer, m/s².
    pub accel: [f64; 3],
    /// Gyroscope, rad/s.
    pub gyro: [f64; 3],
    /// Magnetometer, µT.
    pub mag: [f64; 3],
    /// Die temperature, °C.
    pub temp_c: f64,
}

/// Converts raw counts to nominal units with the board's scale factors.
pub fn raw_to_units(sample: &RawSample, t_us: u64, scales: &SensorScales) -> UnitSample {
    let scale3 = |v: [i16; 3], k: f32| v.map(|c| f64::from(c) * f64::from(k));
    UnitSample {
        t_s: t_us as f64 * 1e-6,
        accel: scale3(sample.accel, scales.accel_mps2_per_count),
        gyro: scale3(sample.gyro, scales.gyro_rads_per_count),
        mag: scale3(sample.mag, scales.mag_ut_per_count),
        temp_c: f64::from(scales.temp_offset_c)
            + f64::from(sample.temp) * f64::from(scales.temp_c_per_count),
    }
}

/// The samples of one received batch, in physical units.
#[derive(Debug, Clone, PartialEq)]
pub struct SampleChunk {
    /// Raw (nominal units from counts × scale) or calibrated by the board.
    pub kind: StreamKind,
    /// Stream index of the first sample (counting emitted samples since the stream started).
    pub first_index: u32,
    /// Samples lost between the previous chunk and this one (gap in the stream index).
    pub lost_before: u32,
    /// The samples, oldest first.
    pub samples: Vec<UnitSample>,
}

impl SampleChunk {
    /// A chunk from a raw batch.
    pub fn from_raw(batch: &SampleBatch, scales: &SensorScales, lost_before: u32) -> Self {
        Self {
            kind: StreamKind::Raw,
            first_index: batch.header().first_index,
            lost_before,
            samples: batch
                .iter()
                .map(|(s, t_us)| raw_to_units(&s, t_us, scales))
                .collect(),
        }
    }

    /// A chunk from a calibrated batch (already in units on the board).
    pub fn from_calibrated(batch: &CalibratedBatch, lost_before: u32) -> Self {
        let widen = |v: [f32; 3]| v.map(f64::from);
        Self {
            kind: StreamKind::Calibrated,
            first_index: batch.header().first_index,
            lost_before,
            samples: batch
                .iter()
                .map(|(s, t_us)| UnitSample {
                    t_s: t_us as f64 * 1e-6,
                    accel: widen(s.accel),
                    gyro: widen(s.gyro),
                    mag: widen(s.mag),
                    temp_c: f64::from(s.temp_c),
                })
                .collect(),
        }
    }
}

/// Tracks stream indices to count samples lost between batches.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct GapTracker {
    next_index: Option<u32>,
}

impl GapTracker {
    /// Samples missing before a batch starting at `header`, then expects the one after it.
    pub(crate) fn observe(&mut self, header: &BatchHeader, len: usize) -> u32 {
        let lost = match self.next_index {
            Some(expected) if header.first_index > expected => header.first_index - expected,
            _ => 0,
        };
        let len = u32::try_from(len).unwrap_or(u32::MAX);
        self.next_index = Some(header.first_index.saturating_add(len));
        lost
    }

    /// Forgets the stream (a new stream restarts its indices at 0).
    pub(crate) fn reset(&mut self) {
        self.next_index = None;
    }
}

/// Writes samples as a recording CSV; columns of sensors the board lacks are left out.
pub struct RecordingWriter<W: Write> {
    out: W,
    sensors: SensorSet,
    t0_s: Option<f64>,
    rows: u64,
}

impl<W: Write> RecordingWriter<W> {
    /// Writes the header line for the board's `sensors` and returns the writer.
    pub fn new(mut out: W, sensors: SensorSet) -> std::io::Result<Self> {
        let mut header = String::from("t_s");
        for (present, names) in [
            (sensors.accel, ",ax,ay,az"),
            (sensors.gyro, ",gx,gy,gz"),
            (sensors.mag, ",mx,my,mz"),
            (sensors.temp, ",temp_c"),
        ] {
            if present {
                header.push_str(names);
            }
        }
        writeln!(out, "{header}")?;
        Ok(Self {
            out,
            sensors,
            t0_s: None,
            rows: 0,
        })
    }

    /// Writes one row; `t_s` counts from the first sample written.
    pub fn write(&mut self, sample: &UnitSample) -> std::io::Result<()> {
        let t0 = *self.t0_s.get_or_insert(sample.t_s);
        let mut row = format!("{:.6}", sample.t_s - t0);
        for (present, values) in [
            (self.sensors.accel, &sample.accel),
            (self.sensors.gyro, &sample.gyro),
            (self.sensors.mag, &sample.mag),
        ] {
            if present {
                // Six decimals resolve far below one count of any supported chip.
                for v in values {
                    row.push_str(&format!(",{v:.6}"));
                }
            }
        }
        if self.sensors.temp {
            row.push_str(&format!(",{:.4}", sample.temp_c));
        }
        writeln!(self.out, "{row}")?;
        self.rows += 1;
        Ok(())
    }

    /// Rows written so far.
    pub fn rows(&self) -> u64 {
        self.rows
    }

    /// Flushes the rows written so far to the underlying writer.
    pub fn flush(&mut self) -> std::io::Result<()> {
        self.out.flush()
    }

    /// Flushes and returns the underlying writer.
    pub fn finish(mut self) -> std::io::Result<W> {
        self.out.flush()?;
        Ok(self.out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scales() -> SensorScales {
        SensorScales {
            accel_mps2_per_count: 0.000_598_55,
            sample_rate_hz: 119.0,
            ..SensorScales::EXAMPLE_LSM9DS1
        }
    }

    #[test]
    fn raw_counts_become_units_by_the_welcome_scales() {
        let raw = RawSample {
            accel: [0, 0, 16_384],
            gyro: [100, -100, 0],
            mag: [1000, 0, -2000],
            temp: 32,
        };
        let u = raw_to_units(&raw, 2_500_000, &scales());
        // Tolerances: f32 scale factors carry ~1e-7 relative error.
        assert!((u.accel[2] - 16_384.0 * 0.000_598_55).abs() < 1e-6);
        assert!((u.gyro[1] + 0.015_27).abs() < 1e-8);
        assert!((u.mag[2] + 28.0).abs() < 1e-5);
        assert!((u.temp_c - 27.0).abs() < 1e-9, "25 °C + 32/16 °C");
        assert!((u.t_s - 2.5).abs() < 1e-12);
    }

    #[test]
    fn gap_tracker_counts_missing_indices_between_batches() {
        let mut gaps = GapTracker::default();
        let header = |first_index| BatchHeader {
            first_index,
            t0_us: 0,
            tick_us: 1,
        };
        assert_eq!(gaps.observe(&header(0), 20), 0);
        assert_eq!(gaps.observe(&header(20), 20), 0);
        assert_eq!(gaps.observe(&header(60), 20), 20);
    }

    #[test]
    fn recording_csv_omits_absent_sensors_and_starts_time_at_zero() {
        let sensors = SensorSet {
            accel: true,
            gyro: true,
            mag: false,
            temp: true,
        };
        let mut writer = RecordingWriter::new(Vec::new(), sensors).expect("vec write");
        let sample = |t_s| UnitSample {
            t_s,
            accel: [0.0, 0.0, 9.80665],
            gyro: [0.001, 0.0, -0.002],
            mag: [1.0, 2.0, 3.0],
            temp_c: 24.5,
        };
        writer.write(&sample(10.0)).expect("vec write");
        writer.write(&sample(10.01)).expect("vec write");
        let text = String::from_utf8(writer.finish().expect("vec flush")).expect("utf-8");
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines[0], "t_s,ax,ay,az,gx,gy,gz,temp_c");
        assert_eq!(
            lines[1],
            "0.000000,0.000000,0.000000,9.806650,0.001000,0.000000,-0.002000,24.5000"
        );
        assert!(lines[2].starts_with("0.010000,"), "{}", lines[2]);
    }
}
