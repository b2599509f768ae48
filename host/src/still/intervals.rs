//! What the detector finds: the holds, their per-sensor statistics, and the noise floors used.

use super::directions::cluster_directions;
use super::samples::{hold_samples, DroppedSamples, HoldSamples};
use crate::fit::{Pose, Vec3};
use crate::recording::{LabelKind, Recording, Sensor};

/// Die-temperature statistics over one interval, in °C.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TempStats {
    /// Mean temperature.
    pub mean: f64,
    /// Lowest temperature.
    pub min: f64,
    /// Highest temperature.
    pub max: f64,
}

/// The label a hold carries, as the recording's label column writes it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct HoldLabel {
    /// Which column it comes from (`pose` or `segment`).
    pub kind: LabelKind,
    /// The label's text, e.g. `P12` or `z_p`.
    pub text: String,
}

/// As a message names the hold's label: the column, then the text (`pose P12`, `segment z_p`).
impl std::fmt::Display for HoldLabel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} {}", self.kind.column(), self.text)
    }
}

/// One static hold.
#[derive(Debug, Clone, PartialEq)]
pub struct StillInterval {
    /// The hold's number as `imucal still` lists it and every message names it: counted from 1
    /// in order of time among the holds found, and kept when others are left out.
    pub number: usize,
    /// First row (main stream) of the hold.
    pub start: usize,
    /// One past the last row.
    pub end: usize,
    /// Time of the first row, s.
    pub t_start: f64,
    /// Time of the last row, s.
    pub t_end: f64,
    /// Label from a `pose` or `segment` column, if any, as a number: the label itself when it
    /// is an integer, else its index in order of first appearance (see
    /// [`crate::recording::Labels::value`]); [`StillInterval::label_name`] is its text.
    pub label: Option<i64>,
    /// The label's text and column, as tables and messages show it.
    pub label_name: Option<HoldLabel>,
    /// Accelerometer statistics, if the recording has one.
    pub accel: Option<Pose>,
    /// Gyroscope statistics, if the recording has one.
    pub gyro: Option<Pose>,
    /// Magnetometer statistics of the samples within `[t_start, t_end]`, if any.
    pub mag: Option<Pose>,
    /// Standard error of each sensor's hold mean (accelerometer, gyroscope, magnetometer),
    /// corrected for correlated samples as the residual analysis's is
    /// ([`crate::stats::autocorrelation::run_stats`]); `None` for fewer than four samples.
    pub sigma_mean: [Option<Vec3>; 3],
    /// Temperature statistics, if the recording has a temperature column.
    pub temp: Option<TempStats>,
    /// Index into [`StillReport::directions`] of this hold's gravity direction.
    pub direction: Option<usize>,
    /// Samples the outlier screen dropped from the statistics above, per sensor (empty when
    /// none was).
    pub dropped: Vec<DroppedSamples>,
}

impl StillInterval {
    /// Rows of the main stream that belong to this hold: every row of `start..end`, or, for a
    /// hold from a `pose` column, only the rows carrying its label.
    pub fn rows(&self, recording: &Recording) -> Vec<usize> {
        let labels = recording
            .labels
            .as_ref()
            .filter(|l| l.kind == LabelKind::Pose);
        let label_index = labels.and_then(|l| {
            let first = l.per_row.get(self.start).copied().flatten()?;
            Some((l, first))
        });
        (self.start..self.end.min(recording.len()))
            .filter(|&row| match label_index {
                Some((l, index)) => l.per_row.get(row).copied().flatten() == Some(index),
                None => true,
            })
            .collect()
    }

    /// The screened samples of `sensor` in this hold, the ones its statistics are made of.
    pub fn samples(&self, recording: &Recording, sensor: Sensor) -> Option<HoldSamples> {
        hold_samples(
            recording,
            &self.rows(recording),
            self.t_start,
            self.t_end,
            sensor,
        )
    }

    /// One sentence naming the samples the outlier screen dropped from this hold, per sensor;
    /// `None` when nothing was dropped.
    pub fn dropped_sentence(&self) -> Option<String> {
        if self.dropped.is_empty() {
            return None;
        }
        let what: Vec<String> = self.dropped.iter().map(DroppedSamples::phrase).collect();
        // The screen's bound is set so that a pose's own noise crosses it with small
        // probability over all its samples; a spike or a knock is a few samples. When most
        // samples lie beyond it, they do not scatter about one value: the board moved.
        let cause = if self.dropped.iter().any(|d| 2 * d.dropped > d.total) {
            "most of its samples lie far from its median, so it is not one pose: the board moved \
             during it (when the stillness window, --window, is longer than the holds, each \
             window takes in a move and moves pass as holds: lower it, 0.5 s by default)"
        } else {
            "a spike, a corrupted read or a knock during the hold"
        };
        Some(format!(
            "{}: outliers dropped from its statistics: {} (robust standard deviations from the \
             hold's median): {cause}",
            self.name(),
            what.join(", ")
        ))
    }

    /// The hold as messages name it, by its number in the `imucal still` table, its time span
    /// and its label: "hold #3 at 12.0–16.0 s (pose P12)".
    pub fn name(&self) -> String {
        format!(
            "hold #{} at {:.1}–{:.1} s{}",
            self.number,
            self.t_start,
            self.t_end,
            self.label_phrase()
        )
    }

    /// The hold's label in parentheses after a space, as messages name the hold (` (pose P12)`),
    /// or nothing for a hold without one.
    pub fn label_phrase(&self) -> String {
        self.label_name
            .as_ref()
            .map_or(String::new(), |l| format!(" ({l})"))
    }

    /// Duration in seconds.
    pub fn duration(&self) -> f64 {
        self.t_end - self.t_start
    }

    /// The standard error of one sensor's hold mean (see `sigma_mean`).
    pub fn pose_sigma_mean(&self, sensor: Sensor) -> Option<Vec3> {
        self.sigma_mean[sensor_index(sensor)]
    }

    /// The pose of one sensor.
    pub fn pose(&self, sensor: Sensor) -> Option<&Pose> {
        match sensor {
            Sensor::Accel => self.accel.as_ref(),
            Sensor::Gyro => self.gyro.as_ref(),
            Sensor::Mag => self.mag.as_ref(),
        }
    }
}

/// Estimated white-noise level of one sensor and the stillness threshold derived from it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoiseFloor {
    /// Sensor the estimate belongs to.
    pub sensor: Sensor,
    /// Per-axis noise standard deviation of single samples, in the file's units.
    pub sigma: Vec3,
    /// Threshold on `S = Σ v_k/σ_k²` (3 when the window variance equals the noise exactly).
    pub threshold: f64,
    /// Margin over the pure χ² quantile contained in `threshold`.
    pub margin: f64,
}

/// What the detector found.
#[derive(Debug, Clone, PartialEq)]
pub struct StillReport {
    /// Holds in time order.
    pub intervals: Vec<StillInterval>,
    /// Distinct gravity directions (unit vectors, bias-centred), clustered at
    /// [`StillOptions::direction_angle_deg`].
    pub directions: Vec<Vec3>,
    /// Noise estimates and thresholds used (empty when holds came from a `pose` column).
    pub noise: Vec<NoiseFloor>,
    /// Window length in samples.
    pub window: usize,
    /// True when holds were taken from a `pose` column rather than detected.
    pub from_pose_column: bool,
    /// Whether windows were also held to the absolute gyroscope bound of rest
    /// ([`super::MAX_STILL_GYRO_STD_DPS`]); false for a gyroscope in counts, without a
    /// gyroscope, or for holds from a `pose` column.
    pub rate_bound_applied: bool,
}

impl StillReport {
    /// The window in seconds: its samples times the sample period of `recording` (from its
    /// median rate), to the microsecond. The rate comes from time stamps, whose rounding would
    /// otherwise print as float noise (0.49999999999998934 s for 50 samples at 100 Hz); a
    /// microsecond is far finer than any sample period. `None` without a window (holds from a
    /// `pose` column) or a rate.
    pub fn window_s(&self, recording: &Recording) -> Option<f64> {
        let rate = recording.rate_hz().filter(|_| self.window > 0)?;
        Some((self.window as f64 / rate * 1e6).round() / 1e6)
    }

    /// One-line human summary.
    pub fn summary(&self) -> String {
        // Start from +0 so that an empty report prints "0.0 s", not "-0.0 s".
        let total: f64 = 0.0
            + self
                .intervals
                .iter()
                .map(StillInterval::duration)
                .sum::<f64>();
        let how = if self.from_pose_column {
            "from the pose column"
        } else {
            "detected"
        };
        format!(
            "{} {how} ({total:.1} s in total), {}",
            crate::words::counted(self.intervals.len(), "still interval"),
            crate::words::counted(self.directions.len(), "distinct gravity direction")
        )
    }

    /// Drop the intervals for which `exclude` is true and cluster the gravity directions of the
    /// rest again (direction indices refer to the kept intervals only).
    pub fn retain_intervals(
        &mut self,
        recording: &Recording,
        direction_angle_deg: f64,
        mut exclude: impl FnMut(usize, &StillInterval) -> bool,
    ) {
        let mut index = 0;
        self.intervals.retain(|interval| {
            let drop = exclude(index, interval);
            index += 1;
            !drop
        });
        for interval in &mut self.intervals {
            interval.direction = None;
        }
        self.cluster_directions(recording, direction_angle_deg);
    }

    /// Cluster the holds' gravity directions (see [`cluster_directions`]) and record each
    /// hold's direction.
    pub(super) fn cluster_directions(&mut self, recording: &Recording, angle_deg: f64) {
        let means: Vec<Option<Vec3>> = self
            .intervals
            .iter()
            .map(|i| i.accel.as_ref().map(|p| p.mean))
            .collect();
        let counts = recording.units.is_counts(Sensor::Accel).then(|| {
            // The largest per-sample standard deviation of any hold and axis.
            self.intervals
                .iter()
                .filter_map(|i| i.accel.as_ref())
                .map(|p| p.var.max().max(0.0).sqrt())
                .fold(0.0, f64::max)
        });
        let (members, directions) = cluster_directions(&means, counts, angle_deg);
        for (interval, direction) in self.intervals.iter_mut().zip(members) {
            interval.direction = direction;
        }
        self.directions = directions;
    }

    /// Poses of one sensor, one per interval that has that sensor.
    pub fn poses(&self, sensor: Sensor) -> Vec<Pose> {
        self.intervals
            .iter()
            .filter_map(|i| i.pose(sensor).cloned())
            .collect()
    }

    /// Each of [`Self::poses`] named as the hold warnings name it: "hold #3 at 12.0–16.0 s
    /// (pose P12)".
    pub fn pose_names(&self, sensor: Sensor) -> Vec<String> {
        self.intervals
            .iter()
            .filter(|i| i.pose(sensor).is_some())
            .map(StillInterval::name)
            .collect()
    }

    /// The standard error of each of [`Self::poses`]' means, in the same order.
    pub fn pose_sigmas(&self, sensor: Sensor) -> Vec<Option<Vec3>> {
        self.intervals
            .iter()
            .filter(|i| i.pose(sensor).is_some())
            .map(|i| i.pose_sigma_mean(sensor))
            .collect()
    }
}

/// `text` (a fit's sentence) with each pose the fit names by its position among the poses it was
/// given, "pose 6" (counted from 0), named as the hold it is among `names` ([`StillReport::pose_names`]):
/// "hold #7 at 30.0–34.0 s". A position beyond `names` is left as it is.
pub fn name_poses(text: &str, names: &[String]) -> String {
    const WORD: &str = "pose ";
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(at) = rest.find(WORD) {
        let (before, from) = rest.split_at(at);
        out.push_str(before);
        let after = &from[WORD.len()..];
        let digits = after.len() - after.trim_start_matches(|c: char| c.is_ascii_digit()).len();
        let word_start = out
            .chars()
            .next_back()
            .is_none_or(|c| !c.is_alphanumeric() && c != '_');
        let word_end = after[digits..]
            .chars()
            .next()
            .is_none_or(|c| !c.is_alphanumeric() && c != '_');
        let name = after[..digits]
            .parse::<usize>()
            .ok()
            .filter(|_| digits > 0 && word_start && word_end)
            .and_then(|i| names.get(i));
        match name {
            Some(name) => {
                out.push_str(name);
                rest = &after[digits..];
            }
            None => {
                out.push_str(WORD);
                rest = after;
            }
        }
    }
    out.push_str(rest);
    out
}

/// Position of `sensor` in per-sensor arrays ordered accelerometer, gyroscope, magnetometer.
pub(super) fn sensor_index(sensor: Sensor) -> usize {
    match sensor {
        Sensor::Accel => 0,
        Sensor::Gyro => 1,
        Sensor::Mag => 2,
    }
}

#[cfg(test)]
mod name_tests {
    use super::name_poses;

    #[test]
    fn a_fits_pose_position_is_named_as_the_hold_and_other_words_are_left() {
        let names = [
            "hold #1 at 0.0–2.0 s (pose 5)".to_string(),
            "hold #2 at 3.0–5.0 s".to_string(),
        ];
        assert_eq!(
            name_poses(
                "pose 1 is tilted; pose 0 too; pose 7; expose 1; pose 10x",
                &names
            ),
            "hold #2 at 3.0–5.0 s is tilted; hold #1 at 0.0–2.0 s (pose 5) too; pose 7; expose 1; \
             pose 10x"
        );
    }
}
