//! The gyroscope rotations between consecutive still holds of a recording, as plain
//! [`GyroMotion`]s for the gyroscope-scale fit (Tedaldi et al. 2014, section IV-B;
//! [`crate::fit::gyro_scale`]), and that fit run on a recording.

use super::intervals::StillReport;
use crate::fit::gyro_bias::fit_gyro_bias;
use crate::fit::gyro_scale::{fit_gyro_scale, stamp_slope_s, GyroMotion};
use crate::fit::{Calibration, CalibrationStd, Fit, FitError, Vec3};
use crate::recording::{Recording, Sensor};

/// Still time (seconds) kept on each side of a motion: the hold boundaries come from windowed
/// variance and may cut a little into the motion, while a second of rest adds only noise.
const REST_MARGIN_S: f64 = 1.0;

/// The motions between consecutive still intervals of a recording: gravity before and after from
/// the holds' accelerometer means through `accel` (a calibrated accelerometer), and the gyroscope
/// rows from one second before the end of a hold to one second after the start of the next,
/// bias-corrected by `bias` (data units) and converted to rad/s by `unit_scale`.
pub fn motions_between_holds(
    recording: &Recording,
    still: &StillReport,
    accel: &Calibration,
    bias: &Vec3,
    unit_scale: f64,
) -> Result<Vec<GyroMotion>, FitError> {
    let (Some(gyro), Some(_)) = (
        recording.samples(Sensor::Gyro),
        recording.samples(Sensor::Accel),
    ) else {
        return Err(FitError::Underdetermined(
            "the gyroscope scale needs both accelerometer and gyroscope columns".into(),
        ));
    };
    if recording.time_is_index {
        return Err(FitError::Underdetermined(
            "the recording has no time column; give the sample rate so the rotation can be integrated".into(),
        ));
    }
    let time = &recording.time;
    let mut motions = Vec::new();
    for pair in still.intervals.windows(2) {
        let (hold, next) = (&pair[0], &pair[1]);
        let (Some(before), Some(after)) = (hold.accel.as_ref(), next.accel.as_ref()) else {
            continue;
        };
        let first = (hold.start..hold.end)
            .find(|&i| {
                time.get(i)
                    .is_some_and(|t| *t >= hold.t_end - REST_MARGIN_S)
            })
            .unwrap_or(hold.start);
        let last = (next.start..next.end)
            .take_while(|&i| {
                time.get(i)
                    .is_some_and(|t| *t <= next.t_start + REST_MARGIN_S)
            })
            .last()
            .unwrap_or(next.start);
        let (Some(rows), Some(times)) = (gyro.get(first..=last), time.get(first..=last)) else {
            continue;
        };
        // Evenly spaced samples are assumed; the slope of the stamps keeps the jitter of the two
        // ends out of the step. A file's stamps may repeat or come in bursts (taken on a host),
        // so no step is refused here; only stamps that never advance give no step.
        let Some(dt) = stamp_slope_s(times.iter().copied()) else {
            continue;
        };
        motions.push(GyroMotion {
            gravity_before: accel.apply(&before.mean),
            gravity_after: accel.apply(&after.mean),
            rates: rows.iter().map(|w| (w - bias) * unit_scale).collect(),
            dt,
            angle_sigma: None,
        });
    }
    Ok(motions)
}

/// The gyroscope calibration of a recording by Tedaldi's method: bias from the still poses
/// (seed 000 eq. 9), then scale and misalignment from the motions between them
/// ([`fit_gyro_scale`]). The result maps the file's units to rad/s: `A = A_fit·unit_scale`,
/// `b` = the bias in the file's units, with `std` scaled alike; residuals are angle errors in
/// radians per motion.
pub fn fit_gyro_scale_recording(
    recording: &Recording,
    still: &StillReport,
    accel: &Calibration,
    unit_scale: f64,
) -> Result<Fit, FitError> {
    let bias_fit = fit_gyro_bias(&still.poses(Sensor::Gyro), unit_scale)?;
    let motions = motions_between_holds(recording, still, accel, &bias_fit.cal.b, unit_scale)?;
    let mut fit = fit_gyro_scale(&motions, None)?;
    fit.cal = Calibration {
        a: fit.cal.a * unit_scale,
        b: bias_fit.cal.b,
    };
    fit.std = fit.std.map(|s| CalibrationStd {
        a: s.a * unit_scale,
        b: bias_fit.std.map_or(Vec3::zeros(), |bs| bs.b),
    });
    Ok(fit)
}
