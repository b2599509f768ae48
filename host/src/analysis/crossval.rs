//! Held-out evaluation by pose and the rule that accepts an effect.
//!
//! Folds: leave-one-pose-out when there are at most [`MAX_FOLDS`] observations, otherwise
//! `MAX_FOLDS` folds of interleaved poses (pose `i` in fold `i mod K`), so that every fold spans
//! the whole recording in time and temperature. Each observation is predicted by the model
//! fitted without its fold; its held-out loss is the squared residual in units of its own noise,
//! `Lᵢ = Σₖ(rᵢₖ/σᵢₖ)²` (about 1 per component at the floor).
//!
//! Acceptance of an extension over the current model, both conditions required:
//! 1. *More than chance*: the one-sided Wilcoxon signed-rank test on the paired differences
//!    `dᵢ = L_currentᵢ − L_extendedᵢ` rejects "no improvement" at `α = 0.01/m`, `m` = number of
//!    candidates tested in that round (Bonferroni). The signed-rank test uses only the ranks, so
//!    one badly predicted pose cannot carry it and it needs no assumption about the size of the
//!    noise, only that under the null the differences are symmetric about zero. Exact null
//!    distribution up to 60 pairs, normal approximation with tie correction beyond.
//!    α = 0.01 keeps the family-wise false-acceptance rate of a whole analysis (a few rounds)
//!    near 1–2 %, while a real effect of a few noise σ gives p-values far smaller.
//! 2. *Worth having*: the mean held-out loss falls by at least [`MIN_GAIN_PER_COMPONENT`] per
//!    residual component, i.e. the effect predicts at least half a noise σ (RMS) of each pose.
//!    Smaller effects may be real but are below what a user can see in one pose, and a term
//!    the firmware applies must earn its place.

use super::effects::EffectKind;
use super::extended_fit::{fit_rows, ExtendedFit, Problem};
use crate::stats::distributions::normal_upper_tail;
use nalgebra::DVector;

/// Largest number of folds.
pub const MAX_FOLDS: usize = 12;
/// Family-wise significance level of one round of candidates.
pub const ALPHA: f64 = 0.01;
/// Minimum fall of the mean held-out loss per residual component, in noise variances.
pub const MIN_GAIN_PER_COMPONENT: f64 = 0.25;

/// Held-out losses of one model.
#[derive(Debug, Clone)]
pub struct HeldOut {
    /// Per-observation held-out loss `Lᵢ` (noise units).
    pub losses: Vec<f64>,
    /// Per-observation held-out residual in physical units (as [`super::extended_fit::physical_residual`]).
    pub residuals: Vec<f64>,
}

impl HeldOut {
    /// Mean loss.
    pub fn mean_loss(&self) -> f64 {
        self.losses.iter().sum::<f64>() / self.losses.len().max(1) as f64
    }

    /// RMS of the physical residuals.
    pub fn rms(&self) -> f64 {
        (self.residuals.iter().map(|r| r * r).sum::<f64>() / self.residuals.len().max(1) as f64)
            .sqrt()
    }
}

/// Fold index of each observation: leave-one-out up to [`MAX_FOLDS`] observations, otherwise
/// a fixed pseudo-random balanced assignment (a plain `i mod K` would line up with a schedule
/// that repeats every `K` poses and hold out one orientation at a time).
pub fn folds(n: usize) -> Vec<usize> {
    let k = n.clamp(1, MAX_FOLDS);
    if n <= MAX_FOLDS {
        return (0..n).collect();
    }
    // Order the poses by a fixed hash (SplitMix64) and deal them out round-robin.
    let mix = |i: u64| {
        let mut z = i.wrapping_add(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    };
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by_key(|&i| mix(i as u64));
    let mut out = vec![0; n];
    for (rank, &i) in order.iter().enumerate() {
        out[i] = rank % k;
    }
    out
}

/// Smallest number of observations for which every training fold of [`folds`] has more
/// residuals (`components` per observation) than `unknowns`, so that a model with that many
/// unknowns can be fitted and tested held out.
pub fn observations_needed(unknowns: usize, components: usize) -> usize {
    let c = components.max(1);
    let mut n = 2;
    loop {
        let k = n.clamp(1, MAX_FOLDS);
        let smallest_training = n - n.div_ceil(k);
        if smallest_training * c > unknowns {
            return n;
        }
        n += 1;
    }
}

/// Held-out losses of `effects`, each fold started from `full` (the fit on all observations).
/// `None` when some fold cannot be fitted.
pub fn held_out(problem: &Problem, effects: &[EffectKind], full: &ExtendedFit) -> Option<HeldOut> {
    let n = problem.points.len();
    let fold_of = folds(n);
    let k = fold_of.iter().max().map_or(0, |m| m + 1);
    let mut losses = vec![0.0; n];
    let mut residuals = vec![0.0; n];
    for fold in 0..k {
        let train: Vec<usize> = (0..n).filter(|&i| fold_of[i] != fold).collect();
        let fit = fit_rows(problem, effects, &train, &full.params)?;
        for i in (0..n).filter(|&i| fold_of[i] == fold) {
            let r = problem.residual(i, effects, fit.params.as_slice());
            losses[i] = r.norm_squared();
            residuals[i] =
                super::extended_fit::physical_residual(problem, i, effects, &fit.params).0;
        }
    }
    losses
        .iter()
        .all(|v| v.is_finite())
        .then_some(HeldOut { losses, residuals })
}

/// One-sided Wilcoxon signed-rank p-value for "the differences tend to be positive".
pub fn wilcoxon_signed_rank(d: &[f64]) -> f64 {
    let mut nz: Vec<f64> = d
        .iter()
        .copied()
        .filter(|v| *v != 0.0 && v.is_finite())
        .collect();
    let n = nz.len();
    if n == 0 {
        return 1.0;
    }
    nz.sort_by(|a, b| a.abs().total_cmp(&b.abs()));
    // Mid-ranks for ties, doubled to stay integral.
    let mut ranks2 = vec![0usize; n];
    let mut i = 0;
    let mut tie_term = 0.0;
    while i < n {
        let mut j = i;
        while j + 1 < n && nz[j + 1].abs() == nz[i].abs() {
            j += 1;
        }
        for r in &mut ranks2[i..=j] {
            *r = i + j + 2; // 2 × mean of ranks i+1..=j+1
        }
        let t = (j - i + 1) as f64;
        tie_term += t * t * t - t;
        i = j + 1;
    }
    let w2: usize = nz
        .iter()
        .zip(&ranks2)
        .filter(|(v, _)| **v > 0.0)
        .map(|(_, r)| *r)
        .sum();
    if n <= 60 {
        // Exact: number of sign assignments with doubled positive-rank sum ≥ w2.
        let total: usize = ranks2.iter().sum();
        let mut counts = vec![0f64; total + 1];
        counts[0] = 1.0;
        for &r in &ranks2 {
            for s in (r..=total).rev() {
                counts[s] += counts[s - r];
            }
        }
        let tail: f64 = counts[w2..].iter().sum();
        return tail / 2f64.powi(n as i32);
    }
    let nf = n as f64;
    let w = w2 as f64 / 2.0;
    let mean = nf * (nf + 1.0) / 4.0;
    let var = nf * (nf + 1.0) * (2.0 * nf + 1.0) / 24.0 - tie_term / 48.0;
    if var <= 0.0 {
        return 1.0;
    }
    // Continuity correction of one half.
    normal_upper_tail((w - mean - 0.5) / var.sqrt())
}

/// The comparison of an extended model with the current one.
#[derive(Debug, Clone)]
pub struct Comparison {
    /// One-sided signed-rank p-value of the improvement.
    pub p_value: f64,
    /// Fall of the mean held-out loss per residual component (noise variances).
    pub gain_per_component: f64,
    /// Relative fall of the mean held-out loss, `1 − L_ext/L_current` (the reported score).
    pub score: f64,
}

impl Comparison {
    /// Compare held-out losses.
    pub fn new(current: &HeldOut, extended: &HeldOut, components: usize) -> Self {
        let d: Vec<f64> = current
            .losses
            .iter()
            .zip(&extended.losses)
            .map(|(a, b)| a - b)
            .collect();
        let gain = (current.mean_loss() - extended.mean_loss()) / components.max(1) as f64;
        let base = current.mean_loss();
        let score = if base > 0.0 {
            1.0 - extended.mean_loss() / base
        } else {
            0.0
        };
        Self {
            p_value: wilcoxon_signed_rank(&d),
            gain_per_component: gain,
            score,
        }
    }

    /// The acceptance rule of the module comment, with `m` candidates in the round.
    pub fn passes(&self, m: usize) -> bool {
        self.p_value <= ALPHA / m.max(1) as f64 && self.gain_per_component >= MIN_GAIN_PER_COMPONENT
    }
}

/// Start vector for `extended` from a fit of `current` (a prefix of it): the fitted parameters
/// followed by zeros for the new effect.
pub fn extend_start(current: &DVector<f64>, extra: usize) -> DVector<f64> {
    let mut v = current.as_slice().to_vec();
    v.extend(std::iter::repeat_n(0.0, extra));
    DVector::from_vec(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn signed_rank_exact_tail_matches_enumeration() {
        // n = 5 all positive: only one of 32 sign patterns reaches the maximum, p = 1/32.
        assert!((wilcoxon_signed_rank(&[1.0, 2.0, 3.0, 4.0, 5.0]) - 1.0 / 32.0).abs() < 1e-15);
        // All negative: every pattern has W ≥ 0, p = 1.
        assert!((wilcoxon_signed_rank(&[-1.0, -2.0, -3.0]) - 1.0).abs() < 1e-15);
    }

    #[test]
    fn signed_rank_normal_approximation_is_close_to_exact_at_the_switch() {
        // 61 differences alternating in sign with a small positive excess: compare with the exact
        // value on the first 60 (the approximation error at n ≈ 60 is below 0.01 in p).
        let d: Vec<f64> = (1..=61)
            .map(|i| if i % 3 == 0 { -(i as f64) } else { i as f64 })
            .collect();
        let approx = wilcoxon_signed_rank(&d);
        let exact = wilcoxon_signed_rank(&d[..60]);
        assert!((approx - exact).abs() < 0.02, "{approx} vs {exact}");
    }

    #[test]
    fn observations_needed_leave_one_out_counts_one_held_out_pose() {
        // 9 unknowns, one residual per pose: every 9-pose training set must exceed 9, so 11 poses.
        assert_eq!(observations_needed(9, 1), 11);
        // 6 unknowns, three residuals per pose: 3 training poses (9 > 6), so 4 poses.
        assert_eq!(observations_needed(6, 3), 4);
        // Beyond 12 poses a fold holds out ⌈n/12⌉: the answer is the first n that works.
        for (p, c) in [(9, 1), (6, 3), (30, 1), (15, 3)] {
            let n = observations_needed(p, c);
            let training = |n: usize| n - n.div_ceil(n.clamp(1, MAX_FOLDS));
            assert!(training(n) * c > p && training(n - 1) * c <= p);
        }
    }

    #[test]
    fn folds_are_leave_one_out_for_few_poses_and_interleaved_for_many() {
        assert_eq!(folds(5), vec![0, 1, 2, 3, 4]);
        let f = folds(72);
        // Balanced: 72 poses in 12 folds of 6.
        for fold in 0..12 {
            assert_eq!(f.iter().filter(|&&x| x == fold).count(), 6);
        }
        // Not periodic with the 12-pose schedule: poses 0, 12, 24, … are not all in one fold.
        assert!((1..6).any(|r| f[12 * r] != f[0]));
    }
}
