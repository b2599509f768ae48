//! Still-interval detection: finds the static holds in a recording that has no `pose` column,
//! and turns each hold into per-sensor [`crate::fit::Pose`] statistics.
//!
//! Method (the windowed-variance stillness test of `ARCHITECTURE.md`, firmware "Stillness",
//! done offline): for every window of `W` samples the per-axis sample variance `v_k` is
//! computed. For white Gaussian noise of variance `σ_k²`, `(W−1)·v_k/σ_k² ~ χ²(W−1)`, so the
//! statistic `S = Σ_k v_k/σ_k²` over the three axes satisfies `(W−1)·S ~ χ²(3(W−1))` while the
//! board is still. The noise `σ_k²` is the sensor's own, estimated from the quietest stretch:
//! the `p`-th percentile of all windowed variances divided by the `p`-quantile of
//! `χ²(W−1)/(W−1)` (the percentile of a still window's variance, not its mean). A window is
//! still when `S` is below the `1−α` quantile of `χ²(3(W−1))/(W−1)` times a margin for noise
//! that is not white (slow wander, table vibration, the tremor of a hand holding the board).
//! The margin is chosen from the data by Otsu's method (maximum between-class variance of the
//! histogram of `log S`, which is bimodal: still versus moving), kept within
//! [`MIN_MARGIN`, `MAX_MARGIN`]; it can also be fixed. Accelerometer and gyroscope must both
//! pass, and a gyroscope in known units must also vary by no more than a board at rest can
//! ([`MAX_STILL_GYRO_STD_DPS`], reasoning in `detect`): the relative test alone would accept the
//! quietest stretch of a recording that never rests. Windows never cross a break in the time stamps or a change of `segment` label at a
//! break. Runs of still windows are merged across short blips, kept when they last long
//! enough, and their gravity directions are clustered by angle.
//!
//! Inside each hold, gross outliers (a spike, a corrupted read) are screened out of every
//! sensor's samples by median/MAD with a Bonferroni bound before any statistic is taken
//! ([`crate::stats::robust`]); each hold lists what was dropped.
//!
//! Files: `options` (settings, errors), `intervals` (what is found), `detect` (the windowed test
//! and the runs it gives), `samples` (a hold's screened samples), `holds` (per-sensor
//! statistics of a hold), `directions` (clustering of gravity directions), `motions` (the
//! gyroscope rotations between consecutive holds, for the gyroscope-scale fit).

mod detect;
pub mod directions;
mod holds;
mod intervals;
pub mod motions;
mod options;
mod samples;

use crate::recording::{LabelKind, Recording};

use detect::detect;
pub use detect::{BREAK_S, MAX_STILL_GYRO_STD_DPS};
use holds::from_pose_column;
pub use intervals::{name_poses, HoldLabel, NoiseFloor, StillInterval, StillReport, TempStats};
pub use options::{StillError, StillOptions, MAX_MARGIN, MIN_MARGIN};
pub use samples::{hold_samples, DroppedSamples, HoldSamples};

/// Find the static holds of a recording: from its `pose` column when it has one, otherwise by
/// detection (within each `segment`, never across a boundary).
pub fn find_still(
    recording: &Recording,
    options: &StillOptions,
) -> Result<StillReport, StillError> {
    // A `pose` column needs no window, but its holds are still reported in seconds and their
    // magnetometer samples taken by time: row numbers would pass for both.
    if recording.time_is_index {
        return Err(StillError::NoRate(recording.source.display().to_string()));
    }
    let mut report = match &recording.labels {
        Some(labels) if labels.kind == LabelKind::Pose => from_pose_column(recording),
        _ => detect(recording, options)?,
    };
    for (k, interval) in report.intervals.iter_mut().enumerate() {
        interval.number = k + 1;
    }
    report.cluster_directions(recording, options.direction_angle_deg);
    Ok(report)
}
