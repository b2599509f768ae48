//! Live stillness and up direction from the streamed raw samples, on the host.
//!
//! The same test as the firmware's detector (the standard deviation of every accelerometer and
//! gyroscope axis over a sliding window below the thresholds), so that the prompt shows "still"
//! when a pose capture will succeed. The up direction is the window's mean specific force (raw,
//! uncalibrated: good to a few degrees, enough to tell the 45°-spaced targets apart).

use std::collections::VecDeque;

use imucal_protocol::StillThresholds;

use crate::device::UnitSample;
use crate::fit::Vec3;

/// What the monitor says about the latest window.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionState {
    /// Largest per-axis accelerometer standard deviation over the window, m/s².
    pub accel_std_mps2: f64,
    /// Largest per-axis gyroscope standard deviation over the window, rad/s.
    pub gyro_std_rads: f64,
    /// Mean specific force over the window (points up when still), m/s², raw.
    pub up: Vec3,
    /// Whether both spreads are within the thresholds.
    pub still: bool,
    /// Board time for which the board has been still without a break, s.
    pub still_for_s: f64,
}

/// Sliding-window stillness on board time stamps.
#[derive(Debug, Clone)]
pub struct MotionMonitor {
    window_s: f64,
    thresholds: StillThresholds,
    samples: VecDeque<UnitSample>,
    still_since_s: Option<f64>,
    state: Option<MotionState>,
}

/// Largest per-axis population standard deviation of `values` over the window.
fn max_axis_std<'a>(values: impl Iterator<Item = &'a [f64; 3]> + Clone) -> f64 {
    let n = values.clone().count().max(1) as f64;
    let mean = values
        .clone()
        .fold([0.0; 3], |acc, v| {
            [acc[0] + v[0], acc[1] + v[1], acc[2] + v[2]]
        })
        .map(|s| s / n);
    let var = values.fold([0.0; 3], |acc, v| {
        [0, 1, 2].map(|i| acc[i] + (v[i] - mean[i]).powi(2))
    });
    var.iter()
        .map(|s| (s / n).max(0.0).sqrt())
        .fold(0.0, f64::max)
}

impl MotionMonitor {
    /// A monitor over windows of `window_s` seconds of board time.
    pub fn new(window_s: f64, thresholds: StillThresholds) -> Self {
        Self {
            window_s: if window_s.is_finite() && window_s > 0.0 {
                window_s
            } else {
                0.5
            },
            thresholds,
            samples: VecDeque::new(),
            still_since_s: None,
            state: None,
        }
    }

    /// Forget everything (after a gap in the stream, e.g. a pose capture).
    pub fn reset(&mut self) {
        self.samples.clear();
        self.still_since_s = None;
        self.state = None;
    }

    /// Add one sample; returns the new state once a full window is in.
    pub fn push(&mut self, sample: &UnitSample) -> Option<MotionState> {
        if let Some(last) = self.samples.back() {
            // A clock going backwards means a new stream or a reboot: start over.
            if sample.t_s < last.t_s {
                self.reset();
            }
        }
        self.samples.push_back(*sample);
        let newest = sample.t_s;
        while self
            .samples
            .front()
            .is_some_and(|s| newest - s.t_s > self.window_s)
        {
            self.samples.pop_front();
        }
        let oldest = self.samples.front().map_or(newest, |s| s.t_s);
        // A window counts once it spans at least 90 % of its length (sample spacing).
        if self.samples.len() < 4 || newest - oldest < 0.9 * self.window_s {
            return None;
        }
        let accel_std = max_axis_std(self.samples.iter().map(|s| &s.accel));
        let gyro_std = max_axis_std(self.samples.iter().map(|s| &s.gyro));
        let n = self.samples.len() as f64;
        let up = self
            .samples
            .iter()
            .fold(Vec3::zeros(), |acc, s| acc + Vec3::from(s.accel))
            / n;
        let still = accel_std < f64::from(self.thresholds.accel_std_mps2)
            && gyro_std < f64::from(self.thresholds.gyro_std_rads);
        let still_for_s = if still {
            let since = *self.still_since_s.get_or_insert(newest);
            newest - since
        } else {
            self.still_since_s = None;
            0.0
        };
        let state = MotionState {
            accel_std_mps2: accel_std,
            gyro_std_rads: gyro_std,
            up,
            still,
            still_for_s,
        };
        self.state = Some(state);
        Some(state)
    }

    /// The latest state, if a full window has been seen.
    pub fn state(&self) -> Option<MotionState> {
        self.state
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(t_s: f64, accel: [f64; 3], gyro: [f64; 3]) -> UnitSample {
        UnitSample {
            t_s,
            accel,
            gyro,
            mag: [0.0; 3],
            temp_c: 25.0,
        }
    }

    const THRESHOLDS: StillThresholds = StillThresholds {
        accel_std_mps2: 0.1,
        gyro_std_rads: 0.02,
    };

    #[test]
    fn a_constant_reading_is_still_and_counts_still_time_from_the_first_full_window() {
        let mut monitor = MotionMonitor::new(0.5, THRESHOLDS);
        let mut last = None;
        for k in 0..=60 {
            last = monitor.push(&sample(k as f64 * 0.025, [0.0, 0.0, 9.8], [0.01; 3]));
        }
        let state = last.expect("a full window");
        assert!(state.still);
        // 61 samples over 1.5 s; the first full window closes at 0.45 s (0.9 of 0.5 s), give or
        // take one sample period (0.025 s) of floating-point time stamps.
        assert!(
            (state.still_for_s - 1.05).abs() <= 0.025 + 1e-9,
            "{}",
            state.still_for_s
        );
        assert!((state.up - Vec3::new(0.0, 0.0, 9.8)).norm() < 1e-12);
    }

    #[test]
    fn a_gyro_swing_above_the_threshold_is_motion() {
        let mut monitor = MotionMonitor::new(0.5, THRESHOLDS);
        let mut last = None;
        for k in 0..40 {
            // Alternating ±0.05 rad/s has a standard deviation of 0.05 > 0.02.
            let w = if k % 2 == 0 { 0.05 } else { -0.05 };
            last = monitor.push(&sample(k as f64 * 0.025, [0.0, 0.0, 9.8], [w, 0.0, 0.0]));
        }
        let state = last.expect("a full window");
        assert!(!state.still);
        // A window of N samples holds an odd or even count of the two values: σ is 0.05 for
        // even N and 0.05·√(1 − 1/N²) ≥ 0.04993 for odd N ≥ 19 (a window spans 0.45–0.5 s at 40 Hz).
        assert!(
            (0.049_93..=0.05 + 1e-12).contains(&state.gyro_std_rads),
            "{}",
            state.gyro_std_rads
        );
        assert_eq!(state.still_for_s, 0.0);
    }
}
