//! Levenberg–Marquardt refinement of the norm model `|A(xᵢ − b)| = ref` (the default method).
//!
//! Seed 003 (Chen et al.) iterates on the norm model from a six-position start; seed 000
//! (Puc et al., eq. 17–29) gives the algebraic ellipsoid start for the magnetometer. Here the
//! residual is the measurement residual `rᵢ = (|A(xᵢ − b)| − ref)/σ'ᵢ`, with `σ'ᵢ` the noise of
//! the calibrated norm; to first order this is the orthogonal distance to the ellipsoid in units
//! of its noise, so the weighted least-squares estimate is the maximum-likelihood one and
//! `(JᵀJ)⁻¹` is its Cramér–Rao bound. Gauge: `A` upper-triangular with positive diagonal
//! (9 unknowns); a start with a general `A = QR` is converted to `R`, since `|Au| = |Ru|`.
//!
//! For robustness with large offsets the unknowns are solved for in centred, scaled data
//! `x̃ = (x − c)/s` (c = start offset, s = RMS distance from it), where every parameter is of
//! order one: `A = ref·R̃/s`, `b = c + s·b̃`.
//!
//! `σ'ᵢ = σᵢ·|Aᵀv̂ᵢ|` (v̂ = direction of the calibrated point) is the radial part of the noise.
//! The tangential part lengthens every norm on average by `σ_t²/(2|v|)`; a second pass subtracts
//! this (the first-order "essential bias" of the geometric fit), which matters at low
//! signal-to-noise. The residual and its Jacobian share each point's noise, so the
//! least-squares score `Jᵀr` is biased at second order; on partial coverage this bias is
//! amplified along the poorly determined centre–radius direction (−1.3 σ_CRB on a 90° cap).
//! The final pass solves the corrected score `Jᵀr − E[Jᵀr] = 0` instead (Stefanski 1989,
//! Nakamura 1990), which removes it (see `examples/fit_montecarlo.rs`). The covariance follows
//! [`super::uncertainty`].
//!
//! Passes over large data: the first pass only sets the weights, so it stops a tenth of a
//! standard error from its optimum and, from twice [`NormLmOptions::iteration_samples`] on, is
//! fitted on a quarter as many samples spread evenly over the data (every `LANES·stride`-th;
//! its noise scale is then taken over every sample); the second pass steers its steps with
//! `JᵀJ` summed over `iteration_samples` of them (every `stride`-th block) but solves the full
//! `Jᵀr = 0`, or, when it ends in the corrected score, solves that score straight from the
//! first pass's solution (its least-squares root would only start that iteration); the
//! corrected score stops at a hundredth of a standard error; the covariance and leverages are
//! summed over every sample at the solution.

use std::borrow::Cow;

use nalgebra::{DMatrix, DVector};

use super::chen::fit_chen;
use super::corrected_score::{re_evaluate, solve_corrected_score, upper_from_params};
use super::covariance::{
    calibration_std, normal_covariance, param_names, reduced_chi_square, UPPER_TRIANGULAR_LAYOUT,
};
use super::coverage::{guard_fit, sphere_start, CoverageHint, EllipsoidModel};
use super::li::li_start;
use super::li::{fit_li_start, LiOptions};
use super::linalg::{equilibrated_condition_from_normal_matrix, upper_triangular_gauge};
use super::lm::{levenberg_marquardt, LeastSquaresProblem, LmOptions, LmSolution};
use super::loo::{held_out_rms, leave_one_out_rms, UPDATED_FOLDS_MIN_POSES};
use super::norm_jacobian::{
    hessian_stride, in_two_halves, jacobian_row, norm_residual, residuals_and_normal_equations,
    NormSamples, ITERATION_SAMPLES, LANES,
};
use super::norm_loo::{first_order_loo_rms, FoldUpdate, FOLD_UPDATE_MAX_POINTS};
use super::six_position::fit_six_position;
use super::uncertainty::{scaled_covariance, NoiseLevel, Z_95};
use super::validate::{check_finite_points, check_finite_poses};
use super::{Calibration, Fit, FitError, Mat3, Method, Pose, Vec3};

/// Points on the (distorted) sphere and the noise of each point's norm.
#[derive(Debug, Clone, PartialEq)]
pub struct NormObservations<'a> {
    /// Readings (pose means or samples), in data units: borrowed when the caller keeps them
    /// (a million magnetometer samples need not be copied to be fitted).
    pub points: Cow<'a, [Vec3]>,
    /// One-sigma noise of the points along their radial direction, in data units.
    pub sigma: NormNoise,
}

/// One-sigma noise of the points' norms along their radial direction, in data units.
#[derive(Debug, Clone, PartialEq)]
pub enum NormNoise {
    /// The same noise for every point, held once rather than once per point.
    Uniform(f64),
    /// The noise of each point, in the order of the points.
    PerPoint(Vec<f64>),
}

impl NormNoise {
    /// The noise of point `i` (which must exist for [`NormNoise::PerPoint`]).
    pub fn at(&self, i: usize) -> f64 {
        match self {
            Self::Uniform(sigma) => *sigma,
            Self::PerPoint(sigma) => sigma[i],
        }
    }
}

impl<'a> NormObservations<'a> {
    /// Pose means, each with the noise of its mean (`var/n`) projected on its direction from `centre`.
    pub fn from_poses(poses: &[Pose], centre: &Vec3) -> Self {
        let points: Vec<Vec3> = poses.iter().map(|p| p.mean).collect();
        let sigma = poses
            .iter()
            .map(|p| {
                let d = (p.mean - centre)
                    .try_normalize(0.0)
                    .unwrap_or_else(|| Vec3::repeat(1.0 / 3f64.sqrt()));
                d.component_mul(&d).dot(&p.var_of_mean()).max(0.0).sqrt()
            })
            .collect();
        Self {
            points: points.into(),
            sigma: NormNoise::PerPoint(sigma),
        }
    }

    /// Samples with one common (possibly unknown, then use 1) noise level.
    pub fn uniform(points: impl Into<Cow<'a, [Vec3]>>, sigma: f64) -> Self {
        Self {
            points: points.into(),
            sigma: NormNoise::Uniform(sigma),
        }
    }

    /// The noise of each point, in the order of the points.
    pub fn sigmas(&self) -> impl Iterator<Item = f64> + '_ {
        (0..self.points.len()).map(|i| self.sigma.at(i))
    }
}

/// Options of [`refine_lm`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NormLmOptions {
    /// Solver settings.
    pub lm: LmOptions,
    /// `true` when `sigma` is the real noise (covariance `(JᵀJ)⁻¹`, inflated by the Birge ratio
    /// when the scatter exceeds it); `false` when it is only relative, so the noise is estimated
    /// from the residual. See [`super::uncertainty`].
    pub noise_known: bool,
    /// In the final pass, remove the `σ_t²/(2n)` lengthening of each norm by tangential noise
    /// and solve the corrected score (second-order bias) instead of the least-squares one (with
    /// unknown noise, σ is first estimated from the residual).
    pub correct_norm_bias: bool,
    /// On a problem of at least twice this many samples (`None`: never), about this many
    /// spread evenly over the data steer the iterations: the first (weighting) pass is fitted
    /// on a quarter as many (every `LANES`-th of their blocks' samples), and the second pass's
    /// iterations sum `JᵀJ` over them. The solution is
    /// the root of the second pass's exact `Jᵀr` over every sample, and its covariance and
    /// leverages are summed over every sample at the solution. See
    /// [`super::norm_jacobian::hessian_stride`] and the module comment.
    pub iteration_samples: Option<usize>,
}

impl Default for NormLmOptions {
    fn default() -> Self {
        Self {
            lm: LmOptions::default(),
            noise_known: true,
            correct_norm_bias: true,
            iteration_samples: Some(ITERATION_SAMPLES),
        }
    }
}

/// A norm-model fit with its goodness of fit.
#[derive(Debug, Clone)]
pub struct NormLmOutcome {
    /// The fit.
    pub fit: Fit,
    /// `χ²/(N − 9)`: about 1 when the residual is at the noise floor given by `sigma`.
    pub reduced_chi_square: Option<f64>,
    /// Leave-one-out RMS of the relative norm residual to first order, from the leverages of
    /// the final normal matrix ([`super::norm_loo`]): one pass, not one refit per point.
    pub first_order_loo_rms: Option<f64>,
    /// The fit without any one point, to first order ([`FoldUpdate`]); kept for fits of pose
    /// means (a noise per point) and of up to 10 000 samples, `None` for larger clouds.
    pub fold_update: Option<FoldUpdate>,
}

/// The weighted norm residual in centred, scaled coordinates.
struct NormProblem {
    /// Centred, scaled points `x̃ᵢ`.
    points: Vec<Vec3>,
    /// `1/σ'ᵢ` in units of the reference.
    weights: Vec<f64>,
    /// Half the tangential noise variance `½σ_t²` of each calibrated point (reference units):
    /// noise across the sphere lengthens a vector by `σ_t²/(2n)` on average, which is removed.
    tangential: Vec<f64>,
    /// The stride of blocks over which `JᵀJ` is summed ([`hessian_stride`]; 1: all).
    hessian_stride: usize,
}

impl NormProblem {
    fn samples(&self) -> NormSamples<'_> {
        NormSamples {
            points: &self.points,
            weights: &self.weights,
            tangential: &self.tangential,
        }
    }

    /// Residuals, `JᵀJ` and `Jᵀr` at `p` in one pass ([`residuals_and_normal_equations`]).
    fn evaluate(&self, p: &DVector<f64>) -> (DVector<f64>, DMatrix<f64>, DVector<f64>) {
        let r = upper_from_params(p);
        let b = Vec3::new(p[6], p[7], p[8]);
        let mut res = vec![0.0; self.points.len()];
        let (upper, grad) =
            residuals_and_normal_equations(&r, &b, self.samples(), &mut res, self.hessian_stride);
        let mut jtj = DMatrix::zeros(9, 9);
        let mut at = 0;
        for i in 0..9 {
            for j in i..9 {
                jtj[(i, j)] = upper[at];
                jtj[(j, i)] = upper[at];
                at += 1;
            }
        }
        (DVector::from_vec(res), jtj, DVector::from_row_slice(&grad))
    }
}

impl LeastSquaresProblem for NormProblem {
    fn residuals(&self, p: &DVector<f64>) -> DVector<f64> {
        let r = upper_from_params(p);
        let b = Vec3::new(p[6], p[7], p[8]);
        DVector::from_iterator(
            self.points.len(),
            self.points
                .iter()
                .zip(&self.weights)
                .zip(&self.tangential)
                .map(|((x, w), k)| norm_residual((r * (x - b)).norm(), *w, *k)),
        )
    }

    fn jacobian(&self, p: &DVector<f64>) -> DMatrix<f64> {
        let r = upper_from_params(p);
        let b = Vec3::new(p[6], p[7], p[8]);
        let mut j = DMatrix::zeros(self.points.len(), 9);
        for (i, ((x, w), k)) in self
            .points
            .iter()
            .zip(&self.weights)
            .zip(&self.tangential)
            .enumerate()
        {
            for (c, v) in jacobian_row(&r, &b, x, *w, *k).iter().enumerate() {
                j[(i, c)] = *v;
            }
        }
        j
    }

    /// `JᵀJ` and `Jᵀr` accumulated row by row, never holding `J`; the residual is recomputed in
    /// the same pass (equal to `res` bit for bit).
    fn normal_equations(
        &self,
        p: &DVector<f64>,
        _res: &DVector<f64>,
    ) -> (DMatrix<f64>, DVector<f64>) {
        let (_, jtj, grad) = self.evaluate(p);
        (jtj, grad)
    }

    /// One pass gives the normal equations with the residuals: the Jacobian row shares
    /// `R(x − b)` and its norm with the residual, so this costs about a residual evaluation.
    fn residuals_with_normal_equations(
        &self,
        p: &DVector<f64>,
    ) -> Option<(DVector<f64>, DMatrix<f64>, DVector<f64>)> {
        Some(self.evaluate(p))
    }
}

/// The first pass's solution only sets the second pass's weights and norm corrections, which
/// move by a fraction of the step still left; it stops once the Gauss–Newton step left is under
/// this many standard errors (the second pass converges to full precision).
const WEIGHTING_STEP_SE: f64 = 0.1;

/// The corrected-score iteration stops once a step is under this many standard errors: each
/// step gains a factor of order σ (5·10⁻⁸ on the 10⁶-sample recording of the benches), so what
/// is left after that step is smaller still, and far below the uncertainty the fit states.
const NEGLIGIBLE_SCORE_STEP_SE: f64 = 1e-2;

/// `cost/(N − 9)`: the variance of a weighted residual, which is also the scale of `(JᵀJ)⁻¹`
/// that gives the parameters' variance (a step `δ` is `√(δᵀJᵀJδ/that)` standard errors).
fn standard_error2(cost: f64, n: usize) -> f64 {
    cost / n.saturating_sub(9).max(1) as f64
}

/// The options of the first (weighting) pass: `ftol` raised to `WEIGHTING_STEP_SE²/(N − 9)`,
/// since the Gauss–Newton step's predicted relative reduction `δᵀJᵀJδ/cost` is its squared
/// length in standard errors over `N − 9`.
fn weighting_pass_options(lm: &LmOptions, n: usize) -> LmOptions {
    let ftol = WEIGHTING_STEP_SE.powi(2) / n.saturating_sub(9).max(1) as f64;
    LmOptions {
        cost_tolerance: lm.cost_tolerance.max(ftol),
        ..*lm
    }
}

/// The final pass of a large problem solved as the corrected score straight from the first
/// pass's solution `first` (fitted on `first_count` of the `n` samples), without its
/// least-squares iterations; `None` when that iteration does not settle (the caller then runs
/// them). `noise_var(i)` is sample `i`'s per-axis noise variance (scaled units), `start_cost`
/// the weighted cost of every sample at `first`.
///
/// The chord iteration steers with the first pass's `JᵀJ` scaled from its samples to all
/// of them (within ≈ `√(9/m)` of the full one for `m` samples, plus the change of the weights
/// between the passes), so each step gains about as much as a least-squares step would; the
/// first pass's solution lies about `√(n/m)` standard errors from the final one (≈ 8 for 10⁶
/// samples), three steps from where the iteration stops. The result is then evaluated once
/// over every sample with the full `JᵀJ`.
fn corrected_from_first_pass(
    problem: &mut NormProblem,
    first: &LmSolution,
    first_count: usize,
    n: usize,
    start_cost: f64,
    noise_var: impl Fn(usize) -> f64 + Sync,
) -> Option<LmSolution> {
    if problem.hessian_stride <= 1 || first_count == 0 || first.jtj.shape() != (9, 9) {
        return None;
    }
    let jtj = &first.jtj * (n as f64 / first_count as f64);
    let negligible_step2 = NEGLIGIBLE_SCORE_STEP_SE.powi(2) * standard_error2(start_cost, n);
    let (corrected, steps) = solve_corrected_score(
        problem.samples(),
        &jtj,
        &first.params,
        &noise_var,
        negligible_step2,
    )?;
    problem.hessian_stride = 1;
    let mut sol = re_evaluate(&*problem, first.clone(), corrected);
    sol.iterations = steps;
    Some(sol)
}

/// The weight `1/σ'` of the norm of `x` through `R̃`, `b̃` (scaled units, per-axis noise
/// `axis_sigma`): the radial part `σ̃|R̃ᵀv̂|` of the noise; also `|R̃ᵀv̂|²` and the norm `|R̃(x − b̃)|`.
fn radial_weight(r: &Mat3, b: &Vec3, x: &Vec3, axis_sigma: f64) -> (f64, f64, f64) {
    let v = r * (x - b);
    let vh = v
        .try_normalize(0.0)
        .unwrap_or_else(|| Vec3::repeat(1.0 / 3f64.sqrt()));
    let radial2 = (r.transpose() * vh).norm_squared();
    let weight = 1.0 / (axis_sigma * radial2.sqrt()).max(f64::MIN_POSITIVE);
    (weight, radial2, v.norm())
}

fn check_inputs(obs: &NormObservations<'_>, reference: f64) -> Result<(), FitError> {
    if !(reference.is_finite() && reference > 0.0) {
        return Err(FitError::Underdetermined(format!(
            "the reference magnitude must be a positive number, got {reference}; pass g or the field strength, or 1"
        )));
    }
    if let NormNoise::PerPoint(sigma) = &obs.sigma {
        if obs.points.len() != sigma.len() {
            return Err(FitError::Underdetermined(format!(
                "{} points but {} noise values were given; give one σ per point",
                obs.points.len(),
                sigma.len()
            )));
        }
    }
    if let Some(i) = obs
        .points
        .iter()
        .position(|p| p.iter().any(|v| !v.is_finite()))
    {
        return Err(FitError::NonFinite(format!("reading {i}")));
    }
    if let Some(i) = obs.sigmas().position(|s| !(s.is_finite() && s > 0.0)) {
        return Err(FitError::Underdetermined(format!(
            "the noise of reading {i} is {}, not a positive number; record more than one sample per pose",
            obs.sigma.at(i)
        )));
    }
    if obs.points.len() < 9 {
        return Err(FitError::Underdetermined(format!(
            "only {} readings for 9 unknowns; record at least 9 distinct orientations (12 recommended)",
            obs.points.len()
        )));
    }
    Ok(())
}

/// Refine `start` by Levenberg–Marquardt on the weighted norm residual; see the module comment.
///
/// The covariance is in the order `A11 A12 A13 A22 A23 A33 b1 b2 b3`; the condition number is
/// that of the weighted Jacobian in the centred, scaled parameters (so independent of units).
pub fn refine_lm(
    obs: &NormObservations<'_>,
    start: &Calibration,
    reference: f64,
    opts: &NormLmOptions,
) -> Result<Fit, FitError> {
    refine_lm_detailed(obs, start, reference, opts).map(|o| o.fit)
}

/// As [`refine_lm`], also returning the reduced chi-square.
pub fn refine_lm_detailed(
    obs: &NormObservations<'_>,
    start: &Calibration,
    reference: f64,
    opts: &NormLmOptions,
) -> Result<NormLmOutcome, FitError> {
    check_inputs(obs, reference)?;
    let n = obs.points.len();
    let start_usable = start.a.iter().chain(start.b.iter()).all(|v| v.is_finite())
        && start.a.determinant().abs() > 0.0
        && upper_triangular_gauge(&start.a)
            .iter()
            .all(|v| v.is_finite());
    // An unusable start (singular or non-finite) is replaced by the sphere around the mean.
    let centre = if start_usable {
        start.b
    } else {
        obs.points.iter().sum::<Vec3>() / n as f64
    };
    let s = (obs
        .points
        .iter()
        .map(|p| (p - centre).norm_squared())
        .sum::<f64>()
        / n as f64)
        .sqrt();
    if !(s.is_finite() && s > 0.0) {
        return Err(FitError::Underdetermined(
            "all readings are identical; rotate the sensor between readings".into(),
        ));
    }
    let r0 = if start_usable {
        upper_triangular_gauge(&start.a) * (s / reference)
    } else {
        Mat3::identity()
    };
    let mut scaled: Vec<Vec3> = obs.points.iter().map(|p| (p - centre) / s).collect();
    let mut params = DVector::from_vec(vec![
        r0[(0, 0)],
        r0[(0, 1)],
        r0[(0, 2)],
        r0[(1, 1)],
        r0[(1, 2)],
        r0[(2, 2)],
        0.0,
        0.0,
        0.0,
    ]);

    // Two passes: the noise of each norm (σ propagated through A) is taken from the start, then
    // from the first solution, where also the noise-induced lengthening is corrected. On a
    // large problem the first pass runs on the iteration samples alone (see
    // `NormLmOptions::iteration_samples`).
    let stride = hessian_stride(n, opts.iteration_samples);
    let every = stride * LANES;
    let mut iterations = 0;
    let mut solution: Option<LmSolution> = None;
    // The problem of the last pass (its points move from pass to pass, never copied).
    let mut last_problem: Option<NormProblem> = None;
    // Whether the first pass runs on the iteration samples, and how many it had.
    let subsampled_first = stride > 1;
    let mut first_count = n;
    for pass in 0..2 {
        let subsampled = pass == 0 && stride > 1;
        // Point `i` of this pass is point `i·sigma_step` of the observations.
        let (points, sigma_step): (Vec<Vec3>, usize) = if subsampled {
            (scaled.iter().step_by(every).copied().collect(), every)
        } else {
            let points = match last_problem.take() {
                Some(problem) if problem.points.len() == n => problem.points,
                _ => std::mem::take(&mut scaled),
            };
            (points, 1)
        };
        let sigma = |i: usize| obs.sigma.at(i * sigma_step);
        let r = upper_from_params(&params);
        let b = Vec3::new(params[6], params[7], params[8]);
        // Per-axis noise σ̃ in scaled units; its radial part σ̃|R̃ᵀv̂| sets the weight, the rest
        // (tangential) the norm correction `k`, which needs the noise scale: `radial` holds
        // `|R̃ᵀv̂|²` until then. The residual at this pass's start is summed along.
        // On two threads for large problems, like the passes of the iterations.
        let mut weights = vec![0.0; points.len()];
        let (mut radial, start_cost) = in_two_halves(
            points.len(),
            &mut weights,
            |range, weights| {
                let mut cost = 0.0;
                let radial: Vec<f64> = points[range.clone()]
                    .iter()
                    .zip(range)
                    .zip(weights.iter_mut())
                    .map(|((x, i), w)| {
                        let (weight, radial2, norm) = radial_weight(&r, &b, x, sigma(i) / s);
                        cost += norm_residual(norm, weight, 0.0).powi(2);
                        *w = weight;
                        radial2
                    })
                    .collect();
                (radial, cost)
            },
            |(mut first, first_cost), (second, second_cost)| {
                first.extend(second);
                (first, first_cost + second_cost)
            },
        );
        // With unknown noise `sigma` is relative; its scale comes from the first pass's
        // residual. When that pass ran on the iteration samples, from the residual of every
        // sample at its solution instead, weighted as this pass weights them (from that
        // solution, not from the first pass's start: a difference of the order of the step
        // between the two, far below the scale's own statistical error).
        let noise_scale = match (&solution, opts.noise_known) {
            (Some(prev), false) => {
                let cost = if stride > 1 { start_cost } else { prev.cost };
                reduced_chi_square(cost, n, 9).unwrap_or(0.0).sqrt()
            }
            _ => 1.0,
        };
        let frobenius2 = r.norm_squared();
        let correct = pass == 1 && opts.correct_norm_bias;
        for (i, k) in radial.iter_mut().enumerate() {
            *k = if correct {
                0.5 * (sigma(i) / s * noise_scale).powi(2) * (frobenius2 - *k).max(0.0)
            } else {
                0.0
            };
        }
        let tangential = radial;
        let count = points.len();
        let mut problem = NormProblem {
            points,
            weights,
            tangential,
            hessian_stride: if subsampled { 1 } else { stride },
        };
        let lm = if pass == 0 {
            weighting_pass_options(&opts.lm, count)
        } else {
            opts.lm
        };
        // On a large problem whose final pass solves the corrected score, that pass's
        // least-squares root would only start the corrected score's iteration, which
        // converges from the first pass's solution as well (see `corrected_from_first_pass`):
        // its least-squares iterations, each a pass over every sample, are skipped.
        let direct = match (
            &solution,
            pass == 1 && subsampled_first && opts.correct_norm_bias,
        ) {
            (Some(first), true) => {
                corrected_from_first_pass(&mut problem, first, first_count, n, start_cost, |i| {
                    (obs.sigma.at(i) / s * noise_scale).powi(2)
                })
            }
            _ => None,
        };
        if let Some(sol) = direct {
            iterations += sol.iterations;
            params = sol.params.clone();
            solution = Some(sol);
            last_problem = Some(problem);
            continue;
        }
        let mut sol = levenberg_marquardt(&problem, params.clone(), &lm)
            .map_err(|e| e.into_fit_error(Method::Lm.name()))?;
        iterations += sol.iterations;
        if pass == 0 {
            first_count = count;
        }
        if pass == 1 && opts.correct_norm_bias {
            // Computed where it is used: a vector of it would be one more value per sample.
            let noise_var = |i: usize| (obs.sigma.at(i) / s * noise_scale).powi(2);
            let negligible_step2 = NEGLIGIBLE_SCORE_STEP_SE.powi(2) * standard_error2(sol.cost, n);
            if let Some((corrected, _)) = solve_corrected_score(
                problem.samples(),
                &sol.jtj,
                &sol.params,
                &noise_var,
                negligible_step2,
            ) {
                problem.hessian_stride = 1;
                sol = re_evaluate(&problem, sol, corrected);
            }
        }
        // The covariance, leverages and condition number need the full `JᵀJ` at the solution.
        if pass == 1 && problem.hessian_stride > 1 {
            problem.hessian_stride = 1;
            let at = sol.params.clone();
            sol = re_evaluate(&problem, sol, at);
        }
        params = sol.params.clone();
        solution = Some(sol);
        last_problem = Some(problem);
    }
    let (Some(sol), Some(problem)) = (solution, last_problem) else {
        return Err(FitError::NotConverged {
            method: Method::Lm.name(),
            iterations,
            detail: "no pass ran".into(),
        });
    };

    // Positive diagonal: flipping the sign of a row of R leaves every norm unchanged.
    let mut r = upper_from_params(&params);
    let mut signs = DVector::from_element(9, 1.0);
    for row in 0..3 {
        if r[(row, row)] < 0.0 {
            r.row_mut(row).neg_mut();
            for (k, entry) in UPPER_TRIANGULAR_LAYOUT.iter().enumerate().take(6) {
                if matches!(entry, super::covariance::ParamEntry::A(rr, _) if *rr == row) {
                    signs[k] = -1.0;
                }
            }
        }
    }
    let a = r * (reference / s);
    let b = centre + Vec3::new(params[6], params[7], params[8]) * s;
    if a.iter().chain(b.iter()).any(|v| !v.is_finite()) || r.determinant() == 0.0 {
        return Err(FitError::NotConverged {
            method: Method::Lm.name(),
            iterations,
            detail: "the solution is degenerate (a zero or non-finite scale)".into(),
        });
    }
    let cal = Calibration { a, b };

    let chi2_red = reduced_chi_square(sol.cost, n, 9);
    let to_natural: Vec<f64> = (0..9)
        .map(|k| signs[k] * if k < 6 { reference / s } else { s })
        .collect();
    // One policy for every fit (`uncertainty`): Birge-inflated with known noise, estimated
    // from the residual otherwise.
    let level = if opts.noise_known {
        NoiseLevel::Known
    } else {
        NoiseLevel::Unknown
    };
    let scaled = scaled_covariance(normal_covariance(&sol.jtj), sol.cost, n, 9, level);
    let coverage_factor = scaled.as_ref().map_or(Z_95, |s| s.coverage_factor);
    let covariance = scaled.map(|s| {
        DMatrix::from_fn(9, 9, |i, j| {
            s.covariance[(i, j)] * to_natural[i] * to_natural[j]
        })
    });
    let std = covariance
        .as_ref()
        .map(|c| calibration_std(c, &UPPER_TRIANGULAR_LAYOUT));
    // What still needs the problem's per-sample values is computed first, so that they (and
    // the solver's residuals) are freed before the residuals of the fit are allocated.
    let LmSolution {
        jtj,
        termination,
        residuals: solver_residuals,
        ..
    } = sol;
    drop(solver_residuals);
    let first_order_loo_rms = first_order_loo_rms(
        &upper_from_params(&params),
        &Vec3::new(params[6], params[7], params[8]),
        problem.samples(),
        &jtj,
    );
    // Pose means (a noise per point) always; clouds of samples only when small. The closure
    // takes the problem, so its values are freed here whether it runs or not.
    let poses = matches!(obs.sigma, NormNoise::PerPoint(_));
    let fold_update = (poses || n <= FOLD_UPDATE_MAX_POINTS)
        .then(|| {
            let NormProblem {
                points,
                weights,
                tangential,
                ..
            } = problem;
            FoldUpdate::new(
                &params,
                (points, weights, tangential),
                &jtj,
                centre,
                s,
                reference,
            )
        })
        .flatten();
    // Each residual on its own, on two threads for large problems; the RMS sums them in order.
    let mut residuals = vec![0.0; n];
    in_two_halves(
        n,
        &mut residuals,
        |range, out| {
            for (e, x) in out.iter_mut().zip(&obs.points[range]) {
                *e = (cal.apply(x).norm() - reference) / reference;
            }
        },
        |(), ()| (),
    );
    let rms = (residuals.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
    let fit = Fit {
        method: Method::Lm,
        cal,
        residuals,
        rms,
        loo_rms: None,
        covariance,
        param_names: param_names(&UPPER_TRIANGULAR_LAYOUT),
        std,
        condition_number: equilibrated_condition_from_normal_matrix(&jtj),
        iterations,
        termination: Some(termination),
        coverage_factor,
        reference,
    };
    Ok(NormLmOutcome {
        fit,
        reduced_chi_square: chi2_red,
        first_order_loo_rms,
        fold_update,
    })
}

/// Accelerometer start: six-position (seed 000 eq. 11–15), else Li's ellipsoid (seed 000
/// eq. 17–29) on the pose means, else Chen's coarse model (seed 003), else the sphere.
fn accel_start(poses: &[Pose], reference: f64) -> Calibration {
    if let Ok(f) = fit_six_position(poses, None, reference) {
        return f.cal;
    }
    let means: Vec<Vec3> = poses.iter().map(|p| p.mean).collect();
    if let Some(cal) = fit_li_start(
        &means,
        reference,
        LiOptions {
            subtract_mean: true,
        },
    ) {
        return cal;
    }
    if let Ok(f) = fit_chen(poses, reference) {
        return f.cal;
    }
    sphere_start(&means, reference)
}

/// Per-axis noise of each pose mean, in data units (for the coverage rule).
fn pose_mean_noise(poses: &[Pose]) -> Vec<f64> {
    poses
        .iter()
        .map(|p| (p.var_of_mean().sum() / 3.0).max(0.0).sqrt())
        .collect()
}

/// Apply the coverage rule of [`super::coverage`] to a norm-model outcome (judging a failed fit
/// by its start).
fn guard_outcome(
    outcome: Result<NormLmOutcome, FitError>,
    points: &[Vec3],
    noise: Option<&[f64]>,
    reference: f64,
    hint: CoverageHint,
    start: Option<&Calibration>,
) -> Result<NormLmOutcome, FitError> {
    let (fit, chi2, loo, update) = match outcome {
        Ok(o) => (
            Ok(o.fit),
            o.reduced_chi_square,
            o.first_order_loo_rms,
            o.fold_update,
        ),
        Err(e) => (Err(e), None, None, None),
    };
    guard_fit(
        fit,
        points,
        noise,
        reference,
        EllipsoidModel::General,
        hint,
        || {
            start
                .copied()
                .filter(Calibration::is_finite)
                .or_else(|| li_start(points, reference))
        },
    )
    .map(|fit| NormLmOutcome {
        fit,
        reduced_chi_square: chi2,
        first_order_loo_rms: loo,
        fold_update: update,
    })
}

fn accel_lm_without_loo(poses: &[Pose], reference: f64) -> Result<NormLmOutcome, FitError> {
    check_finite_poses(poses)?;
    refit_accel_lm_from(poses, reference, &accel_start(poses, reference))
}

/// The accelerometer's norm-model LM on `poses` started from `start`, with the coverage guard
/// (a failed fit is judged through `start`). For held-out refits, `start` is the fit on every
/// pose: the refit's solution lies within about a standard error of it, so the algebraic
/// starts are skipped and the iterations begin next to the answer.
pub fn refit_accel_lm_from(
    poses: &[Pose],
    reference: f64,
    start: &Calibration,
) -> Result<NormLmOutcome, FitError> {
    check_finite_poses(poses)?;
    let means: Vec<Vec3> = poses.iter().map(|p| p.mean).collect();
    let noise = pose_mean_noise(poses);
    let outcome = accel_lm_from_start(poses, reference, start);
    guard_outcome(
        outcome,
        &means,
        Some(&noise),
        reference,
        CoverageHint::Poses,
        Some(start),
    )
}

fn accel_lm_from_start(
    poses: &[Pose],
    reference: f64,
    start: &Calibration,
) -> Result<NormLmOutcome, FitError> {
    let obs = NormObservations::from_poses(poses, &start.b);
    // Poses without a usable variance (single samples, or a variance of exactly zero) leave the
    // noise unknown: weight uniformly and take the noise from the residual.
    let noise_known = obs.sigmas().all(|s| s.is_finite() && s > 0.0);
    let obs = if noise_known {
        obs
    } else {
        NormObservations::uniform(obs.points, 1.0)
    };
    refine_lm_detailed(
        &obs,
        start,
        reference,
        &NormLmOptions {
            noise_known,
            ..NormLmOptions::default()
        },
    )
}

/// The default accelerometer fit: LM on the norm model over static poses, weighted by each
/// pose's noise, with the leave-one-pose-out RMS.
pub fn fit_accel_lm(poses: &[Pose], reference: f64) -> Result<Fit, FitError> {
    let outcome = accel_lm_without_loo(poses, reference)?;
    let mut fit = outcome.fit;
    let all = fit.cal;
    fit.loo_rms = match outcome
        .fold_update
        .filter(|_| poses.len() >= UPDATED_FOLDS_MIN_POSES)
    {
        Some(update) => held_out_rms(poses, reference, |i| update.calibration_without(i)),
        None => leave_one_out_rms(poses, reference, |rest| {
            refit_accel_lm_from(rest, reference, &all).map(|o| o.fit.cal)
        }),
    };
    Ok(fit)
}

/// As [`fit_accel_lm`] (without the leave-one-out RMS), also returning the reduced chi-square.
pub fn fit_accel_lm_detailed(poses: &[Pose], reference: f64) -> Result<NormLmOutcome, FitError> {
    accel_lm_without_loo(poses, reference)
}

/// The default magnetometer fit: LM on the norm model over samples, started from Li's ellipsoid
/// with mean subtraction (seed 000 Table 2); the noise is estimated from the residual. The
/// leave-one-sample-out RMS is the first-order one of [`super::norm_loo`] (one pass, no refits).
pub fn fit_mag_lm(points: &[Vec3], reference: f64) -> Result<Fit, FitError> {
    fit_mag_lm_detailed(points, reference).map(|o| o.fit)
}

/// As [`fit_mag_lm`], also returning the reduced chi-square (relative to unit noise, so it is
/// the estimated noise variance in data units).
pub fn fit_mag_lm_detailed(points: &[Vec3], reference: f64) -> Result<NormLmOutcome, FitError> {
    check_finite_points(points)?;
    let start = fit_li_start(
        points,
        reference,
        LiOptions {
            subtract_mean: true,
        },
    );
    // Without an algebraic start a failed fit is judged through the algebraic fit itself, not
    // through the sphere it was started from.
    let judge_by = start;
    let start = start.unwrap_or_else(|| sphere_start(points, reference));
    let obs = NormObservations::uniform(points, 1.0);
    let outcome = refine_lm_detailed(
        &obs,
        &start,
        reference,
        &NormLmOptions {
            noise_known: false,
            ..NormLmOptions::default()
        },
    );
    guard_outcome(
        outcome,
        points,
        None,
        reference,
        CoverageHint::Samples,
        judge_by.as_ref(),
    )
    .map(|mut outcome| {
        outcome.fit.loo_rms = outcome.first_order_loo_rms;
        outcome
    })
}

/// Cramér–Rao bound of the upper-triangular norm-model parameters (`A11 A12 A13 A22 A23 A33
/// b1 b2 b3`) for noise-free readings `clean` of a sensor with calibration `truth` (in the
/// upper-triangular gauge) and white noise of standard deviation `axis_sigma[i]` per axis on
/// reading `i`. Errors-in-variables form: each reading contributes `∇θfᵀ∇θf / (∇ₓfᵀΣ∇ₓf)` with
/// `f = |A(x − b)|`. `None` when the readings do not determine the parameters.
pub fn cramer_rao_bound(
    clean: &[Vec3],
    axis_sigma: &[f64],
    truth: &Calibration,
) -> Option<DMatrix<f64>> {
    let mut info = DMatrix::zeros(9, 9);
    for (x, sigma) in clean.iter().zip(axis_sigma) {
        let u = x - truth.b;
        let v = truth.a * u;
        let vh = v.try_normalize(0.0)?;
        let grad_x = truth.a.transpose() * vh;
        let var = sigma * sigma * grad_x.norm_squared();
        let g = DVector::from_vec(vec![
            vh[0] * u[0],
            vh[0] * u[1],
            vh[0] * u[2],
            vh[1] * u[1],
            vh[1] * u[2],
            vh[2] * u[2],
            -grad_x[0],
            -grad_x[1],
            -grad_x[2],
        ]);
        info += &g * g.transpose() / var;
    }
    normal_covariance(&info)
}
