//! Leave-one-pose-out cross-validation of static-pose fits: each pose is predicted by a fit made
//! without it, and the held-out norm residual `(|A(x−b)| − ref)/ref` is summarised as an RMS.
//! This measures how well a calibration generalises to orientations it has not seen.

use super::{Calibration, FitError, Pose};

/// RMS of the held-out relative norm residual `(|A(x_i − b_{−i})| − ref)/ref` over all poses,
/// where `(A, b)_{−i}` is `fit` applied to every pose except `i`.
///
/// Returns `None` when there are fewer than two poses, the reference is not positive, or any
/// refit is refused (then some pose cannot be predicted and an RMS over the rest would flatter
/// the method).
pub fn leave_one_out_rms(
    poses: &[Pose],
    reference: f64,
    fit: impl Fn(&[Pose]) -> Result<Calibration, FitError>,
) -> Option<f64> {
    leave_one_out_rms_indexed(poses, reference, |_, rest| fit(rest))
}

/// As [`leave_one_out_rms`], but `fit` also receives the index of the held-out pose (for
/// methods with per-pose side information, such as expected directions).
pub fn leave_one_out_rms_indexed(
    poses: &[Pose],
    reference: f64,
    fit: impl Fn(usize, &[Pose]) -> Result<Calibration, FitError>,
) -> Option<f64> {
    let errors = leave_one_out_errors(poses, reference, fit)?
        .into_iter()
        .collect::<Option<Vec<f64>>>()?;
    Some((errors.iter().map(|r| r * r).sum::<f64>() / errors.len() as f64).sqrt())
}

/// The held-out relative norm residual of every pose, in pose order, each predicted by `fit`
/// on the other poses (`fit` receives the held-out index); `None` for a pose whose refit was
/// refused or whose residual is not finite. `None` overall when there are fewer than two poses
/// or the reference is not positive.
pub fn leave_one_out_errors(
    poses: &[Pose],
    reference: f64,
    fit: impl Fn(usize, &[Pose]) -> Result<Calibration, FitError>,
) -> Option<Vec<Option<f64>>> {
    if poses.len() < 2 || reference.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let errors = poses
        .iter()
        .enumerate()
        .map(|(i, held_out)| {
            let rest: Vec<Pose> = poses
                .iter()
                .enumerate()
                .filter(|&(j, _)| j != i)
                .map(|(_, p)| p.clone())
                .collect();
            let cal = fit(i, &rest).ok()?;
            let r = (cal.apply(&held_out.mean).norm() - reference) / reference;
            r.is_finite().then_some(r)
        })
        .collect();
    Some(errors)
}
