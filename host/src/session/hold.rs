//! How long the board averages a pose: until the mean of `|a|` is as good as the fit needs.
//!
//! The norm model sees a pose only through `|a|` along its up direction, so what matters is the
//! standard error of the mean of `|a|`: `σ|a| / √n` for `n` samples, with `σ|a|` measured on the
//! still window just before the capture (sensor noise and whatever the hand adds). The fit's
//! verdict asks for an expected `|a|` error of at most a quarter of the budget in the worst
//! direction; with twelve or more poses spread over the sphere and nine parameters, the worst
//! direction's σ stays below about twice one pose's σ (each direction is pinned by several
//! poses, the worst by fewer), so each pose's mean is asked for an eighth of the budget. The
//! fit's own covariance is checked afterwards and asks for more positions when this fell short.

use std::time::Duration;

use super::solve::STANDARD_GRAVITY;
use crate::device::UnitSample;
use crate::fit::Vec3;

/// Shortest hold: the board's own stillness window needs some samples, and a hand takes a
/// moment to settle after the prompt's beep.
const MIN_HOLD: Duration = Duration::from_millis(300);

/// Fraction of the `|a|` budget asked of one pose's mean (see the module documentation).
const POSE_SHARE_OF_BUDGET: f64 = 1.0 / 8.0;

/// Hold length for the next capture from the `window_s` seconds of `samples` that ended still,
/// the `|a|` budget `budget_mg` and the longest hold `max`. With fewer than four samples (no
/// noise estimate) the longest hold is used.
pub fn hold_length(
    samples: &[UnitSample],
    window_s: f64,
    budget_mg: f64,
    max: Duration,
) -> Duration {
    let Some(last) = samples.last() else {
        return max;
    };
    let window: Vec<&UnitSample> = samples
        .iter()
        .rev()
        .take_while(|s| last.t_s - s.t_s <= window_s)
        .collect();
    let n = window.len();
    let first = window.last().map_or(last.t_s, |s| s.t_s);
    if n < 4 || last.t_s <= first {
        return max;
    }
    let norms: Vec<f64> = window.iter().map(|s| Vec3::from(s.accel).norm()).collect();
    let rate_hz = (n - 1) as f64 / (last.t_s - first);
    let mean = norms.iter().sum::<f64>() / n as f64;
    let var = norms.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
    let target = budget_mg * POSE_SHARE_OF_BUDGET * STANDARD_GRAVITY / 1000.0;
    let samples_needed = var / (target * target);
    let seconds = samples_needed / rate_hz;
    if !seconds.is_finite() {
        return max;
    }
    Duration::from_secs_f64(seconds.clamp(
        MIN_HOLD.as_secs_f64(),
        max.as_secs_f64().max(MIN_HOLD.as_secs_f64()),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn noisy(count: usize, rate_hz: f64, sigma: f64) -> Vec<UnitSample> {
        (0..count)
            .map(|k| UnitSample {
                t_s: k as f64 / rate_hz,
                // Alternating ±σ has a standard deviation of σ·√(n/(n−1)) ≈ σ.
                accel: [0.0, 0.0, 9.8 + if k % 2 == 0 { sigma } else { -sigma }],
                gyro: [0.0; 3],
                mag: [0.0; 3],
                temp_c: 25.0,
            })
            .collect()
    }

    #[test]
    fn the_hold_lasts_until_the_mean_reaches_an_eighth_of_the_budget() {
        // σ = 2 mg at 100 Hz against a 2 mg budget: n = (2 / 0.25)² = 64 samples = 0.64 s.
        let sigma = 2.0e-3 * STANDARD_GRAVITY;
        let hold = hold_length(&noisy(51, 100.0, sigma), 0.5, 2.0, Duration::from_secs(3));
        // 51 alternating samples (26 high, 25 low) have the sample variance
        // σ²·(1 − 1/51²)·51/50.
        let expected = 0.64 * (1.0 - 1.0 / 51.0_f64.powi(2)) * 51.0 / 50.0;
        assert!((hold.as_secs_f64() - expected).abs() < 1e-6, "{hold:?}");
    }

    #[test]
    fn a_quiet_sensor_holds_for_the_shortest_time_and_a_noisy_one_for_the_longest() {
        let quiet = hold_length(&noisy(51, 100.0, 1e-5), 0.5, 2.0, Duration::from_secs(3));
        assert_eq!(quiet, MIN_HOLD);
        let noisy_hold = hold_length(&noisy(51, 100.0, 1.0), 0.5, 2.0, Duration::from_secs(3));
        assert_eq!(noisy_hold, Duration::from_secs(3));
        assert_eq!(
            hold_length(&[], 0.5, 2.0, Duration::from_secs(3)),
            Duration::from_secs(3)
        );
    }
}
