//! Mean and standard error of a run of correlated samples.
//!
//! Samples of real sensors are not independent (digital low-pass filters, slow wander), so the
//! variance of a mean is `σ²/n_eff` with the effective sample size `n_eff = n·(1 − ρ)/(1 + ρ)`
//! from the lag-1 autocorrelation `ρ` of the noise (the AR(1) result, e.g. Bartlett 1946; von
//! Storch & Zwiers, *Statistical Analysis in Climate Research*, §6.6). Slow deterministic motion
//! inside a hold (a hand's sway) would make `ρ` of the raw samples close to 1, so `ρ` is taken
//! from the first differences instead: for AR(1) noise the differences have lag-1
//! autocorrelation `−(1 − ρ)/2`, while motion much slower than the sample rate contributes little
//! to them. The white-noise variance is then `E[Δx²]/(2(1 − ρ))`, also from the differences.

use super::Vec3;

/// Largest lag-1 autocorrelation of the noise accepted; beyond it the AR(1) correction
/// (factor `(1 + ρ)/(1 − ρ)³` on the variance of the mean) is itself too uncertain.
pub const MAX_NOISE_CORRELATION: f64 = 0.9;

/// Mean, standard error and noise statistics of a run of samples.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunStats {
    /// Mean per axis.
    pub mean: Vec3,
    /// Standard error of the mean per axis.
    pub sigma_mean: Vec3,
    /// Effective sample size (mean over axes).
    pub n_eff: f64,
    /// Lag-1 autocorrelation of the noise (mean over axes).
    pub rho: f64,
}

/// Statistics of `samples` as described in the module comment; `None` for fewer than 4 samples
/// (too few to estimate a correlation) or non-finite data.
pub fn run_stats(samples: &[Vec3]) -> Option<RunStats> {
    let n = samples.len();
    if n < 4 || samples.iter().any(|s| s.iter().any(|v| !v.is_finite())) {
        return None;
    }
    let nf = n as f64;
    let mean = samples.iter().sum::<Vec3>() / nf;
    // The first differences' statistics in one pass, without storing them (a hold of a
    // long recording has tens of thousands of samples): their mean telescopes to
    // (last − first)/(n − 1); then their centred variance, lag-1 covariance and smallest step.
    let len = (n - 1) as f64;
    let d_mean = (samples[n - 1] - samples[0]) / len;
    let (mut d_var, mut d_cov) = (Vec3::zeros(), Vec3::zeros());
    let mut step = Vec3::repeat(f64::INFINITY);
    let mut previous: Option<Vec3> = None;
    for w in samples.windows(2) {
        let d = w[1] - w[0];
        let centred = d - d_mean;
        d_var += centred.component_mul(&centred);
        if let Some(p) = previous {
            d_cov += p.component_mul(&centred);
        }
        previous = Some(centred);
        for k in 0..3 {
            let size = d[k].abs();
            if size > 0.0 && size < step[k] {
                step[k] = size;
            }
        }
    }
    d_var /= len;
    d_cov /= len;
    let mut sigma_mean = Vec3::zeros();
    let mut rho_sum = 0.0;
    let mut n_eff_sum = 0.0;
    for k in 0..3 {
        let r_d = if d_var[k] > 0.0 {
            d_cov[k] / d_var[k]
        } else {
            -0.5
        };
        let rho = (1.0 + 2.0 * r_d).clamp(0.0, MAX_NOISE_CORRELATION);
        let white_var = d_var[k] / (2.0 * (1.0 - rho));
        let n_eff = (nf * (1.0 - rho) / (1.0 + rho)).max(1.0);
        // A quantised, noise-free axis has zero variance; keep a floor of one quantum²/12 so that
        // weights stay finite (the step is the smallest non-zero difference).
        let quantum_var = if step[k].is_finite() {
            step[k] * step[k] / 12.0
        } else {
            0.0
        };
        sigma_mean[k] = (white_var.max(quantum_var) / n_eff).sqrt();
        rho_sum += rho;
        n_eff_sum += n_eff;
    }
    Some(RunStats {
        mean,
        sigma_mean,
        n_eff: n_eff_sum / 3.0,
        rho: rho_sum / 3.0,
    })
}
