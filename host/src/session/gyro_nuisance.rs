//! Uncertainty the gyroscope's scale fit inherits from what it takes as known: the
//! accelerometer's calibration (the gravity directions at the moves' ends, and the frame `A` is
//! written in) and the gyroscope's bias. An error in either is common to every move, so the
//! moves' residual scatter ([`crate::fit::gyro_scale::fit_gyro_scale`]) does not show it.
//!
//! First-order propagation (GUM, JCGM 100:2008 §5.1.2): with `Σ_n = Σ λₖ vₖvₖᵀ` the nuisance
//! covariance, the fit is repeated with the nuisance moved by `√λₖ·vₖ` (one σ along each
//! principal axis), and each change `Δₖ` of the nine entries of `A` adds `ΔₖΔₖᵀ` to their
//! covariance. The accelerometer's and the bias's errors are independent of the moves' noise,
//! so the sum is added to the fit's own covariance.

use nalgebra::{DMatrix, DVector, SymmetricEigen};

use super::gyro_moves::motions_of;
use crate::device::UnitSample;
use crate::fit::covariance::ParamEntry;
use crate::fit::gyro_scale::fit_gyro_scale;
use crate::fit::{Calibration, Fit, Mat3, Vec3};

/// The inputs the gyroscope's scale fit takes as known, with their uncertainty.
pub struct Nuisance<'a> {
    /// The accelerometer's fit (calibration, covariance and parameter names).
    pub accel: &'a Fit,
    /// Gyroscope bias, rad/s.
    pub bias: Vec3,
    /// One-sigma of the bias per axis, rad/s.
    pub bias_sigma: Vec3,
    /// White noise of one gyroscope sample, rad/s (`None`: estimated from each move's ends).
    pub rate_noise: Option<f64>,
}

/// The entry of a calibration a parameter name (`"A12"`, `"b3"`) stands for.
fn entry_named(name: &str) -> Option<ParamEntry> {
    let a = (0..3).flat_map(|r| (0..3).map(move |c| ParamEntry::A(r, c)));
    a.chain((0..3).map(ParamEntry::B))
        .find(|e| e.name() == name)
}

/// `cal` with its parameters (named by `names`) moved by `step`.
fn moved(cal: &Calibration, names: &[String], step: &DVector<f64>) -> Option<Calibration> {
    let mut out = *cal;
    for (name, delta) in names.iter().zip(step.iter()) {
        match entry_named(name)? {
            ParamEntry::A(r, c) => out.a[(r, c)] += delta,
            ParamEntry::B(i) => out.b[i] += delta,
        }
    }
    Some(out)
}

/// The nine entries of `a`, row-major (the scale fit's parameter order).
pub(super) fn entries(a: &Mat3) -> DVector<f64> {
    DVector::from_row_slice(a.transpose().as_slice())
}

/// `fit`'s calibration moved one σ along each principal axis of its covariance (`√λₖ·vₖ`);
/// `None` without a covariance or with a parameter name that is not an entry.
pub(super) fn principal_steps(fit: &Fit) -> Option<Vec<Calibration>> {
    let eigen = SymmetricEigen::new(fit.covariance.as_ref()?.clone());
    let mut steps = Vec::new();
    for (k, &lambda) in eigen.eigenvalues.iter().enumerate() {
        if lambda <= 0.0 {
            continue;
        }
        let step = eigen.eigenvectors.column(k) * lambda.sqrt();
        steps.push(moved(&fit.cal, &fit.param_names, &step.into_owned())?);
    }
    Some(steps)
}

/// Covariance (9×9, row-major entries of `A`) the fit inherits from `nuisance`, for the fit
/// `a_fit` of `moves`; `None` when the accelerometer has no covariance or a refit fails.
pub fn inherited_covariance(
    moves: &[Vec<UnitSample>],
    a_fit: &Mat3,
    nuisance: &Nuisance<'_>,
    still_rate: f64,
) -> Option<DMatrix<f64>> {
    let accel = &nuisance.accel.cal;
    let refit = |accel: &Calibration, bias: &Vec3| -> Option<(usize, DVector<f64>)> {
        let motions = motions_of(moves, accel, a_fit, bias, still_rate, nuisance.rate_noise);
        let fit = fit_gyro_scale(&motions, Some(a_fit)).ok()?;
        Some((motions.len(), entries(&fit.cal.a)))
    };
    // The reference is refitted from the same start, so only the nuisance step differs.
    let (used, base) = refit(accel, &nuisance.bias)?;
    let mut steps: Vec<(Calibration, Vec3)> = principal_steps(nuisance.accel)?
        .into_iter()
        .map(|accel| (accel, nuisance.bias))
        .collect();
    for i in 0..3 {
        steps.push((*accel, nuisance.bias + Vec3::ith(i, nuisance.bias_sigma[i])));
    }
    let mut cov = DMatrix::zeros(9, 9);
    for (accel_step, bias_step) in &steps {
        let (count, entries) = refit(accel_step, bias_step)?;
        // A one-σ step that changes which moves are usable measures the selection, not the
        // sensitivity; such a step is left out (it happens only for moves at the edge of use).
        if count != used {
            continue;
        }
        let delta = entries - &base;
        cov += &delta * delta.transpose();
    }
    Some(cov)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parameter_names_map_back_to_their_entries() {
        assert_eq!(entry_named("A23"), Some(ParamEntry::A(1, 2)));
        assert_eq!(entry_named("b1"), Some(ParamEntry::B(0)));
        assert_eq!(entry_named("c1"), None);
    }

    #[test]
    fn a_step_moves_only_the_named_entries() {
        let names = vec!["A12".to_string(), "b3".to_string()];
        let cal = moved(
            &Calibration::identity(),
            &names,
            &DVector::from_vec(vec![0.01, -0.5]),
        )
        .expect("known names");
        assert_eq!(cal.a[(0, 1)], 0.01);
        assert_eq!(cal.a[(1, 0)], 0.0);
        assert_eq!(cal.b[2], -0.5);
    }
}
