//! Axis-aligned ellipsoid by linear least squares (seed 004 §1.2.3–1.2.5): the ellipsoid
//! `((x−x0)/A)² + ((y−y0)/B)² + ((z−z0)/C)² = 1` expands to `x² + a·y² + b·z² + c·x + d·y + e·z + f
//! = 0`, so each sample gives a row `[y² z² x y z 1]` with right-hand side `−x²`. Then
//! `x0 = −c/2`, `y0 = −d/(2a)`, `z0 = −e/(2b)`, `A² = x0² + a·y0² + b·z0² − f`, `B = A/√a`,
//! `C = A/√b`, and the calibration is `A = diag(ref/A, ref/B, ref/C)`, `b = (x0, y0, z0)`.
//!
//! The samples are first centred on their mean and scaled to unit RMS radius so the design matrix
//! is well conditioned; the model is invariant under this change of variables, and the centre and
//! radii are mapped back afterwards.

use std::cmp::Ordering;

use nalgebra::DMatrix;

use super::coverage::{guard_fit, CoverageHint, EllipsoidModel};
use super::li::li_start;
use super::linalg::least_squares;
use super::loo::leave_one_out_rms;
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
    fit.loo_rms = leave_one_out_rms(poses, reference, |rest| {
        let m: Vec<Vec3> = rest.iter().map(|p| p.mean).collect();
        solve(&m, reference).map(|(cal, _)| cal)
    });
    Ok(fit)
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
    let ls = least_squares(&x, &y, "axis-aligned ellipsoid")?;
    let v = &ls.solution;
    let (a, b, c, d, e, f) = (v[0], v[1], v[2], v[3], v[4], v[5]);
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
    let centre = Vec3::new(-c / 2.0, -d / (2.0 * a), -e / (2.0 * b));
    let rx_sq = centre.x * centre.x + a * centre.y * centre.y + b * centre.z * centre.z - f;
    if rx_sq.partial_cmp(&0.0) != Some(Ordering::Greater) {
        return Err(not_closed());
    }
    let rx = rx_sq.sqrt();
    let radii = Vec3::new(rx, rx / a.sqrt(), rx / b.sqrt()) * spread;
    let cal = Calibration {
        a: Mat3::from_diagonal(&radii.map(|r| reference / r)),
        b: mean + centre * spread,
    };
    if !cal.a.iter().chain(cal.b.iter()).all(|v| v.is_finite()) {
        return Err(not_closed());
    }
    Ok((cal, ls.condition_number))
}
