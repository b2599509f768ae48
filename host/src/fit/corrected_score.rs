//! Corrected score for the weighted norm residual `rᵢ = wᵢ(|R(xᵢ − b)| − 1)` of the norm-model
//! LM (`norm_lm.rs`), in its centred, scaled coordinates and upper-triangular gauge.
//!
//! The least-squares estimate solves `Jᵀr = 0`; because `rᵢ` and the Jacobian row both contain
//! the noise of `xᵢ`, `E[Jᵀr] ≠ 0` at the truth (second order in σ), and on partial coverage
//! this is amplified along the poorly determined centre–radius direction. The corrected score
//! `Jᵀr − Σᵢ E[rᵢ∇rᵢ]` has zero expectation at the truth to second order (L. A. Stefanski 1989,
//! "Unbiased estimation of a nonlinear function of a normal mean with application to
//! measurement error models"; T. Nakamura 1990, "Corrected score function for errors-in-variables
//! models", Biometrika 77).

use nalgebra::{DMatrix, DVector};

use super::lm::{LeastSquaresProblem, LmSolution};
use super::norm_jacobian::{for_each_block, in_two_halves, NormSamples, LANES};
use super::{Mat3, Vec3};

/// The upper-triangular `R` of the parameter vector `A11 A12 A13 A22 A23 A33 b1 b2 b3`.
pub(super) fn upper_from_params(p: &DVector<f64>) -> Mat3 {
    Mat3::new(p[0], p[1], p[2], 0.0, p[3], p[4], 0.0, 0.0, p[5])
}

/// The corrected score `Jᵀr − Σᵢ E[rᵢ·∇rᵢ]` at `p`, the expectation to second order in the noise
/// (per-axis variance `noise_var(i)` of point `i`, scaled units): the residual and its gradient
/// share the noise of `xᵢ`, so the least-squares score `Jᵀr` does not vanish in expectation at
/// the truth. With `u = x − b`, `v = Ru`, `v̂ = v/|v|`, `P_t = I − v̂v̂ᵀ` and `n` the noise:
/// `r ≈ w·v̂ᵀRn`, `∂r/∂R_jk = w·v̂_j(n)·u_k(n)`, `∂r/∂b = −w·Rᵀv̂(n)` with
/// `v̂(n) ≈ v̂ + P_tRn/|v|`, so `E[r ∂r/∂R_jk] = w²σ²(v̂_j (Rᵀv̂)_k + u_k (P_tRRᵀv̂)_j/|v|)` and
/// `E[r ∂r/∂b] = −w²σ² RᵀP_tRRᵀv̂/|v|`. One pass, in blocks of lanes, on two threads for large
/// problems.
fn corrected_score(
    samples: NormSamples<'_>,
    p: &DVector<f64>,
    noise_var: &(impl Fn(usize) -> f64 + Sync),
) -> DVector<f64> {
    let r = upper_from_params(p);
    let b = Vec3::new(p[6], p[7], p[8]);
    let total = in_two_halves(
        samples.len(),
        &mut [],
        |range, _| {
            let from = range.start;
            score_sums(&r, &b, samples.range(range), |i| noise_var(from + i))
        },
        |mut first, second| {
            first.iter_mut().zip(second).for_each(|(a, b)| *a += b);
            first
        },
    );
    DVector::from_row_slice(&total)
}

/// The corrected score of [`corrected_score`] over the given samples (`noise_var(i)` of
/// their sample `i`).
fn score_sums(
    r: &Mat3,
    b: &Vec3,
    samples: NormSamples<'_>,
    noise_var: impl Fn(usize) -> f64,
) -> [f64; 9] {
    let mut acc = [[0.0; LANES]; 9];
    for_each_block(r, b, samples, |start, valid, block| {
        let mut c = [0.0; LANES];
        for (lane, c) in c.iter_mut().enumerate().take(valid) {
            *c = block.weight[lane] * block.weight[lane] * noise_var(start + lane);
        }
        for lane in 0..LANES {
            let vh = Vec3::from_fn(|i, _| block.direction[i][lane]);
            let u = Vec3::from_fn(|i, _| block.u[i][lane]);
            let radial = r.transpose() * vh;
            let r_radial = r * radial;
            let tangential = (r_radial - vh * vh.dot(&r_radial)) * block.inverse_norm[lane];
            let db = -(r.transpose() * tangential);
            let c = c[lane];
            let score = |k: usize| block.rows[k][lane] * block.res[lane];
            for (k, &(row, col)) in UPPER_ENTRIES.iter().enumerate() {
                acc[k][lane] += score(k) - c * (vh[row] * radial[col] + u[col] * tangential[row]);
            }
            for k in 0..3 {
                acc[6 + k][lane] += score(6 + k) - c * db[k];
            }
        }
    });
    acc.map(|lanes| lanes.iter().sum())
}

/// Entries `(row, col)` of the upper-triangular parameters, in parameter order.
const UPPER_ENTRIES: [(usize, usize); 6] = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];

/// Corrected score (Stefanski 1989; Nakamura 1990): solve `Jᵀr − Σ E[r∇r] = 0` from the
/// least-squares solution `start`, where the normal matrix is `jtj`. The least-squares root is
/// biased at second order in the noise, and on partial coverage that bias is amplified along
/// the poorly determined direction; the corrected root is not. The iteration keeps `jtj` (a
/// chord method): the root lies O(σ²) from `start`, so `JᵀJ` changes by as little, and each
/// step, like a Gauss–Newton one, gains a factor of order σ (the residual's curvature term).
/// The iteration stops once a step's length in the metric of `jtj`, `δᵀ(JᵀJ)δ`, is at most
/// `negligible_step2` (the caller's square of a negligible fraction of a standard error), or
/// relative to the parameters at rounding level. Returns the root and the number of steps;
/// `None` when the iteration does not settle.
pub(super) fn solve_corrected_score(
    samples: NormSamples<'_>,
    jtj: &DMatrix<f64>,
    start: &DVector<f64>,
    noise_var: &(impl Fn(usize) -> f64 + Sync),
    negligible_step2: f64,
) -> Option<(DVector<f64>, usize)> {
    let factor = jtj.clone().cholesky()?;
    let mut p = start.clone();
    for steps in 1..=30 {
        let step = factor.solve(&(-corrected_score(samples, &p, noise_var)));
        if !step.iter().all(|v| v.is_finite()) {
            return None;
        }
        p += &step;
        if step.dot(&(jtj * &step)) <= negligible_step2 || step.norm() <= 1e-12 * (p.norm() + 1e-12)
        {
            return Some((p, steps));
        }
    }
    None
}

/// Residuals, `JᵀJ` and `Jᵀr` at `p`, in one pass when the problem offers it.
fn evaluate<P: LeastSquaresProblem>(
    problem: &P,
    p: &DVector<f64>,
) -> (DVector<f64>, DMatrix<f64>, DVector<f64>) {
    problem
        .residuals_with_normal_equations(p)
        .unwrap_or_else(|| {
            let r = problem.residuals(p);
            let (jtj, jtr) = problem.normal_equations(p, &r);
            (r, jtj, jtr)
        })
}

/// `sol` moved to `params`: residuals, normal matrix and cost there.
pub(super) fn re_evaluate<P: LeastSquaresProblem>(
    problem: &P,
    mut sol: LmSolution,
    params: DVector<f64>,
) -> LmSolution {
    (sol.residuals, sol.jtj, _) = evaluate(problem, &params);
    sol.cost = sol.residuals.norm_squared();
    sol.params = params;
    sol
}
