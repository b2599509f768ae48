//! Min/max six-face calibration (seed 004 §1.2.1): with each face of the board up once, the axis
//! reads its maximum and minimum at ±ref, so per axis `b = (max + min)/2` and
//! `scale = ref / ((max − min)/2)`; `A = diag(scale)` (no cross-axis terms).

use nalgebra::DMatrix;

use super::linalg::rms;
use super::loo::leave_one_out_rms;
use super::validate::{check_finite_poses, check_reference, find_faces};
use super::{Calibration, CalibrationStd, Fit, FitError, Mat3, Method, Pose, Vec3};

/// Fit per-axis bias and scale from the six face poses.
///
/// The face poses are found by direction (see [`find_faces`]); the extremes of axis `k` are the
/// `k` readings of the `+k` and `−k` poses. Refused when a face is missing ("no pose with −Z up").
/// The covariance (order `A11 A22 A33 b1 b2 b3`) follows from the variance of the two pose means
/// used per axis.
pub fn fit_minmax(poses: &[Pose], reference: f64) -> Result<Fit, FitError> {
    let cal = minmax_calibration(poses, reference)?;
    let faces = find_faces(poses)?;

    let residuals: Vec<f64> = poses
        .iter()
        .map(|p| (cal.apply(&p.mean).norm() - reference) / reference)
        .collect();
    let loo_rms = leave_one_out_rms(poses, reference, |rest| minmax_calibration(rest, reference));

    // Per axis: b = (M + m)/2, s = 2r/(M − m); first-order propagation of the two means' variances.
    let mut cov = DMatrix::zeros(6, 6);
    let mut has_noise = true;
    for k in 0..3 {
        let (hi, lo) = (&poses[faces[2 * k]], &poses[faces[2 * k + 1]]);
        let (v_hi, v_lo) = (hi.var_of_mean()[k], lo.var_of_mean()[k]);
        has_noise &= v_hi > 0.0 || v_lo > 0.0;
        let d = hi.mean[k] - lo.mean[k];
        let ds = 2.0 * reference / (d * d);
        cov[(k, k)] = ds * ds * (v_hi + v_lo);
        cov[(k + 3, k + 3)] = 0.25 * (v_hi + v_lo);
        let cross = 0.5 * ds * (v_lo - v_hi);
        cov[(k, k + 3)] = cross;
        cov[(k + 3, k)] = cross;
    }
    let (covariance, std) = if has_noise {
        let std = CalibrationStd {
            a: Mat3::from_diagonal(
                &Vec3::new(cov[(0, 0)], cov[(1, 1)], cov[(2, 2)]).map(f64::sqrt),
            ),
            b: Vec3::new(cov[(3, 3)], cov[(4, 4)], cov[(5, 5)]).map(f64::sqrt),
        };
        (Some(cov), Some(std))
    } else {
        (None, None)
    };

    Ok(Fit {
        method: Method::MinMax,
        cal,
        rms: rms(&residuals),
        residuals,
        loo_rms,
        covariance,
        param_names: ["A11", "A22", "A33", "b1", "b2", "b3"]
            .map(String::from)
            .to_vec(),
        std,
        condition_number: 1.0,
        iterations: 0,
        termination: None,
        coverage_factor: crate::fit::uncertainty::Z_95,
        reference,
    })
}

/// The min/max calibration alone (no residuals or statistics).
pub fn minmax_calibration(poses: &[Pose], reference: f64) -> Result<Calibration, FitError> {
    check_reference(reference)?;
    check_finite_poses(poses)?;
    let faces = find_faces(poses)?;
    let mut scale = Vec3::zeros();
    let mut b = Vec3::zeros();
    for k in 0..3 {
        let hi = poses[faces[2 * k]].mean[k];
        let lo = poses[faces[2 * k + 1]].mean[k];
        let half_span = 0.5 * (hi - lo);
        if half_span.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            return Err(FitError::Underdetermined(format!(
                "axis {} reads no higher with its face up than down; check the pose labels",
                ["X", "Y", "Z"][k]
            )));
        }
        b[k] = 0.5 * (hi + lo);
        scale[k] = reference / half_span;
    }
    Ok(Calibration {
        a: Mat3::from_diagonal(&scale),
        b,
    })
}
