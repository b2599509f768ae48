//! The moves between holds with the magnetic field as a second reference direction, for the
//! joint gyroscope fit ([`crate::fit::gyro_joint::fit_gyro_joint`]).
//!
//! The board streams the magnetometer with the gyroscope, so each move's still ends give the
//! field direction as well as gravity's. The field is read with the session's magnetometer
//! calibration turned into the accelerometer frame (the fit of all the turning samples and the
//! dip-invariance alignment, [`super::solve`]), and averaged over the same sway-corrected still
//! stretches as gravity ([`super::gyro_moves`]). A move's field is left out when an end's mean
//! magnitude is off the reference field by more than twice the `|m|` budget (something magnetic
//! near that hold) or the magnetometer did not change its reading within an end (no
//! magnetometer).
//!
//! The uncertainty inherited from the magnetometer's calibration is propagated like the
//! accelerometer's and the bias's ([`super::gyro_nuisance`]): refits with its parameters moved
//! one σ along each principal axis. Its alignment needs none: the fit finds the field frame's
//! rotation itself.

use nalgebra::DMatrix;

use super::gyro_moves::{direction_variance, gravity_motion, move_ends, MoveEnds};
use super::gyro_nuisance::{entries, principal_steps, Nuisance};
use crate::device::UnitSample;
use crate::fit::alignment::Alignment;
use crate::fit::gyro_joint::{fit_gyro_joint, FieldEnds, JointFit, JointMotion};
use crate::fit::{Calibration, Fit, FitError, Mat3, Vec3};

/// The magnetometer as the session fitted it.
pub struct FieldReference<'a> {
    /// The magnetometer's fit in its own frame (calibration, covariance, parameter names).
    pub mag: &'a Fit,
    /// The rotation of its frame into the accelerometer's.
    pub alignment: &'a Alignment,
    /// The reference field magnitude, µT.
    pub field_ut: f64,
    /// The `|m|` budget, % of the field: an end whose magnitude is off by more than twice it
    /// is disturbed.
    pub mag_budget_pct: f64,
}

impl FieldReference<'_> {
    fn calibration(&self, mag: &Calibration) -> Calibration {
        self.alignment.apply_to(mag)
    }
}

/// Number of changes of the raw magnetometer reading within `samples` plus one: the independent
/// readings among them when the magnetometer converts slower than the stream is sampled (a
/// reading repeats until the next conversion).
fn distinct_readings(samples: &[UnitSample]) -> usize {
    1 + samples.windows(2).filter(|w| w[0].mag != w[1].mag).count()
}

/// The field at a move's still ends, read with `mag` (accelerometer frame); `None` when an end
/// has fewer than two distinct readings or is off the reference magnitude.
fn field_ends(
    ends: &MoveEnds,
    samples: &[UnitSample],
    mag: &Calibration,
    reference: &FieldReference<'_>,
    rate_noise: Option<f64>,
) -> Option<FieldEnds> {
    let (start, end) = ends.turn();
    let (head, tail) = ends.turned_ends(|j| mag.apply(&Vec3::from(samples[j].mag)));
    let limit = 2.0 * reference.mag_budget_pct / 100.0;
    let mut variance = ends.gyro_angle_var(ends.rate_noise(rate_noise));
    for (vectors, raw) in [(&head, &samples[..=start]), (&tail, &samples[end..])] {
        let distinct = distinct_readings(raw);
        if distinct < 2 {
            return None;
        }
        let mean = vectors.iter().sum::<Vec3>() / vectors.len() as f64;
        if (mean.norm() / reference.field_ut - 1.0).abs() > limit {
            return None;
        }
        // The scatter per sample over the independent readings, not the repeated samples.
        variance += direction_variance(vectors)? * vectors.len() as f64 / distinct as f64;
    }
    let mean = |v: &[Vec3]| v.iter().sum::<Vec3>() / v.len() as f64;
    Some(FieldEnds {
        before: mean(&head),
        after: mean(&tail),
        sigma: variance.sqrt(),
    })
}

/// Every usable move with its gravity and (when usable) field directions; `mag` is the
/// magnetometer's calibration in the accelerometer frame, `a` the current gyroscope matrix.
#[allow(clippy::too_many_arguments)]
pub fn joint_motions_of(
    moves: &[Vec<UnitSample>],
    accel: &Calibration,
    mag: &Calibration,
    reference: &FieldReference<'_>,
    a: &Mat3,
    bias: &Vec3,
    still_rate: f64,
    rate_noise: Option<f64>,
) -> Vec<JointMotion> {
    moves
        .iter()
        .filter_map(|samples| {
            let ends = move_ends(samples, a, bias, still_rate)?;
            let gravity = gravity_motion(&ends, samples, accel, rate_noise)?;
            let field = field_ends(&ends, samples, mag, reference, rate_noise);
            Some(JointMotion { gravity, field })
        })
        .collect()
}

/// Seconds of stream in the moves whose field was used.
pub fn field_seconds(motions: &[JointMotion]) -> f64 {
    motions
        .iter()
        .filter(|m| m.field.is_some())
        .map(|m| m.gravity.dt * (m.gravity.rates.len().saturating_sub(1)) as f64)
        .sum()
}

/// The joint fit of `moves`, twice (the second time with the still ends turned by the first
/// result, as [`super::gyro_fit`] does for gravity alone), with the covariance it inherits from
/// the accelerometer, the bias and the magnetometer added. Returns the fit and its motions.
pub fn fit_with_field(
    moves: &[Vec<UnitSample>],
    nuisance: &Nuisance<'_>,
    reference: &FieldReference<'_>,
    still_rate: f64,
) -> Result<(JointFit, Vec<JointMotion>), FitError> {
    let accel = &nuisance.accel.cal;
    let mag = reference.calibration(&reference.mag.cal);
    let noise = nuisance.rate_noise;
    let motions_for = |accel: &Calibration, mag: &Calibration, a: &Mat3, bias: &Vec3| {
        joint_motions_of(moves, accel, mag, reference, a, bias, still_rate, noise)
    };
    let first = motions_for(accel, &mag, &Mat3::identity(), &nuisance.bias);
    let rough = fit_gyro_joint(&first, None)?;
    let a_rough = rough.fit.cal.a;
    let motions = motions_for(accel, &mag, &a_rough, &nuisance.bias);
    let mut joint = fit_gyro_joint(&motions, Some(&a_rough))?;
    let a_fit = joint.fit.cal.a;

    // First-order propagation of the inputs taken as known (see `gyro_nuisance`).
    let refit = |accel: &Calibration, mag: &Calibration, bias: &Vec3| {
        let motions = motions_for(accel, mag, &a_fit, bias);
        let fit = fit_gyro_joint(&motions, Some(&a_fit)).ok()?;
        let used = motions.iter().filter(|m| m.field.is_some()).count();
        Some(((motions.len(), used), entries(&fit.fit.cal.a)))
    };
    let inherited = (|| {
        let (used, base) = refit(accel, &mag, &nuisance.bias)?;
        let mut steps: Vec<(Calibration, Calibration, Vec3)> = principal_steps(nuisance.accel)?
            .into_iter()
            .map(|accel_step| (accel_step, mag, nuisance.bias))
            .collect();
        for i in 0..3 {
            let bias = nuisance.bias + Vec3::ith(i, nuisance.bias_sigma[i]);
            steps.push((*accel, mag, bias));
        }
        for mag_step in principal_steps(reference.mag)? {
            steps.push((*accel, reference.calibration(&mag_step), nuisance.bias));
        }
        let mut cov = DMatrix::zeros(9, 9);
        for (accel_step, mag_step, bias_step) in &steps {
            let (count, entries) = refit(accel_step, mag_step, bias_step)?;
            // A step that changes which moves are used measures the selection, not the
            // sensitivity (see `gyro_nuisance`).
            if count != used {
                continue;
            }
            let delta = entries - &base;
            cov += &delta * delta.transpose();
        }
        Some(cov)
    })();
    if let (Some(own), Some(inherited)) = (joint.fit.covariance.as_mut(), inherited) {
        *own += inherited;
        joint.fit.std = Some(crate::fit::covariance::calibration_std(
            own,
            &crate::fit::covariance::FULL_MATRIX_LAYOUT,
        ));
    }
    Ok((joint, motions))
}
