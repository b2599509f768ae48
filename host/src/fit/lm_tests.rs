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
    let sol =
        levenberg_marquardt(&Line { t, y }, DVector::from_vec(vec![-50.0, 40.0]), &opts).unwrap();
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
    let err =
        levenberg_marquardt(&Rosenbrock, DVector::from_vec(vec![-1.2, 1.0]), &opts).unwrap_err();
    assert_eq!(err.iterations, 2);
}

// Standard problems of Moré, Garbow & Hillstrom, "Testing unconstrained optimization software",
// ACM TOMS 7 (1981), with their standard starting points and known minima.

/// MGH problem 13, Powell singular: the Jacobian is singular at the minimum x* = 0 (F = 0), so
/// convergence is only linear there.
struct PowellSingular;
impl LeastSquaresProblem for PowellSingular {
    fn residuals(&self, x: &DVector<f64>) -> DVector<f64> {
        let s5 = 5f64.sqrt();
        let s10 = 10f64.sqrt();
        DVector::from_vec(vec![
            x[0] + 10.0 * x[1],
            s5 * (x[2] - x[3]),
            (x[1] - 2.0 * x[2]).powi(2),
            s10 * (x[0] - x[3]).powi(2),
        ])
    }
    fn jacobian(&self, x: &DVector<f64>) -> DMatrix<f64> {
        let s5 = 5f64.sqrt();
        let s10 = 10f64.sqrt();
        let d3 = 2.0 * (x[1] - 2.0 * x[2]);
        let d4 = 2.0 * s10 * (x[0] - x[3]);
        DMatrix::from_row_slice(
            4,
            4,
            &[
                1.0,
                10.0,
                0.0,
                0.0, //
                0.0,
                0.0,
                s5,
                -s5, //
                0.0,
                d3,
                -2.0 * d3,
                0.0, //
                d4,
                0.0,
                0.0,
                -d4,
            ],
        )
    }
}

/// MGH problem 4, Brown badly scaled: minimum F = 0 at (10⁶, 2·10⁻⁶).
struct BrownBadlyScaled;
impl LeastSquaresProblem for BrownBadlyScaled {
    fn residuals(&self, x: &DVector<f64>) -> DVector<f64> {
        DVector::from_vec(vec![x[0] - 1e6, x[1] - 2e-6, x[0] * x[1] - 2.0])
    }
    fn jacobian(&self, x: &DVector<f64>) -> DMatrix<f64> {
        DMatrix::from_row_slice(3, 2, &[1.0, 0.0, 0.0, 1.0, x[1], x[0]])
    }
}

/// MGH problem 2, Freudenstein and Roth: from the standard start the iteration ends in the
/// local minimum F = 48.9842… at (11.41…, −0.8968…), a non-zero residual.
struct FreudensteinRoth;
impl LeastSquaresProblem for FreudensteinRoth {
    fn residuals(&self, x: &DVector<f64>) -> DVector<f64> {
        DVector::from_vec(vec![
            -13.0 + x[0] + ((5.0 - x[1]) * x[1] - 2.0) * x[1],
            -29.0 + x[0] + ((x[1] + 1.0) * x[1] - 14.0) * x[1],
        ])
    }
    fn jacobian(&self, x: &DVector<f64>) -> DMatrix<f64> {
        let y = x[1];
        DMatrix::from_row_slice(
            2,
            2,
            &[
                1.0,
                10.0 * y - 3.0 * y * y - 2.0,
                1.0,
                3.0 * y * y + 2.0 * y - 14.0,
            ],
        )
    }
}

#[test]
fn rosenbrock_stops_with_a_convergence_reason() {
    let sol = levenberg_marquardt(
        &Rosenbrock,
        DVector::from_vec(vec![-1.2, 1.0]),
        &LmOptions::default(),
    )
    .unwrap();
    assert!(sol.termination.is_converged(), "{:?}", sol.termination);
}

#[test]
fn powell_singular_approaches_the_origin_despite_the_singular_jacobian() {
    let sol = levenberg_marquardt(
        &PowellSingular,
        DVector::from_vec(vec![3.0, -1.0, 0.0, 1.0]),
        &LmOptions {
            max_iterations: 1000,
            ..LmOptions::default()
        },
    )
    .expect("Powell singular converges");
    // Convergence is linear (singular Jacobian at x*), so the tolerances stop it at a small but
    // non-zero x; the cost falls as |x|⁴, far below |x|.
    assert!(sol.params.amax() < 1e-3, "x = {}", sol.params);
    assert!(sol.cost < 1e-12, "F = {}", sol.cost);
    assert!(sol.termination.is_converged(), "{:?}", sol.termination);
}

#[test]
fn brown_badly_scaled_reaches_its_minimum_across_twelve_decades() {
    let sol = levenberg_marquardt(
        &BrownBadlyScaled,
        DVector::from_vec(vec![1.0, 1.0]),
        &LmOptions {
            max_iterations: 500,
            ..LmOptions::default()
        },
    )
    .expect("Brown badly scaled converges");
    // Zero-residual problem: each parameter to a relative 1e-8 despite the 10¹² spread.
    assert!(
        (sol.params[0] / 1e6 - 1.0).abs() < 1e-8,
        "x1 = {}",
        sol.params[0]
    );
    assert!(
        (sol.params[1] / 2e-6 - 1.0).abs() < 1e-8,
        "x2 = {}",
        sol.params[1]
    );
    assert!(sol.termination.is_converged(), "{:?}", sol.termination);
}

#[test]
fn freudenstein_roth_stops_in_the_known_local_minimum_by_a_convergence_test() {
    let sol = levenberg_marquardt(
        &FreudensteinRoth,
        DVector::from_vec(vec![0.5, -2.0]),
        &LmOptions::default(),
    )
    .expect("Freudenstein-Roth converges to its local minimum");
    // MGH report F = 48.9842 (to the digits printed) at the local minimum.
    assert!(
        (sol.cost - 48.984_253_679_8).abs() < 1e-6,
        "F = {}",
        sol.cost
    );
    assert!(
        (sol.params[0] - 11.4128).abs() < 1e-3,
        "x1 = {}",
        sol.params[0]
    );
    assert!(
        (sol.params[1] + 0.896_805).abs() < 1e-5,
        "x2 = {}",
        sol.params[1]
    );
    // A non-zero residual: it is the cost or gradient test that holds, not an exact fit.
    assert!(
        matches!(
            sol.termination,
            Termination::CostConverged
                | Termination::CostAndStepConverged
                | Termination::GradientConverged
                | Termination::StepConverged
        ),
        "{:?}",
        sol.termination
    );
}

/// A residual with a kink at the minimum, |x − 1|, whose Jacobian is ±1 everywhere: no
/// gradient test can hold, and below the kink no step lowers the cost.
struct Kink;
impl LeastSquaresProblem for Kink {
    fn residuals(&self, x: &DVector<f64>) -> DVector<f64> {
        DVector::from_vec(vec![(x[0] - 1.0).abs().sqrt() + 1.0])
    }
    fn jacobian(&self, x: &DVector<f64>) -> DMatrix<f64> {
        let d = x[0] - 1.0;
        let slope = if d == 0.0 {
            1.0
        } else {
            0.5 * d.signum() / d.abs().sqrt()
        };
        DMatrix::from_element(1, 1, slope)
    }
}

#[test]
fn a_residual_the_jacobian_does_not_describe_is_a_failure_not_a_minimum() {
    // A wrong-signed Jacobian: every predicted descent is an ascent, so no step is accepted and
    // λ overflows. Old behaviour returned this point as a minimum.
    struct WrongSign;
    impl LeastSquaresProblem for WrongSign {
        fn residuals(&self, x: &DVector<f64>) -> DVector<f64> {
            DVector::from_vec(vec![x[0] - 3.0])
        }
        fn jacobian(&self, _x: &DVector<f64>) -> DMatrix<f64> {
            DMatrix::from_element(1, 1, -1.0)
        }
    }
    let err = levenberg_marquardt(
        &WrongSign,
        DVector::from_vec(vec![0.0]),
        &LmOptions::default(),
    )
    .unwrap_err();
    assert_eq!(err.termination, Termination::DampingOverflow);
    assert!(!err.termination.is_converged());
}

#[test]
fn a_kinked_residual_is_not_reported_as_converged_far_from_its_floor() {
    let opts = LmOptions::default();
    match levenberg_marquardt(&Kink, DVector::from_vec(vec![5.0]), &opts) {
        // If a convergence test holds, it must be at the kink (the minimum, F = 1).
        Ok(sol) => assert!((sol.params[0] - 1.0).abs() < 1e-6, "x = {}", sol.params[0]),
        Err(e) => assert!(!e.termination.is_converged()),
    }
}

#[test]
fn the_budget_failure_names_its_reason() {
    let opts = LmOptions {
        max_iterations: 3,
        ..LmOptions::default()
    };
    let err =
        levenberg_marquardt(&Rosenbrock, DVector::from_vec(vec![-1.2, 1.0]), &opts).unwrap_err();
    assert_eq!(err.termination, Termination::EvaluationBudget);
    let message = err.into_fit_error("lm").to_string();
    assert!(message.contains("evaluation_budget"), "{message}");
}

/// `inner` evaluated with its normal equations at every trial point, as the norm model does.
struct WithNormalEquations<P>(P);
impl<P: LeastSquaresProblem> LeastSquaresProblem for WithNormalEquations<P> {
    fn residuals(&self, p: &DVector<f64>) -> DVector<f64> {
        self.0.residuals(p)
    }
    fn jacobian(&self, p: &DVector<f64>) -> DMatrix<f64> {
        self.0.jacobian(p)
    }
    fn residuals_with_normal_equations(
        &self,
        p: &DVector<f64>,
    ) -> Option<(DVector<f64>, DMatrix<f64>, DVector<f64>)> {
        let r = self.0.residuals(p);
        let (jtj, grad) = self.0.normal_equations(p, &r);
        Some((r, jtj, grad))
    }
}

#[test]
fn normal_equations_with_every_trial_point_give_the_same_iterations_and_result() {
    // A noisy decay (non-zero residual at the minimum, rejected steps on the way) and Rosenbrock:
    // the same arithmetic at the same points, so the runs agree to the last bit.
    let t: Vec<f64> = (0..40).map(|i| f64::from(i) * 0.1).collect();
    let y: Vec<f64> = t
        .iter()
        .enumerate()
        .map(|(i, t)| 5.0 * (-1.3 * t).exp() + 0.7 + 0.05 * (2.1 * i as f64).sin())
        .collect();
    let decay = || Decay {
        t: t.clone(),
        y: y.clone(),
    };
    let start = DVector::from_vec(vec![1.0, 3.0, -1.0]);
    let opts = LmOptions::default();
    let runs = [
        (
            levenberg_marquardt(&decay(), start.clone(), &opts),
            levenberg_marquardt(&WithNormalEquations(decay()), start, &opts),
        ),
        (
            levenberg_marquardt(&Rosenbrock, DVector::from_vec(vec![-1.2, 1.0]), &opts),
            levenberg_marquardt(
                &WithNormalEquations(Rosenbrock),
                DVector::from_vec(vec![-1.2, 1.0]),
                &opts,
            ),
        ),
    ];
    for (plain, fused) in runs {
        let (plain, fused) = (plain.unwrap(), fused.unwrap());
        assert_eq!(plain.params, fused.params);
        assert_eq!(plain.iterations, fused.iterations);
        assert_eq!(plain.termination, fused.termination);
        assert_eq!(plain.jtj, fused.jtj);
        assert_eq!(plain.cost, fused.cost);
    }
}
