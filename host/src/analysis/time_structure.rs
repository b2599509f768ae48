//! Whether what a model leaves still follows time: a permutation test of how well each
//! residual is predicted by a bias fitted to its neighbours in time.
//!
//! A recording is sequential, so every slow change of the bias that a model does not express — a
//! random walk, a step, hysteresis, a thermal lag — leaves residuals that a bias vector fitted to
//! the [`NEIGHBOURS`] observations nearest in time predicts. Observation `i` sees a bias error
//! `e` through `Hᵢ`: the identity for the gyroscope at rest (three residual components), the
//! unit direction of the calibrated reading for a norm model (`|y|` changes by `nᵢ·e`), so the
//! neighbours' directions, which differ from pose to pose, still determine `e`. The statistic is
//! `S = Σᵢ zᵢᵀ·Hᵢ·êᵢ` with `êᵢ` the least-squares bias of `i`'s neighbours (not `i` itself) and `z`
//! the noise-weighted residuals. If the model is right, what it leaves does not depend on time and
//! the time order of the observations (each with its own `zᵢ`, `Hᵢ`) is exchangeable; the p-value
//! is the fraction of [`PERMUTATIONS`] random orders (a fixed-seed generator, so an analysis is
//! reproducible) with an `S` at least as large. Distribution-free: no assumption on the size or
//! shape of the noise. A linear trend that is the straight-line part of a random walk or of a
//! step leaves such residuals; a true drift, once fitted, does not.

use nalgebra::{DVector, Matrix3};

use super::effects::EffectKind;
use super::extended_fit::{base_calibration, BaseKind, ExtendedFit, Problem};
use crate::fit::Vec3;

/// Random orders of the permutation test.
pub const PERMUTATIONS: usize = 2000;
/// Observations nearest in time that predict each one (twice the three unknowns of a bias).
pub const NEIGHBOURS: usize = 6;

/// One observation as the test sees it: noise-weighted residual components and the rows of `H`.
#[derive(Debug, Clone, PartialEq)]
pub struct TimedResidual {
    /// Residual components in noise units.
    pub z: Vec<f64>,
    /// How a bias error reaches each component (one row per component).
    pub h: Vec<Vec3>,
}

fn statistic(obs: &[TimedResidual], order: &[usize]) -> f64 {
    let n = order.len();
    let half = NEIGHBOURS / 2;
    let mut s = 0.0;
    for pos in 0..n {
        let lo = pos
            .saturating_sub(half)
            .min(n.saturating_sub(NEIGHBOURS + 1));
        let hi = (lo + NEIGHBOURS + 1).min(n);
        let mut normal = Matrix3::zeros();
        let mut rhs = Vec3::zeros();
        for &j in order[lo..hi].iter().filter(|&&j| j != order[pos]) {
            for (z, h) in obs[j].z.iter().zip(&obs[j].h) {
                normal += h * h.transpose();
                rhs += h * *z;
            }
        }
        // A small ridge keeps a degenerate neighbourhood (all one direction) solvable.
        let ridge = 1e-9 * normal.trace().max(1e-300);
        let Some(inv) = (normal + Matrix3::identity() * ridge).try_inverse() else {
            continue;
        };
        let e = inv * rhs;
        let o = &obs[order[pos]];
        s +=
            o.z.iter()
                .zip(&o.h)
                .map(|(z, h)| z * h.dot(&e))
                .sum::<f64>();
    }
    s
}

/// One-sided permutation p-value for "the residuals of `obs` (in time order) are predicted by
/// their neighbours in time". Fewer than `NEIGHBOURS + 2` observations give 1.
pub fn follows_time_p(obs: &[TimedResidual]) -> f64 {
    let n = obs.len();
    if n < NEIGHBOURS + 2 {
        return 1.0;
    }
    let mut order: Vec<usize> = (0..n).collect();
    let observed = statistic(obs, &order);
    // SplitMix64: a fixed stream, so the same residuals always give the same p-value.
    let mut state: u64 = 0x5EED_0F71_AE00;
    let mut next = move || {
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut x = state;
        x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        x ^ (x >> 31)
    };
    let mut at_least = 0usize;
    for _ in 0..PERMUTATIONS {
        // Fisher–Yates.
        for i in (1..n).rev() {
            let j = (next() % (i as u64 + 1)) as usize;
            order.swap(i, j);
        }
        if statistic(obs, &order) >= observed {
            at_least += 1;
        }
    }
    (1 + at_least) as f64 / (1 + PERMUTATIONS) as f64
}

/// The residuals of `fit` as the test sees them, in the order of `times`.
pub fn timed_residuals(problem: &Problem, fit: &ExtendedFit, times: &[f64]) -> Vec<TimedResidual> {
    let mut order: Vec<usize> = (0..problem.points.len().min(times.len())).collect();
    order.sort_by(|&a, &b| times[a].total_cmp(&times[b]));
    let cal = base_calibration(problem, &fit.params);
    order
        .into_iter()
        .map(|i| {
            let r = problem.residual(i, &fit.effects, fit.params.as_slice());
            match problem.base {
                BaseKind::Rest { .. } => TimedResidual {
                    z: vec![r[0], r[1], r[2]],
                    h: vec![Vec3::x(), Vec3::y(), Vec3::z()],
                },
                BaseKind::Norm { .. } => {
                    let y = cal.a * (problem.points[i] - cal.b);
                    TimedResidual {
                        z: vec![r[0]],
                        h: vec![y.try_normalize(1e-300).unwrap_or_else(Vec3::zeros)],
                    }
                }
            }
        })
        .collect()
}

/// The effects of `fit` without the one at `index`, and its parameters without that effect's
/// block (a start for the refit).
pub fn without_effect(
    problem: &Problem,
    fit: &ExtendedFit,
    index: usize,
) -> (Vec<EffectKind>, DVector<f64>) {
    let offset = problem.base_params()
        + fit.effects[..index.min(fit.effects.len())]
            .iter()
            .map(|e| e.param_count())
            .sum::<usize>();
    let count = fit.effects.get(index).map_or(0, |e| e.param_count());
    let params: Vec<f64> = fit
        .params
        .iter()
        .enumerate()
        .filter(|(j, _)| !(offset..offset + count).contains(j))
        .map(|(_, v)| *v)
        .collect();
    let mut effects = fit.effects.clone();
    if index < effects.len() {
        effects.remove(index);
    }
    (effects, DVector::from_vec(params))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Deterministic pseudo-noise in [−1, 1].
    fn noise(state: &mut u64) -> f64 {
        *state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1);
        ((*state >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }

    /// Norm-model observations cycling through twelve directions, with residual `nᵢ·e(tᵢ) + noise`.
    fn norm_observations(walk: f64) -> Vec<TimedResidual> {
        let mut s = 11;
        let mut e = Vec3::zeros();
        (0..48)
            .map(|i| {
                let a = i as f64 * 2.4;
                let n = Vec3::new(a.cos(), a.sin(), (0.7 * a).cos()).normalize();
                e += Vec3::new(noise(&mut s), noise(&mut s), noise(&mut s)) * walk;
                TimedResidual {
                    z: vec![n.dot(&e) + noise(&mut s)],
                    h: vec![n],
                }
            })
            .collect()
    }

    #[test]
    fn a_random_walk_seen_through_changing_directions_follows_time() {
        // At the analysis's level α = 0.01.
        assert!(follows_time_p(&norm_observations(1.5)) < 0.01);
    }

    #[test]
    fn white_residuals_do_not_follow_time() {
        // Noise only: p is uniform; this draw is not in the lower 1 %.
        assert!(follows_time_p(&norm_observations(0.0)) > 0.01);
    }

    #[test]
    fn too_few_residuals_carry_no_evidence() {
        let one = TimedResidual {
            z: vec![1.0],
            h: vec![Vec3::x()],
        };
        assert_eq!(follows_time_p(&vec![one; NEIGHBOURS + 1]), 1.0);
    }
}
