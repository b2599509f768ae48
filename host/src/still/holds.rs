//! Per-sensor statistics of one hold: mean, within-hold variance, count and the standard error
//! of the mean (corrected for correlated samples) of each sensor's screened samples ([`super::samples`]), the magnetometer samples inside the hold's time span,
//! and the die temperature.

use super::intervals::{sensor_index, HoldLabel, StillInterval, StillReport, TempStats};
use super::samples::hold_samples;
use crate::fit::Pose;
use crate::fit::Vec3;
use crate::recording::{Recording, Sensor};
use crate::stats::autocorrelation::run_stats_quantised;
use crate::stats::descriptive::mean_variance;

/// Holds from a `pose` column: every row with the same label belongs to one hold.
pub(super) fn from_pose_column(recording: &Recording) -> StillReport {
    let mut intervals = Vec::new();
    let quanta = Sensor::ALL.map(|s| recording.quantum(s));
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
                    Some(index),
                    &quanta,
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

/// The hold of rows `start..end` (statistics over `rows`), before direction clustering;
/// `label` is the index of its label in the recording's labels; `quanta` the recording's
/// resolution per sensor ([`Recording::quantum`], in [`Sensor::ALL`] order).
pub(super) fn interval(
    recording: &Recording,
    rows: &[usize],
    start: usize,
    end: usize,
    label: Option<usize>,
    quanta: &[Vec3; 3],
) -> StillInterval {
    let labels = recording.labels.as_ref();
    let label_name = label.and_then(|index| {
        let labels = labels?;
        Some(HoldLabel {
            kind: labels.kind,
            text: labels.names.get(index)?.clone(),
        })
    });
    let label = label.and_then(|index| Some(labels?.value(index)));
    let t_start = recording.time[start];
    let t_end = recording.time[end - 1];
    let mut dropped = Vec::new();
    let mut sigma_mean = [None; 3];
    let mut pose = |sensor: Sensor| {
        let held = hold_samples(recording, rows, t_start, t_end, sensor)?;
        dropped.extend(held.dropped);
        let quantum = quanta[sensor_index(sensor)];
        sigma_mean[sensor_index(sensor)] =
            run_stats_quantised(&held.kept, quantum).map(|s| s.sigma_mean);
        mean_variance(held.kept.iter()).map(|(mean, var, n)| Pose {
            mean,
            var,
            n,
            label,
        })
    };
    let accel = pose(Sensor::Accel);
    let gyro = pose(Sensor::Gyro);
    let mag = pose(Sensor::Mag);
    let temp = recording.temp_c.as_ref().and_then(|t| {
        let values: Vec<f64> = rows.iter().filter_map(|&i| t.get(i).copied()).collect();
        (!values.is_empty()).then(|| TempStats {
            mean: values.iter().sum::<f64>() / values.len() as f64,
            min: values.iter().copied().fold(f64::INFINITY, f64::min),
            max: values.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        })
    });
    StillInterval {
        // Numbered once all holds are found (see `super::find_still`).
        number: 0,
        start,
        end,
        t_start,
        t_end,
        label,
        label_name,
        accel,
        gyro,
        mag,
        sigma_mean,
        temp,
        direction: None,
        dropped,
    }
}
