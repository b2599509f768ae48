//! The windowed stillness test (module comment of [`super`]) and the runs of still rows it gives.
//!
//! **Absolute bound.** The χ² test is relative: it compares each window with the quietest
//! stretch of the same recording. When a recording has no still stretch at all (a board turned
//! by hand throughout), the quietest windows are slow motion, the "noise" estimate is that
//! motion, and slow turns pass as holds. So a window is also judged against physics: a board at
//! rest does not rotate, and its gyroscope reading then varies only by the sensor's noise.
//! MEMS gyroscopes specify a rate noise density of at most about 0.03 °/s/√Hz (consumer parts:
//! MPU-6050 0.005, LSM9DS1 and BMI160 about 0.007–0.008, L3GD20 0.03), so over the widest output
//! bandwidth they offer (≈ 1 kHz, noise bandwidth ≈ 1.6 kHz) one sample's standard deviation
//! stays below `0.03·√1600 ≈ 1.2 °/s`; [`MAX_STILL_GYRO_STD_DPS`] rounds that up to 1.5 °/s
//! per axis. A window whose gyroscope varies more is moving, whatever the rest of the recording
//! looks like. The test uses the within-window variation, not the mean, so a constant bias
//! (MEMS parts are specified to several °/s) can never fail it. It needs the gyroscope's unit;
//! for raw counts it is not applied ([`StillReport::rate_bound_applied`] says which).

use super::holds::interval;
use super::intervals::{NoiseFloor, StillReport};
use super::options::{StillError, StillOptions, MAX_MARGIN, MIN_MARGIN};
use crate::fit::Vec3;
use crate::recording::{GyroUnit, LabelKind, Recording, Sensor};
use crate::stats::descriptive::{
    for_each_axis_window_variance, for_each_window_variance, mean, percentile_of_positive_bits,
    quantisation_step,
};
use crate::stats::distributions::chi2_quantile_per_dof;
use crate::stats::threshold::otsu;

/// Largest per-axis standard deviation of a gyroscope's samples, in °/s, that a board at rest
/// can show (sensor noise only; see the module comment for the datasheet reasoning).
pub const MAX_STILL_GYRO_STD_DPS: f64 = 1.5;

/// A gyroscope whose quietest window varies by more than this (°/s) is not in the declared unit:
/// a board turned by hand for calibration moves at tens of °/s, never at this rate in every
/// half-second of a recording, while raw counts read as rad/s give hundreds. The rest bound is
/// then not applied, and the unit checks downstream name the unit.
pub const IMPLAUSIBLE_QUIETEST_GYRO_DPS: f64 = 100.0;

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

pub(super) fn detect(
    recording: &Recording,
    options: &StillOptions,
) -> Result<StillReport, StillError> {
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
    // (Row numbers for times are refused by `find_still`, for a pose column alike.)
    let source = recording.source.display().to_string();
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
    // Per section, per window: whether the gyroscope varies more than rest allows.
    let mut turning: Vec<Vec<bool>> = ratio.iter().map(|r| vec![false; r.len()]).collect();
    // Smallest over the windows of the largest per-axis gyroscope variance (file units).
    let mut quietest_gyro_var = f64::INFINITY;
    let rate_limit = recording
        .units
        .to_si(Sensor::Gyro)
        .map(|to_rad_s| MAX_STILL_GYRO_STD_DPS.to_radians() / to_rad_s);
    // The windowed variances are reduced as they are computed, never stored: per axis into
    // the selection buffer for the noise percentile (one buffer the length of the recording,
    // refilled for every stream and axis), then all three axes at once into the windows'
    // ratios and the gyroscope's rest test.
    let windows: usize = ratio.iter().map(Vec::len).sum();
    let mut scratch: Vec<u64> = Vec::with_capacity(windows);
    for (sensor, x) in &streams {
        let step = quantisation_step(x);
        let mut sigma = Vec3::zeros();
        for k in 0..3 {
            // Windows with exactly zero variance are an axis pinned at a rail (saturation) or
            // below one quantisation step; the quantisation floor below covers the latter, and
            // counting them would set the noise to zero and call every other hold moving.
            scratch.clear();
            for &(a, b) in &sections {
                for_each_axis_window_variance(&x[a..b], k, w, |v| {
                    if v > 0.0 {
                        scratch.push(v.to_bits());
                    }
                });
            }
            let quiet = percentile_of_positive_bits(&mut scratch, options.noise_percentile)
                / percentile_factor.max(1e-12);
            // Uniform quantisation error has variance step²/12: no real sensor is quieter.
            let floor = step[k] * step[k] / 12.0;
            sigma[k] = quiet.max(floor).max(f64::MIN_POSITIVE).sqrt();
        }
        let rest_limit = match sensor {
            Sensor::Gyro => rate_limit,
            _ => None,
        };
        for ((&(a, b), out), turns) in sections
            .iter()
            .zip(ratio.iter_mut())
            .zip(turning.iter_mut())
        {
            let mut slots = out.iter_mut().zip(turns.iter_mut());
            for_each_window_variance(&x[a..b], w, |v| {
                let Some((r, t)) = slots.next() else { return };
                let stat: f64 = (0..3).map(|k| v[k] / (sigma[k] * sigma[k])).sum();
                *r = r.max(stat / chi2_threshold);
                if let Some(limit) = rest_limit {
                    *t = v.iter().any(|var| *var > limit * limit);
                    quietest_gyro_var = quietest_gyro_var.min(v.max());
                }
            });
        }
        sigmas.push(sigma);
    }
    let margin = match options.margin {
        Some(m) => m,
        None => {
            // The emptied scratch buffer's allocation is taken over (same size and alignment).
            scratch.clear();
            let mut logs: Vec<f64> = scratch.into_iter().map(f64::from_bits).collect();
            logs.extend(ratio.iter().flatten().filter(|r| **r > 0.0).map(|r| r.ln()));
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

    let to_dps = |var: f64| {
        recording
            .units
            .to_si(Sensor::Gyro)
            .map_or(f64::NAN, |to_rad_s| (var.sqrt() * to_rad_s).to_degrees())
    };
    let unit_implausible = to_dps(quietest_gyro_var) > IMPLAUSIBLE_QUIETEST_GYRO_DPS;
    if unit_implausible {
        for t in turning.iter_mut().flatten() {
            *t = false;
        }
    }

    let mut runs: Vec<(usize, usize)> = Vec::new();
    for ((&(a, b), section_ratio), section_turning) in sections.iter().zip(&ratio).zip(&turning) {
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
            let still = section_ratio[s] <= margin && !section_turning[s];
            match (still, run_start) {
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
    // Rest by the relative test only where the rest bound failed, nowhere where both passed:
    // both kinds of passing window looked for in one scan, which stops once both are found.
    let (mut passes_turning, mut passes_resting) = (false, false);
    'scan: for (rs, ts) in ratio.iter().zip(&turning) {
        for (r, t) in rs.iter().zip(ts) {
            if *r <= margin {
                if *t {
                    passes_turning = true;
                } else {
                    passes_resting = true;
                }
                if passes_turning && passes_resting {
                    break 'scan;
                }
            }
        }
    }
    let relative_found_rest = passes_turning && !passes_resting;
    let quanta = Sensor::ALL.map(|s| recording.quantum(s));
    let intervals: Vec<_> = merged
        .into_iter()
        .filter(|&(a, b)| recording.time[b - 1] - recording.time[a] >= options.min_hold_s)
        .map(|(a, b)| {
            let label = labels.and_then(|l| majority_label(&l.per_row[a..b]));
            let rows: Vec<usize> = (a..b).collect();
            interval(recording, &rows, a, b, label, &quanta)
        })
        .collect();
    if intervals.is_empty() && relative_found_rest && quietest_gyro_var.is_finite() {
        return Err(StillError::NeverAtRest {
            path: source,
            quietest_dps: to_dps(quietest_gyro_var),
            unit: recording.units.symbol(Sensor::Gyro),
            other_units: match recording.units.gyro {
                GyroUnit::Rads => "dps or counts",
                GyroUnit::Dps => "rads or counts",
                GyroUnit::Counts => "rads or dps",
            },
            bound_dps: MAX_STILL_GYRO_STD_DPS,
            window_note: if options.window_s > options.min_hold_s {
                format!(
                    "; or the stillness window (--window {} s) is longer than the holds, so each \
                     window takes in a move: lower it (0.5 s by default)",
                    options.window_s
                )
            } else {
                String::new()
            },
        });
    }
    Ok(StillReport {
        intervals,
        directions: Vec::new(),
        noise,
        window: w,
        from_pose_column: false,
        rate_bound_applied: rate_limit.is_some() && recording.gyro.is_some() && !unit_implausible,
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
