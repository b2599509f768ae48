//! Still-interval detection: finds the static holds in a recording that has no `pose` column,
//! and turns each hold into per-sensor [`Pose`] statistics.
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
//! pass. Windows never cross a break in the time stamps or a change of `segment` label at a
//! break. Runs of still windows are merged across short blips, kept when they last long
//! enough, and their gravity directions are clustered by angle.

use crate::fit::{Pose, Vec3};
use crate::recording::{LabelKind, Recording, Sensor};

/// Settings of the detector. [`StillOptions::default`] suits hand-placed poses at 50–1000 Hz.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StillOptions {
    /// Window length in seconds over which variance is computed.
    pub window_s: f64,
    /// Shortest hold kept, in seconds.
    pub min_hold_s: f64,
    /// Probability that a window of pure white noise is called moving (the test's size `α`).
    pub false_alarm: f64,
    /// Percentile (0–1) of windowed variances taken as the quietest stretch.
    pub noise_percentile: f64,
    /// Factor on the threshold for noise that is not white; 1 is the pure χ² test. `None`
    /// chooses it from the data (Otsu's method, within [`MIN_MARGIN`, `MAX_MARGIN`]).
    pub margin: Option<f64>,
    /// Runs separated by at most this many seconds are merged when their means agree.
    pub merge_gap_s: f64,
    /// Holds whose gravity directions are within this angle (degrees) count as one direction.
    pub direction_angle_deg: f64,
}

impl Default for StillOptions {
    fn default() -> Self {
        Self {
            window_s: 0.5,
            min_hold_s: 1.0,
            false_alarm: 1e-3,
            noise_percentile: 0.1,
            margin: None,
            merge_gap_s: 0.5,
            direction_angle_deg: 10.0,
        }
    }
}

/// Smallest automatic margin: below it, slow wander of real sensors over a window splits holds
/// (seen on the Xsens data at 2: 40 pieces instead of 38 holds).
pub const MIN_MARGIN: f64 = 4.0;
/// Largest automatic margin: window variance 256/3 ≈ 85 times the noise, i.e. a standard
/// deviation about 9 times the noise, above which slow hand motion would pass as still.
pub const MAX_MARGIN: f64 = 256.0;

/// Why still intervals could not be found.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StillError {
    /// The recording has neither an accelerometer nor a gyroscope (nor a magnetometer on the
    /// same rows) to detect stillness with.
    #[error("`{0}` has no accelerometer or gyroscope columns to detect still intervals with")]
    NoSensor(String),
    /// Times are row numbers, so windows in seconds cannot be formed.
    #[error("`{0}` has no `t_s` column and no sample rate was given; still detection works in seconds, so pass the rate (e.g. `--rate 100`)")]
    NoRate(String),
    /// An option is out of range.
    #[error("still-detection option {name} = {value} is out of range ({expected})")]
    BadOption {
        /// Option name.
        name: &'static str,
        /// Value given.
        value: f64,
        /// What is allowed.
        expected: &'static str,
    },
}

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

/// One static hold.
#[derive(Debug, Clone, PartialEq)]
pub struct StillInterval {
    /// First row (main stream) of the hold.
    pub start: usize,
    /// One past the last row.
    pub end: usize,
    /// Time of the first row, s.
    pub t_start: f64,
    /// Time of the last row, s.
    pub t_end: f64,
    /// Label from a `pose` or `segment` column, if any.
    pub label: Option<i64>,
    /// Accelerometer statistics, if the recording has one.
    pub accel: Option<Pose>,
    /// Gyroscope statistics, if the recording has one.
    pub gyro: Option<Pose>,
    /// Magnetometer statistics of the samples within `[t_start, t_end]`, if any.
    pub mag: Option<Pose>,
    /// Temperature statistics, if the recording has a temperature column.
    pub temp: Option<TempStats>,
    /// Index into [`StillReport::directions`] of this hold's gravity direction.
    pub direction: Option<usize>,
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

    /// Duration in seconds.
    pub fn duration(&self) -> f64 {
        self.t_end - self.t_start
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
}

impl StillReport {
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
            "{} still intervals {how} ({total:.1} s in total), {} distinct gravity directions",
            self.intervals.len(),
            self.directions.len()
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
        cluster_directions(recording, self, direction_angle_deg);
    }

    /// Poses of one sensor, one per interval that has that sensor.
    pub fn poses(&self, sensor: Sensor) -> Vec<Pose> {
        self.intervals
            .iter()
            .filter_map(|i| i.pose(sensor).cloned())
            .collect()
    }
}

/// Find the static holds of a recording: from its `pose` column when it has one, otherwise by
/// detection (within each `segment`, never across a boundary).
pub fn find_still(
    recording: &Recording,
    options: &StillOptions,
) -> Result<StillReport, StillError> {
    let mut report = match &recording.labels {
        Some(labels) if labels.kind == LabelKind::Pose => from_pose_column(recording),
        _ => detect(recording, options)?,
    };
    cluster_directions(recording, &mut report, options.direction_angle_deg);
    Ok(report)
}

fn check(
    name: &'static str,
    value: f64,
    ok: bool,
    expected: &'static str,
) -> Result<(), StillError> {
    if ok && value.is_finite() {
        Ok(())
    } else {
        Err(StillError::BadOption {
            name,
            value,
            expected,
        })
    }
}

/// Holds from a `pose` column: every row with the same label belongs to one hold.
fn from_pose_column(recording: &Recording) -> StillReport {
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
    }
}

/// Per-window variance of each axis for windows starting at `0..=n−w` (two-pass per window
/// via prefix sums of values centred on the global mean, which keeps large raw offsets from
/// cancelling digits).
fn window_variances(x: &[Vec3], w: usize) -> Vec<Vec3> {
    let n = x.len();
    if n < w || w < 2 {
        return Vec::new();
    }
    let mean = x.iter().sum::<Vec3>() / n as f64;
    let mut s1 = vec![Vec3::zeros(); n + 1];
    let mut s2 = vec![Vec3::zeros(); n + 1];
    for (i, v) in x.iter().enumerate() {
        let d = v - mean;
        s1[i + 1] = s1[i] + d;
        s2[i + 1] = s2[i] + d.component_mul(&d);
    }
    let wf = w as f64;
    (0..=n - w)
        .map(|s| {
            let sum = s1[s + w] - s1[s];
            let sq = s2[s + w] - s2[s];
            (sq - sum.component_mul(&sum) / wf).map(|v| (v / (wf - 1.0)).max(0.0))
        })
        .collect()
}

/// Smallest positive step between consecutive samples on each axis (the quantisation step
/// for integer or fixed-point data), used as a floor for the noise estimate.
fn quantisation_step(x: &[Vec3]) -> Vec3 {
    let mut step = Vec3::repeat(f64::INFINITY);
    for w in x.windows(2) {
        for k in 0..3 {
            let d = (w[1][k] - w[0][k]).abs();
            if d > 0.0 && d < step[k] {
                step[k] = d;
            }
        }
    }
    step.map(|s| if s.is_finite() { s } else { 0.0 })
}

/// Standard normal quantile (Acklam's rational approximation, relative error < 1.2e-9).
fn normal_quantile(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969683028665376e1,
        2.209460984245205e2,
        -2.759285104469687e2,
        1.38357751867269e2,
        -3.066479806614716e1,
        2.506628277459239,
    ];
    const B: [f64; 5] = [
        -5.447609879822406e1,
        1.615858368580409e2,
        -1.556989798598866e2,
        6.680131188771972e1,
        -1.328068155288572e1,
    ];
    const C: [f64; 6] = [
        -7.784894002430293e-3,
        -3.223964580411365e-1,
        -2.400758277161838,
        -2.549732539343734,
        4.374664141464968,
        2.938163982698783,
    ];
    const D: [f64; 4] = [
        7.784695709041462e-3,
        3.224671290700398e-1,
        2.445134137142996,
        3.754408661907416,
    ];
    let p = p.clamp(1e-15, 1.0 - 1e-15);
    let tail = |q: f64| {
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    };
    if p < 0.02425 {
        tail((-2.0 * p.ln()).sqrt())
    } else if p > 1.0 - 0.02425 {
        -tail((-2.0 * (1.0 - p).ln()).sqrt())
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    }
}

/// Quantile of `χ²(ν)/ν` by the Wilson–Hilferty cube approximation (good to ~1% for ν ≥ 10).
pub fn chi2_quantile_per_dof(p: f64, dof: f64) -> f64 {
    let c = 2.0 / (9.0 * dof);
    let z = normal_quantile(p);
    (1.0 - c + z * c.sqrt()).max(0.0).powi(3)
}

/// Value at fraction `p` of a list (nearest rank).
fn percentile(values: &mut [f64], p: f64) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    values.sort_by(f64::total_cmp);
    let rank = ((values.len() - 1) as f64 * p).round() as usize;
    values[rank.min(values.len() - 1)]
}

/// Rows `[start, end)` between breaks: a time step longer than [`BREAK_S`], or a change of
/// `segment` label together with a step longer than three sample periods (separate recordings
/// joined in one file). A label change without a break (phases of one continuous recording) is
/// not a boundary.
fn sections(recording: &Recording, rate: f64) -> Vec<(usize, usize)> {
    let n = recording.len();
    let segment = recording
        .labels
        .as_ref()
        .filter(|l| l.kind == LabelKind::Segment);
    let mut out = Vec::new();
    let mut start = 0;
    for i in 1..=n {
        let boundary = i == n || {
            let dt = recording.time[i] - recording.time[i - 1];
            let relabelled = segment.is_some_and(|l| l.per_row.get(i) != l.per_row.get(i - 1));
            dt > BREAK_S || (relabelled && dt > 3.0 / rate)
        };
        if boundary {
            out.push((start, i));
            start = i;
        }
    }
    out
}

/// A gap in the time stamps longer than this (seconds) is a break in the recording.
pub const BREAK_S: f64 = 1.0;

/// Otsu's threshold (maximum between-class variance) of `values` over a 256-bin histogram.
fn otsu(values: &[f64]) -> Option<f64> {
    let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if !(lo.is_finite() && hi.is_finite() && hi > lo) {
        return None;
    }
    const BINS: usize = 256;
    let width = (hi - lo) / BINS as f64;
    let mut hist = [0usize; BINS];
    for v in values {
        let bin = (((v - lo) / width) as usize).min(BINS - 1);
        hist[bin] += 1;
    }
    let total = values.len() as f64;
    let centre = |i: usize| lo + (i as f64 + 0.5) * width;
    let sum_all: f64 = hist
        .iter()
        .enumerate()
        .map(|(i, &c)| c as f64 * centre(i))
        .sum();
    let (mut w0, mut sum0, mut best, mut best_t) = (0.0, 0.0, -1.0, None);
    for (i, &count) in hist.iter().enumerate().take(BINS - 1) {
        w0 += count as f64;
        sum0 += count as f64 * centre(i);
        let w1 = total - w0;
        if w0 == 0.0 || w1 == 0.0 {
            continue;
        }
        let between = w0 * w1 * (sum0 / w0 - (sum_all - sum0) / w1).powi(2);
        if between > best {
            best = between;
            best_t = Some(lo + (i as f64 + 1.0) * width);
        }
    }
    best_t
}

fn detect(recording: &Recording, options: &StillOptions) -> Result<StillReport, StillError> {
    check(
        "window_s",
        options.window_s,
        options.window_s > 0.0,
        "> 0 s",
    )?;
    check(
        "min_hold_s",
        options.min_hold_s,
        options.min_hold_s >= 0.0,
        ">= 0 s",
    )?;
    check(
        "false_alarm",
        options.false_alarm,
        options.false_alarm > 0.0 && options.false_alarm < 0.5,
        "between 0 and 0.5",
    )?;
    check(
        "noise_percentile",
        options.noise_percentile,
        options.noise_percentile > 0.0 && options.noise_percentile < 1.0,
        "between 0 and 1",
    )?;
    if let Some(m) = options.margin {
        check("margin", m, m >= 1.0, ">= 1")?;
    }
    check(
        "merge_gap_s",
        options.merge_gap_s,
        options.merge_gap_s >= 0.0,
        ">= 0 s",
    )?;
    let source = recording.source.display().to_string();
    if recording.time_is_index {
        return Err(StillError::NoRate(source));
    }
    // Stillness is judged on the row-synchronous inertial sensors; a magnetometer on the same
    // rows is used only when there is nothing else.
    let mut streams: Vec<(Sensor, &[Vec3])> = [Sensor::Accel, Sensor::Gyro]
        .into_iter()
        .filter_map(|s| recording.samples(s).map(|x| (s, x)))
        .collect();
    if streams.is_empty() {
        match &recording.mag {
            Some(m) if m.time.len() == recording.len() => streams.push((Sensor::Mag, &m.samples)),
            _ => return Err(StillError::NoSensor(source)),
        }
    }
    let rate = recording.rate_hz().unwrap_or(1.0);
    let w = ((options.window_s * rate).round() as usize).max(5);
    let dof = (w - 1) as f64;
    let sections = sections(recording, rate);

    // Noise per sensor from the quietest windows of the whole recording (all sections).
    let percentile_factor = chi2_quantile_per_dof(options.noise_percentile, dof);
    let chi2_threshold = 3.0 * chi2_quantile_per_dof(1.0 - options.false_alarm, 3.0 * dof);
    let mut sigmas = Vec::new();
    // Per section, per window: the largest ratio S / χ²-threshold over the sensors.
    let mut ratio: Vec<Vec<f64>> = sections
        .iter()
        .map(|&(a, b)| vec![0.0; (b - a + 1).saturating_sub(w)])
        .collect();
    for (_, x) in &streams {
        let per_section: Vec<Vec<Vec3>> = sections
            .iter()
            .map(|&(a, b)| window_variances(&x[a..b], w))
            .collect();
        let step = quantisation_step(x);
        let mut sigma = Vec3::zeros();
        for k in 0..3 {
            // Windows with exactly zero variance are an axis pinned at a rail (saturation) or
            // below one quantisation step; the quantisation floor below covers the latter, and
            // counting them would set the noise to zero and call every other hold moving.
            let mut axis: Vec<f64> = per_section
                .iter()
                .flatten()
                .map(|v| v[k])
                .filter(|v| *v > 0.0)
                .collect();
            let quiet =
                percentile(&mut axis, options.noise_percentile) / percentile_factor.max(1e-12);
            // Uniform quantisation error has variance step²/12: no real sensor is quieter.
            let floor = step[k] * step[k] / 12.0;
            sigma[k] = quiet.max(floor).max(f64::MIN_POSITIVE).sqrt();
        }
        for (vars, out) in per_section.iter().zip(ratio.iter_mut()) {
            for (v, r) in vars.iter().zip(out.iter_mut()) {
                let stat: f64 = (0..3).map(|k| v[k] / (sigma[k] * sigma[k])).sum();
                *r = r.max(stat / chi2_threshold);
            }
        }
        sigmas.push(sigma);
    }
    let margin = match options.margin {
        Some(m) => m,
        None => {
            let logs: Vec<f64> = ratio
                .iter()
                .flatten()
                .filter(|r| **r > 0.0)
                .map(|r| r.ln())
                .collect();
            otsu(&logs)
                .map_or(MIN_MARGIN, f64::exp)
                .clamp(MIN_MARGIN, MAX_MARGIN)
        }
    };
    let noise: Vec<NoiseFloor> = streams
        .iter()
        .zip(&sigmas)
        .map(|((sensor, _), sigma)| NoiseFloor {
            sensor: *sensor,
            sigma: *sigma,
            threshold: chi2_threshold * margin,
            margin,
        })
        .collect();

    let mut runs: Vec<(usize, usize)> = Vec::new();
    for (&(a, b), section_ratio) in sections.iter().zip(&ratio) {
        let len = b - a;
        if section_ratio.is_empty() {
            continue;
        }
        let windows = section_ratio.len();
        // Row i is judged by the window centred on it (clamped at the section's ends).
        let half = w / 2;
        let mut run_start: Option<usize> = None;
        for i in 0..len {
            let s = i.saturating_sub(half).min(windows - 1);
            match (section_ratio[s] <= margin, run_start) {
                (true, None) => run_start = Some(i),
                (false, Some(r)) => {
                    runs.push((a + r, a + i));
                    run_start = None;
                }
                _ => {}
            }
        }
        if let Some(r) = run_start {
            runs.push((a + r, b));
        }
    }

    // Merge runs split by a short blip when every axis mean agrees within 3 noise sigmas.
    let section_of = |row: usize| sections.iter().position(|&(a, b)| row >= a && row < b);
    let mut merged: Vec<(usize, usize)> = Vec::new();
    for run in runs {
        if let Some(last) = merged.last_mut() {
            let gap = recording.time[run.0] - recording.time[last.1 - 1];
            let same_section = section_of(run.0) == section_of(last.0);
            let agree = streams.iter().zip(&noise).all(|((_, x), floor)| {
                let m1 = mean(&x[last.0..last.1]);
                let m2 = mean(&x[run.0..run.1]);
                (0..3).all(|k| (m1[k] - m2[k]).abs() <= 3.0 * floor.sigma[k])
            });
            if same_section && gap <= options.merge_gap_s && agree {
                last.1 = run.1;
                continue;
            }
        }
        merged.push(run);
    }

    let labels = recording.labels.as_ref();
    let intervals = merged
        .into_iter()
        .filter(|&(a, b)| recording.time[b - 1] - recording.time[a] >= options.min_hold_s)
        .map(|(a, b)| {
            let label = labels.and_then(|l| majority_label(&l.per_row[a..b]).map(|i| l.value(i)));
            let rows: Vec<usize> = (a..b).collect();
            interval(recording, &rows, a, b, label)
        })
        .collect();
    Ok(StillReport {
        intervals,
        directions: Vec::new(),
        noise,
        window: w,
        from_pose_column: false,
    })
}

/// The label carried by more than half of the rows, if any.
fn majority_label(rows: &[Option<usize>]) -> Option<usize> {
    let mut counts: Vec<usize> = Vec::new();
    for i in rows.iter().flatten() {
        if counts.len() <= *i {
            counts.resize(i + 1, 0);
        }
        counts[*i] += 1;
    }
    counts
        .iter()
        .enumerate()
        .filter(|(_, c)| 2 * **c > rows.len())
        .map(|(i, _)| i)
        .next()
}

fn mean(x: &[Vec3]) -> Vec3 {
    x.iter().sum::<Vec3>() / x.len().max(1) as f64
}

/// Mean, per-axis sample variance and count of the selected samples.
fn pose_of<'a>(
    samples: impl Iterator<Item = &'a Vec3> + Clone,
    label: Option<i64>,
) -> Option<Pose> {
    let n = samples.clone().count();
    if n == 0 {
        return None;
    }
    let m = samples.clone().sum::<Vec3>() / n as f64;
    let var = if n > 1 {
        samples
            .map(|x| (x - m).component_mul(&(x - m)))
            .sum::<Vec3>()
            / (n - 1) as f64
    } else {
        Vec3::zeros()
    };
    Some(Pose {
        mean: m,
        var,
        n,
        label,
    })
}

fn interval(
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
        let inside = m
            .time
            .iter()
            .zip(&m.samples)
            .filter(|(t, _)| **t >= t_start && **t <= t_end)
            .map(|(_, x)| x);
        pose_of(inside, label)
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

/// Centre used to turn accelerometer means into directions: zero for data in physical units
/// (offsets are small next to g), the per-axis midrange of the hold means for raw counts
/// (whose offset can be as large as the signal, e.g. unsigned 16-bit data).
fn direction_centre(recording: &Recording, intervals: &[StillInterval]) -> Vec3 {
    if !recording.units.is_counts(Sensor::Accel) {
        return Vec3::zeros();
    }
    let means: Vec<Vec3> = intervals
        .iter()
        .filter_map(|i| i.accel.as_ref().map(|p| p.mean))
        .collect();
    if means.is_empty() {
        return Vec3::zeros();
    }
    let lo = means
        .iter()
        .fold(Vec3::repeat(f64::INFINITY), |a, m| a.inf(m));
    let hi = means
        .iter()
        .fold(Vec3::repeat(f64::NEG_INFINITY), |a, m| a.sup(m));
    (lo + hi) / 2.0
}

/// Greedy clustering of hold directions: each hold joins the first direction within the angle,
/// whose representative is the normalised sum of its members, or starts a new one.
fn cluster_directions(recording: &Recording, report: &mut StillReport, angle_deg: f64) {
    let centre = direction_centre(recording, &report.intervals);
    let cos_limit = angle_deg.to_radians().cos();
    let mut sums: Vec<Vec3> = Vec::new();
    for interval in &mut report.intervals {
        let Some(pose) = &interval.accel else {
            continue;
        };
        let d = pose.mean - centre;
        let norm = d.norm();
        if !(norm > 0.0 && norm.is_finite()) {
            continue;
        }
        let u = d / norm;
        let found = sums.iter().position(|s| s.normalize().dot(&u) >= cos_limit);
        let index = match found {
            Some(i) => {
                sums[i] += u;
                i
            }
            None => {
                sums.push(u);
                sums.len() - 1
            }
        };
        interval.direction = Some(index);
    }
    report.directions = sums.into_iter().map(|s| s.normalize()).collect();
}
