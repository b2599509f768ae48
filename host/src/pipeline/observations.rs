//! The observations `fit`'s verdict and the residual analysis test a model on: one per still pose (accelerometer,
//! gyroscope, and magnetometer when it has enough still poses) or per short window of the
//! magnetometer stream, each with its mean reading, the standard error of that mean, its mean
//! temperature, its mid time, and the specific force measured at the same time.
//!
//! Standard error of a mean: the within-pose variance `s²` divided by an *effective* sample
//! size ([`crate::stats::autocorrelation::run_stats`]). Samples of real sensors are not independent (digital low-pass filters, slow wander), so
//! `n_eff = n·(1 − ρ)/(1 + ρ)` from the lag-1 autocorrelation `ρ` of the noise (the AR(1) result,
//! e.g. Bartlett 1946; von Storch & Zwiers, *Statistical Analysis in Climate Research*, §6.6).
//! Slow deterministic motion inside a hold (a hand's sway) would make `ρ` of the raw samples
//! close to 1 and the floor meaningless, so `ρ` is taken from the first differences instead:
//! for AR(1) noise the differences have lag-1 autocorrelation `−(1 − ρ)/2`, while motion much
//! slower than the sample rate contributes little to them. The white-noise variance is then
//! `E[Δx²]/(2(1 − ρ))`, also from the differences. Both choices make the floor the noise of the
//! sensor, not of the person holding it.
//!
//! Guard at the ends of a detected hold: a sample is called still when the window centred on it
//! is quiet, and the threshold sits above the noise, so the first and last window of a hold can
//! hold the end of the motion (up to half a window) and its decay (the hand letting go). At rest
//! a gyroscope's mean is its residual, so a tenth of a second at a few °/s moves the mean of an
//! 8 s hold by several standard errors; the difference-based noise estimate grows with it. One
//! detector window is dropped at each end ([`hold_guard`]), never more than a quarter of the
//! hold. Holds from a `pose` column are the user's own boundaries and are kept whole.

use crate::fit::{Pose, Vec3};
use crate::recording::{Recording, Sensor};
use crate::stats::autocorrelation::run_stats_quantised;
use crate::still::{hold_samples, StillReport};

/// One observation: a still pose or a short window of samples.
#[derive(Debug, Clone, PartialEq)]
pub struct Observation {
    /// Mean reading, in the data's units.
    pub mean: Vec3,
    /// Standard error of the mean per axis, in the data's units (see the module comment).
    pub sigma_mean: Vec3,
    /// Number of samples averaged.
    pub n: usize,
    /// Effective number of independent samples after the autocorrelation correction.
    pub n_eff: f64,
    /// Lag-1 autocorrelation of the noise (mean over the axes), 0 for white noise.
    pub noise_correlation: f64,
    /// Mean die temperature, °C, when the recording has one.
    pub temp_c: Option<f64>,
    /// Mid time, s.
    pub time_s: f64,
    /// Mean accelerometer reading over the same interval (raw data units), when recorded.
    pub accel_mean: Option<Vec3>,
    /// Label from the recording, if any.
    pub label: Option<i64>,
}

fn mean_of(values: &[f64]) -> Option<f64> {
    (!values.is_empty()).then(|| values.iter().sum::<f64>() / values.len() as f64)
}

/// Samples dropped at each end of a detected hold of `len` samples (see the module comment):
/// the detector's window, at most a quarter of the hold; none for holds from a `pose` column.
pub fn hold_guard(still: &StillReport, len: usize) -> usize {
    if still.from_pose_column {
        0
    } else {
        still.window.min(len / 4)
    }
}

/// One observation per still interval for `sensor` (accelerometer, gyroscope, or the
/// magnetometer samples that fall inside each hold), without the guard at each end.
pub fn pose_observations(
    recording: &Recording,
    still: &StillReport,
    sensor: Sensor,
) -> Vec<Observation> {
    let mut out = Vec::new();
    let quantum = recording.quantum(sensor);
    for interval in &still.intervals {
        let guard = hold_guard(still, interval.end.saturating_sub(interval.start));
        let (start, end) = (interval.start + guard, interval.end - guard);
        let rows: Vec<usize> = interval
            .rows(recording)
            .into_iter()
            .filter(|&i| (start..end).contains(&i))
            .collect();
        let (t_start, t_end) = match (recording.time.get(start), end.checked_sub(1)) {
            (Some(&a), Some(last)) if guard > 0 => (
                a,
                recording.time.get(last).copied().unwrap_or(interval.t_end),
            ),
            _ => (interval.t_start, interval.t_end),
        };
        let temp = recording.temp_c.as_ref().and_then(|t| {
            mean_of(
                &rows
                    .iter()
                    .filter_map(|&i| t.get(i).copied())
                    .collect::<Vec<f64>>(),
            )
        });
        // The screened samples (spikes dropped) of the trimmed hold.
        let accel_mean = hold_samples(recording, &rows, t_start, t_end, Sensor::Accel)
            .filter(|h| !h.kept.is_empty())
            .map(|h| h.kept.iter().sum::<Vec3>() / h.kept.len() as f64);
        let Some(held) = hold_samples(recording, &rows, t_start, t_end, sensor) else {
            continue;
        };
        let samples = held.kept;
        let Some(stats) = run_stats_quantised(&samples, quantum) else {
            continue;
        };
        out.push(Observation {
            mean: stats.mean,
            sigma_mean: stats.sigma_mean,
            n: samples.len(),
            n_eff: stats.n_eff,
            noise_correlation: stats.rho,
            temp_c: temp,
            time_s: 0.5 * (t_start + t_end),
            accel_mean,
            label: interval.label,
        });
    }
    out
}

/// Magnetometer observations from the whole stream: consecutive windows of `window` samples
/// (at most `max_windows` of them, evenly spread), each with the temperature of the nearest
/// main-stream rows when the recording has a temperature column.
pub fn window_observations(
    recording: &Recording,
    window: usize,
    max_windows: usize,
) -> Vec<Observation> {
    let Some(mag) = &recording.mag else {
        return Vec::new();
    };
    let window = window.max(4);
    let count = mag.samples.len() / window;
    if count == 0 || max_windows == 0 {
        return Vec::new();
    }
    let stride = count.div_ceil(max_windows).max(1);
    let quantum = recording.quantum(Sensor::Mag);
    let mut out = Vec::new();
    for w in (0..count).step_by(stride) {
        let range = w * window..(w + 1) * window;
        let Some(stats) = run_stats_quantised(&mag.samples[range.clone()], quantum) else {
            continue;
        };
        let t0 = mag.time[range.start];
        let t1 = mag.time[range.end - 1];
        let temp = recording.temp_c.as_ref().and_then(|temps| {
            let lo = recording.time.partition_point(|t| *t < t0);
            let hi = recording
                .time
                .partition_point(|t| *t <= t1)
                .max(lo + 1)
                .min(temps.len());
            mean_of(temps.get(lo.min(hi)..hi).unwrap_or(&[]))
        });
        out.push(Observation {
            mean: stats.mean,
            sigma_mean: stats.sigma_mean,
            n: window,
            n_eff: stats.n_eff,
            noise_correlation: stats.rho,
            temp_c: temp,
            time_s: 0.5 * (t0 + t1),
            accel_mean: None,
            label: None,
        });
    }
    out
}

/// Samples per magnetometer window observation (at the sensors' usual 50–100 Hz, a fraction of
/// a second: short enough that the board turns little within it, long enough for a variance).
pub const MAG_WINDOW_SAMPLES: usize = 20;
/// Most magnetometer window observations used, evenly spread over the stream.
pub const MAX_MAG_WINDOWS: usize = 300;

/// The magnetometer's observations: the still poses when there are at least twelve over nine
/// or more distinct gravity directions (or the holds come from a `pose` column), since only then
/// do they determine the ellipsoid; otherwise windows of `window` samples of the whole stream
/// (at most `max_windows`, [`window_observations`]).
pub fn mag_observations(
    recording: &Recording,
    still: Option<&StillReport>,
    window: usize,
    max_windows: usize,
) -> Vec<Observation> {
    if let Some(still) = still {
        let obs = pose_observations(recording, still, Sensor::Mag);
        let covered = still.from_pose_column || still.directions.len() >= 9;
        if obs.len() >= 12 && covered {
            return obs;
        }
    }
    window_observations(recording, window, max_windows)
}

/// Observations as fit poses (the variance of one sample recovered from the mean's).
pub fn to_poses(obs: &[Observation]) -> Vec<Pose> {
    obs.iter()
        .map(|o| Pose {
            mean: o.mean,
            var: o.sigma_mean.component_mul(&o.sigma_mean) * o.n as f64,
            n: o.n,
            label: o.label,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stats::autocorrelation::run_stats;

    /// Deterministic pseudo-normal numbers (sum of 12 uniforms from a linear congruential generator).
    fn noise(seed: u64, n: usize) -> Vec<f64> {
        let mut state = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (0..n)
            .map(|_| {
                (0..12)
                    .map(|_| {
                        state = state
                            .wrapping_mul(6364136223846793005)
                            .wrapping_add(1442695040888963407);
                        (state >> 11) as f64 / (1u64 << 53) as f64
                    })
                    .sum::<f64>()
                    - 6.0
            })
            .collect()
    }

    #[test]
    fn white_noise_gives_the_textbook_standard_error() {
        let e = noise(7, 3 * 4000);
        let samples: Vec<Vec3> = (0..4000)
            .map(|i| Vec3::new(e[3 * i], e[3 * i + 1], e[3 * i + 2]) * 0.2)
            .collect();
        let s = run_stats(&samples).unwrap();
        // σ/√n = 0.2/√4000 = 3.16e-3; the estimate of σ from 4000 samples is good to ~2 %,
        // and ρ̂ of white noise scatters by ~1/√n, moving n_eff by a few %: allow 8 %.
        for k in 0..3 {
            assert!(
                (s.sigma_mean[k] / 3.162e-3 - 1.0).abs() < 0.08,
                "axis {k}: {}",
                s.sigma_mean[k]
            );
        }
        assert!(s.rho < 0.06, "rho = {}", s.rho);
    }

    #[test]
    fn correlated_noise_inflates_the_standard_error_by_the_ar1_factor() {
        // AR(1) with ρ = 0.6 and unit innovations: var = 1/(1 − 0.36); var of the mean ≈ var·(1.6/0.4)/n.
        let e = noise(11, 20000);
        let mut x = 0.0;
        let samples: Vec<Vec3> = e
            .iter()
            .map(|v| {
                x = 0.6 * x + v;
                Vec3::repeat(x)
            })
            .collect();
        let s = run_stats(&samples).unwrap();
        let expected = (1.0 / 0.64 * 4.0 / 20000.0_f64).sqrt();
        // ρ̂ is within ±0.03 for 20000 samples, which moves the AR(1) factor by up to ~15 %.
        assert!(
            (s.sigma_mean[0] / expected - 1.0).abs() < 0.15,
            "{} vs {expected}",
            s.sigma_mean[0]
        );
        assert!((s.rho - 0.6).abs() < 0.05, "rho = {}", s.rho);
    }

    #[test]
    fn slow_sway_does_not_count_as_noise() {
        let e = noise(3, 3 * 400);
        let samples: Vec<Vec3> = (0..400)
            .map(|i| {
                let sway = 0.2 * (2.0 * std::f64::consts::PI * 0.2 * i as f64 / 100.0).sin();
                Vec3::new(e[3 * i], e[3 * i + 1], e[3 * i + 2]) * 0.01 + Vec3::repeat(sway)
            })
            .collect();
        let s = run_stats(&samples).unwrap();
        // Noise 0.01/√400 = 5e-4. The sway's variance is 200× the noise's, but its sample-to-sample
        // differences add ~2 % to theirs (and a little to ρ̂): allow 30 %.
        for k in 0..3 {
            assert!(
                s.sigma_mean[k] < 5e-4 * 1.3,
                "axis {k}: {}",
                s.sigma_mean[k]
            );
        }
    }

    #[test]
    fn too_few_or_non_finite_samples_give_no_statistics() {
        assert!(run_stats(&[Vec3::zeros(); 3]).is_none());
        assert!(run_stats(&[
            Vec3::zeros(),
            Vec3::zeros(),
            Vec3::repeat(f64::NAN),
            Vec3::zeros()
        ])
        .is_none());
    }
}
