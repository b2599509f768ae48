//! Stage 2: checked input → a [`RecordingCalibration`]. Accelerometer and gyroscope fits use
//! the still-interval poses, the magnetometer its (thinned) samples over many orientations. The
//! accelerometer's default is the evidence-based [`super::chain`]; the magnetometer is then
//! rotated into the accelerometer's frame ([`super::align`]). Each sensor is judged on its own:
//! a refusal of one leaves the others fitted.

use std::collections::BTreeMap;

use super::observations::{MAG_WINDOW_SAMPLES, MAX_MAG_WINDOWS};
use crate::fit::{Fit, Method, Pose, Vec3};
use crate::geomag::{local_field_today, LocalField, Location, RadiusCheck};
use crate::recording::{Recording, Sensor, Units};
use crate::still::{name_poses, StillReport};

use super::align::align_mag;
use super::calibration::{
    bias_noise_test, norm_noise_test, pose_noise_floor, sample_noise_floor, stream_noise_test,
    RecordingCalibration, SensorOutcome,
};
use super::chain::{default_accel_chain, unknowns, CandidateOutcome};
use super::gyro::{fit_gyroscope, gyro_unit_scale, moot_gyro_scale};
use super::input::{check_input_then, CheckedInput, InputOptions};
use super::methods::{fit_accel, fit_mag, leave_one_out_where_refittable};
use super::references::References;
use super::PipelineError;
use crate::device::params_json::Provenance;

/// How to fit.
#[derive(Debug, Clone, Default)]
pub struct FitOptions {
    /// Checked reference values.
    pub references: Option<References>,
    /// Where the recording was made: the World Magnetic Model's field there today is the
    /// magnetometer reference when no field magnitude is given, and checks the fitted radius.
    pub location: Option<Location>,
    /// Methods chosen by the user, per sensor; the others use their default.
    pub methods: Vec<(Sensor, Method)>,
    /// The board's device id, when known.
    pub device_id: Option<String>,
}

impl FitOptions {
    fn method(&self, sensor: Sensor) -> Option<Method> {
        self.methods
            .iter()
            .find(|(s, _)| *s == sensor)
            .map(|(_, m)| *m)
    }
}

/// Seconds since the Unix epoch now (0 if the clock is before it).
pub fn now_unix_s() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs())
}

/// The reference values a fit uses: the checked references, and the modelled field at the
/// recording's location when the magnetometer is fitted there.
struct FitReferences {
    references: References,
    field_model: Option<LocalField>,
    /// The magnetometer's reference: the stated field, else the modelled one.
    field_ut: Option<f64>,
}

impl FitReferences {
    fn new(options: &FitOptions, fits_mag: bool) -> Result<Self, PipelineError> {
        let references = match options.references {
            Some(r) => r,
            None => References::checked(crate::recording::STANDARD_GRAVITY, None, None)?,
        };
        let field_model = match (&options.location, fits_mag) {
            (Some(location), true) => Some(
                local_field_today(location)
                    .map_err(|e| PipelineError::FieldModel(e.to_string()))?,
            ),
            _ => None,
        };
        Ok(Self {
            references,
            field_model,
            field_ut: references.field_ut.or(field_model.map(|m| m.total_ut)),
        })
    }
}

/// Fit every sensor of `input` that passed its checks.
pub fn calibrate(
    input: &CheckedInput,
    options: &FitOptions,
) -> Result<RecordingCalibration, PipelineError> {
    let references = FitReferences::new(options, input.sensors.contains(&Sensor::Mag))?;
    Ok(calibrate_with(input, options, &references, None))
}

/// [`check_input`](super::check_input) and [`calibrate`] in one: the magnetometer's fit starts
/// as soon as its checks pass, beside still detection, instead of after it (on a recording of
/// 10⁶ rows the detection is the input stage's longest part). The result is the same as the
/// two steps give.
pub fn check_and_calibrate(
    recording: Recording,
    sensors: &[Sensor],
    input_options: &InputOptions,
    stated_field_ut: Option<f64>,
    options: &FitOptions,
) -> Result<(CheckedInput, RecordingCalibration), PipelineError> {
    let references = FitReferences::new(options, sensors.contains(&Sensor::Mag))?;
    let method = options.method(Sensor::Mag);
    let (input, mag) = check_input_then(
        recording,
        sensors,
        input_options,
        stated_field_ut,
        |recording, points| fit_magnetometer(recording, points, &references, method),
    );
    let calibration = calibrate_with(&input, options, &references, mag);
    Ok((input, calibration))
}

/// Fit the sensors of `input`, the magnetometer's outcome given when already fitted.
fn calibrate_with(
    input: &CheckedInput,
    options: &FitOptions,
    references: &FitReferences,
    fitted_mag: Option<SensorOutcome>,
) -> RecordingCalibration {
    let recording = &input.recording;
    let fit_one = |sensor: Sensor| {
        let unit = recording.units.symbol(sensor);
        match input.refusal(sensor) {
            Some(reason) => SensorOutcome::without_fit(sensor, unit, reason.to_string()),
            None if sensor == Sensor::Mag => fit_magnetometer(
                recording,
                input.mag_points(),
                references,
                options.method(sensor),
            ),
            None => {
                let context = SensorContext {
                    input,
                    references: &references.references,
                    method: options.method(sensor),
                };
                context.fit(sensor)
            }
        }
    };
    // The sensors' fits share nothing but the input, so each runs on its own thread: on a
    // long recording the magnetometer's pass over every sample overlaps the accelerometer's
    // chain. The outcomes keep the order of `input.sensors`.
    let mut fitted_mag = fitted_mag;
    let mut sensors: Vec<SensorOutcome> = std::thread::scope(|scope| {
        let fits: Vec<_> = input
            .sensors
            .iter()
            .map(|&sensor| {
                let done = if sensor == Sensor::Mag {
                    fitted_mag.take()
                } else {
                    None
                };
                match done {
                    Some(outcome) => Fitting::Done(Box::new(outcome)),
                    None => Fitting::Running(scope.spawn(move || fit_one(sensor))),
                }
            })
            .collect();
        fits.into_iter()
            .map(|fit| match fit {
                Fitting::Done(outcome) => *outcome,
                Fitting::Running(handle) => handle
                    .join()
                    .unwrap_or_else(|panic| std::panic::resume_unwind(panic)),
            })
            .collect()
    });
    // The magnetometer's residual against its samples' noise, whichever thread fitted it, and
    // the residual analysis's test on the means of its poses or windows.
    for outcome in sensors.iter_mut().filter(|s| s.sensor == Sensor::Mag) {
        if let Ok(fit) = &outcome.fit {
            if let Some(noise) = &input.mag_noise {
                outcome.noise_floor = sample_noise_floor(input.mag_points(), fit, noise);
            }
            test_mag_residual(outcome, recording);
        }
    }
    align_outcomes(&mut sensors, input.still.as_ref());

    let methods = sensors
        .iter()
        .filter_map(|s| {
            let fit = s.fit.as_ref().ok()?;
            Some((s.sensor.name().to_string(), fit.method.name().to_string()))
        })
        .collect();
    RecordingCalibration {
        provenance: Provenance {
            tool: Provenance::tool(),
            source: recording.source.display().to_string(),
            device_id: options.device_id.clone(),
            methods,
            input_units: input_units(&recording.units, &input.sensors),
            created_unix_s: now_unix_s(),
            board_firmware: None,
        },
        sensors,
        gravity_mps2: references.references.gravity_mps2,
        field_ut: references.field_ut,
        still_summary: input.still.as_ref().map(StillReport::summary),
        warnings: input.warnings.clone(),
    }
}

/// A sensor's fit: already done, or running on a thread.
enum Fitting<'scope> {
    Done(Box<SensorOutcome>),
    Running(std::thread::ScopedJoinHandle<'scope, SensorOutcome>),
}

fn input_units(units: &Units, sensors: &[Sensor]) -> BTreeMap<String, String> {
    sensors
        .iter()
        .map(|s| (s.name().to_string(), units.symbol(*s).to_string()))
        .collect()
}

/// What fitting one inertial sensor needs.
struct SensorContext<'a> {
    input: &'a CheckedInput,
    references: &'a References,
    method: Option<Method>,
}

impl SensorContext<'_> {
    fn fit(&self, sensor: Sensor) -> SensorOutcome {
        let recording = &self.input.recording;
        let mut outcome =
            SensorOutcome::without_fit(sensor, recording.units.symbol(sensor), String::new());
        outcome.to_nominal = recording.units.to_si(sensor);
        let Some(still) = &self.input.still else {
            outcome.fit = Err("still intervals are needed for this sensor".to_string());
            return outcome;
        };
        let poses = still.poses(sensor);
        outcome.n_poses = poses.len();
        outcome.n_samples = poses.iter().map(|p| p.n).sum();
        let gravity = self.references.gravity_mps2;
        let fit = if sensor == Sensor::Accel {
            outcome.output_unit = "m/s²".to_string();
            let fit = match self.method {
                Some(m) => fit_accel(m, &poses, gravity).map(|mut f| {
                    if f.loo_rms.is_none() {
                        let names = still.pose_names(sensor);
                        held_out_where_refittable(
                            &mut f,
                            &poses,
                            &names,
                            gravity,
                            &mut outcome.notes,
                        );
                    }
                    f
                }),
                None => default_accel_chain(&poses, gravity).map(|mut choice| {
                    // The candidates' sentences name the holds as the `still` table does.
                    let names = still.pose_names(sensor);
                    choice.reason = name_poses(&choice.reason, &names);
                    for candidate in &mut choice.candidates {
                        if let CandidateOutcome::Refused(why)
                        | CandidateOutcome::NotValidated(why) = &mut candidate.outcome
                        {
                            *why = name_poses(why, &names);
                        }
                    }
                    outcome.notes.push(choice.reason.clone());
                    let fit = choice.fit.clone();
                    outcome.chain = Some(choice);
                    fit
                }),
            };
            if let Ok(f) = &fit {
                // The residual analysis's test, so that `fit` and `analyze` judge alike.
                match norm_noise_test(&poses, &still.pose_sigmas(sensor), f, unknowns(f.method)) {
                    Some((test, floor)) => {
                        outcome.noise_test = Some(test);
                        outcome.noise_floor = Some(floor);
                    }
                    None => outcome.noise_floor = pose_noise_floor(&poses, f),
                }
            }
            fit
        } else {
            let (scale, unit) = gyro_unit_scale(recording, self.references.gyro_scale);
            if let Some(moot) = moot_gyro_scale(recording, self.references.gyro_scale) {
                outcome.notes.push(moot);
            }
            outcome.output_unit = unit.to_string();
            outcome.to_nominal = (unit == "rad/s").then_some(scale);
            let method = self.method.unwrap_or(Method::GyroBias);
            let fit = fit_gyroscope(method, recording, still, gravity, scale);
            if let Some(f) = fit.as_ref().ok().filter(|f| f.method == Method::GyroBias) {
                outcome.noise_test = bias_noise_test(&poses, &still.pose_sigmas(sensor), f);
            }
            fit
        };
        // A refusal names a pose by its position among the poses fitted: named as the hold.
        outcome.fit = fit.map_err(|e| name_poses(&e.to_string(), &still.pose_names(sensor)));
        outcome
    }
}

/// Give `fit` (a model the user chose) the held-out error over the poses it can be refit
/// without ([`leave_one_out_where_refittable`]), saying which poses are not in it.
fn held_out_where_refittable(
    fit: &mut Fit,
    poses: &[Pose],
    names: &[String],
    gravity: f64,
    notes: &mut Vec<String>,
) {
    let Some((rms, kept)) = leave_one_out_where_refittable(fit.method, poses, gravity) else {
        notes.push(format!(
            "{}: no leave-one-out RMS: fewer than two of the {} poses can be held out (the \
             model is refused without each of the others); record more poses",
            fit.method.name(),
            poses.len()
        ));
        return;
    };
    fit.loo_rms = Some(rms);
    if kept.len() < poses.len() {
        let left: Vec<String> = (0..poses.len())
            .filter(|i| !kept.contains(i))
            .map(|i| {
                names
                    .get(i)
                    .map_or_else(|| format!("pose {i}"), |n| format!("the {n}"))
            })
            .collect();
        notes.push(format!(
            "{}: leave-one-out RMS over {} of {} poses; without {} the model is refused, so \
             {} not held out",
            fit.method.name(),
            kept.len(),
            poses.len(),
            left.join(", "),
            if left.len() == 1 { "it is" } else { "they are" }
        ));
    }
}

/// Fit the magnetometer's `points` (its checked samples) of `recording`.
fn fit_magnetometer(
    recording: &Recording,
    points: &[Vec3],
    references: &FitReferences,
    method: Option<Method>,
) -> SensorOutcome {
    let unit = recording.units.symbol(Sensor::Mag);
    let mut outcome = SensorOutcome::without_fit(Sensor::Mag, unit, String::new());
    outcome.to_nominal = recording.units.to_si(Sensor::Mag);
    outcome.n_samples = points.len();
    outcome.output_unit = match references.field_ut {
        Some(_) => "µT".to_string(),
        None => "field = 1".to_string(),
    };
    outcome.field_model = references.field_model;
    let method = method.unwrap_or(Method::Lm);
    let fit = fit_mag(method, points, references.field_ut.unwrap_or(1.0));
    if let (Ok(f), Some(model), Some(to_ut)) =
        (&fit, &references.field_model, recording.units.mag.to_si())
    {
        // Mean distance of the raw readings from the fitted offset: the sphere's radius.
        let radius =
            points.iter().map(|p| (p - f.cal.b).norm()).sum::<f64>() / points.len().max(1) as f64;
        let check = RadiusCheck::new(radius * to_ut, model);
        outcome.notes.push(check.sentence());
        outcome.radius_check = Some(check);
    }
    outcome.fit = fit.map_err(|e| e.to_string());
    outcome
}

/// Unknowns of a magnetometer model: an axis-aligned ellipsoid's six, else a general one's nine.
fn mag_unknowns(method: Method) -> usize {
    match method {
        Method::MinMax | Method::AxisAligned | Method::MinMaxAxisAlignedMean => 6,
        _ => 9,
    }
}

/// The magnetometer's χ² test: the means of its residual over short windows of the recorded
/// stream against their own standard errors ([`stream_noise_test`]).
fn test_mag_residual(outcome: &mut SensorOutcome, recording: &Recording) {
    let Ok(fit) = &outcome.fit else { return };
    let Some(mag) = &recording.mag else { return };
    let test = stream_noise_test(
        &mag.samples,
        fit,
        MAG_WINDOW_SAMPLES,
        MAX_MAG_WINDOWS,
        mag_unknowns(fit.method),
    );
    if let Some(test) = test {
        outcome.noise_test = Some(test);
        outcome.noise_test_of = Some(format!("noise of its {MAG_WINDOW_SAMPLES}-sample means"));
    }
}

/// Rotate the magnetometer fit into the accelerometer frame when both were asked for.
fn align_outcomes(sensors: &mut [SensorOutcome], still: Option<&StillReport>) {
    let accel: Option<Option<Fit>> = sensors
        .iter()
        .find(|r| r.sensor == Sensor::Accel)
        .map(|r| r.fit.as_ref().ok().cloned());
    let Some(accel) = accel else {
        return;
    };
    let Some(mag) = sensors.iter_mut().find(|r| r.sensor == Sensor::Mag) else {
        return;
    };
    let Ok(mag_fit) = &mut mag.fit else {
        return;
    };
    let outcome = match (&accel, still) {
        (Some(accel), Some(still)) => {
            align_mag(still, &accel.cal, &mag_fit.cal).map_err(|e| e.to_string())
        }
        _ => Err("the accelerometer was not fitted".to_string()),
    };
    if let Ok(alignment) = &outcome {
        mag_fit.cal = alignment.apply_to(&mag_fit.cal);
    }
    mag.alignment = Some(outcome);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::check_input;
    use crate::recording::LoadOptions;

    /// A recording with every sensor, read from a temporary file.
    fn recording(rows: usize) -> Recording {
        let path = std::env::temp_dir().join(format!(
            "imucal-check-and-calibrate-{}.csv",
            std::process::id()
        ));
        let mut text = Vec::new();
        crate::synthetic::write_long_recording(rows, &mut text).expect("written to memory");
        std::fs::write(&path, text).expect("temporary file");
        let recording = Recording::load(&path, &LoadOptions::default()).expect("reads back");
        let _ = std::fs::remove_file(&path);
        recording
    }

    #[test]
    fn checking_and_fitting_in_one_gives_what_the_two_steps_give() {
        let recording = recording(60_000);
        let sensors = recording.sensors();
        assert_eq!(
            sensors.len(),
            3,
            "accelerometer, gyroscope and magnetometer"
        );
        let input_options = InputOptions::default();
        let options = FitOptions::default();
        let input = check_input(recording.clone(), &sensors, &input_options, None);
        let two_steps = calibrate(&input, &options).expect("fits");
        let (_, in_one) =
            check_and_calibrate(recording, &sensors, &input_options, None, &options).expect("fits");
        for (a, b) in two_steps.sensors.iter().zip(&in_one.sensors) {
            assert_eq!(a.sensor, b.sensor);
            let (fa, fb) = (
                a.fit.as_ref().expect("fitted"),
                b.fit.as_ref().expect("fitted"),
            );
            // The same arithmetic on the same samples: equal bit for bit.
            assert_eq!(fa.cal, fb.cal, "{}", a.sensor);
            assert_eq!(fa.rms.to_bits(), fb.rms.to_bits(), "{}", a.sensor);
            assert_eq!(a.notes, b.notes, "{}", a.sensor);
            assert_eq!(a.n_samples, b.n_samples, "{}", a.sensor);
        }
        assert_eq!(two_steps.sensors.len(), in_one.sensors.len());
    }
}
