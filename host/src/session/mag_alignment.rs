//! The magnetometer's rotation into the accelerometer frame in a guided session, from the
//! poses' calibrated gravity and field ([`crate::fit::alignment`], dot-product invariance),
//! with poses whose field disagrees with the calibration screened out first.
//!
//! The board averages each pose itself, so a spike inside a hold (one corrupted magnetometer
//! read of 10⁵ µT among a thousand) reaches the host inside the pose's mean, where it moves the
//! field by ~100 µT and turns the alignment by tens of degrees. The magnetometer's calibration
//! comes from the tumble, not from the poses, so every pose's calibrated magnitude `|mᵢ|`
//! should equal the field `H` to within the calibration's own error. Poses whose `|mᵢ| − H` is
//! beyond the median/MAD Bonferroni bound of [`crate::stats::robust`] over the poses (scale
//! floored at the fit's RMS residual, the size of a disagreement the calibration itself
//! explains) are left out of the alignment, and each is named.

use crate::fit::alignment::{fit_alignment, Alignment};
use crate::fit::{Fit, Vec3};
use crate::stats::robust::screen_scalars;

/// The alignment, or why there is none, and one sentence per pose left out of it.
#[derive(Debug, Clone)]
pub struct SessionAlignment {
    /// The rotation (magnetometer frame → accelerometer frame), or the reason it failed.
    pub outcome: Result<Alignment, String>,
    /// One sentence per pose whose field was left out.
    pub notes: Vec<String>,
}

/// Align the magnetometer fit `mag` (reference `field` µT) to the accelerometer from the
/// poses: `gravity[i]` is pose `i`'s calibrated accelerometer mean, `raw_field[i]` its raw
/// magnetometer mean, `names[i]` its name.
pub fn align_session_mag(
    gravity: &[Vec3],
    raw_field: &[Vec3],
    names: &[&str],
    mag: &Fit,
    field: f64,
) -> SessionAlignment {
    let fields: Vec<Vec3> = raw_field.iter().map(|m| mag.cal.apply(m)).collect();
    let deviations: Vec<f64> = fields.iter().map(|m| m.norm() - field).collect();
    let screening = screen_scalars(&deviations, mag.rms * field);
    let notes = names
        .iter()
        .zip(&deviations)
        .zip(&screening.keep)
        .filter(|(_, keep)| !**keep)
        .map(|((name, deviation), _)| {
            format!(
                "the magnetometer's mean in position {} reads {:.1} µT against the {field:.1} µT \
                 field ({deviation:+.1} µT, beyond the {:.1}-σ bound over the positions), so a \
                 spike or a magnet disturbed that hold; it is left out of the alignment to the \
                 accelerometer",
                name,
                field + deviation,
                screening.bound_sigmas
            )
        })
        .collect();
    let outcome = fit_alignment(&screening.kept(gravity), &screening.kept(&fields))
        .map_err(|e| e.to_string());
    SessionAlignment { outcome, notes }
}
