//! Variance of a long run's mean by the method of batch means (e.g. Law & Kelton, *Simulation
//! Modeling and Analysis*, §9.5.3; Flyvbjerg & Petersen 1989): split the run into `k` equal
//! batches and take the variance of the `k` batch means over `k`. Unlike `σ²/n`, it holds when
//! the samples are correlated or wander, as long as the batches are longer than the
//! correlation. A gyroscope's bias instability has no short correlation time (its wander grows
//! with the time scale), so the batches are made as long as the estimate allows: `k = 16`
//! batches (15 degrees of freedom: the estimate is within about ±35 % at 1σ), fewer for short
//! runs, at least 8 samples each.
//!
//! Under white noise `(k − 1)·s²_batch / (σ²/b)` follows `χ²(k − 1)` (`b` samples per batch),
//! so [`excess_wander`] calls the batch estimate larger than `σ²/n` only when that ratio lies
//! beyond its upper 1 % point: white noise keeps its textbook standard error.

use super::distributions::chi2_upper_tail;
use super::Vec3;

/// Significance of the test that the batch means scatter more than white noise would make
/// them: 1 %, the consistency level of [`super::chi_square`].
const WANDER_ALPHA: f64 = 0.01;

/// Fewest batches for an estimate (below it the run is too short to say anything).
const MIN_BATCHES: usize = 8;
/// Batches of a long run.
const BATCHES: usize = 16;
/// Fewest samples per batch.
const MIN_BATCH_LEN: usize = 8;

/// Per-axis variance of the mean of `samples` by batch means, with the number of batches, or
/// `None` when the run is too short for [`MIN_BATCHES`] batches of [`MIN_BATCH_LEN`] samples or
/// a value is not finite.
pub fn batch_var_of_mean(samples: &[Vec3]) -> Option<(Vec3, usize)> {
    let n = samples.len();
    let k = (n / MIN_BATCH_LEN).min(BATCHES);
    if k < MIN_BATCHES || samples.iter().any(|s| !s.iter().all(|v| v.is_finite())) {
        return None;
    }
    let per_batch = n / k;
    let means: Vec<Vec3> = samples
        .chunks_exact(per_batch)
        .take(k)
        .map(|batch| batch.iter().sum::<Vec3>() / per_batch as f64)
        .collect();
    let grand = means.iter().sum::<Vec3>() / k as f64;
    let scatter = means
        .iter()
        .map(|m| (m - grand).component_mul(&(m - grand)))
        .sum::<Vec3>()
        / (k - 1) as f64;
    Some((scatter / k as f64, k))
}

/// The variance of the mean to use for a run whose white-noise estimate is `white_var_of_mean`
/// (per axis, `σ²/n`): the batch-means estimate on an axis where the batch means scatter
/// significantly more than white noise explains (see the module comment), else the white one.
pub fn excess_wander(samples: &[Vec3], white_var_of_mean: Vec3) -> Vec3 {
    let Some((batch, k)) = batch_var_of_mean(samples) else {
        return white_var_of_mean;
    };
    let dof = (k - 1) as f64;
    Vec3::from_fn(|axis, _| {
        let white = white_var_of_mean[axis];
        if white.is_nan() || white <= 0.0 {
            return white;
        }
        // The batch means of white noise have variance σ²/b = k·white each.
        let statistic = dof * batch[axis] / white;
        if chi2_upper_tail(statistic, dof) < WANDER_ALPHA {
            batch[axis]
        } else {
            white
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_distr::{Distribution, Normal};

    fn white(seed: u64, n: usize) -> Vec<Vec3> {
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let normal = Normal::new(0.0, 1.0).expect("σ > 0");
        (0..n)
            .map(|_| Vec3::from_fn(|_, _| normal.sample(&mut rng)))
            .collect()
    }

    #[test]
    fn white_noise_keeps_its_textbook_standard_error_in_almost_every_run() {
        // Each run is tested at 1 % per axis: of 200 runs × 3 axes, about 6 keep the batch
        // estimate by chance; 20 would mean the test is biased.
        let mut replaced = 0;
        for seed in 0..200 {
            let samples = white(seed, 2500);
            let white_var = Vec3::repeat(1.0 / 2500.0);
            let used = excess_wander(&samples, white_var);
            replaced += (0..3).filter(|&a| used[a] != white_var[a]).count();
        }
        assert!(replaced <= 20, "{replaced} of 600 axes");
    }

    #[test]
    fn a_wandering_bias_gets_the_spread_of_its_batch_means() {
        // Unit white noise plus a random walk whose steps add up to a wander of several
        // standard errors of the mean over the run (as a gyroscope's bias over minutes).
        let n = 10_000;
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let mut walk = 0.0;
        let samples: Vec<Vec3> = white(3, n)
            .into_iter()
            .map(|s| {
                walk += rng.gen_range(-0.02..0.02);
                s + Vec3::new(walk, 0.0, 0.0)
            })
            .collect();
        let white_var = Vec3::repeat(1.0 / n as f64);
        let used = excess_wander(&samples, white_var);
        // The walk's own spread of the mean: several times the white standard error.
        assert!(used[0] > 4.0 * white_var[0], "{used:?}");
        assert_eq!(used[1], white_var[1]);
    }

    #[test]
    fn short_or_non_finite_runs_give_no_batch_estimate() {
        assert!(batch_var_of_mean(&white(1, 63)).is_none());
        let mut samples = white(1, 100);
        samples[5][1] = f64::NAN;
        assert!(batch_var_of_mean(&samples).is_none());
        let white_var = Vec3::repeat(0.01);
        assert_eq!(excess_wander(&samples, white_var), white_var);
    }
}
