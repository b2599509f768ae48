//! Stillness detection from the windowed variance of accelerometer and gyroscope.
//!
//! A fixed ring of the last `N` raw samples (accelerometer and gyroscope counts) keeps running sums
//! of counts and squared counts in `i64`. Integer sums are exact, so adding the new sample and
//! removing the oldest never drifts, and the variance `(N·Σx² − (Σx)²)/N²` has no cancellation
//! error; only the final comparison with the thresholds is in floating point.

use crate::imu::{RawSample, SensorScales};
use imucal_protocol::math::sqrt_f32;

/// Largest window accepted; keeps `N·Σx²` below `2^62` for `i16` counts (`N² · 2^30`).
pub const MAX_WINDOW: usize = 1 << 15;

/// Stillness limits, as standard deviations over the window in nominal units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StillnessThresholds {
    /// Largest accelerometer standard deviation on any axis, m/s².
    pub accel_std_mps2: f32,
    /// Largest gyroscope standard deviation on any axis, rad/s.
    pub gyro_std_rads: f32,
}

impl Default for StillnessThresholds {
    /// A hand-held board resting on a table: a few times the noise of common MEMS parts
    /// (≈0.01 m/s² and ≈0.002 rad/s at 100 Hz), well below what a hand holding it produces.
    fn default() -> Self {
        Self {
            accel_std_mps2: 0.05,
            gyro_std_rads: 0.01,
        }
    }
}

/// Windowed standard deviations of the last full window, in nominal units.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct WindowSpread {
    /// Largest per-axis accelerometer standard deviation, m/s².
    pub accel_std_mps2: f32,
    /// Largest per-axis gyroscope standard deviation, rad/s.
    pub gyro_std_rads: f32,
}

/// Sliding-window stillness detector over `N` samples.
///
/// The board is still when the window is full and every accelerometer and gyroscope axis has a
/// standard deviation at or below its threshold.
#[derive(Debug, Clone)]
pub struct StillnessDetector<const N: usize> {
    /// Accelerometer then gyroscope counts of the last `N` samples.
    ring: [[i16; 6]; N],
    /// Index of the slot the next sample overwrites.
    next: usize,
    /// Number of valid samples in the ring (saturates at `N`).
    filled: usize,
    sum: [i64; 6],
    sum_sq: [i64; 6],
    thresholds: StillnessThresholds,
}

impl<const N: usize> StillnessDetector<N> {
    /// Compile-time check of the window length (evaluated when `new` is instantiated).
    const WINDOW_OK: () = assert!(
        N >= 2 && N <= MAX_WINDOW,
        "window must hold 2..=32768 samples"
    );

    /// An empty detector; it reports "not still" until `N` samples have been seen.
    pub fn new(thresholds: StillnessThresholds) -> Self {
        #[allow(clippy::let_unit_value)]
        let () = Self::WINDOW_OK;
        Self {
            ring: [[0; 6]; N],
            next: 0,
            filled: 0,
            sum: [0; 6],
            sum_sq: [0; 6],
            thresholds,
        }
    }

    /// Current thresholds.
    pub fn thresholds(&self) -> StillnessThresholds {
        self.thresholds
    }

    /// Replace the thresholds; the window content is kept.
    pub fn set_thresholds(&mut self, thresholds: StillnessThresholds) {
        self.thresholds = thresholds;
    }

    /// Forget every sample, e.g. after the sensor configuration changed.
    pub fn reset(&mut self) {
        self.next = 0;
        self.filled = 0;
        self.sum = [0; 6];
        self.sum_sq = [0; 6];
    }

    /// Add one sample, dropping the oldest once the window is full.
    pub fn push(&mut self, sample: &RawSample) {
        let incoming = [
            sample.accel[0],
            sample.accel[1],
            sample.accel[2],
            sample.gyro[0],
            sample.gyro[1],
            sample.gyro[2],
        ];
        // `next < N` always holds (it wraps below); `get_mut` keeps the path panic-free anyway.
        if let Some(slot) = self.ring.get_mut(self.next) {
            let outgoing = *slot;
            let window_full = self.filled == N;
            for axis in 0..6 {
                let new = i64::from(incoming[axis]);
                self.sum[axis] += new;
                self.sum_sq[axis] += new * new;
                if window_full {
                    let old = i64::from(outgoing[axis]);
                    self.sum[axis] -= old;
                    self.sum_sq[axis] -= old * old;
                }
            }
            *slot = incoming;
        }
        self.next = if self.next + 1 >= N { 0 } else { self.next + 1 };
        if self.filled < N {
            self.filled += 1;
        }
    }

    /// Whether the window is full.
    pub fn window_full(&self) -> bool {
        self.filled == N
    }

    /// Largest per-axis standard deviations over the window, or `None` until it is full.
    pub fn spread(&self, scales: &SensorScales) -> Option<WindowSpread> {
        if !self.window_full() {
            return None;
        }
        let accel_var = self.max_variance_counts(0..3);
        let gyro_var = self.max_variance_counts(3..6);
        Some(WindowSpread {
            accel_std_mps2: sqrt_f32(accel_var) * scales.accel_mps2_per_count.abs(),
            gyro_std_rads: sqrt_f32(gyro_var) * scales.gyro_rads_per_count.abs(),
        })
    }

    /// Whether the board is still: full window and both spreads within their thresholds.
    ///
    /// Compares variances with squared thresholds, so no square root is taken per sample.
    pub fn is_still(&self, scales: &SensorScales) -> bool {
        if !self.window_full() {
            return false;
        }
        let accel_limit = self.thresholds.accel_std_mps2 / scales.accel_mps2_per_count.abs();
        let gyro_limit = self.thresholds.gyro_std_rads / scales.gyro_rads_per_count.abs();
        // A NaN limit (bad thresholds or scales) compares false: never still, never a panic.
        self.max_variance_counts(0..3) <= accel_limit * accel_limit
            && self.max_variance_counts(3..6) <= gyro_limit * gyro_limit
    }

    /// Largest population variance, in counts², over the given axes of the window.
    fn max_variance_counts(&self, axes: core::ops::Range<usize>) -> f32 {
        // Window length fits i64 exactly (N ≤ 2^15).
        let n = self.filled as i64;
        let mut largest = 0.0f32;
        for axis in axes {
            let (Some(&sum), Some(&sum_sq)) = (self.sum.get(axis), self.sum_sq.get(axis)) else {
                continue;
            };
            // Exact: N·Σx² ≤ 2^15·2^15·2^30 = 2^60 and (Σx)² ≤ (2^15·2^15)² = 2^60.
            let scaled = n * sum_sq - sum * sum;
            let variance = scaled as f32 / (n * n) as f32;
            if variance > largest {
                largest = variance;
            }
        }
        largest
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scales() -> SensorScales {
        imucal_protocol::SensorScales::EXAMPLE_LSM9DS1
    }

    fn sample(accel: [i16; 3], gyro: [i16; 3]) -> RawSample {
        RawSample {
            accel,
            gyro,
            ..RawSample::default()
        }
    }

    #[test]
    fn spread_equals_population_std_of_the_last_window_only() {
        let mut detector = StillnessDetector::<4>::new(StillnessThresholds::default());
        // A large outlier that leaves the window must leave no trace in the sums.
        detector.push(&sample([30_000, 0, 0], [0; 3]));
        for x in [100, 102, 98, 100] {
            detector.push(&sample([x, 16_000, -16_000], [5, 5, 5]));
        }
        let spread = detector.spread(&scales()).unwrap();
        // Population std of {100,102,98,100} is √2 counts; f32 rounding is far below 1e-6.
        let expected = 2f32.sqrt() * scales().accel_mps2_per_count;
        assert!((spread.accel_std_mps2 - expected).abs() < 1e-6 * expected.max(1e-9) + 1e-9);
        assert_eq!(spread.gyro_std_rads, 0.0);
    }

    #[test]
    fn not_still_until_the_window_is_full() {
        let mut detector = StillnessDetector::<8>::new(StillnessThresholds::default());
        for _ in 0..7 {
            detector.push(&sample([0, 0, 16_384], [0; 3]));
            assert!(!detector.is_still(&scales()));
        }
        detector.push(&sample([0, 0, 16_384], [0; 3]));
        assert!(detector.is_still(&scales()));
    }

    #[test]
    fn threshold_splits_just_below_and_just_above() {
        // Alternating ±d counts has population std exactly d counts.
        let thresholds = StillnessThresholds::default();
        let limit_counts = thresholds.gyro_std_rads / scales().gyro_rads_per_count;
        let below = (limit_counts * 0.9) as i16;
        let above = (limit_counts * 1.1) as i16 + 1;
        for (d, still) in [(below, true), (above, false)] {
            let mut detector = StillnessDetector::<16>::new(thresholds);
            for i in 0..16 {
                let g = if i % 2 == 0 { d } else { -d };
                detector.push(&sample([0, 0, 16_384], [g, 0, 0]));
            }
            assert_eq!(detector.is_still(&scales()), still, "d = {d} counts");
        }
    }

    #[test]
    fn extreme_counts_do_not_overflow_the_sums() {
        let mut detector = StillnessDetector::<MAX_WINDOW>::new(StillnessThresholds::default());
        for i in 0..(2 * MAX_WINDOW) {
            let v = if i % 2 == 0 { i16::MIN } else { i16::MAX };
            detector.push(&sample([v; 3], [v; 3]));
        }
        let spread = detector.spread(&scales()).unwrap();
        // Alternating −32768/32767 has population std 32767.5 counts exactly.
        let expected = 32_767.5 * scales().accel_mps2_per_count;
        assert!((spread.accel_std_mps2 - expected).abs() < 1e-5 * expected);
        assert!(!detector.is_still(&scales()));
    }

    #[test]
    fn nan_thresholds_mean_never_still_instead_of_panicking() {
        let thresholds = StillnessThresholds {
            accel_std_mps2: f32::NAN,
            gyro_std_rads: 0.01,
        };
        let mut detector = StillnessDetector::<2>::new(thresholds);
        detector.push(&sample([0; 3], [0; 3]));
        detector.push(&sample([0; 3], [0; 3]));
        assert!(!detector.is_still(&scales()));
    }
}
