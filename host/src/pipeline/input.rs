//! Stage 1: a loaded recording → the sensors that may be fitted, their still intervals and the
//! magnetometer samples, with every input check of [`crate::input_checks`] applied in one place.
//! Every command that reads a recording (`fit`, `report`, `analyze`) goes through
//! [`check_input`], so a unit mix-up refused by one is refused by all.
//!
//! A refusal concerns only the sensor(s) it names: the others are still fitted.

use crate::fit::Vec3;
use crate::input_checks;
use crate::recording::{Recording, Sensor};
use crate::stats::robust::{screen_stream, stream_noise, Screening};
use crate::still::{find_still, StillOptions, StillReport};

use super::methods::thin_redundant_indices;

/// How to form the fitting input from a recording. The default keeps every magnetometer sample.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct InputOptions {
    /// Still-interval detection (its `min_hold_s` and `direction_angle_deg` also drive the checks).
    pub still: StillOptions,
    /// Magnetometer fits use at most this many samples, thinned first where the stream repeats
    /// one reading, then evenly ([`super::methods::thin_redundant_indices`]; 0 = all, the default:
    /// the fits take one pass per iteration over the samples, and thinning to 2000 cost up to
    /// 0.3 % of held-out accuracy on real recordings, `docs/RESULTS.md` "Speed at scale").
    pub max_mag_samples: usize,
}

/// The recording with the checks' verdicts.
#[derive(Debug)]
pub struct CheckedInput {
    /// The recording as read.
    pub recording: Recording,
    /// The sensors asked for, in order.
    pub sensors: Vec<Sensor>,
    /// Still intervals (holds that cannot be used left out), when an inertial sensor was asked
    /// for and any were found.
    pub still: Option<StillReport>,
    /// Magnetometer samples for its fit ([`CheckedInput::mag_points`]).
    mag_points: MagPoints,
    /// Sensors refused before fitting, with the sentence saying why and how to fix it.
    pub refusals: Vec<(Sensor, String)>,
    /// The refusals that say the declared units (or a stated reference) contradict the data:
    /// every command refuses the recording for these, not only the sensor.
    pub unit_refusals: Vec<(Sensor, String)>,
    /// Findings that cast doubt without refusing.
    pub warnings: Vec<String>,
    /// The magnetometer's noise per sample and axis, in the file's unit, from its stream
    /// ([`stream_noise`]); `None` when too few distinct readings.
    pub mag_noise: Option<Vec3>,
}

impl CheckedInput {
    /// Magnetometer samples for its fit, screened and evenly thinned (none when the
    /// magnetometer was not asked for).
    pub fn mag_points(&self) -> &[Vec3] {
        self.mag_points
            .as_slice(self.recording.samples(Sensor::Mag).unwrap_or(&[]))
    }

    /// Where each of [`Self::mag_points`] is in the recording's magnetometer stream (its time
    /// and temperature are at that index).
    pub fn mag_point_indices(&self) -> Vec<usize> {
        match &self.mag_points {
            MagPoints::Recorded => (0..self.mag_points().len()).collect(),
            MagPoints::Selected { indices, .. } => indices.clone(),
        }
    }

    /// Why `sensor` was refused, if it was.
    pub fn refusal(&self, sensor: Sensor) -> Option<&str> {
        self.refusals
            .iter()
            .find(|(s, _)| *s == sensor)
            .map(|(_, r)| r.as_str())
    }

    /// The unit refusals as one sentence per sensor, `sensor: reason`.
    pub fn unit_refusal_sentences(&self) -> Vec<String> {
        self.unit_refusals
            .iter()
            .map(|(s, r)| format!("{s}: {r}"))
            .collect()
    }
}

/// Run every input check on `sensors` of `recording`. `stated_field_ut` is a field magnitude
/// the user stated (a modelled one is not checked against the data here: it is compared with
/// the fitted radius instead).
pub fn check_input(
    recording: Recording,
    sensors: &[Sensor],
    options: &InputOptions,
    stated_field_ut: Option<f64>,
) -> CheckedInput {
    check_input_then(recording, sensors, options, stated_field_ut, |_, _| ()).0
}

/// [`check_input`], and `then_mag` on the magnetometer's samples as soon as its checks pass,
/// on the thread that ran them, while still detection goes on: a long recording's
/// magnetometer fit then overlaps the detection instead of waiting for it. `None` when the
/// magnetometer was not asked for or was refused.
pub fn check_input_then<T: Send>(
    recording: Recording,
    sensors: &[Sensor],
    options: &InputOptions,
    stated_field_ut: Option<f64>,
    then_mag: impl FnOnce(&Recording, &[Vec3]) -> T + Send,
) -> (CheckedInput, Option<T>) {
    let mut refusals: Vec<(Sensor, String)> = Vec::new();
    let mut unit_refusals: Vec<(Sensor, String)> = Vec::new();
    let inertial: Vec<Sensor> = sensors
        .iter()
        .copied()
        .filter(|s| *s != Sensor::Mag)
        .collect();
    // The magnetometer's checks and fit read the recording independently of the rest: on a
    // long one they run on their own thread while this one checks the time stamps and the
    // accelerometer's unit and detects the still intervals (the two sides take about as long).
    let (time_warnings, mag, accel_unit, still) = std::thread::scope(|scope| {
        let side = scope.spawn(|| {
            sensors
                .contains(&Sensor::Mag)
                .then(|| checked_mag_points(&recording, options, stated_field_ut, then_mag))
        });
        let mut time_warnings = if recording.time_from_file {
            input_checks::time_stamp_warnings(&recording.time)
        } else {
            Vec::new()
        };
        if recording.repeated_rows > 0 {
            time_warnings.insert(
                0,
                format!(
                    "{} repeated the row before them exactly (time stamp and every value) and \
                     were read once: a logger wrote those samples twice, and counted twice they \
                     would shrink every noise estimate and σ",
                    crate::words::counted(recording.repeated_rows, "row")
                ),
            );
        }
        let accel_unit = match (sensors.contains(&Sensor::Accel), &recording.accel) {
            (true, Some(accel)) => {
                input_checks::check_accel_unit(accel, recording.units.accel).err()
            }
            _ => None,
        };
        let still = (!inertial.is_empty()).then(|| still_intervals(&recording, &options.still));
        let mag = side
            .join()
            .unwrap_or_else(|panic| std::panic::resume_unwind(panic));
        (time_warnings, mag, accel_unit, still)
    });
    let mut warnings = time_warnings;
    let mut mag_next = None;
    if let Some(e) = accel_unit {
        unit_refusals.push((Sensor::Accel, e.to_string()));
    }
    let mut mag_points = MagPoints::Selected {
        points: Vec::new(),
        indices: Vec::new(),
    };
    let mut mag_noise = None;
    if let Some((mag, next)) = mag {
        mag_next = next;
        mag_points = mag.points;
        mag_noise = mag.noise;
        warnings.extend(mag.warnings);
        match mag.verdict {
            MagVerdict::Usable => {}
            MagVerdict::Refused(reason) => refusals.push((Sensor::Mag, reason)),
            MagVerdict::UnitRefused(reason) => unit_refusals.push((Sensor::Mag, reason)),
        }
    }
    let still = match still {
        None => None,
        Some(Ok((still, w))) => {
            warnings.extend(w);
            Some(still)
        }
        Some(Err(reason)) => {
            refusals.extend(inertial.iter().map(|s| (*s, reason.clone())));
            None
        }
    };
    if let Some(still) = &still {
        if inertial.contains(&Sensor::Gyro) {
            if let Err(e) = input_checks::check_gyro_unit(&recording, still) {
                unit_refusals.push((Sensor::Gyro, e.to_string()));
            }
        }
        if inertial.contains(&Sensor::Accel)
            && !unit_refusals.iter().any(|(s, _)| *s == Sensor::Accel)
        {
            if let Err(e) = input_checks::check_accel_poses(still) {
                refusals.push((Sensor::Accel, e.to_string()));
            }
        }
    }
    // A unit refusal is the first reason given for its sensor.
    refusals.retain(|(s, _)| !unit_refusals.iter().any(|(u, _)| u == s));
    refusals.splice(0..0, unit_refusals.iter().cloned());
    // A sensor that is not measuring fails every other check as a symptom (a stuck gyroscope
    // "turns 0 times as far as gravity", a stuck magnetometer "was not turned"): the cause is
    // its only reason, and it concerns that sensor, not the recording's units.
    for &sensor in sensors {
        let samples = recording.samples(sensor).unwrap_or(&[]);
        match input_checks::check_not_stuck(samples, sensor) {
            Ok(None) => {}
            Ok(Some(warning)) => warnings.push(warning),
            Err(stuck) => {
                refusals.retain(|(s, _)| *s != sensor);
                unit_refusals.retain(|(s, _)| *s != sensor);
                refusals.insert(0, (sensor, stuck.to_string()));
                if sensor == Sensor::Mag {
                    mag_next = None;
                }
            }
        }
    }
    let checked = CheckedInput {
        recording,
        sensors: sensors.to_vec(),
        unit_refusals,
        still,
        mag_points,
        refusals,
        warnings,
        mag_noise,
    };
    (checked, mag_next)
}

/// Which magnetometer samples its fit uses.
#[derive(Debug)]
enum MagPoints {
    /// Every sample recorded (none dropped, none thinned): read from the recording, not copied.
    Recorded,
    /// The samples kept by the screen or thinning, and their indices in the recording's stream.
    Selected {
        points: Vec<Vec3>,
        indices: Vec<usize>,
    },
}

impl MagPoints {
    /// The samples, `recorded` being the recording's.
    fn as_slice<'a>(&'a self, recorded: &'a [Vec3]) -> &'a [Vec3] {
        match self {
            Self::Recorded => recorded,
            Self::Selected { points, .. } => points,
        }
    }
}

/// The magnetometer samples for its fit with the verdict of its checks.
struct CheckedMag {
    points: MagPoints,
    verdict: MagVerdict,
    warnings: Vec<String>,
    noise: Option<Vec3>,
}

/// What the magnetometer's checks concluded.
enum MagVerdict {
    Usable,
    /// Refused for its coverage.
    Refused(String),
    /// Refused because the declared unit (or stated field) contradicts the data.
    UnitRefused(String),
}

/// The magnetometer's samples screened (and thinned when asked), checked for coverage and
/// field, and `then_mag` on them when the checks pass. `then_mag` runs beside the coverage and
/// field checks, which it does not depend on; its result is dropped when they refuse.
fn checked_mag_points<T: Send>(
    recording: &Recording,
    options: &InputOptions,
    stated_field_ut: Option<f64>,
    then_mag: impl FnOnce(&Recording, &[Vec3]) -> T + Send,
) -> (CheckedMag, Option<T>) {
    let all = recording.samples(Sensor::Mag).unwrap_or(&[]);
    let screening = screen_stream(all);
    let noise = stream_noise(all);
    let mut warnings = Vec::new();
    if screening.dropped > 0 {
        warnings.push(stream_outliers_sentence(&screening, all.len()));
    }
    let kept: Option<Vec<usize>> = (screening.dropped > 0).then(|| {
        (0..all.len())
            .filter(|&i| screening.keep.get(i).copied().unwrap_or(false))
            .collect()
    });
    let kept_len = kept.as_ref().map_or(all.len(), Vec::len);
    let thin_to = match options.max_mag_samples {
        0 => kept_len,
        max => max.min(kept_len),
    };
    // Every sample kept (the default) and none dropped: the recording's own samples, not a copy.
    let points = match (kept, thin_to < kept_len) {
        (None, false) => MagPoints::Recorded,
        (kept, thinned) => {
            let indices: Vec<usize> = match kept {
                Some(kept) if !thinned => kept,
                Some(kept) => {
                    let points: Vec<Vec3> = kept.iter().map(|&i| all[i]).collect();
                    thin_redundant_indices(&points, thin_to)
                        .into_iter()
                        .map(|i| kept[i])
                        .collect()
                }
                None => thin_redundant_indices(all, thin_to),
            };
            MagPoints::Selected {
                points: indices.iter().map(|&i| all[i]).collect(),
                indices,
            }
        }
    };
    let selected = points.as_slice(all);
    let (verdict, fitted) = std::thread::scope(|scope| {
        let fit = scope.spawn(|| then_mag(recording, selected));
        let verdict = match input_checks::check_mag_coverage(selected) {
            Err(e) => MagVerdict::Refused(e.to_string()),
            Ok(radius) => {
                match input_checks::check_mag_field(radius, recording.units.mag, stated_field_ut) {
                    Ok(w) => {
                        warnings.extend(w);
                        MagVerdict::Usable
                    }
                    Err(e) => MagVerdict::UnitRefused(e.to_string()),
                }
            }
        };
        let fitted = fit
            .join()
            .unwrap_or_else(|panic| std::panic::resume_unwind(panic));
        (verdict, fitted)
    });
    let next = matches!(verdict, MagVerdict::Usable).then_some(fitted);
    let checked = CheckedMag {
        points,
        verdict,
        warnings,
        noise,
    };
    (checked, next)
}

/// The warning for magnetometer samples dropped from the fit's stream of `total`.
fn stream_outliers_sentence(screening: &Screening, total: usize) -> String {
    format!(
        "{} of {total} magnetometer samples dropped from the field fit as outliers (up to \
         {:.3e} robust standard deviations from the running median of their neighbours; the \
         bound for this many samples is {:.1}): a spike, a corrupted read or a jerk of the hand; \
         check the wiring or the sensor if spikes recur",
        screening.dropped, screening.worst_sigmas, screening.bound_sigmas
    )
}

/// The still intervals of `recording` as every command sees them: detected, required, and
/// screened (holds the board moved during, saturated or spiked readings), with the warnings to
/// show, among them one per hold and sensor whose outliers were dropped. Refuses when no hold
/// is found or none is usable.
pub fn still_intervals(
    recording: &Recording,
    options: &StillOptions,
) -> Result<(StillReport, Vec<String>), String> {
    let mut still = find_still(recording, options)
        .map_err(|e| format!("still intervals could not be found: {e}"))?;
    input_checks::require_still(recording, &still, options).map_err(|e| e.to_string())?;
    let mut warnings =
        input_checks::screen_holds(recording, &mut still, options.direction_angle_deg)
            .map_err(|e| e.to_string())?;
    warnings.extend(still.intervals.iter().filter_map(|i| i.dropped_sentence()));
    // The detector's window has at least five rows (a variance needs a few); a shorter one
    // asked for is widened, which the user should know.
    if let Some(rate) = recording.rate_hz() {
        if options.window_s * rate < still.window as f64 - 0.5 {
            warnings.push(format!(
                "the stillness window of {} s is shorter than {} rows at {rate:.1} Hz, the \
                 fewest the detector uses; {:.3} s was used",
                options.window_s,
                still.window,
                still.window as f64 / rate
            ));
        }
    }
    Ok((still, warnings))
}
