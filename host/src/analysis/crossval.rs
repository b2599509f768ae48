//! Held-out evaluation by pose and the rule that accepts an effect.
//!
//! Splits: leave-one-pose-out when there are at most [`MAX_FOLDS`] observations, otherwise
//! [`REPEATS`] repetitions of `MAX_FOLDS` folds, each a different pseudo-random balanced
//! assignment of the poses, so that every fold spans the whole recording in time and temperature.
//! When the base model cannot be refit on one of those training sets (six faces and nothing
//! else: a fold that holds out every pose of one face leaves its axis undetermined), leave-one-out
//! over the poses it can be refit without, the rest never held out ([`Splits`]).
//! Each observation is predicted by the model fitted without its fold; its held-out loss is the
//! squared residual in units of its own noise, `Lᵢ = Σₖ(rᵢₖ/σᵢₖ)²` (about 1 per component at the
//! floor), averaged over the repetitions.
//!
//! Acceptance of an extension over the current model, both conditions required:
//! 1. *More than chance*: the corrected resampled t test (Nadeau & Bengio, *Inference for the
//!    generalization error*, Machine Learning 52, 2003) rejects "no improvement" at
//!    `α = 0.01/m`, `m` = number of candidates tested in that round (Bonferroni). Its unit is
//!    the split: `d_j` = mean over the held-out poses of split `j` of `L_current − L_extended`,
//!    `J` = number of splits. The training sets of two splits share most of their poses, so the
//!    `d_j` are positively correlated and the naive variance `s²/J` of their mean is too small;
//!    the correction uses `(1/J + n_test/n_train)·s²` and Student's t with `J − 1` degrees of
//!    freedom (Bouckaert & Frank 2004 found it close to its nominal size with repeated k-fold).
//!    A signed-rank or sign-flip test on per-pose differences assumes independent pairs, which
//!    the shared training data break in the same way; a permutation test of the effect's
//!    variable would respect the dependence but needs hundreds of full cross-validations per
//!    candidate at `α = 0.01/m`. One badly predicted pose cannot carry the t test: it moves the
//!    splits that hold it out, which raises `s²` as much as the mean.
//!    α = 0.01 keeps the family-wise false-acceptance rate of a whole analysis (a few rounds)
//!    near 1–2 %, while a real effect of a few noise σ gives p-values far smaller.
//! 2. *Worth having*: the mean held-out loss falls by at least [`MIN_GAIN_PER_COMPONENT`] per
//!    residual component in units of the *inflated* floor, i.e. the effect predicts at least
//!    half a σ (RMS) of the scatter that real poses show. On real recordings that scatter is
//!    5–100× the white-noise variance (slow wander, placement, the AR(1) floor counts only the
//!    fast noise), so the white-noise floor is inflated by the Birge ratio `max(1, χ²/ν)` of the
//!    extended model (the policy of [`crate::fit::uncertainty`]). The extended model's χ², not
//!    the current one's, as in the F test of nested models: under the hypothesis being tested
//!    the extended model's residual is the noise, while the current model's still contains the
//!    effect, so a strong effect would raise its own bar. Smaller effects may be real but are
//!    below what a user can see in one pose, and a term the firmware applies must earn its place.

use super::effects::EffectKind;
use super::extended_fit::{fit_rows, ExtendedFit, Problem};
use crate::fit::uncertainty::{noise_scale, NoiseLevel};
use crate::stats::distributions::{f_upper_tail, student_t_upper_tail};
use nalgebra::DVector;

/// Largest number of folds.
pub const MAX_FOLDS: usize = 12;
/// Repetitions of the `MAX_FOLDS`-fold split (leave-one-out is not repeated: it is unique).
/// The corrected variance factor is `1/J + 1/11` with `J = 12·REPEATS`: at five repetitions the
/// first term is already below a fifth of the total, so more buy little power for their cost.
pub const REPEATS: usize = 5;
/// Family-wise significance level of one round of candidates.
pub const ALPHA: f64 = 0.01;
/// Significance level of the lack-of-fit test by which a bias free in shape over time or
/// temperature shows that an accepted time or temperature effect has the wrong form (the form
/// check of [`super`]). Higher than [`ALPHA`]: there a miss writes a wrong family to the
/// device, so the free-shape rival needs less evidence than a new effect does.
pub const FORM_ALPHA: f64 = 0.05;
/// Minimum fall of the mean held-out loss per residual component, in variances of the
/// inflated floor.
pub const MIN_GAIN_PER_COMPONENT: f64 = 0.25;

/// Held-out losses of one model.
#[derive(Debug, Clone)]
pub struct HeldOut {
    /// Per-observation held-out loss `Lᵢ` (noise units), mean over the repetitions, for each
    /// observation the splits hold out (in order).
    pub losses: Vec<f64>,
    /// Per-observation held-out residual in physical units (as
    /// [`super::extended_fit::physical_residual`]), RMS over the repetitions.
    pub residuals: Vec<f64>,
    /// Mean loss of the held-out observations of each split (repetition × fold, in order).
    pub split_losses: Vec<f64>,
    /// Mean over the splits of held-out over training observations, `n_test/n_train`.
    pub test_to_train: f64,
    /// Birge ratio `max(1, χ²/ν)` of the model fitted on every observation: the factor by
    /// which the white-noise floor is inflated for the gain criterion.
    pub floor_inflation: f64,
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

/// Fold index of each observation in the first repetition (see [`repeated_folds`]).
pub fn folds(n: usize) -> Vec<usize> {
    repeated_folds(n, 0)
}

/// Number of repetitions of the split for `n` observations: one for leave-one-out.
pub fn repetitions(n: usize) -> usize {
    if n <= MAX_FOLDS {
        1
    } else {
        REPEATS
    }
}

/// Fold index of each observation in repetition `repeat`: leave-one-out up to [`MAX_FOLDS`]
/// observations, otherwise a fixed pseudo-random balanced assignment per repetition (a plain
/// `i mod K` would line up with a schedule that repeats every `K` poses and hold out one
/// orientation at a time).
pub fn repeated_folds(n: usize, repeat: usize) -> Vec<usize> {
    let k = n.clamp(1, MAX_FOLDS);
    if n <= MAX_FOLDS {
        return (0..n).collect();
    }
    // Order the poses by a fixed hash (SplitMix64) and deal them out round-robin.
    let salt = (repeat as u64) << 32;
    let mix = |i: u64| {
        let mut z = i.wrapping_add(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    };
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by_key(|&i| mix(i as u64 ^ salt));
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

/// The held-out splits of one analysis: every model compared is evaluated on the same ones.
///
/// Normally [`repeated_folds`] over every observation. When the base model cannot be refit on
/// one of those training sets (a fold holds out every pose of one face, and the six faces are
/// all the orientations there are), leave-one-out over the observations the base model can be
/// refit without, the others staying in every training set: the rule by which `fit` scores
/// its models on the poses every compared model can be refit without.
#[derive(Debug, Clone, PartialEq)]
pub struct Splits {
    /// Held-out observations of each split, repetition by repetition.
    tests: Vec<Vec<usize>>,
    /// Repetitions (each observation tested is held out once in each).
    repeats: usize,
    /// Observations in all.
    n: usize,
}

impl Splits {
    /// [`repetitions`] of [`repeated_folds`] over `n` observations.
    pub fn folds(n: usize) -> Self {
        let repeats = repetitions(n);
        let mut tests = Vec::new();
        for repeat in 0..repeats {
            let fold_of = repeated_folds(n, repeat);
            let k = fold_of.iter().max().map_or(0, |m| m + 1);
            tests.extend((0..k).map(|fold| (0..n).filter(|&i| fold_of[i] == fold).collect()));
        }
        Self { tests, repeats, n }
    }

    /// The splits of an analysis of `problem`: [`Splits::folds`] when every training set
    /// determines the base model ([`Problem::determines_base`]), otherwise leave-one-out over
    /// the observations whose complement does. `None` when fewer than two can be held out, too
    /// few to compare two models on.
    pub fn for_problem(problem: &Problem) -> Option<Self> {
        let n = problem.points.len();
        let folds = Self::folds(n);
        if folds.tests.iter().all(|test| {
            let train: Vec<usize> = (0..n).filter(|i| !test.contains(i)).collect();
            problem.determines_base(&train)
        }) {
            return Some(folds);
        }
        let tests: Vec<Vec<usize>> = (0..n)
            .filter(|&i| {
                let train: Vec<usize> = (0..n).filter(|&j| j != i).collect();
                problem.determines_base(&train)
            })
            .map(|i| vec![i])
            .collect();
        (tests.len() >= 2).then_some(Self {
            tests,
            repeats: 1,
            n,
        })
    }

    /// Observations that are never held out (needed by the base model in every training set).
    pub fn always_trained(&self) -> usize {
        let mut tested = vec![false; self.n];
        for &i in self.tests.iter().flatten() {
            tested[i] = true;
        }
        tested.iter().filter(|t| !**t).count()
    }
}

/// Held-out losses of `effects` over every split of `splits`, each fold started from `full`
/// (the fit on all observations), over the observations the splits hold out. `None` when some
/// fold cannot be fitted.
pub fn held_out(
    problem: &Problem,
    effects: &[EffectKind],
    full: &ExtendedFit,
    splits: &Splits,
) -> Option<HeldOut> {
    let n = problem.points.len();
    let repeats = splits.repeats.max(1);
    let mut losses = vec![0.0; n];
    let mut squares = vec![0.0; n];
    let mut tested = vec![false; n];
    let mut split_losses = Vec::with_capacity(splits.tests.len());
    let mut ratio_sum = 0.0;
    let mut held = vec![false; n];
    for test in &splits.tests {
        held.iter_mut().for_each(|h| *h = false);
        test.iter().for_each(|&i| held[i] = true);
        let train: Vec<usize> = (0..n).filter(|&i| !held[i]).collect();
        let fit = fit_rows(problem, effects, &train, &full.params)?;
        let mut split = 0.0;
        for &i in test {
            let loss = problem
                .residual(i, effects, fit.params.as_slice())
                .norm_squared();
            let r = super::extended_fit::physical_residual(problem, i, effects, &fit.params).0;
            losses[i] += loss / repeats as f64;
            squares[i] += r * r / repeats as f64;
            tested[i] = true;
            split += loss / test.len() as f64;
        }
        split_losses.push(split);
        ratio_sum += test.len() as f64 / train.len() as f64;
    }
    let residual_count = n * problem.components();
    let floor_inflation = noise_scale(
        full.cost,
        residual_count,
        full.params.len(),
        NoiseLevel::Known,
    )
    .map_or(1.0, |s| s.variance_factor);
    let test_to_train = ratio_sum / split_losses.len().max(1) as f64;
    let keep = |v: Vec<f64>| -> Vec<f64> {
        v.into_iter()
            .zip(&tested)
            .filter(|(_, t)| **t)
            .map(|(x, _)| x)
            .collect()
    };
    let losses = keep(losses);
    losses.iter().all(|v| v.is_finite()).then(|| HeldOut {
        losses,
        residuals: keep(squares).iter().map(|v| v.sqrt()).collect(),
        split_losses,
        test_to_train,
        floor_inflation,
    })
}

/// One-sided p-value of the corrected resampled t test (Nadeau & Bengio 2003) for "the split
/// differences `d` tend to be positive", splits sharing training data with held-out over
/// training size `test_to_train` (see the module comment).
pub fn corrected_resampled_t(d: &[f64], test_to_train: f64) -> f64 {
    let j = d.len();
    if j < 2 || d.iter().any(|v| !v.is_finite()) {
        return 1.0;
    }
    let jf = j as f64;
    let mean = d.iter().sum::<f64>() / jf;
    let var = d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (jf - 1.0);
    let scale = ((1.0 / jf + test_to_train.max(0.0)) * var).sqrt();
    if scale <= 0.0 {
        // Identical differences: the sign decides.
        return if mean > 0.0 { 0.0 } else { 1.0 };
    }
    student_t_upper_tail(mean / scale, jf - 1.0)
}

/// The comparison of an extended model with the current one.
#[derive(Debug, Clone)]
pub struct Comparison {
    /// One-sided p-value of the improvement (corrected resampled t test).
    pub p_value: f64,
    /// Fall of the mean held-out loss per residual component, in variances of the inflated
    /// floor (the white-noise variance times the extended model's Birge ratio).
    pub gain_per_component: f64,
    /// The Birge ratio that inflated the floor.
    pub floor_inflation: f64,
    /// Relative fall of the mean held-out loss, `1 − L_ext/L_current` (the reported score).
    pub score: f64,
}

impl Comparison {
    /// Compare held-out losses of two models evaluated on the same splits.
    pub fn new(current: &HeldOut, extended: &HeldOut, components: usize) -> Self {
        let d: Vec<f64> = current
            .split_losses
            .iter()
            .zip(&extended.split_losses)
            .map(|(a, b)| a - b)
            .collect();
        let floor_inflation = extended.floor_inflation.max(1.0);
        let gain = (current.mean_loss() - extended.mean_loss())
            / components.max(1) as f64
            / floor_inflation;
        let base = current.mean_loss();
        let score = if base > 0.0 {
            1.0 - extended.mean_loss() / base
        } else {
            0.0
        };
        Self {
            p_value: corrected_resampled_t(&d, extended.test_to_train),
            gain_per_component: gain,
            floor_inflation,
            score,
        }
    }

    /// The acceptance rule of the module comment, with `m` candidates in the round.
    pub fn passes(&self, m: usize) -> bool {
        self.p_value <= ALPHA / m.max(1) as f64 && self.gain_per_component >= MIN_GAIN_PER_COMPONENT
    }
}

/// P-value of the lack-of-fit F test of a model (in-sample cost `cost`) against the same model
/// extended by `extra` parameters (cost `cost_extended`, `dof_extended` residual degrees of
/// freedom): `F = ((χ² − χ²_ext)/extra)/(χ²_ext/ν_ext)`. The noise is estimated from the
/// extended model, so a floor that is too small cancels; fitted once on every observation, the
/// test has none of the dependence between cross-validation splits.
pub fn lack_of_fit_p(cost: f64, cost_extended: f64, extra: usize, dof_extended: usize) -> f64 {
    if extra == 0
        || dof_extended == 0
        || cost_extended.is_nan()
        || cost_extended <= 0.0
        || !cost.is_finite()
    {
        return 1.0;
    }
    let f =
        ((cost - cost_extended).max(0.0) / extra as f64) / (cost_extended / dof_extended as f64);
    f_upper_tail(f, extra as f64, dof_extended as f64)
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
    fn corrected_t_widens_the_naive_t_by_the_training_overlap() {
        // d = 1, 2, 4: mean 7/3, s² = 7/3, ν = 2, where P(T ≥ t) = ½ − t/(2√(2 + t²)) exactly.
        let tail2 = |t: f64| 0.5 - t / (2.0 * (2.0 + t * t).sqrt());
        let d = [1.0, 2.0, 4.0];
        let mean: f64 = 7.0 / 3.0;
        // Without overlap it is the one-sample t test: t = mean/√(s²/J).
        let naive = mean / (mean / 3.0).sqrt();
        assert!((corrected_resampled_t(&d, 0.0) - tail2(naive)).abs() < 1e-12);
        // Leave-one-out on 3 poses: n_test/n_train = 1/2, variance (1/3 + 1/2)·s².
        let corrected = mean / ((1.0 / 3.0 + 0.5) * mean).sqrt();
        let p = corrected_resampled_t(&d, 0.5);
        assert!((p - tail2(corrected)).abs() < 1e-12);
        assert!(p > corrected_resampled_t(&d, 0.0));
        // No improvement on average gives p ≥ ½; a single split decides nothing.
        assert!(corrected_resampled_t(&[1.0, -1.0, 0.5, -0.5], 0.1) >= 0.5);
        assert_eq!(corrected_resampled_t(&[3.0], 0.1), 1.0);
    }

    #[test]
    fn lack_of_fit_p_is_the_f_tail_of_the_cost_reduction_per_extra_parameter() {
        // χ² 21.124 → 10 with 3 extra parameters and ν = 10: F = (11.124/3)/(10/10) = 3.708, the
        // tabulated upper 5 % point of F(3, 10) (3 decimals, hence 2e-4 on p).
        assert!((lack_of_fit_p(21.124, 10.0, 3, 10) - 0.05).abs() < 2e-4);
        // Scaling both costs (a floor too small by any factor) leaves p unchanged.
        let p = lack_of_fit_p(21.124 * 7.0, 70.0, 3, 10);
        assert!((p - lack_of_fit_p(21.124, 10.0, 3, 10)).abs() < 1e-12);
        // No reduction: nothing to find.
        assert_eq!(lack_of_fit_p(10.0, 10.0, 3, 10), 1.0);
    }

    #[test]
    fn repetitions_are_different_balanced_splits() {
        assert_eq!(repetitions(12), 1);
        assert_eq!(repetitions(13), REPEATS);
        let first = repeated_folds(40, 0);
        assert_eq!(first, folds(40));
        for r in 1..REPEATS {
            let f = repeated_folds(40, r);
            // Balanced: 40 poses in 12 folds of 3 or 4.
            for fold in 0..MAX_FOLDS {
                let size = f.iter().filter(|&&x| x == fold).count();
                assert!(
                    (3..=4).contains(&size),
                    "repetition {r}, fold {fold}: {size}"
                );
            }
            // Different pairings of poses from the first repetition.
            let pairs_kept = (0..40)
                .flat_map(|i| (i + 1..40).map(move |j| (i, j)))
                .filter(|&(i, j)| first[i] == first[j] && f[i] == f[j])
                .count();
            let pairs = (0..40)
                .flat_map(|i| (i + 1..40).map(move |j| (i, j)))
                .filter(|&(i, j)| first[i] == first[j])
                .count();
            assert!(
                pairs_kept * 2 < pairs,
                "repetition {r}: {pairs_kept} of {pairs} pairs kept"
            );
        }
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
