//! Pose capture: averages the samples of one static orientation into statistics for the host fit.
//!
//! Welford's running mean and variance (one pass, numerically stable) over the still samples only,
//! for every accelerometer, gyroscope and magnetometer axis in nominal uncalibrated units, plus
//! temperature mean/min/max and the duration. The accumulators run in `f64` on exact integer
//! counts: a pose's mean feeds the fit, whose noise floor (`σ/√n`, ≈1e-5 relative for 10⁴ samples)
//! is close to what `f32` rounding accumulates over as many updates.

use imucal_protocol::PoseStats;

use crate::imu::{RawSample, SensorScales};

/// What a pose capture should collect.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PoseConfig {
    /// Number of still samples to average.
    pub samples: u32,
    /// Give up when the samples have not been collected this long after the start, µs.
    pub timeout_us: u64,
}

/// Why a pose capture ended without statistics.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PoseFailure {
    /// The deadline passed and the board moved during the capture, so it was not still long
    /// enough.
    NotStill,
    /// The deadline passed without motion: too few samples arrived (sensor errors) or the
    /// requested still time is longer than the timeout.
    Timeout,
    /// A still sample was at the sensor's full-scale limit, so its mean would be clipped.
    Saturated,
}

/// Where a pose capture stands.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PoseState {
    /// No capture requested.
    Idle,
    /// Waiting for stillness or averaging still samples.
    Capturing,
    /// Statistics are ready.
    Done(PoseStats),
    /// The capture ended without statistics.
    Failed(PoseFailure),
}

/// Welford accumulator of one channel, on counts.
#[derive(Debug, Clone, Copy, Default)]
struct Welford {
    mean: f64,
    m2: f64,
}

impl Welford {
    /// Add `x` as the `n`-th value (`inv_n = 1/n`).
    fn add(&mut self, x: i16, inv_n: f64) {
        let x = f64::from(x);
        let delta = x - self.mean;
        self.mean += delta * inv_n;
        self.m2 += delta * (x - self.mean);
    }
}

/// Channel order in the accumulator array: accel xyz, gyro xyz, mag xyz, temperature.
const CHANNELS: usize = 10;

/// Pose capture state machine; fed one sample at a time with the current stillness verdict.
#[derive(Debug, Clone)]
pub struct PoseCapture {
    state: PoseState,
    config: PoseConfig,
    started_us: u64,
    first_us: u64,
    last_us: u64,
    count: u32,
    /// Distinct magnetometer conversions in the average (fewer than `count` when the
    /// magnetometer converts slower than the samples arrive).
    mag_count: u32,
    saw_motion: bool,
    channels: [Welford; CHANNELS],
    temp_min: i16,
    temp_max: i16,
    /// Saturation limits in counts for accel, gyro, mag (|count| ≥ limit is saturated).
    limits: [i32; 3],
}

impl Default for PoseCapture {
    fn default() -> Self {
        Self::new()
    }
}

impl PoseCapture {
    /// An idle capture.
    pub fn new() -> Self {
        Self {
            state: PoseState::Idle,
            config: PoseConfig {
                samples: 0,
                timeout_us: 0,
            },
            started_us: 0,
            first_us: 0,
            last_us: 0,
            count: 0,
            mag_count: 0,
            saw_motion: false,
            channels: [Welford::default(); CHANNELS],
            temp_min: i16::MAX,
            temp_max: i16::MIN,
            limits: [i32::from(i16::MAX); 3],
        }
    }

    /// Current state.
    pub fn state(&self) -> PoseState {
        self.state
    }

    /// Start a new capture at `now_us`, discarding any previous one.
    ///
    /// A request for zero samples is treated as one, so a finished capture always has data.
    pub fn start(&mut self, config: PoseConfig, scales: &SensorScales, now_us: u64) {
        *self = Self::new();
        self.config = PoseConfig {
            samples: config.samples.max(1),
            timeout_us: config.timeout_us,
        };
        self.started_us = now_us;
        self.limits = [
            full_scale_counts(scales.accel_range_mps2, scales.accel_mps2_per_count),
            full_scale_counts(scales.gyro_range_rads, scales.gyro_rads_per_count),
            full_scale_counts(scales.mag_range_ut, scales.mag_ut_per_count),
        ];
        self.state = PoseState::Capturing;
    }

    /// Abandon a capture and return to idle.
    pub fn cancel(&mut self) {
        self.state = PoseState::Idle;
    }

    /// Take the outcome of a finished capture and return to idle; `None` while idle or capturing.
    pub fn take_outcome(&mut self) -> Option<Result<PoseStats, PoseFailure>> {
        let outcome = match self.state {
            PoseState::Done(summary) => Ok(summary),
            PoseState::Failed(failure) => Err(failure),
            PoseState::Idle | PoseState::Capturing => return None,
        };
        self.state = PoseState::Idle;
        Some(outcome)
    }

    /// Feed one sample taken at `now_us`, with the stillness verdict of the window it completed.
    ///
    /// Still samples are averaged; a sample that is not still discards the average so far and
    /// waits for stillness again, so a bump never mixes two orientations into one mean.
    pub fn update(
        &mut self,
        sample: &RawSample,
        still: bool,
        now_us: u64,
        scales: &SensorScales,
    ) -> PoseState {
        self.update_reading(sample, true, still, now_us, scales)
    }

    /// [`Self::update`] for a sample whose magnetometer value may repeat the previous one
    /// (`mag_is_new` false): the repeat is not averaged again, so the magnetometer mean and
    /// variance count each conversion once. The first sample of an average always contributes
    /// its magnetometer value (a measurement not yet counted).
    pub fn update_reading(
        &mut self,
        sample: &RawSample,
        mag_is_new: bool,
        still: bool,
        now_us: u64,
        scales: &SensorScales,
    ) -> PoseState {
        if self.state != PoseState::Capturing {
            return self.state;
        }
        if still {
            if self.is_saturated(sample) {
                self.state = PoseState::Failed(PoseFailure::Saturated);
                return self.state;
            }
            self.accumulate(sample, mag_is_new, now_us);
            if self.count >= self.config.samples {
                self.state = PoseState::Done(self.summary(scales));
                return self.state;
            }
        } else {
            self.saw_motion = true;
            self.discard_average();
        }
        self.check_deadline(now_us)
    }

    /// End the capture if its deadline has passed; for when no sample arrived this cycle.
    pub fn check_deadline(&mut self, now_us: u64) -> PoseState {
        if self.state == PoseState::Capturing
            && now_us.saturating_sub(self.started_us) >= self.config.timeout_us
        {
            let failure = if self.saw_motion {
                PoseFailure::NotStill
            } else {
                PoseFailure::Timeout
            };
            self.state = PoseState::Failed(failure);
        }
        self.state
    }

    fn discard_average(&mut self) {
        self.count = 0;
        self.mag_count = 0;
        self.channels = [Welford::default(); CHANNELS];
        self.temp_min = i16::MAX;
        self.temp_max = i16::MIN;
    }

    fn is_saturated(&self, sample: &RawSample) -> bool {
        let sensors = [sample.accel, sample.gyro, sample.mag];
        sensors
            .iter()
            .zip(self.limits)
            .any(|(axes, limit)| axes.iter().any(|&c| i32::from(c).abs() >= limit))
    }

    fn accumulate(&mut self, sample: &RawSample, mag_is_new: bool, now_us: u64) {
        if self.count == 0 {
            self.first_us = now_us;
        }
        self.last_us = now_us;
        self.count = self.count.saturating_add(1);
        let inv_n = 1.0 / f64::from(self.count);
        let accel_gyro_temp = [
            (0, sample.accel[0]),
            (1, sample.accel[1]),
            (2, sample.accel[2]),
            (3, sample.gyro[0]),
            (4, sample.gyro[1]),
            (5, sample.gyro[2]),
            (9, sample.temp),
        ];
        for (index, value) in accel_gyro_temp {
            if let Some(channel) = self.channels.get_mut(index) {
                channel.add(value, inv_n);
            }
        }
        if mag_is_new || self.mag_count == 0 {
            self.mag_count = self.mag_count.saturating_add(1);
            let inv_mag_n = 1.0 / f64::from(self.mag_count);
            for (channel, value) in self.channels.iter_mut().skip(6).zip(sample.mag) {
                channel.add(value, inv_mag_n);
            }
        }
        self.temp_min = self.temp_min.min(sample.temp);
        self.temp_max = self.temp_max.max(sample.temp);
    }

    fn summary(&self, scales: &SensorScales) -> PoseStats {
        let denominator = |n: u32| f64::from(n.saturating_sub(1).max(1));
        let mean_var = |first: usize, per_count: f32, n: u32| {
            let per_count = f64::from(per_count);
            let mut mean = [0.0f32; 3];
            let mut variance = [0.0f32; 3];
            for axis in 0..3 {
                if let Some(channel) = self.channels.get(first + axis) {
                    mean[axis] = (channel.mean * per_count) as f32;
                    variance[axis] = (channel.m2 / denominator(n) * per_count * per_count) as f32;
                }
            }
            (mean, variance)
        };
        let temp_c = |counts: f64| {
            (f64::from(scales.temp_offset_c) + counts * f64::from(scales.temp_c_per_count)) as f32
        };
        let temp_mean = self.channels.get(9).map_or(0.0, |c| c.mean);
        // The thermometer's sensitivity may be negative; then the lowest count is the hottest.
        let (low, high) = if scales.temp_c_per_count >= 0.0 {
            (self.temp_min, self.temp_max)
        } else {
            (self.temp_max, self.temp_min)
        };
        let (accel_mean, accel_var) = mean_var(0, scales.accel_mps2_per_count, self.count);
        let (gyro_mean, gyro_var) = mean_var(3, scales.gyro_rads_per_count, self.count);
        let (mag_mean, mag_var) = mean_var(6, scales.mag_ut_per_count, self.mag_count);
        let span_ms = self.last_us.saturating_sub(self.first_us) / 1000;
        PoseStats {
            n: self.count,
            accel_mean,
            accel_var,
            gyro_mean,
            gyro_var,
            mag_mean,
            mag_var,
            temp_mean_c: temp_c(temp_mean),
            temp_min_c: temp_c(f64::from(low)),
            temp_max_c: temp_c(f64::from(high)),
            duration_ms: u32::try_from(span_ms).unwrap_or(u32::MAX),
        }
    }
}

/// Full-scale limit in counts: the chip's range over its sensitivity, capped at the `i16` rail.
///
/// Unusable scales (zero, negative, NaN) fall back to the `i16` rail alone.
fn full_scale_counts(range: f32, per_count: f32) -> i32 {
    let rail = i32::from(i16::MAX);
    let counts = range / per_count;
    if counts.is_finite() && counts >= 1.0 {
        // Positive and finite, so adding ½ and truncating rounds; `as` saturates at i32::MAX.
        ((counts + 0.5) as i32).min(rail)
    } else {
        rail
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scales() -> SensorScales {
        SensorScales {
            // ±2 g on a 16-bit part is 32 768 counts: the rail is the limit.
            accel_range_mps2: 19.613,
            gyro_range_rads: 4.363,
            ..imucal_protocol::SensorScales::EXAMPLE_LSM9DS1
        }
    }

    fn config() -> PoseConfig {
        PoseConfig {
            samples: 5,
            timeout_us: 1_000_000,
        }
    }

    fn still_sample(ax: i16, temp: i16) -> RawSample {
        RawSample {
            accel: [ax, -3, 16_000],
            gyro: [4, -4, 0],
            mag: [1_000, -2_000, 3_000],
            temp,
        }
    }

    #[test]
    fn repeated_magnetometer_values_are_averaged_once() {
        let mut capture = PoseCapture::new();
        capture.start(config(), &scales(), 0);
        // 5 samples, but only two magnetometer conversions: 100 (read twice), 400 (read thrice).
        let reads = [
            (100, true),
            (100, false),
            (400, true),
            (400, false),
            (400, false),
        ];
        let mut state = PoseState::Capturing;
        for (i, (mag_x, new)) in reads.into_iter().enumerate() {
            let mut sample = still_sample(0, 0);
            sample.mag[0] = mag_x;
            state = capture.update_reading(&sample, new, true, 10_000 * i as u64, &scales());
        }
        let PoseState::Done(stats) = state else {
            panic!("capture did not finish: {state:?}");
        };
        assert_eq!(stats.n, 5);
        // Each conversion once: mean (100 + 400) / 2 counts, sample variance of {100, 400}.
        // Counting repeats would give a mean of 280 counts (3.92 µT) instead.
        let per_count = f64::from(scales().mag_ut_per_count);
        assert!((f64::from(stats.mag_mean[0]) - 250.0 * per_count).abs() < 1e-5);
        let variance = 45_000.0 * per_count * per_count;
        assert!((f64::from(stats.mag_var[0]) - variance).abs() < 1e-4 * variance);
        // Other channels keep every sample.
        assert!((f64::from(stats.mag_mean[1]) - (-2_000.0 * per_count)).abs() < 1e-4);
    }

    #[test]
    fn mean_and_sample_variance_match_the_two_pass_formulas() {
        let mut capture = PoseCapture::new();
        capture.start(config(), &scales(), 0);
        let xs = [100i16, 104, 96, 101, 99];
        let temps = [8i16, 10, 9, 12, 11];
        let mut state = PoseState::Capturing;
        for (i, (&x, &t)) in xs.iter().zip(&temps).enumerate() {
            state = capture.update(&still_sample(x, t), true, 10_000 * i as u64, &scales());
        }
        let PoseState::Done(summary) = state else {
            panic!("expected statistics, got {state:?}");
        };
        // Two-pass reference: mean 100, Σ(x−mean)² = 0+16+16+1+1 = 34, variance 34/4 counts².
        let s = f64::from(scales().accel_mps2_per_count);
        let tolerance = 1e-6; // relative; f64 accumulation rounded once to f32
        let mean = (100.0 * s) as f32;
        let variance = (8.5 * s * s) as f32;
        assert!((summary.accel_mean[0] - mean).abs() <= tolerance * mean);
        assert!((summary.accel_var[0] - variance).abs() <= tolerance * variance);
        assert_eq!(summary.accel_var[1], 0.0);
        assert_eq!(summary.n, 5);
        // Temperatures 8..12 counts at 1/16 °C per count above 25 °C.
        assert!((summary.temp_mean_c - (25.0 + 10.0 / 16.0)).abs() < 1e-5);
        assert_eq!(summary.temp_min_c, 25.0 + 8.0 / 16.0);
        assert_eq!(summary.temp_max_c, 25.0 + 12.0 / 16.0);
        assert_eq!(summary.duration_ms, 40);
        assert_eq!(capture.take_outcome(), Some(Ok(summary)));
        assert_eq!(capture.state(), PoseState::Idle);
    }

    #[test]
    fn samples_before_stillness_are_waited_out_not_averaged() {
        let mut capture = PoseCapture::new();
        capture.start(config(), &scales(), 0);
        // A moving sample with a wild value must not enter the mean.
        capture.update(&still_sample(20_000, 0), false, 0, &scales());
        let mut state = PoseState::Capturing;
        for i in 1..=5 {
            state = capture.update(&still_sample(100, 0), true, i, &scales());
        }
        let PoseState::Done(summary) = state else {
            panic!("expected statistics, got {state:?}");
        };
        let expected = 100.0 * scales().accel_mps2_per_count;
        assert!((summary.accel_mean[0] - expected).abs() < 1e-6 * expected);
    }

    #[test]
    fn motion_after_averaging_began_restarts_the_average() {
        let mut capture = PoseCapture::new();
        capture.start(config(), &scales(), 0);
        // Two samples of a first orientation, a bump, then five of a second orientation.
        capture.update(&still_sample(5_000, 0), true, 0, &scales());
        capture.update(&still_sample(5_000, 0), true, 1, &scales());
        capture.update(&still_sample(9_000, 0), false, 2, &scales());
        let mut state = PoseState::Capturing;
        for i in 3..8 {
            state = capture.update(&still_sample(100, 0), true, i, &scales());
        }
        let PoseState::Done(summary) = state else {
            panic!("expected statistics, got {state:?}");
        };
        // Only the second orientation: mean exactly 100 counts, zero variance.
        let expected = 100.0 * scales().accel_mps2_per_count;
        assert!((summary.accel_mean[0] - expected).abs() < 1e-6 * expected);
        assert_eq!(summary.accel_var[0], 0.0);
        assert_eq!(summary.n, 5);
    }

    #[test]
    fn continuous_motion_fails_with_not_still_at_the_deadline() {
        let mut capture = PoseCapture::new();
        capture.start(config(), &scales(), 500);
        let before = capture.update(&still_sample(0, 0), false, 500 + 999_999, &scales());
        assert_eq!(before, PoseState::Capturing);
        let at = capture.update(&still_sample(0, 0), false, 500 + 1_000_000, &scales());
        assert_eq!(at, PoseState::Failed(PoseFailure::NotStill));
    }

    #[test]
    fn no_samples_until_the_deadline_fails_with_timeout() {
        let mut capture = PoseCapture::new();
        capture.start(config(), &scales(), 0);
        capture.update(&still_sample(100, 0), true, 0, &scales());
        assert_eq!(capture.check_deadline(999_999), PoseState::Capturing);
        assert_eq!(
            capture.check_deadline(1_000_000),
            PoseState::Failed(PoseFailure::Timeout)
        );
        assert_eq!(capture.take_outcome(), Some(Err(PoseFailure::Timeout)));
    }

    #[test]
    fn a_still_sample_on_the_rail_fails_with_saturated() {
        let mut capture = PoseCapture::new();
        capture.start(config(), &scales(), 0);
        let mut sample = still_sample(100, 0);
        sample.accel[2] = i16::MIN;
        let state = capture.update(&sample, true, 0, &scales());
        assert_eq!(state, PoseState::Failed(PoseFailure::Saturated));
    }

    #[test]
    fn range_below_the_rail_sets_the_saturation_limit() {
        // A 12-bit magnetometer in 16-bit registers: ±2048 counts full scale.
        let mut scales = scales();
        scales.mag_range_ut = 2048.0 * scales.mag_ut_per_count;
        let mut capture = PoseCapture::new();
        capture.start(config(), &scales, 0);
        let mut sample = still_sample(100, 0);
        sample.mag = [0, 2047, 0];
        assert_eq!(
            capture.update(&sample, true, 0, &scales),
            PoseState::Capturing
        );
        sample.mag[1] = -2048;
        assert_eq!(
            capture.update(&sample, true, 1, &scales),
            PoseState::Failed(PoseFailure::Saturated)
        );
    }

    #[test]
    fn nan_scales_fall_back_to_the_rail_instead_of_rejecting_everything() {
        assert_eq!(full_scale_counts(f32::NAN, 1.0), 32_767);
        assert_eq!(full_scale_counts(10.0, 0.0), 32_767);
        assert_eq!(full_scale_counts(10.0, -1.0), 32_767);
        assert_eq!(full_scale_counts(2048.0, 1.0), 2048);
    }
}
