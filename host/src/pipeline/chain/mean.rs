//! The mean of models the data cannot tell apart: the calibration whose output is the mean of
//! the members' outputs, `A(x − b) = (1/k)·Σ Aᵢ(x − bᵢ)` for every `x`, so `A = mean Aᵢ` and
//! `b = A⁻¹·mean(Aᵢbᵢ)`. Diagonal members give a diagonal mean, so the mean of two 6-unknown
//! axis-aligned models is again one.

use crate::fit::{Calibration, CalibrationStd, Fit, FitError, Mat3, Method, Pose, Vec3};

/// The calibration whose output is the mean of the outputs of `members`.
///
/// Refused when `members` is empty or their mean gain matrix is singular (members that turn
/// the data in opposite senses, which models fitted to the same poses never do).
pub fn mean_calibration(members: &[Calibration]) -> Result<Calibration, FitError> {
    if members.is_empty() {
        return Err(FitError::Underdetermined(
            "no calibrations to take the mean of".into(),
        ));
    }
    let k = members.len() as f64;
    let a = members.iter().fold(Mat3::zeros(), |sum, c| sum + c.a) / k;
    let ab = members.iter().fold(Vec3::zeros(), |sum, c| sum + c.a * c.b) / k;
    let a_inv = a.try_inverse().ok_or_else(|| {
        FitError::Underdetermined(
            "the models to be averaged disagree so much that their mean gain is singular; \
             choose one with --method"
                .into(),
        )
    })?;
    Ok(Calibration { a, b: a_inv * ab })
}

/// The fit of `method` whose calibration is the mean of `members`, with its residuals on the
/// pose means, and `loo_rms` from the caller's held-out refits. It carries no covariance matrix:
/// the members' estimates are correlated (fitted to the same poses) by an amount not modelled.
/// Its standard deviations are the mean of the members' ([`mean_std`]), an upper bound whatever
/// that correlation.
pub fn mean_fit(
    method: Method,
    members: &[&Fit],
    poses: &[Pose],
    reference: f64,
    loo_rms: Option<f64>,
) -> Result<Fit, FitError> {
    let cals: Vec<Calibration> = members.iter().map(|f| f.cal).collect();
    let cal = mean_calibration(&cals)?;
    let means: Vec<Vec3> = poses.iter().map(|p| p.mean).collect();
    let condition_number = members
        .iter()
        .map(|f| f.condition_number)
        .fold(1.0, f64::max);
    let mut fit = Fit::closed_form(method, cal, &means, reference, condition_number);
    fit.loo_rms = loo_rms;
    fit.std = mean_std(members);
    Ok(fit)
}

/// Standard deviations of the mean of `members`' parameters: for a mean of `k` estimates,
/// `Var(mean) = (1/k²)·Σᵢⱼ Cov(i, j) ≤ (1/k²)·(Σᵢ σᵢ)²` (Cauchy–Schwarz, `Cov ≤ σᵢσⱼ`), so the
/// mean of the members' σ bounds it, entry by entry (the offset's to first order, `A` near the
/// identity). `None` when a member has none.
fn mean_std(members: &[&Fit]) -> Option<CalibrationStd> {
    let stds: Vec<&CalibrationStd> = members
        .iter()
        .map(|f| f.std.as_ref())
        .collect::<Option<_>>()?;
    let k = stds.len() as f64;
    (k > 0.0).then(|| CalibrationStd {
        a: stds.iter().fold(Mat3::zeros(), |sum, s| sum + s.a) / k,
        b: stds.iter().fold(Vec3::zeros(), |sum, s| sum + s.b) / k,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_mean_calibration_outputs_the_mean_of_the_members_outputs() {
        let first = Calibration {
            a: Mat3::new(1.02, 0.01, 0.0, 0.0, 0.97, 0.02, 0.0, 0.0, 1.01),
            b: Vec3::new(0.1, -0.2, 0.3),
        };
        let second = Calibration {
            a: Mat3::from_diagonal(&Vec3::new(0.99, 1.03, 0.98)),
            b: Vec3::new(-0.1, 0.05, 0.2),
        };
        let mean = mean_calibration(&[first, second]).expect("invertible");
        for x in [Vec3::new(9.8, 0.1, -0.3), Vec3::new(-1.0, 5.0, 8.0)] {
            let expected = (first.apply(&x) + second.apply(&x)) / 2.0;
            // Exact up to rounding of one 3×3 inverse.
            assert!((mean.apply(&x) - expected).norm() < 1e-12);
        }
    }

    #[test]
    fn diagonal_members_give_a_diagonal_mean() {
        let first = Calibration {
            a: Mat3::from_diagonal(&Vec3::new(1.02, 0.97, 1.01)),
            b: Vec3::new(0.1, -0.2, 0.3),
        };
        let second = Calibration {
            a: Mat3::from_diagonal(&Vec3::new(1.00, 0.99, 1.03)),
            b: Vec3::new(0.12, -0.1, 0.25),
        };
        let mean = mean_calibration(&[first, second]).expect("invertible");
        let off_diagonal = mean.a - Mat3::from_diagonal(&mean.a.diagonal());
        assert!(off_diagonal.norm() < 1e-15);
    }

    #[test]
    fn opposite_gains_are_refused_with_a_reason() {
        let first = Calibration {
            a: Mat3::identity(),
            b: Vec3::zeros(),
        };
        let second = Calibration {
            a: -Mat3::identity(),
            b: Vec3::zeros(),
        };
        let message = mean_calibration(&[first, second])
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(message.contains("singular"), "{message}");
        assert!(mean_calibration(&[]).is_err());
    }
}
