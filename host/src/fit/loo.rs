//! Leave-one-pose-out cross-validation of static-pose fits: each pose is predicted by a fit made
//! without it, and the held-out norm residual `(|A(x−b)| − ref)/ref` is summarised as an RMS.
//! This measures how well a calibration generalises to orientations it has not seen.
//!
//! The generic form refits once per pose. Methods whose fit can be updated for one removed pose
//! (min/max: only the six face poses matter; linear least squares: a rank-one downdate) pass
//! that update to [`held_out_rms`] and cost about one fit in all.

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
    rms_of_all(leave_one_out_errors(poses, reference, fit)?)
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
    held_out_errors(poses, reference, |i| fit(i, &without(poses, i)))
}

/// From this many poses a fit's held-out folds come from its fit on every pose (a closed form, a
/// rank-one downdate or a first-order update), not from one refit per pose. A first-order
/// update misses a relative `O((p/N)²)` of the held-out RMS for `p` unknowns (under 1 % for the
/// norm model's 9 at 100 poses), far below the standard error of that RMS itself (`≈ 1/√(2N)`,
/// 7 % at 100 poses), against which every comparison made with it is judged. Below this, refits
/// are cheap and exact, and each fold gets the coverage rule of its own fit.
pub const UPDATED_FOLDS_MIN_POSES: usize = 100;

/// Every item but the `i`-th, in order: the training set of fold `i`.
pub fn without<T: Clone>(items: &[T], i: usize) -> Vec<T> {
    items
        .iter()
        .enumerate()
        .filter(|&(j, _)| j != i)
        .map(|(_, item)| item.clone())
        .collect()
}

/// The RMS of [`leave_one_out_rms`] given, for each pose `i`, the calibration fitted without it
/// (`calibration_without(i)`): methods with a closed-form or rank-one update for removing one
/// pose use this directly instead of N refits.
pub fn held_out_rms(
    poses: &[Pose],
    reference: f64,
    calibration_without: impl FnMut(usize) -> Result<Calibration, FitError>,
) -> Option<f64> {
    rms_of_all(held_out_errors(poses, reference, calibration_without)?)
}

/// As [`leave_one_out_errors`], with the calibration without pose `i` given directly.
pub fn held_out_errors(
    poses: &[Pose],
    reference: f64,
    mut calibration_without: impl FnMut(usize) -> Result<Calibration, FitError>,
) -> Option<Vec<Option<f64>>> {
    if poses.len() < 2 || reference.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let errors = poses
        .iter()
        .enumerate()
        .map(|(i, held_out)| held_out_error(&calibration_without(i).ok()?, held_out, reference))
        .collect();
    Some(errors)
}

/// Fewest poses whose held-out refits [`held_out_errors_threaded`] splits over two threads:
/// below, a thread's start costs more than the refits it would take over.
pub const PARALLEL_POSES: usize = 32;

/// As [`held_out_errors`], the folds split over two threads when there are at least
/// [`PARALLEL_POSES`] poses (a refit per pose of a long recording's hundreds of holds is
/// costly, and the folds are independent); the errors are the same either way.
pub fn held_out_errors_threaded(
    poses: &[Pose],
    reference: f64,
    calibration_without: impl Fn(usize) -> Result<Calibration, FitError> + Sync,
) -> Option<Vec<Option<f64>>> {
    let n = poses.len();
    if n < PARALLEL_POSES {
        return held_out_errors(poses, reference, calibration_without);
    }
    if reference.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let one = |i: usize| held_out_error(&calibration_without(i).ok()?, &poses[i], reference);
    let mid = n / 2;
    let errors = std::thread::scope(|scope| {
        let second = scope.spawn(|| (mid..n).map(one).collect::<Vec<_>>());
        let mut errors: Vec<Option<f64>> = (0..mid).map(one).collect();
        errors.extend(
            second
                .join()
                .unwrap_or_else(|panic| std::panic::resume_unwind(panic)),
        );
        errors
    });
    Some(errors)
}

/// The relative norm residual `(|A(x − b)| − ref)/ref` of the held-out pose `held_out` under
/// `cal` (fitted without it), `None` when not finite.
pub fn held_out_error(cal: &Calibration, held_out: &Pose, reference: f64) -> Option<f64> {
    let r = (cal.apply(&held_out.mean).norm() - reference) / reference;
    r.is_finite().then_some(r)
}

/// RMS of the held-out errors, or `None` when any pose could not be predicted (or there are
/// none).
pub fn rms_of_all(errors: Vec<Option<f64>>) -> Option<f64> {
    let errors = errors.into_iter().collect::<Option<Vec<f64>>>()?;
    if errors.is_empty() {
        return None;
    }
    Some((errors.iter().map(|r| r * r).sum::<f64>() / errors.len() as f64).sqrt())
}
