//! A Levenberg–Marquardt solver for nonlinear least squares `min Σ rᵢ(p)²`, with MINPACK's
//! stopping rules and a typed reason for stopping.
//!
//! Marquardt's variant (K. Levenberg 1944, D. W. Marquardt 1963): the damped normal equations
//! `(JᵀJ + λ·D) δ = −Jᵀr` with `D = diag(JᵀJ)` (scale invariance), and the λ update of
//! H. B. Nielsen (1999), a trust-region rule driven by the gain ratio ρ = actual / predicted
//! reduction. Termination follows MINPACK's `lmder` (Moré, Garbow & Hillstrom, "User guide for
//! MINPACK-1", 1980, §2.3): `ftol` on both the actual and the predicted relative reduction of the
//! cost, `xtol` on the step relative to the parameters, `gtol` on the cosine of the angle between
//! the residual and each Jacobian column, and a budget of residual evaluations. Two deviations,
//! both stricter: the `xtol` and the predicted-reduction tests are made on the Gauss–Newton step
//! (λ = 0), so a step made tiny by heavy damping is not mistaken for convergence; and λ growing past 10¹⁶ without any test
//! being met (MINPACK's info 6–8 territory when the tolerances are sane) is a failure.
//! Used by every iterative fit (norm model, frame alignment, gyroscope scale, effect analysis).

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
    /// The residual with `JᵀJ` and `Jᵀr` at `p`, for problems where the normal equations come
    /// at little more than the cost of the residual (they share the per-residual work). The
    /// solver then evaluates every trial point this way and needs no second pass after
    /// accepting it. `None` (the default): the solver asks for [`Self::residuals`] at trial
    /// points and for [`Self::normal_equations`] only at accepted ones.
    fn residuals_with_normal_equations(
        &self,
        _p: &DVector<f64>,
    ) -> Option<(DVector<f64>, DMatrix<f64>, DVector<f64>)> {
        None
    }
}

/// Stopping rules and the starting damping (MINPACK's `ftol`, `xtol`, `gtol`, `maxfev`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LmOptions {
    /// Maximum number of residual evaluations (trial steps, accepted or rejected).
    pub max_iterations: usize,
    /// `xtol`: converged when the Gauss–Newton step satisfies `|δ| ≤ xtol·(|p| + xtol)`.
    pub step_tolerance: f64,
    /// `ftol`: converged when both the actual reduction of the cost and the reduction the
    /// Gauss–Newton step predicts are at most `ftol·cost`.
    pub cost_tolerance: f64,
    /// `gtol`: converged when `|Jⱼᵀr| ≤ gtol·|Jⱼ|·|r|` for every column `j` (the residual is
    /// orthogonal to the Jacobian's columns to this cosine).
    pub gradient_tolerance: f64,
    /// Initial λ relative to the diagonal of `JᵀJ`; 0 gives a pure Gauss–Newton first step.
    pub initial_lambda: f64,
}

/// A Gauss–Newton step under this fraction of a standard error is negligible
/// ([`Termination::StepNegligible`]).
pub const NEGLIGIBLE_STEP_SE: f64 = 1e-3;

impl Default for LmOptions {
    fn default() -> Self {
        Self {
            max_iterations: 200,
            step_tolerance: 1e-10,
            cost_tolerance: 1e-12,
            gradient_tolerance: 1e-10,
            initial_lambda: 1e-3,
        }
    }
}

/// Why the solver stopped (MINPACK's `info`, with the failures split by cause).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Termination {
    /// The residual is zero to working precision: its norm fell below `ε_mach` times its norm
    /// at the start (zero-residual problems with a singular Jacobian converge only linearly,
    /// and no relative test would ever hold).
    ExactFit,
    /// Actual and predicted relative cost reductions both at most `ftol` (MINPACK info 1).
    CostConverged,
    /// The Gauss–Newton step is at most `xtol` relative to the parameters (info 2).
    StepConverged,
    /// Both of the above (info 3).
    CostAndStepConverged,
    /// The residual is orthogonal to every Jacobian column to within `gtol` (info 4).
    GradientConverged,
    /// No step lowered the cost, and the Gauss–Newton step left is under
    /// [`NEGLIGIBLE_STEP_SE`] of a standard error (`δᵀJᵀJδ` against the residual variance
    /// `cost/(m − n)`): a minimum to within the round-off of the residuals. On a small,
    /// well-fitted problem the cost's round-off can exceed `ftol` relative to it (a cost of
    /// order 1 from weights of thousands), so no step lowers it measurably although the point is
    /// a minimum for every statistical purpose.
    StepNegligible,
    /// The evaluation budget ran out while the cost was still falling (info 5). A failure.
    EvaluationBudget,
    /// No step lowered the cost although no convergence test held, until λ passed 10¹⁶: the
    /// Jacobian does not describe the residual (a kink, or round-off far above the tolerances).
    /// A failure.
    DampingOverflow,
    /// The damped normal matrix could not be factorised for any λ. A failure.
    SingularSystem,
    /// A residual or Jacobian entry became NaN or infinite. A failure.
    NonFinite,
}

impl Termination {
    /// `true` for the reasons that mean a minimum was reached.
    pub fn is_converged(self) -> bool {
        matches!(
            self,
            Termination::ExactFit
                | Termination::CostConverged
                | Termination::StepConverged
                | Termination::CostAndStepConverged
                | Termination::GradientConverged
                | Termination::StepNegligible
        )
    }

    /// Stable snake-case name used in JSON.
    pub fn name(self) -> &'static str {
        match self {
            Termination::ExactFit => "exact_fit",
            Termination::CostConverged => "cost_converged",
            Termination::StepConverged => "step_converged",
            Termination::CostAndStepConverged => "cost_and_step_converged",
            Termination::GradientConverged => "gradient_converged",
            Termination::StepNegligible => "step_negligible",
            Termination::EvaluationBudget => "evaluation_budget",
            Termination::DampingOverflow => "damping_overflow",
            Termination::SingularSystem => "singular_system",
            Termination::NonFinite => "non_finite",
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
    /// Residual evaluations used.
    pub iterations: usize,
    /// Which convergence test was met (always one with [`Termination::is_converged`]).
    pub termination: Termination,
}

/// Why the solver stopped without a solution.
#[derive(Debug, Clone, PartialEq)]
pub struct LmFailure {
    /// Residual evaluations used.
    pub iterations: usize,
    /// The reason (never one with [`Termination::is_converged`]).
    pub termination: Termination,
    /// What went wrong, as a phrase.
    pub detail: String,
}

impl LmFailure {
    fn new(iterations: usize, termination: Termination, detail: impl Into<String>) -> Self {
        Self {
            iterations,
            termination,
            detail: detail.into(),
        }
    }

    /// The failure as a [`FitError::NotConverged`](super::FitError::NotConverged) of `method`.
    pub fn into_fit_error(self, method: &'static str) -> super::FitError {
        super::FitError::NotConverged {
            method,
            iterations: self.iterations,
            detail: format!("{}: {}", self.termination.name(), self.detail),
        }
    }
}

fn sum_of_squares(r: &DVector<f64>) -> f64 {
    r.iter().map(|v| v * v).sum()
}

/// Largest cosine between the residual and a Jacobian column (MINPACK's `gnorm`); columns
/// without sensitivity are skipped, as in MINPACK.
fn gradient_cosine(jtj: &DMatrix<f64>, grad: &DVector<f64>, cost: f64) -> f64 {
    let rnorm = cost.sqrt();
    // |Jⱼ|² is the diagonal of JᵀJ, so the test needs no Jacobian.
    (0..jtj.ncols())
        .filter_map(|j| {
            let cn = jtj[(j, j)].max(0.0).sqrt();
            (cn > 0.0).then(|| grad[j].abs() / (cn * rnorm))
        })
        .fold(0.0, f64::max)
}

/// Solve `(JᵀJ + λ·D) δ = −g` with Marquardt's scaling floored so that parameters without
/// sensitivity stay bounded; `None` when the damped matrix is not positive definite.
fn damped_step(jtj: &DMatrix<f64>, grad: &DVector<f64>, lambda: f64) -> Option<DVector<f64>> {
    let scale = jtj.diagonal().max().max(f64::MIN_POSITIVE);
    let mut damped = jtj.clone();
    for i in 0..jtj.nrows() {
        damped[(i, i)] += lambda * jtj[(i, i)].max(1e-12 * scale);
    }
    let step = damped.cholesky()?.solve(&(-grad));
    step.iter().all(|v| v.is_finite()).then_some(step)
}

/// Minimise `Σ rᵢ(p)²` from `start`.
///
/// Returns a solution only when a convergence test held ([`Termination::is_converged`]);
/// otherwise an [`LmFailure`] naming the reason (non-finite start, evaluation budget, damping
/// overflow, singular system).
pub fn levenberg_marquardt<P: LeastSquaresProblem + ?Sized>(
    problem: &P,
    start: DVector<f64>,
    opts: &LmOptions,
) -> Result<LmSolution, LmFailure> {
    let mut p = start;
    let (mut r, start_normal) = match problem.residuals_with_normal_equations(&p) {
        Some((r, jtj, grad)) => (r, Some((jtj, grad))),
        None => (problem.residuals(&p), None),
    };
    let mut cost = sum_of_squares(&r);
    if !cost.is_finite() || p.iter().any(|v| !v.is_finite()) {
        return Err(LmFailure::new(
            0,
            Termination::NonFinite,
            "the residual at the starting point is not finite",
        ));
    }
    let zero_cost = f64::EPSILON * f64::EPSILON * cost;
    let (mut jtj, mut grad) = start_normal.unwrap_or_else(|| problem.normal_equations(&p, &r));
    let mut lambda = opts.initial_lambda;
    let mut nu = 2.0;
    let mut evaluations = 0;
    let mut need_jacobian = false;
    loop {
        if need_jacobian {
            (jtj, grad) = problem.normal_equations(&p, &r);
            need_jacobian = false;
        }
        if !jtj.iter().all(|v| v.is_finite()) || !grad.iter().all(|v| v.is_finite()) {
            return Err(LmFailure::new(
                evaluations,
                Termination::NonFinite,
                "the Jacobian became non-finite",
            ));
        }
        if cost <= zero_cost {
            return Ok(finish(
                problem,
                p,
                r,
                cost,
                evaluations,
                Termination::ExactFit,
                Some(jtj),
            ));
        }
        if gradient_cosine(&jtj, &grad, cost) <= opts.gradient_tolerance {
            return Ok(finish(
                problem,
                p,
                r,
                cost,
                evaluations,
                Termination::GradientConverged,
                Some(jtj),
            ));
        }
        if evaluations >= opts.max_iterations {
            return Err(LmFailure::new(
                evaluations,
                Termination::EvaluationBudget,
                format!(
                    "the cost was still falling after {} evaluations (cost {cost:.3e})",
                    opts.max_iterations
                ),
            ));
        }
        let Some(step) = damped_step(&jtj, &grad, lambda) else {
            lambda = if lambda == 0.0 { 1e-3 } else { lambda * nu };
            nu *= 2.0;
            if lambda > 1e20 {
                return Err(LmFailure::new(
                    evaluations,
                    Termination::SingularSystem,
                    "the normal matrix is singular for every damping",
                ));
            }
            continue;
        };
        // Both tests are made on the Gauss–Newton step (λ = 0), the best the linear model can
        // do: a step that is short only because λ is large is not convergence. Without a
        // Gauss–Newton step (singular JᵀJ) the damped step stands in when λ ≤ 1.
        let gauss_newton =
            damped_step(&jtj, &grad, 0.0).or_else(|| (lambda <= 1.0).then(|| step.clone()));
        let xtol_bound = opts.step_tolerance * (p.norm() + opts.step_tolerance);
        let step_converged = gauss_newton
            .as_ref()
            .is_some_and(|gn| gn.norm() <= xtol_bound);
        let best_predicted_rel = gauss_newton
            .as_ref()
            .map_or(f64::INFINITY, |gn| -gn.dot(&grad) / cost);

        let p_new = &p + &step;
        let (r_new, normal_new) = match problem.residuals_with_normal_equations(&p_new) {
            Some((r, jtj, grad)) => (r, Some((jtj, grad))),
            None => (problem.residuals(&p_new), None),
        };
        evaluations += 1;
        let cost_new = sum_of_squares(&r_new);
        let predicted = -(2.0 * step.dot(&grad) + step.dot(&(&jtj * &step)));
        let actual_rel = if cost_new.is_finite() {
            (cost - cost_new) / cost
        } else {
            -1.0
        };
        // ftol: neither this step nor any step of the linear model lowers the cost by more
        // than ftol relative (−gᵀδ_GN is the Gauss–Newton predicted reduction).
        let cost_converged =
            actual_rel.abs() <= opts.cost_tolerance && best_predicted_rel <= opts.cost_tolerance;
        let rho = (cost - cost_new) / predicted;
        let accepted = cost_new.is_finite()
            && r_new.iter().all(|v| v.is_finite())
            && cost_new <= cost
            && predicted > 0.0
            && rho.is_finite()
            && rho > 0.0;
        if accepted {
            p = p_new;
            r = r_new;
            cost = cost_new;
            match normal_new {
                Some(normal) => (jtj, grad) = normal,
                None => need_jacobian = true,
            }
            lambda *= (1.0 - (2.0 * rho - 1.0).powi(3)).max(1.0 / 3.0);
            nu = 2.0;
        } else {
            // Rejected: increase damping (shorter, more gradient-like step).
            lambda = if lambda == 0.0 { 1e-3 } else { lambda * nu };
            nu *= 2.0;
        }
        let termination = match (cost_converged, step_converged) {
            (true, true) => Some(Termination::CostAndStepConverged),
            (true, false) => Some(Termination::CostConverged),
            (false, true) => Some(Termination::StepConverged),
            (false, false) => None,
        };
        if let Some(t) = termination {
            let current = (!need_jacobian).then_some(jtj);
            return Ok(finish(problem, p, r, cost, evaluations, t, current));
        }
        if lambda > 1e16 {
            // Rejected steps leave `p` where the Gauss–Newton step was taken, so the test is on
            // the current point.
            let dof = r.len().saturating_sub(p.len());
            if !accepted && dof > 0 && best_predicted_rel * dof as f64 <= NEGLIGIBLE_STEP_SE.powi(2)
            {
                let current = (!need_jacobian).then_some(jtj);
                return Ok(finish(
                    problem,
                    p,
                    r,
                    cost,
                    evaluations,
                    Termination::StepNegligible,
                    current,
                ));
            }
            return Err(LmFailure::new(
                evaluations,
                Termination::DampingOverflow,
                format!(
                    "no step lowered the cost (cost {cost:.3e}) although the gradient is not \
                     small; the residual is not smooth there"
                ),
            ));
        }
    }
}

/// The solution at `params`; `jtj` is the normal matrix there when already known.
fn finish<P: LeastSquaresProblem + ?Sized>(
    problem: &P,
    params: DVector<f64>,
    residuals: DVector<f64>,
    cost: f64,
    iterations: usize,
    termination: Termination,
    jtj: Option<DMatrix<f64>>,
) -> LmSolution {
    let jtj = jtj.unwrap_or_else(|| problem.normal_equations(&params, &residuals).0);
    LmSolution {
        params,
        residuals,
        jtj,
        cost,
        iterations,
        termination,
    }
}

#[cfg(test)]
#[path = "lm_tests.rs"]
mod tests;
