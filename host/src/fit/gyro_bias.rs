//! Gyroscope bias from still data (seed 000 eq. 9, `b_ω = ω̄`; seed 004 §1.2.2): the bias is the
//! mean reading while the board is still. With several still poses the pose means are combined
//! with inverse-variance weights per axis; `A = scale·I` only converts the file's unit to rad/s
//! (scale and misalignment need rotations between poses and are fitted elsewhere).

use nalgebra::DMatrix;

use super::linalg::rms;
use super::uncertainty::{noise_scale, NoiseLevel, Z_95};
use super::validate::check_finite_poses;
use super::{Calibration, CalibrationStd, Fit, FitError, Mat3, Method, Pose, Vec3};

/// Fit the gyroscope bias from still poses; `scale` converts the data's unit to rad/s.
///
/// `b` is the per-axis inverse-variance-weighted mean of the pose means (equal weights when a
/// pose reports no variance); its covariance is `1/Σw` per axis. The residual of each pose is
/// `|A(mean_i − b)|` in rad/s, and `loo_rms` is the same with `b` fitted without pose `i`.
pub fn fit_gyro_bias(poses: &[Pose], scale: f64) -> Result<Fit, FitError> {
    if !scale.is_finite() {
        return Err(FitError::NonFinite("gyroscope unit scale".into()));
    }
    if scale <= 0.0 {
        return Err(FitError::Underdetermined(format!(
            "a unit scale of {scale} cannot convert to rad/s; pass a positive factor \
             (e.g. π/180 for °/s)"
        )));
    }
    if poses.is_empty() {
        return Err(FitError::Underdetermined(
            "no still poses were given; record the board still for a few seconds".into(),
        ));
    }
    check_finite_poses(poses)?;

    let all: Vec<usize> = (0..poses.len()).collect();
    let (b, var_b) = weighted_mean(poses, &all);
    let a = Mat3::identity() * scale;
    let cal = Calibration { a, b };
    let residuals: Vec<f64> = poses.iter().map(|p| cal.apply(&p.mean).norm()).collect();

    let loo_rms = (poses.len() >= 2).then(|| {
        let held_out: Vec<f64> = (0..poses.len())
            .map(|i| {
                let rest: Vec<usize> = (0..poses.len()).filter(|&j| j != i).collect();
                let (b_rest, _) = weighted_mean(poses, &rest);
                (a * (poses[i].mean - b_rest)).norm()
            })
            .collect();
        rms(&held_out)
    });

    // One policy (`uncertainty`): per axis, χ² of the pose means about `b` against their
    // variances; the Birge ratio inflates `1/Σw` when the poses scatter more than their noise
    // (correlated samples, drift between holds).
    let scales: Vec<_> = (0..3)
        .map(|axis| {
            let chi_square: f64 = poses
                .iter()
                .map(|p| (p.mean[axis] - b[axis]).powi(2) / p.var_of_mean()[axis])
                .sum();
            noise_scale(chi_square, poses.len(), 1, NoiseLevel::Known)
        })
        .collect();
    let var_b = Vec3::from_fn(|axis, _| {
        scales[axis].map_or(var_b[axis], |s| var_b[axis] * s.variance_factor)
    });
    // One factor for the three axes: the widest, so that every axis's interval holds.
    let coverage_factor = scales
        .iter()
        .flatten()
        .map(|s| s.coverage_factor)
        .fold(Z_95, f64::max);
    // Zero variance everywhere means the data carries no noise estimate: report no covariance
    // rather than a covariance of zero.
    let (covariance, std) = if var_b.iter().all(|v| v.is_finite() && *v > 0.0) {
        let cov = DMatrix::from_diagonal(&nalgebra::DVector::from_column_slice(var_b.as_slice()));
        let std = CalibrationStd {
            a: Mat3::zeros(),
            b: var_b.map(f64::sqrt),
        };
        (Some(cov), Some(std))
    } else {
        (None, None)
    };

    Ok(Fit {
        method: Method::GyroBias,
        cal,
        rms: rms(&residuals),
        residuals,
        loo_rms,
        covariance,
        param_names: vec!["b1".into(), "b2".into(), "b3".into()],
        std,
        condition_number: 1.0,
        iterations: 0,
        termination: None,
        coverage_factor,
        reference: 1.0,
    })
}

/// Inverse-variance-weighted mean of the selected pose means per axis, and its variance.
/// Falls back to sample-count weights on an axis where any selected pose reports zero variance.
fn weighted_mean(poses: &[Pose], selected: &[usize]) -> (Vec3, Vec3) {
    let mut mean = Vec3::zeros();
    let mut var = Vec3::zeros();
    for axis in 0..3 {
        let vars: Vec<f64> = selected
            .iter()
            .map(|&i| poses[i].var_of_mean()[axis])
            .collect();
        if vars.iter().all(|v| *v > 0.0) {
            let w_sum: f64 = vars.iter().map(|v| 1.0 / v).sum();
            mean[axis] = selected
                .iter()
                .zip(&vars)
                .map(|(&i, v)| poses[i].mean[axis] / v)
                .sum::<f64>()
                / w_sum;
            var[axis] = 1.0 / w_sum;
        } else {
            let n_sum: f64 = selected.iter().map(|&i| poses[i].n.max(1) as f64).sum();
            mean[axis] = selected
                .iter()
                .map(|&i| poses[i].mean[axis] * poses[i].n.max(1) as f64)
                .sum::<f64>()
                / n_sum;
            var[axis] = 0.0;
        }
    }
    (mean, var)
}
