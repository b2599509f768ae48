//! The gyroscope: bias from the still poses (seed 000 eq. 9) by default, or Tedaldi's scale and
//! misalignment from the motions between holds (Tedaldi, Pretto & Menegatti 2014), whose gravity
//! directions come from the default accelerometer chain.

use crate::fit::{Fit, FitError, Method, Pose, Vec3};
use crate::recording::{Recording, Sensor};
use crate::stats::batch_means::excess_wander;
use crate::still::StillReport;

use super::chain::default_accel_chain;
use super::methods::fit_gyro;

/// The unit conversion of the gyroscope data to rad/s, and the unit the fit's output is in.
pub fn gyro_unit_scale(recording: &Recording, gyro_scale: Option<f64>) -> (f64, &'static str) {
    match (recording.units.to_si(Sensor::Gyro), gyro_scale) {
        (Some(s), _) | (None, Some(s)) => (s, "rad/s"),
        (None, None) => (1.0, "counts"),
    }
}

/// A note when a rad/s-per-count scale was given for a gyroscope whose data are declared in a
/// physical unit (the unit's own scale is used; the given one is not).
pub fn moot_gyro_scale(recording: &Recording, gyro_scale: Option<f64>) -> Option<String> {
    let given = gyro_scale?;
    recording.units.to_si(Sensor::Gyro).map(|_| {
        format!(
            "--gyro-scale {given} was not used: the data are declared in {}, whose scale to \
             rad/s is known; it applies only with --gyro-unit counts",
            recording.units.symbol(Sensor::Gyro)
        )
    })
}

/// Fit the gyroscope of `recording` with `method` (bias or scale); `scale` converts its data to
/// rad/s and `gravity` (m/s²) is the accelerometer's reference for the scale fit.
pub fn fit_gyroscope(
    method: Method,
    recording: &Recording,
    still: &StillReport,
    gravity: f64,
    scale: f64,
) -> Result<Fit, FitError> {
    match method {
        Method::GyroScale => {
            let accel = default_accel_chain(&still.poses(Sensor::Accel), gravity)?;
            crate::still::motions::fit_gyro_scale_recording(recording, still, &accel.fit.cal, scale)
        }
        m => fit_gyro(m, &bias_poses(recording, still), scale),
    }
}

/// The gyroscope's still poses with a variance of the mean that allows for the bias wandering
/// within a hold ([`excess_wander`]): over a long hold a MEMS gyroscope's bias moves by more
/// than white noise explains, and `σ²/n` would understate the bias's uncertainty many times.
/// Each pose's `var` is scaled so that `var/n` is that variance of the mean.
fn bias_poses(recording: &Recording, still: &StillReport) -> Vec<Pose> {
    let all = recording.samples(Sensor::Gyro).unwrap_or(&[]);
    still
        .intervals
        .iter()
        .filter_map(|interval| {
            let mut pose = interval.pose(Sensor::Gyro)?.clone();
            let samples: Vec<Vec3> = interval
                .rows(recording)
                .into_iter()
                .filter_map(|row| all.get(row).copied())
                .collect();
            pose.var = excess_wander(&samples, pose.var_of_mean()) * pose.n.max(1) as f64;
            Some(pose)
        })
        .collect()
}
