//! Six-position linear least squares (seed 000 eq. 11–15). With `b* = A·b`, each static pose gives
//! `A·x − b* = y` (eq. 11), stacked as `X·β = Y` with rows `[x y z −1]`, `β = [Aᵀ; b*ᵀ]` and `Y` the
//! expected calibrated vectors (eq. 12). `β̂` minimises `‖Xβ − Y‖²` (eq. 13), solved by SVD; then
//! `A = β̂ᵀ[1:3,1:3]` (eq. 14) and `b = A⁻¹·β̂ᵀ[1:3,4]` (eq. 15).
//!
//! Unlike the norm-model fits this uses the expected direction of each pose, so it determines the
//! full `A` including the rotation of the output frame onto the labelled faces.

use nalgebra::DMatrix;

use super::linalg::{least_squares, rms, std_from_covariance};
use super::loo::leave_one_out_rms_indexed;
use super::uncertainty::{noise_scale, NoiseLevel, Z_95};
use super::validate::{
    check_finite_poses, check_reference, check_spread, face_of, median_centre, FACE_TOLERANCE_DEG,
    MIN_SPREAD_DEG,
};
use super::{Calibration, CalibrationStd, Fit, FitError, Mat3, Method, Pose, Vec3};

/// Fit `A` (full 3×3) and `b` from static poses whose expected calibrated directions are known.
///
/// `expected` gives the direction of the reference vector for each pose (normalised here, scaled by
/// `reference`); when `None`, each pose is assigned the nearest ±axis, and a pose more than
/// 30° from every axis is refused. The covariance (order `A11 … A33 b1 b2 b3`) is the linear LS
/// covariance `σ_j²(XᵀX)⁻¹` per output axis, with `σ_j²` from the within-pose variance (or from
/// the residuals when the poses report none), mapped onto `b = A⁻¹b*` to first order.
pub fn fit_six_position(
    poses: &[Pose],
    expected: Option<&[Vec3]>,
    reference: f64,
) -> Result<Fit, FitError> {
    check_reference(reference)?;
    check_finite_poses(poses)?;
    let dirs = expected_directions(poses, expected)?;
    let solved = solve(poses, &dirs, reference)?;
    let cal = solved.cal;

    // The norm residual, as every other static-pose fit and its own leave-one-out report it,
    // so that fit error, held-out error and the noise floor measure the same thing. (The
    // vector error against each face's ±axis would add how squarely each face was placed.)
    let residuals: Vec<f64> = poses
        .iter()
        .map(|p| (cal.apply(&p.mean).norm() - reference) / reference)
        .collect();

    let loo_rms = leave_one_out_rms_indexed(poses, reference, |i, rest| {
        let rest_dirs: Vec<Vec3> = dirs
            .iter()
            .enumerate()
            .filter(|&(j, _)| j != i)
            .map(|(_, d)| *d)
            .collect();
        solve(rest, &rest_dirs, reference).map(|s| s.cal)
    });

    let (covariance, coverage_factor) = match covariance(poses, &dirs, &solved, reference) {
        Some((cov, k)) => (Some(cov), k),
        None => (None, Z_95),
    };
    let std = covariance.as_ref().map(|cov| {
        let s = std_from_covariance(cov);
        CalibrationStd {
            a: Mat3::from_fn(|r, c| s[3 * r + c]),
            b: Vec3::new(s[9], s[10], s[11]),
        }
    });

    Ok(Fit {
        method: Method::SixPosition,
        cal,
        rms: rms(&residuals),
        residuals,
        loo_rms,
        covariance,
        param_names: param_names(),
        std,
        condition_number: solved.condition_number,
        iterations: 0,
        termination: None,
        coverage_factor,
        reference,
    })
}

/// The six-position calibration alone, for poses with the given unit directions.
pub fn six_position_calibration(
    poses: &[Pose],
    expected: &[Vec3],
    reference: f64,
) -> Result<Calibration, FitError> {
    check_reference(reference)?;
    check_finite_poses(poses)?;
    let dirs = expected_directions(poses, Some(expected))?;
    solve(poses, &dirs, reference).map(|s| s.cal)
}

/// The nearest ±axis of each pose (direction from the median centre), or `None` for a pose more
/// than 30° from every axis.
pub fn nearest_axes(poses: &[Pose]) -> Vec<Option<Vec3>> {
    let means: Vec<Vec3> = poses.iter().map(|p| p.mean).collect();
    let centre = median_centre(&means);
    means
        .iter()
        .map(|m| {
            face_of(&(m - centre), FACE_TOLERANCE_DEG).map(|face| {
                let mut u = Vec3::zeros();
                u[face / 2] = if face % 2 == 0 { 1.0 } else { -1.0 };
                u
            })
        })
        .collect()
}

fn param_names() -> Vec<String> {
    let mut names: Vec<String> = (1..=3)
        .flat_map(|r| (1..=3).map(move |c| format!("A{r}{c}")))
        .collect();
    names.extend((1..=3).map(|k| format!("b{k}")));
    names
}

fn expected_directions(poses: &[Pose], expected: Option<&[Vec3]>) -> Result<Vec<Vec3>, FitError> {
    match expected {
        Some(e) => {
            if e.len() != poses.len() {
                return Err(FitError::Underdetermined(format!(
                    "{} expected directions for {} poses; give one per pose",
                    e.len(),
                    poses.len()
                )));
            }
            e.iter()
                .enumerate()
                .map(|(i, d)| {
                    if !d.iter().all(|v| v.is_finite()) {
                        return Err(FitError::NonFinite(format!(
                            "expected direction of pose {i}"
                        )));
                    }
                    d.try_normalize(1e-12).ok_or_else(|| {
                        FitError::Underdetermined(format!(
                            "the expected direction of pose {i} has zero length; give a unit vector"
                        ))
                    })
                })
                .collect()
        }
        None => nearest_axes(poses)
            .into_iter()
            .enumerate()
            .map(|(i, d)| {
                d.ok_or_else(|| {
                    FitError::Underdetermined(format!(
                        "pose {i} is more than {FACE_TOLERANCE_DEG}° from every axis, and the \
                         six-position fit takes each pose's face from its reading: every pose \
                         must lie on a face (an axis up or down); for tilted poses use a norm \
                         model (--method lm or axis-aligned)"
                    ))
                })
            })
            .collect(),
    }
}

struct Solved {
    cal: Calibration,
    /// Design matrix with columns scaled to unit norm, and that scaling.
    design: DMatrix<f64>,
    column_scale: Vec<f64>,
    condition_number: f64,
}

fn solve(poses: &[Pose], dirs: &[Vec3], reference: f64) -> Result<Solved, FitError> {
    if poses.len() < 4 {
        return Err(FitError::Underdetermined(format!(
            "only {} poses; the six-position fit needs at least 4 (six faces recommended)",
            poses.len()
        )));
    }
    check_spread(dirs, MIN_SPREAD_DEG)?;
    let raw = DMatrix::from_fn(
        poses.len(),
        4,
        |i, j| if j < 3 { poses[i].mean[j] } else { -1.0 },
    );
    // Equilibrate columns so the condition number does not depend on the data's units.
    let column_scale: Vec<f64> = (0..4)
        .map(|j| {
            let n = raw.column(j).norm();
            if n > 0.0 {
                1.0 / n
            } else {
                1.0
            }
        })
        .collect();
    let design = DMatrix::from_fn(raw.nrows(), 4, |i, j| raw[(i, j)] * column_scale[j]);
    let y = DMatrix::from_fn(poses.len(), 3, |i, j| dirs[i][j] * reference);
    let ls = least_squares(&design, &y, "six-position fit")?;
    let beta = DMatrix::from_fn(4, 3, |r, c| ls.solution[(r, c)] * column_scale[r]);
    let a = Mat3::from_fn(|r, c| beta[(c, r)]);
    let b_star = Vec3::new(beta[(3, 0)], beta[(3, 1)], beta[(3, 2)]);
    let a_inv = a.try_inverse().ok_or_else(|| {
        FitError::Underdetermined(
            "the fitted scale matrix is singular; check the pose labels".into(),
        )
    })?;
    Ok(Solved {
        cal: Calibration {
            a,
            b: a_inv * b_star,
        },
        design,
        column_scale,
        condition_number: ls.equilibrated_condition,
    })
}

/// Linear LS covariance of `(A, b)` (see [`fit_six_position`]); `None` if no noise estimate exists.
/// The covariance and its 95 % coverage factor ([`super::uncertainty`]).
fn covariance(
    poses: &[Pose],
    dirs: &[Vec3],
    s: &Solved,
    reference: f64,
) -> Option<(DMatrix<f64>, f64)> {
    let n = poses.len();
    let a = s.cal.a;
    // Per output axis: the noise of output j in pose i is Σ_k A_jk² var(mean_ik). The variance
    // factor follows the common policy (`uncertainty`): χ² against that noise, Birge-inflated;
    // without reported variances the noise is estimated from the residual.
    let noise_of = |p: &Pose, j: usize| -> f64 {
        (0..3)
            .map(|k| a[(j, k)].powi(2) * p.var_of_mean()[k])
            .sum::<f64>()
    };
    let known = poses.iter().all(|p| (0..3).all(|j| noise_of(p, j) > 0.0));
    let mut sigma_sq = [0.0; 3];
    let mut coverage_factor = Z_95;
    for (j, sj) in sigma_sq.iter_mut().enumerate() {
        let residual = |p: &Pose, u: &Vec3| s.cal.apply(&p.mean)[j] - u[j] * reference;
        let (chi_square, level) = if known {
            let chi: f64 = poses
                .iter()
                .zip(dirs)
                .map(|(p, u)| residual(p, u).powi(2) / noise_of(p, j))
                .sum();
            (chi, NoiseLevel::Known)
        } else {
            let rss: f64 = poses
                .iter()
                .zip(dirs)
                .map(|(p, u)| residual(p, u).powi(2))
                .sum();
            (rss, NoiseLevel::Unknown)
        };
        let scale = noise_scale(chi_square, n, 4, level)?;
        coverage_factor = coverage_factor.max(scale.coverage_factor);
        let factor = scale.variance_factor;
        // Known noise: the unit covariance carries the mean pose noise; unknown: unit weights.
        let unit = if known {
            poses.iter().map(|p| noise_of(p, j)).sum::<f64>() / n as f64
        } else {
            1.0
        };
        *sj = unit * factor;
    }
    let xtx = s.design.transpose() * &s.design;
    let xtx_inv = xtx.try_inverse()?;
    // Back to unscaled parameters: β_r = β'_r · scale_r.
    let unscaled = DMatrix::from_fn(4, 4, |r, c| {
        xtx_inv[(r, c)] * s.column_scale[r] * s.column_scale[c]
    });
    let mut cov_theta = DMatrix::zeros(12, 12);
    for (j, sj) in sigma_sq.iter().enumerate() {
        for r in 0..4 {
            for c in 0..4 {
                cov_theta[(4 * j + r, 4 * j + c)] = sj * unscaled[(r, c)];
            }
        }
    }
    // θ = (A_j1, A_j2, A_j3, b*_j) per output j  →  (A row-major, b = A⁻¹ b*).
    let a_inv = a.try_inverse()?;
    let mut jac = DMatrix::zeros(12, 12);
    for j in 0..3 {
        for k in 0..3 {
            jac[(3 * j + k, 4 * j + k)] = 1.0;
            for m in 0..3 {
                jac[(9 + m, 4 * j + k)] = -a_inv[(m, j)] * s.cal.b[k];
            }
        }
        for m in 0..3 {
            jac[(9 + m, 4 * j + 3)] = a_inv[(m, j)];
        }
    }
    let cov = &jac * cov_theta * jac.transpose();
    cov.iter()
        .all(|v| v.is_finite())
        .then_some((cov, coverage_factor))
}
