//! Per-sensor statistics of one hold: mean, within-hold variance and count of each sensor's
//! samples, the magnetometer samples inside the hold's time span, and the die temperature.

use super::intervals::{StillInterval, StillReport, TempStats};
use crate::fit::{Pose, Vec3};
use crate::recording::Recording;
use crate::stats::descriptive::mean_variance;

/// Holds from a `pose` column: every row with the same label belongs to one hold.
pub(super) fn from_pose_column(recording: &Recording) -> StillReport {
    let mut intervals = Vec::new();
    if let Some(labels) = &recording.labels {
        for index in 0..labels.names.len() {
            let rows: Vec<usize> = labels
                .per_row
                .iter()
                .enumerate()
                .filter(|(_, l)| **l == Some(index))
                .map(|(i, _)| i)
                .collect();
            if let (Some(&first), Some(&last)) = (rows.first(), rows.last()) {
                intervals.push(interval(
                    recording,
                    &rows,
                    first,
                    last + 1,
                    Some(labels.value(index)),
                ));
            }
        }
    }
    intervals.sort_by_key(|i| i.start);
    StillReport {
        intervals,
        directions: Vec::new(),
        noise: Vec::new(),
        window: 0,
        from_pose_column: true,
        rate_bound_applied: false,
    }
}

/// Mean, per-axis sample variance and count of the selected samples.
fn pose_of<'a>(
    samples: impl Iterator<Item = &'a Vec3> + Clone,
    label: Option<i64>,
) -> Option<Pose> {
    mean_variance(samples).map(|(mean, var, n)| Pose {
        mean,
        var,
        n,
        label,
    })
}

/// The hold of rows `start..end` (statistics over `rows`), before direction clustering.
pub(super) fn interval(
    recording: &Recording,
    rows: &[usize],
    start: usize,
    end: usize,
    label: Option<i64>,
) -> StillInterval {
    let t_start = recording.time[start];
    let t_end = recording.time[end - 1];
    let pick = |x: &Option<Vec<Vec3>>| {
        x.as_ref()
            .and_then(|x| pose_of(rows.iter().filter_map(|&i| x.get(i)), label))
    };
    let mag = recording.mag.as_ref().and_then(|m| {
        // Time stamps are non-decreasing (the reader refuses any that go back), so the samples
        // inside the hold are one contiguous run found by two binary searches, not a scan of
        // the whole stream per hold.
        let first = m.time.partition_point(|t| *t < t_start);
        let last = m.time.partition_point(|t| *t <= t_end).max(first);
        pose_of(m.samples.get(first..last)?.iter(), label)
    });
    let temp = recording.temp_c.as_ref().and_then(|t| {
        let values: Vec<f64> = rows.iter().filter_map(|&i| t.get(i).copied()).collect();
        (!values.is_empty()).then(|| TempStats {
            mean: values.iter().sum::<f64>() / values.len() as f64,
            min: values.iter().copied().fold(f64::INFINITY, f64::min),
            max: values.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        })
    });
    StillInterval {
        start,
        end,
        t_start,
        t_end,
        label,
        accel: pick(&recording.accel),
        gyro: pick(&recording.gyro),
        mag,
        temp,
        direction: None,
    }
}
