//! A small Levenberg–Marquardt solver for nonlinear least squares `min Σ rᵢ(p)²`.
//!
//! Marquardt's variant (K. Levenberg 1944, D. W. Marquardt 1963): the damped normal equations
//! `(JᵀJ + λ·D) δ = −Jᵀr` with `D = diag(JᵀJ)` (scale invariance), and the λ update of
//! H. B. Nielsen (1999), a trust-region rule driven by the gain ratio ρ = actual / predicted
//! reduction. No geodesic acceleration. Used by every iterative fit in this module
//! (norm model, frame alignment, gyroscope scale).

use nalgebra::{DMatrix, DVector};

/// A least-squares problem: residuals and their Jacobian at a parameter vector.
pub trait LeastSquaresProblem {
    /// Residual vector at `p`. Non-finite entries make the solver reject the point.
    fn residuals(&self, p: &DVector<f64>) -> DVector<f64>;
    /// Jacobian `∂r/∂p` at `p` (rows = residuals, columns = parameters).
    fn jacobian(&self, p: &DVector<f64>) -> DMatrix<f64>;
    /// The Gauss–Newton normal matrix `JᵀJ` and gradient half `Jᵀr` at `p`, where `r` is the
    /// residual at `p`. The default forms `J`; problems with many residuals accumulate both
    /// residual by residual instead, so memory does not grow with the number of residuals.
    fn normal_equations(&self, p: &DVector<f64>, r: &DVector<f64>) -> (DMatrix<f64>, DVector<f64>) {
        let j = self.jacobian(p);
        (j.transpose() * &j, j.transpose() * r)
    }
}

/// Stopping rules and the starting damping.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LmOptions {
    /// Maximum number of trial steps (accepted or rejected).
    pub max_iterations: usize,
    /// Stop when an accepted step satisfies `|δ| ≤ step_tolerance·(|p| + step_tolerance)`.
    pub step_tolerance: f64,
    /// Stop when an accepted step reduces the cost by less than `cost_tolerance·cost`.
    pub cost_tolerance: f64,
    /// Initial λ relative to the diagonal of `JᵀJ`; 0 gives a pure Gauss–Newton first step.
    pub initial_lambda: f64,
}

impl Default for LmOptions {
    fn default() -> Self {
        Self {
            max_iterations: 200,
            step_tolerance: 1e-10,
            cost_tolerance: 1e-14,
            initial_lambda: 1e-3,
        }
    }
}

/// A converged solution.
#[derive(Debug, Clone)]
pub struct LmSolution {
    /// Parameters at the minimum.
    pub params: DVector<f64>,
    /// Residuals at the minimum.
    pub residuals: DVector<f64>,
    /// `JᵀJ` at the minimum (the Gauss–Newton normal matrix).
    pub jtj: DMatrix<f64>,
    /// Cost `Σ rᵢ²` at the minimum.
    pub cost: f64,
    /// Trial steps used.
    pub iterations: usize,
}

/// Why the solver stopped without a solution.
#[derive(Debug, Clone, PartialEq)]
pub struct LmFailure {
    /// Trial steps used.
    pub iterations: usize,
    /// What went wrong, as a phrase.
    pub detail: String,
}

impl LmFailure {
    /// The failure as a [`FitError::NotConverged`](super::FitError::NotConverged) of `method`.
    pub fn into_fit_error(self, method: &'static str) -> super::FitError {
        super::FitError::NotConverged {
            method,
            iterations: self.iterations,
            detail: self.detail,
        }
    }
}

fn sum_of_squares(r: &DVector<f64>) -> f64 {
    r.iter().map(|v| v * v).sum()
}

/// Minimise `Σ rᵢ(p)²` from `start`.
///
/// Returns [`LmFailure`] when the start is not finite, when the iteration budget runs out, or
/// when the damped system cannot be solved for any λ.
pub fn levenberg_marquardt<P: LeastSquaresProblem + ?Sized>(
    problem: &P,
    start: DVector<f64>,
    opts: &LmOptions,
) -> Result<LmSolution, LmFailure> {
    let mut p = start;
    let mut r = problem.residuals(&p);
    let mut cost = sum_of_squares(&r);
    if !cost.is_finite() || p.iter().any(|v| !v.is_finite()) {
        return Err(LmFailure {
            iterations: 0,
            detail: "the residual at the starting point is not finite".into(),
        });
    }
    let n = p.len();
    let (mut jtj, mut grad) = problem.normal_equations(&p, &r);
    let mut lambda = opts.initial_lambda;
    let mut nu = 2.0;
    let mut iterations = 0;
    let mut need_jacobian = false;
    while iterations < opts.max_iterations {
        if need_jacobian {
            (jtj, grad) = problem.normal_equations(&p, &r);
            need_jacobian = false;
        }
        if !jtj.iter().all(|v| v.is_finite()) || !grad.iter().all(|v| v.is_finite()) {
            return Err(LmFailure {
                iterations,
                detail: "the Jacobian became non-finite".into(),
            });
        }
        // A zero gradient is an exact stationary point; nothing further to do.
        let scale = jtj.diagonal().max().max(f64::MIN_POSITIVE);
        if grad.amax() <= 1e-15 * scale.sqrt() * cost.sqrt().max(f64::MIN_POSITIVE) || cost == 0.0 {
            return Ok(finish(problem, p, r, cost, iterations));
        }
        iterations += 1;
        let mut damped = jtj.clone();
        for i in 0..n {
            // Marquardt scaling, floored so that parameters with no sensitivity stay bounded.
            let d = jtj[(i, i)].max(1e-12 * scale);
            damped[(i, i)] += lambda * d;
        }
        let step = match damped.cholesky() {
            Some(ch) => ch.solve(&(-&grad)),
            None => {
                lambda = if lambda == 0.0 { 1e-3 } else { lambda * nu };
                nu *= 2.0;
                if lambda > 1e20 {
                    return Err(LmFailure {
                        iterations,
                        detail: "the normal matrix is singular for every damping".into(),
                    });
                }
                continue;
            }
        };
        if step.norm() <= opts.step_tolerance * (p.norm() + opts.step_tolerance) {
            // The model step is below the resolution asked for: converged.
            return Ok(finish(problem, p, r, cost, iterations));
        }
        let p_new = &p + &step;
        let r_new = problem.residuals(&p_new);
        let cost_new = sum_of_squares(&r_new);
        let predicted = -(2.0 * step.dot(&grad) + step.dot(&(&jtj * &step)));
        let rho = (cost - cost_new) / predicted;
        if cost_new.is_finite()
            && cost_new <= cost
            && predicted > 0.0
            && rho.is_finite()
            && rho > 0.0
        {
            let reduction = cost - cost_new;
            let small_step = step.norm() <= opts.step_tolerance * (p.norm() + opts.step_tolerance);
            p = p_new;
            r = r_new;
            cost = cost_new;
            need_jacobian = true;
            lambda *= (1.0 - (2.0 * rho - 1.0).powi(3)).max(1.0 / 3.0);
            nu = 2.0;
            if small_step || reduction <= opts.cost_tolerance * cost {
                return Ok(finish(problem, p, r, cost, iterations));
            }
        } else {
            // Rejected: increase damping (shorter, more gradient-like step).
            lambda = if lambda == 0.0 { 1e-3 } else { lambda * nu };
            nu *= 2.0;
            if lambda > 1e16 {
                // No step of any length lowers the cost: a minimum to round-off precision.
                return Ok(finish(problem, p, r, cost, iterations));
            }
        }
    }
    Err(LmFailure {
        iterations,
        detail: format!(
            "the cost was still falling after {} steps (cost {cost:.3e})",
            opts.max_iterations
        ),
    })
}

fn finish<P: LeastSquaresProblem + ?Sized>(
    problem: &P,
    params: DVector<f64>,
    residuals: DVector<f64>,
    cost: f64,
    iterations: usize,
) -> LmSolution {
    let (jtj, _) = problem.normal_equations(&params, &residuals);
    LmSolution {
        params,
        residuals,
        jtj,
        cost,
        iterations,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rosenbrock's valley as residuals: r = (10(y − x²), 1 − x); minimum at (1, 1).
    struct Rosenbrock;
    impl LeastSquaresProblem for Rosenbrock {
        fn residuals(&self, p: &DVector<f64>) -> DVector<f64> {
            DVector::from_vec(vec![10.0 * (p[1] - p[0] * p[0]), 1.0 - p[0]])
        }
        fn jacobian(&self, p: &DVector<f64>) -> DMatrix<f64> {
            DMatrix::from_row_slice(2, 2, &[-20.0 * p[0], 10.0, -1.0, 0.0])
        }
    }

    #[test]
    fn rosenbrock_reaches_the_valley_floor_from_the_classic_start() {
        let sol = levenberg_marquardt(
            &Rosenbrock,
            DVector::from_vec(vec![-1.2, 1.0]),
            &LmOptions::default(),
        )
        .expect("Rosenbrock converges");
        // Zero-residual problem: the minimum is exact up to the step tolerance.
        assert!((sol.params[0] - 1.0).abs() < 1e-8, "x = {}", sol.params[0]);
        assert!((sol.params[1] - 1.0).abs() < 1e-8, "y = {}", sol.params[1]);
        assert!(sol.cost < 1e-20);
    }

    /// Straight-line fit r_i = a + b·t_i − y_i: linear, so Gauss–Newton is exact in one step.
    struct Line {
        t: Vec<f64>,
        y: Vec<f64>,
    }
    impl LeastSquaresProblem for Line {
        fn residuals(&self, p: &DVector<f64>) -> DVector<f64> {
            DVector::from_iterator(
                self.t.len(),
                self.t.iter().zip(&self.y).map(|(t, y)| p[0] + p[1] * t - y),
            )
        }
        fn jacobian(&self, _p: &DVector<f64>) -> DMatrix<f64> {
            DMatrix::from_fn(self.t.len(), 2, |i, j| if j == 0 { 1.0 } else { self.t[i] })
        }
    }

    #[test]
    fn linear_problem_is_solved_by_the_first_undamped_step() {
        let t: Vec<f64> = (0..5).map(f64::from).collect();
        // y = 2 + 3t with residual pattern (+1, −1, 0, −1, +1) orthogonal to [1, t]: LS answer is (2, 3).
        let bumps = [1.0, -1.0, 0.0, -1.0, 1.0];
        let y = t
            .iter()
            .zip(bumps)
            .map(|(t, e)| 2.0 + 3.0 * t + e)
            .collect();
        let opts = LmOptions {
            initial_lambda: 0.0,
            ..LmOptions::default()
        };
        let sol = levenberg_marquardt(&Line { t, y }, DVector::from_vec(vec![-50.0, 40.0]), &opts)
            .unwrap();
        // The first step lands on the minimum (to round-off); the second only confirms it.
        assert!(sol.iterations <= 2, "iterations = {}", sol.iterations);
        assert!((sol.params[0] - 2.0).abs() < 1e-10 && (sol.params[1] - 3.0).abs() < 1e-10);
        assert!((sol.cost - 4.0).abs() < 1e-10, "cost = {}", sol.cost);
    }

    /// y = a·exp(−k·t) + c sampled without noise.
    struct Decay {
        t: Vec<f64>,
        y: Vec<f64>,
    }
    impl LeastSquaresProblem for Decay {
        fn residuals(&self, p: &DVector<f64>) -> DVector<f64> {
            DVector::from_iterator(
                self.t.len(),
                self.t
                    .iter()
                    .zip(&self.y)
                    .map(|(t, y)| p[0] * (-p[1] * t).exp() + p[2] - y),
            )
        }
        fn jacobian(&self, p: &DVector<f64>) -> DMatrix<f64> {
            DMatrix::from_fn(self.t.len(), 3, |i, j| {
                let e = (-p[1] * self.t[i]).exp();
                match j {
                    0 => e,
                    1 => -p[0] * self.t[i] * e,
                    _ => 1.0,
                }
            })
        }
    }

    #[test]
    fn exponential_decay_parameters_are_recovered_exactly_from_clean_data() {
        let t: Vec<f64> = (0..40).map(|i| f64::from(i) * 0.1).collect();
        let y = t.iter().map(|t| 5.0 * (-1.3 * t).exp() + 0.7).collect();
        let sol = levenberg_marquardt(
            &Decay { t, y },
            DVector::from_vec(vec![1.0, 0.1, 0.0]),
            &LmOptions::default(),
        )
        .unwrap();
        // Noise-free data: only round-off and the step tolerance limit the answer.
        assert!((sol.params[0] - 5.0).abs() < 1e-7, "a = {}", sol.params[0]);
        assert!((sol.params[1] - 1.3).abs() < 1e-7, "k = {}", sol.params[1]);
        assert!((sol.params[2] - 0.7).abs() < 1e-7, "c = {}", sol.params[2]);
    }

    #[test]
    fn a_non_finite_start_is_refused_not_iterated() {
        let err = levenberg_marquardt(
            &Rosenbrock,
            DVector::from_vec(vec![f64::NAN, 1.0]),
            &LmOptions::default(),
        )
        .unwrap_err();
        assert_eq!(err.iterations, 0);
    }

    #[test]
    fn an_exhausted_budget_is_reported_as_not_converged() {
        let opts = LmOptions {
            max_iterations: 2,
            ..LmOptions::default()
        };
        let err = levenberg_marquardt(&Rosenbrock, DVector::from_vec(vec![-1.2, 1.0]), &opts)
            .unwrap_err();
        assert_eq!(err.iterations, 2);
    }
}
