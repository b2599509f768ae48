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
//!
//! Readings written with a resolution `q` (a count, a logger's last decimal) add the rounding
//! of the mean: with Gaussian noise σ about a true value anywhere within a step, the mean of
//! many rounded samples is biased by a periodic function of that value whose variance is
//! `Σₖ q²/(2π²k²)·exp(−4π²k²σ²/q²)` (Widrow & Kollár, *Quantization Noise*, 2008, ch. 5):
//! `q²/12` when the noise is far below the step (every sample rounds alike, so it does not
//! average out) and negligible once σ ≥ q/2. σ is the noise the rounding leaves visible,
//! `white − q²/12` (Sheppard), floored at zero, which errs towards the larger bias.

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
/// (too few to estimate a correlation) or non-finite data. The resolution is the run's own
/// smallest step; see [`run_stats_quantised`] for a recording's.
pub fn run_stats(samples: &[Vec3]) -> Option<RunStats> {
    run_stats_quantised(samples, Vec3::repeat(f64::INFINITY))
}

/// Variance of the rounding bias of a mean of many samples with noise `sigma` written with
/// resolution `q` (module comment); zero without a finite positive `q`.
pub fn rounding_bias_variance(sigma: f64, q: f64) -> f64 {
    if !(q.is_finite() && q > 0.0) {
        return 0.0;
    }
    let r = (sigma / q).max(0.0);
    // Terms fall as exp(−4π²k²r²)/k²: a few hundred reach f64's precision even at r = 0
    // (where the sum is π²/6, checked against q²/12 in the tests).
    let sum: f64 = (1..=400)
        .map(|k| {
            let k = f64::from(k);
            (-4.0 * std::f64::consts::PI.powi(2) * k * k * r * r).exp() / (k * k)
        })
        .sum();
    q * q / (2.0 * std::f64::consts::PI.powi(2)) * sum
}

/// [`run_stats`] with the readings' resolution per axis known (the smallest step of the whole
/// recording, [`crate::recording::Recording::quantum`]): a run that never changes then still
/// carries the rounding of its mean.
pub fn run_stats_quantised(samples: &[Vec3], quantum: Vec3) -> Option<RunStats> {
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
        // The resolution: the finer of the run's own smallest step and the recording's.
        let q = step[k].min(quantum[k]);
        let quantum_var = if q.is_finite() { q * q / 12.0 } else { 0.0 };
        // A quantised, noise-free axis has zero scatter: the per-sample floor of q²/12 keeps
        // weights finite, and the rounding of the mean does not average out (module comment).
        let resolved_sigma = (white_var - quantum_var).max(0.0).sqrt();
        sigma_mean[k] =
            (white_var.max(quantum_var) / n_eff + rounding_bias_variance(resolved_sigma, q)).sqrt();
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The rounding bias variance by direct integration: the mean of many samples of
    /// `μ + σ·Z` rounded to multiples of `q`, minus `μ`, squared and averaged over `μ` uniform
    /// within a step.
    fn integrated_bias_variance(sigma: f64, q: f64) -> f64 {
        let phi = |x: f64| 0.5 * (1.0 + erf(x / std::f64::consts::SQRT_2));
        let points = 400;
        (0..points)
            .map(|i| {
                let mu = q * (i as f64 + 0.5) / points as f64;
                let expected: f64 = (-20i32..=20)
                    .map(|j| {
                        let centre = f64::from(j) * q;
                        let p = phi((centre + q / 2.0 - mu) / sigma)
                            - phi((centre - q / 2.0 - mu) / sigma);
                        centre * p
                    })
                    .sum();
                (expected - mu).powi(2)
            })
            .sum::<f64>()
            / points as f64
    }

    /// Abramowitz & Stegun 7.1.26 is too coarse here; a series and continued fraction would be
    /// long, so the error function by Simpson's rule on its integral (ample at these sizes).
    fn erf(x: f64) -> f64 {
        let n = 2000;
        let h = x / n as f64;
        let f = |t: f64| (-t * t).exp();
        let mut sum = f(0.0) + f(x);
        for i in 1..n {
            sum += f(i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
        }
        sum * h / 3.0 * 2.0 / std::f64::consts::PI.sqrt()
    }

    #[test]
    fn the_rounding_bias_of_a_mean_matches_direct_integration_over_the_true_value() {
        let q = 0.01;
        // Noise far below the step: every sample rounds alike, the uniform q²/12.
        assert!((rounding_bias_variance(0.0, q) / (q * q / 12.0) - 1.0).abs() < 1e-2);
        for sigma in [0.1 * q, 0.2 * q, 0.3 * q, 0.4 * q] {
            let formula = rounding_bias_variance(sigma, q);
            let direct = integrated_bias_variance(sigma, q);
            assert!(
                (formula / direct - 1.0).abs() < 1e-3,
                "σ = {sigma}: {formula:e} against {direct:e}"
            );
        }
        // Half a step of noise already dithers the rounding away.
        assert!(rounding_bias_variance(0.5 * q, q) < 1e-3 * q * q / 12.0);
        assert_eq!(rounding_bias_variance(0.1, f64::INFINITY), 0.0);
    }

    #[test]
    fn a_run_that_never_changes_keeps_the_rounding_of_its_mean() {
        let samples = vec![Vec3::new(-0.98, 0.01, 0.0); 400];
        let q = 0.01;
        let stats = run_stats_quantised(&samples, Vec3::repeat(q)).expect("400 samples");
        for k in 0..3 {
            // Not averaged down by √400: the mean is as uncertain as one rounding.
            assert!(
                stats.sigma_mean[k] >= q / 12f64.sqrt(),
                "{:?}",
                stats.sigma_mean
            );
        }
        // Without a known resolution the same run has no scatter to tell.
        let unknown = run_stats(&samples).expect("400 samples");
        assert_eq!(unknown.sigma_mean, Vec3::zeros());
    }
}
