//! Chen, Sun, Li & Yan (seed 003): accelerometer calibration without a turntable in two steps.
//!
//! 1. Coarse model (§2): per axis `A_x = B_x + S_x·V_x + E_xy·V_y + E_xz·V_z` from the six face
//!    poses by least squares, `[B S E E]ᵀ = (GᵀG)⁻¹Gᵀ·[±g 0 …]` with `G = [1 V_x V_y V_z]`. In this
//!    library's convention that is `y = K·x + B`, i.e. `A = K`, `b = −K⁻¹B`: the same linear
//!    problem as the six-position fit of seed 000 eq. 11–15, solved here on the six faces.
//! 2. Fine model (§3): the norm equations `f_i = |A(x_i − b)|² − g² = 0` over all poses (twelve in
//!    the paper: the faces plus six 45° tilts), linearised by a first-order Taylor expansion and
//!    iterated from the coarse solution (Newton / Gauss–Newton).
//!
//! Why the paper's 12-unknown Newton system is rank-deficient: `f_i` depends on `A` only through
//! `AᵀA`, so `A → Q·A` for any rotation `Q` leaves every `f_i` unchanged. Differentiating along
//! `Q = exp(Ω)` with `Ω` skew-symmetric gives `δf_i = 2·yᵢᵀΩyᵢ = 0` (`yᵢ = A(xᵢ − b)`): the three
//! infinitesimal rotations are null directions of the 12-column Jacobian at every point, so its
//! rank is at most 9 whatever the poses ([`norm_jacobian_full`] exposes it). The paper's iteration
//! only works because its start pins the rotation and a minimum-norm step does not move it. Here
//! the gauge is fixed instead: the start is made upper-triangular by QR (`A = Q·R`,
//! `|A·u| = |R·u|`), and Gauss–Newton runs on the 9 unknowns `A11 A12 A13 A22 A23 A33 b1 b2 b3`
//! ([`norm_jacobian_gauge`]), weighted by each pose's noise.

use nalgebra::{DMatrix, DVector};

use super::coverage::{guard_fit, CoverageHint, EllipsoidModel};
use super::li::li_start;
use super::linalg::{
    equilibrated_condition_number, inverse_spd, least_squares, rms, std_from_covariance,
    upper_triangular_gauge,
};
use super::loo::leave_one_out_rms;
use super::six_position::six_position_calibration;
use super::uncertainty::{scaled_covariance, NoiseLevel, Z_95};
use super::validate::{
    check_distinct, check_finite_poses, check_reference, check_spread, find_faces, MIN_SPREAD_DEG,
};
use super::{Calibration, CalibrationStd, Fit, FitError, Mat3, Method, Pose, Vec3};

/// Maximum Gauss–Newton iterations before giving up.
pub const MAX_ITERATIONS: usize = 100;

/// Positions of the 9 gauge-fixed unknowns within `A` (upper triangle, row-major).
const UPPER: [(usize, usize); 6] = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];

/// Chen's method: coarse six-face linear fit, then Gauss–Newton on the norm model over all poses.
///
/// Needs the six faces (for the start) and at least 9 distinct orientations (9 unknowns). The
/// returned `A` is upper-triangular (the norm-model gauge). Covariance order:
/// `A11 A12 A13 A22 A23 A33 b1 b2 b3`, from the inverse of the noise-weighted Gauss–Newton normal
/// matrix (or `σ̂²(JᵀJ)⁻¹` from the residuals when the poses report no variance).
///
/// The coverage rule of [`super::coverage`] is applied before returning.
pub fn fit_chen(poses: &[Pose], reference: f64) -> Result<Fit, FitError> {
    let means: Vec<Vec3> = poses.iter().map(|p| p.mean).collect();
    let noise: Vec<f64> = poses
        .iter()
        .map(|p| (p.var_of_mean().sum() / 3.0).max(0.0).sqrt())
        .collect();
    let start = chen_coarse(poses, reference).ok();
    guard_fit(
        fit_chen_unchecked(poses, reference),
        &means,
        Some(&noise),
        reference,
        EllipsoidModel::General,
        CoverageHint::Poses,
        || {
            start
                .filter(Calibration::is_finite)
                .or_else(|| li_start(&means, reference))
        },
    )
}

fn fit_chen_unchecked(poses: &[Pose], reference: f64) -> Result<Fit, FitError> {
    let start = chen_coarse(poses, reference)?;
    let refined = refine_norm_model(poses, &start, reference)?;
    let cal = refined.cal;

    let residuals: Vec<f64> = poses
        .iter()
        .map(|p| (cal.apply(&p.mean).norm() - reference) / reference)
        .collect();

    // A held-out face leaves no coarse start on the rest; the full-data start is used then (it
    // only selects the basin, the refit itself sees only the remaining poses).
    let loo_rms = leave_one_out_rms(poses, reference, |rest| {
        let s = chen_coarse(rest, reference).unwrap_or(start);
        refine_norm_model(rest, &s, reference).map(|r| r.cal)
    });

    let std = refined.covariance.as_ref().map(|cov| {
        let s = std_from_covariance(cov);
        let mut a = Mat3::zeros();
        for (k, &(r, c)) in UPPER.iter().enumerate() {
            a[(r, c)] = s[k];
        }
        CalibrationStd {
            a,
            b: Vec3::new(s[6], s[7], s[8]),
        }
    });

    Ok(Fit {
        method: Method::Chen,
        cal,
        rms: rms(&residuals),
        residuals,
        loo_rms,
        covariance: refined.covariance,
        param_names: gauge_param_names(),
        std,
        condition_number: refined.condition_number,
        iterations: refined.iterations,
        termination: None,
        coverage_factor: refined.coverage_factor,
        reference,
    })
}

/// Step 1 of seed 003: the linear coarse calibration from the six face poses (full `A`).
pub fn chen_coarse(poses: &[Pose], reference: f64) -> Result<Calibration, FitError> {
    check_reference(reference)?;
    check_finite_poses(poses)?;
    let faces = find_faces(poses)?;
    let face_poses: Vec<Pose> = faces.iter().map(|&i| poses[i].clone()).collect();
    let axes: Vec<Vec3> = (0..6)
        .map(|f| {
            let mut u = Vec3::zeros();
            u[f / 2] = if f % 2 == 0 { 1.0 } else { -1.0 };
            u
        })
        .collect();
    six_position_calibration(&face_poses, &axes, reference)
}

/// Result of the gauge-fixed Gauss–Newton refinement.
#[derive(Debug, Clone)]
pub struct Refined {
    /// Calibration with upper-triangular `A`.
    pub cal: Calibration,
    /// Iterations used.
    pub iterations: usize,
    /// Covariance of the 9 unknowns, if a noise estimate exists.
    pub covariance: Option<DMatrix<f64>>,
    /// `k` such that `±k·σ` is a 95 % interval ([`super::uncertainty`]).
    pub coverage_factor: f64,
    /// Condition number of the weighted 9-column Jacobian at the solution.
    pub condition_number: f64,
}

/// Step 2 of seed 003 with the gauge fixed: Gauss–Newton on `fᵢ = (|A(xᵢ − b)|² − ref²)/ref²`
/// over the 9 unknowns, started from `start` made upper-triangular.
pub fn refine_norm_model(
    poses: &[Pose],
    start: &Calibration,
    reference: f64,
) -> Result<Refined, FitError> {
    check_reference(reference)?;
    check_finite_poses(poses)?;
    if poses.len() < 9 {
        return Err(FitError::Underdetermined(format!(
            "only {} poses; the norm model has 9 unknowns and needs at least 9 orientations",
            poses.len()
        )));
    }
    let mut cal = Calibration {
        a: upper_triangular_gauge(&start.a),
        b: start.b,
    };
    if !cal.a.iter().chain(cal.b.iter()).all(|v| v.is_finite()) {
        return Err(FitError::NonFinite("starting calibration".into()));
    }
    let calibrated: Vec<Vec3> = poses
        .iter()
        .filter_map(|p| cal.apply(&p.mean).try_normalize(1e-300))
        .collect();
    check_distinct(&calibrated, 9)?;
    check_spread(&calibrated, MIN_SPREAD_DEG)?;

    // Noise of fᵢ from the pose variance: ∂f/∂x = 2Aᵀy/ref².
    let noise_sd = |cal: &Calibration| -> Option<Vec<f64>> {
        let sds: Vec<f64> = poses
            .iter()
            .map(|p| {
                let grad = cal.a.transpose() * cal.apply(&p.mean) * (2.0 / (reference * reference));
                grad.component_mul(&grad).dot(&p.var_of_mean()).sqrt()
            })
            .collect();
        sds.iter().all(|s| *s > 0.0 && s.is_finite()).then_some(sds)
    };
    let weights = noise_sd(&cal).map(|sds| sds.iter().map(|s| 1.0 / s).collect::<Vec<f64>>());
    let weight = |i: usize| weights.as_ref().map_or(1.0, |w| w[i]);

    let cost = |c: &Calibration| -> f64 {
        residual_vector(poses, c, reference)
            .iter()
            .enumerate()
            .map(|(i, f)| (weight(i) * f).powi(2))
            .sum()
    };

    let mut current = cost(&cal);
    let mut iterations = 0;
    let mut converged = false;
    while iterations < MAX_ITERATIONS {
        iterations += 1;
        let jac = norm_jacobian_gauge(poses, &cal, reference);
        let f = residual_vector(poses, &cal, reference);
        let jw = DMatrix::from_fn(jac.nrows(), 9, |i, j| jac[(i, j)] * weight(i));
        let rhs = DMatrix::from_fn(f.len(), 1, |i, _| -f[i] * weight(i));
        let step = least_squares(&jw, &rhs, "Chen's norm model")?.solution;
        let theta = gauge_params(&cal);
        // Step halving keeps the iteration monotone far from the solution.
        let mut t = 1.0;
        let mut accepted = false;
        for _ in 0..40 {
            let trial = from_gauge_params(&(&theta + step.column(0) * t));
            let c = cost(&trial);
            if c.is_finite() && c <= current {
                cal = trial;
                let decrease = current - c;
                current = c;
                accepted = true;
                if step.norm() * t <= 1e-12 * (1.0 + theta.norm()) || decrease <= 1e-30 {
                    converged = true;
                }
                break;
            }
            t *= 0.5;
        }
        // No decrease along the Gauss–Newton direction: already at the minimum to rounding.
        if !accepted || converged {
            converged = true;
            break;
        }
    }
    if !converged {
        return Err(FitError::NotConverged {
            method: "chen",
            iterations,
            detail: format!(
                "weighted cost still {current:.3e}; check for moving or mislabelled poses"
            ),
        });
    }

    let jac = norm_jacobian_gauge(poses, &cal, reference);
    let jw = DMatrix::from_fn(jac.nrows(), 9, |i, j| jac[(i, j)] * weight(i));
    let condition_number = equilibrated_condition_number(&jw);
    let normal = jw.transpose() * &jw;
    // One policy (`uncertainty`): χ² of the weighted residual, Birge-inflated with known noise.
    let chi_square = cost(&cal);
    let level = if weights.is_some() {
        NoiseLevel::Known
    } else {
        NoiseLevel::Unknown
    };
    let scaled = scaled_covariance(inverse_spd(&normal), chi_square, poses.len(), 9, level);
    let coverage_factor = scaled.as_ref().map_or(Z_95, |s| s.coverage_factor);
    let covariance = scaled.map(|s| s.covariance);
    Ok(Refined {
        cal,
        iterations,
        covariance,
        coverage_factor,
        condition_number,
    })
}

/// Chen's norm residuals `fᵢ = (|A(xᵢ − b)|² − ref²)/ref²`.
pub fn residual_vector(poses: &[Pose], cal: &Calibration, reference: f64) -> Vec<f64> {
    let r2 = reference * reference;
    poses
        .iter()
        .map(|p| (cal.apply(&p.mean).norm_squared() - r2) / r2)
        .collect()
}

/// Jacobian of [`residual_vector`] with respect to all 12 entries of the paper's model: `A`
/// row-major (`A11 … A33`) then `b1 b2 b3`. Its rank is at most 9 (see the module comment).
pub fn norm_jacobian_full(poses: &[Pose], cal: &Calibration, reference: f64) -> DMatrix<f64> {
    let r2 = reference * reference;
    let mut jac = DMatrix::zeros(poses.len(), 12);
    for (i, p) in poses.iter().enumerate() {
        let d = p.mean - cal.b;
        let y = cal.a * d;
        for r in 0..3 {
            for c in 0..3 {
                jac[(i, 3 * r + c)] = 2.0 * y[r] * d[c] / r2;
            }
        }
        let gb = -(cal.a.transpose() * y) * (2.0 / r2);
        for k in 0..3 {
            jac[(i, 9 + k)] = gb[k];
        }
    }
    jac
}

/// Jacobian of [`residual_vector`] with respect to the 9 gauge-fixed unknowns
/// `A11 A12 A13 A22 A23 A33 b1 b2 b3` (full column rank for a well-spread pose set).
pub fn norm_jacobian_gauge(poses: &[Pose], cal: &Calibration, reference: f64) -> DMatrix<f64> {
    let full = norm_jacobian_full(poses, cal, reference);
    let columns: Vec<usize> = UPPER.iter().map(|&(r, c)| 3 * r + c).chain(9..12).collect();
    DMatrix::from_fn(full.nrows(), 9, |i, j| full[(i, columns[j])])
}

fn gauge_param_names() -> Vec<String> {
    let mut names: Vec<String> = UPPER
        .iter()
        .map(|&(r, c)| format!("A{}{}", r + 1, c + 1))
        .collect();
    names.extend((1..=3).map(|k| format!("b{k}")));
    names
}

fn gauge_params(cal: &Calibration) -> DVector<f64> {
    DVector::from_iterator(
        9,
        UPPER
            .iter()
            .map(|&(r, c)| cal.a[(r, c)])
            .chain(cal.b.iter().copied()),
    )
}

fn from_gauge_params(theta: &DVector<f64>) -> Calibration {
    let mut a = Mat3::zeros();
    for (k, &(r, c)) in UPPER.iter().enumerate() {
        a[(r, c)] = theta[k];
    }
    Calibration {
        a,
        b: Vec3::new(theta[6], theta[7], theta[8]),
    }
}
