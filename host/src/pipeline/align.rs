//! Magnetometer → accelerometer frame: the dot-product-invariance alignment of
//! [`crate::fit::alignment`] (gravity and field keep the same angle, the dip, in every still
//! pose) fed with the calibrated gravity and field of the holds that have both sensors.

use crate::fit::alignment::{fit_alignment, Alignment};
use crate::fit::{Calibration, FitError, Vec3};
use crate::still::StillReport;

/// The rotation of the calibrated magnetometer into the calibrated accelerometer's frame, from
/// the still holds of `still` that have both sensors.
pub fn align_mag(
    still: &StillReport,
    accel: &Calibration,
    mag: &Calibration,
) -> Result<Alignment, FitError> {
    let (gravity, field): (Vec<Vec3>, Vec<Vec3>) = still
        .intervals
        .iter()
        .filter_map(|i| {
            Some((
                accel.apply(&i.accel.as_ref()?.mean),
                mag.apply(&i.mag.as_ref()?.mean),
            ))
        })
        .unzip();
    fit_alignment(&gravity, &field)
}
