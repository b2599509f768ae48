//! Axis-aligned ellipsoid by linear least squares (seed 004 §1.2.3–1.2.5): the ellipsoid
//! `((x−x0)/A)² + ((y−y0)/B)² + ((z−z0)/C)² = 1` expands to `x² + a·y² + b·z² + c·x + d·y + e·z + f
//! = 0`, so each sample gives a row `[y² z² x y z 1]` with right-hand side `−x²`. Then
//! `x0 = −c/2`, `y0 = −d/(2a)`, `z0 = −e/(2b)`, `A² = x0² + a·y0² + b·z0² − f`, `B = A/√a`,
//! `C = A/√b`, and the calibration is `A = diag(ref/A, ref/B, ref/C)`, `b = (x0, y0, z0)`.
//!
//! The samples are first centred on their mean and scaled to unit RMS radius so the design matrix
//! is well conditioned; the model is invariant under this change of variables, and the centre and
//! radii are mapped back afterwards.
//!
//! The leave-one-pose-out RMS of the pose fit uses the rank-one downdate of the least-squares
//! solution (Sherman–Morrison), not one refit per pose.

use std::cmp::Ordering;

use nalgebra::DMatrix;

use super::coverage::{guard_fit, CoverageHint, EllipsoidModel};
use super::li::li_start;
use super::linalg::{inverse_spd, least_squares, RANK_TOLERANCE};
use super::loo::held_out_rms;
use super::validate::{check_finite_points, check_finite_poses, check_reference};
use super::{Calibration, Fit, FitError, Mat3, Method, Pose, Vec3};

/// Fit an axis-aligned ellipsoid to `points` and return the calibration mapping it onto the sphere
/// of radius `reference`. Needs at least six points that are not all on one plane.
/// The coverage rule of [`super::coverage`] (6 unknowns) is applied before returning.
pub fn fit_axis_aligned(points: &[Vec3], reference: f64) -> Result<Fit, FitError> {
    guard_fit(
        fit_axis_aligned_unchecked(points, reference),
        points,
        None,
        reference,
        EllipsoidModel::AxisAligned,
        CoverageHint::Either,
        || li_start(points, reference),
    )
}

fn fit_axis_aligned_unchecked(points: &[Vec3], reference: f64) -> Result<Fit, FitError> {
    let (cal, condition_number) = solve(points, reference)?;
    Ok(Fit::closed_form(
        Method::AxisAligned,
        cal,
        points,
        reference,
        condition_number,
    ))
}

/// [`fit_axis_aligned`] on static pose means, with the leave-one-pose-out RMS.
pub fn fit_axis_aligned_poses(poses: &[Pose], reference: f64) -> Result<Fit, FitError> {
    check_finite_poses(poses)?;
    let means: Vec<Vec3> = poses.iter().map(|p| p.mean).collect();
    let mut fit = fit_axis_aligned(&means, reference)?;
    fit.loo_rms = leave_one_out_axis_aligned(poses, &means, reference);
    Ok(fit)
}

/// The linear least-squares problem of the module comment in centred, scaled coordinates.
struct Design {
    mean: Vec3,
    spread: f64,
    x: DMatrix<f64>,
    y: DMatrix<f64>,
}

fn design(points: &[Vec3]) -> Result<Design, FitError> {
    let mean = points.iter().sum::<Vec3>() / points.len() as f64;
    let spread = (points
        .iter()
        .map(|p| (p - mean).norm_squared())
        .sum::<f64>()
        / points.len() as f64)
        .sqrt();
    if spread.partial_cmp(&0.0) != Some(Ordering::Greater) {
        return Err(FitError::Underdetermined(
            "all samples are identical; rotate the board between samples".into(),
        ));
    }
    let q: Vec<Vec3> = points.iter().map(|p| (p - mean) / spread).collect();
    let x = DMatrix::from_fn(q.len(), 6, |i, j| {
        let p = &q[i];
        [p.y * p.y, p.z * p.z, p.x, p.y, p.z, 1.0][j]
    });
    let y = DMatrix::from_fn(q.len(), 1, |i, _| -q[i].x * q[i].x);
    Ok(Design { mean, spread, x, y })
}

/// Leave-one-pose-out RMS by the rank-one downdate of linear least squares: without row `i`,
/// `β₋ᵢ = β − (XᵀX)⁻¹xᵢ·eᵢ/(1 − hᵢ)` with residual `eᵢ = yᵢ − xᵢᵀβ` and leverage
/// `hᵢ = xᵢᵀ(XᵀX)⁻¹xᵢ` (Sherman–Morrison). The model is invariant under the centring and scaling,
/// so the whole set's normalisation serves every fold. One fit in all instead of N.
fn leave_one_out_axis_aligned(poses: &[Pose], means: &[Vec3], reference: f64) -> Option<f64> {
    let fold = folds_without(means, reference)?;
    held_out_rms(poses, reference, |i| fold(i).map(|(cal, _)| cal))
}

/// The axis-aligned calibration of `means` without point `i`, for any `i`, by the rank-one
/// downdate above: the least-squares solution of the other points up to rounding, without the
/// coverage rule that [`fit_axis_aligned`] applies. `None` when there are six points or fewer,
/// or the full problem is singular.
pub fn calibrations_without(
    means: &[Vec3],
    reference: f64,
) -> Option<impl Fn(usize) -> Result<Calibration, FitError>> {
    let fold = folds_without(means, reference)?;
    Some(move |i: usize| fold(i).map(|(cal, _)| cal))
}

/// As [`calibrations_without`], with point `i`'s leverage in the design.
pub fn folds_without(
    means: &[Vec3],
    reference: f64,
) -> Option<impl Fn(usize) -> Result<(Calibration, f64), FitError>> {
    if means.len() <= 6 {
        return None;
    }
    let d = design(means).ok()?;
    let gram_inv = inverse_spd(&(d.x.transpose() * &d.x))?;
    let beta = &gram_inv * (d.x.transpose() * &d.y);
    Some(move |i: usize| {
        if i >= d.x.nrows() {
            return Err(FitError::Underdetermined(format!(
                "point {i} does not exist ({} points)",
                d.x.nrows()
            )));
        }
        let xi = d.x.row(i).transpose();
        let gx = &gram_inv * &xi;
        let leverage = xi.dot(&gx);
        // A pose with all the leverage is needed to determine the fit: without it the fold is
        // rank-deficient, as a refit would find.
        if 1.0 - leverage <= RANK_TOLERANCE.sqrt() {
            return Err(FitError::Underdetermined(
                "a pose determines the fit alone".into(),
            ));
        }
        let e = d.y[(i, 0)] - xi.dot(&beta.column(0));
        let fold = beta.column(0) - gx * (e / (1.0 - leverage));
        let v = [fold[0], fold[1], fold[2], fold[3], fold[4], fold[5]];
        calibration_from_coefficients(&v, &d, reference).map(|cal| (cal, leverage))
    })
}

/// The calibration and the condition number of the (normalised) design matrix.
fn solve(points: &[Vec3], reference: f64) -> Result<(Calibration, f64), FitError> {
    check_reference(reference)?;
    check_finite_points(points)?;
    if points.len() < 6 {
        return Err(FitError::Underdetermined(format!(
            "only {} samples; the axis-aligned ellipsoid needs at least 6",
            points.len()
        )));
    }
    let d = design(points)?;
    let ls = least_squares(&d.x, &d.y, "axis-aligned ellipsoid")?;
    let v = &ls.solution;
    let cal = calibration_from_coefficients(&[v[0], v[1], v[2], v[3], v[4], v[5]], &d, reference)?;
    Ok((cal, ls.condition_number))
}

/// The calibration from the coefficients `a b c d e f` of the normalised problem.
fn calibration_from_coefficients(
    v: &[f64; 6],
    d: &Design,
    reference: f64,
) -> Result<Calibration, FitError> {
    let [a, b, c, dy, e, f] = *v;
    let not_closed = || {
        FitError::Underdetermined(
            "the samples do not lie on a closed axis-aligned ellipsoid; cover more orientations \
             (every axis up and down)"
                .into(),
        )
    };
    if a.partial_cmp(&0.0) != Some(Ordering::Greater)
        || b.partial_cmp(&0.0) != Some(Ordering::Greater)
    {
        return Err(not_closed());
    }
    let centre = Vec3::new(-c / 2.0, -dy / (2.0 * a), -e / (2.0 * b));
    let rx_sq = centre.x * centre.x + a * centre.y * centre.y + b * centre.z * centre.z - f;
    if rx_sq.partial_cmp(&0.0) != Some(Ordering::Greater) {
        return Err(not_closed());
    }
    let rx = rx_sq.sqrt();
    let radii = Vec3::new(rx, rx / a.sqrt(), rx / b.sqrt()) * d.spread;
    let cal = Calibration {
        a: Mat3::from_diagonal(&radii.map(|r| reference / r)),
        b: d.mean + centre * d.spread,
    };
    if !cal.a.iter().chain(cal.b.iter()).all(|v| v.is_finite()) {
        return Err(not_closed());
    }
    Ok(cal)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::loo::leave_one_out_rms;

    #[test]
    fn rank_one_leave_one_out_equals_refitting_without_each_pose() {
        let poses: Vec<Pose> = (0..15)
            .map(|i| {
                let t = f64::from(i);
                let z = 1.0 - 2.0 * (t + 0.5) / 15.0;
                let phi = t * 2.399_963_229_728_653;
                let r = (1.0 - z * z).sqrt();
                let noise = 0.01 * (5.3 * t).sin();
                Pose {
                    mean: Vec3::new(1.05 * r * phi.cos() + 0.2, 0.95 * r * phi.sin(), z - 0.1)
                        * (9.81 + noise),
                    var: Vec3::repeat(1e-4),
                    n: 50,
                    label: None,
                }
            })
            .collect();
        let means: Vec<Vec3> = poses.iter().map(|p| p.mean).collect();
        let fast = leave_one_out_axis_aligned(&poses, &means, 9.81).expect("determined");
        let brute = leave_one_out_rms(&poses, 9.81, |rest| {
            let m: Vec<Vec3> = rest.iter().map(|p| p.mean).collect();
            solve(&m, 9.81).map(|(cal, _)| cal)
        })
        .expect("determined");
        // Exact algebra; the normal-equation downdate and the SVD refits round differently.
        assert!(
            (fast - brute).abs() <= 1e-9 * brute,
            "{fast:e} vs {brute:e}"
        );
        assert!(
            brute > 1e-4,
            "the held-out error is not trivially zero: {brute:e}"
        );
    }
}
