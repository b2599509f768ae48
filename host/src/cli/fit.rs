//! `imucal fit`: fit each requested sensor of a recording and print a table or JSON.
//!
//! Accelerometer and gyroscope fits use still-interval poses (from a `pose` column or
//! detected); the magnetometer uses all its samples (it needs orientation coverage, which
//! still holds do not give), evenly thinned to a bounded number. Each sensor is judged on its
//! own: an input check or fit that refuses one sensor is reported for that sensor while the
//! others are fitted, and the exit code is non-zero when any requested sensor failed.
//!
//! With both an accelerometer and a magnetometer, the magnetometer is rotated into the
//! accelerometer's frame by the dot-product-invariance alignment of `fit::alignment` (gravity
//! and field keep the same angle, the dip, in every still pose). With `--location`, the World
//! Magnetic Model's field there (`geomag`) is the magnetometer reference unless `--field-ut` is
//! given, and the fitted raw radius is compared with it.

use anyhow::{bail, Context};
use imucal::fit::alignment::{fit_alignment, Alignment};
use imucal::fit::{Fit, FitError, Method, Pose, Vec3};
use imucal::geomag::{self, LocalField, Location, RadiusCheck};
use imucal::input_checks;
use imucal::recording::{Recording, Sensor};
use imucal::still::{find_still, StillReport};
use nalgebra::Rotation3;
use serde_json::{json, Value};

use super::args::{FitArgs, SensorChoice};
use super::methods;

/// One sensor's outcome, ready to print.
struct SensorResult {
    sensor: Sensor,
    fit: Result<Fit, String>,
    n_poses: usize,
    n_samples: usize,
    input_unit: &'static str,
    output_unit: String,
    /// Relative (or absolute, for the gyroscope) residual expected from the noise alone.
    noise_floor: Option<f64>,
    /// Why a method other than the default was used, and other findings worth a line.
    notes: Vec<String>,
    /// Magnetometer only: the rotation into the accelerometer frame, or why there is none.
    alignment: Option<Result<Alignment, String>>,
    /// Magnetometer only: the modelled field used as reference or for the radius check.
    field_model: Option<LocalField>,
    /// Magnetometer only: the fitted raw radius against the modelled field.
    radius_check: Option<RadiusCheck>,
}

impl SensorResult {
    /// A sensor refused before fitting (input checks), with the sentence saying why.
    fn refused(sensor: Sensor, recording: &Recording, reason: String) -> Self {
        Self {
            fit: Err(reason),
            ..Self::not_yet_fitted(sensor, recording)
        }
    }

    /// A sensor about to be fitted: counts and units are filled in by the fit.
    fn not_yet_fitted(sensor: Sensor, recording: &Recording) -> Self {
        Self {
            sensor,
            fit: Err("not fitted".to_string()),
            n_poses: 0,
            n_samples: 0,
            input_unit: recording.units.symbol(sensor),
            output_unit: String::new(),
            noise_floor: None,
            notes: Vec::new(),
            alignment: None,
            field_model: None,
            radius_check: None,
        }
    }

    /// Whether `A`'s entries still carry the fit's per-entry uncertainties (a rotated `A` does
    /// not: its uncertainty is the rotation's, reported with the alignment).
    fn a_std_applies(&self) -> bool {
        !matches!(self.alignment, Some(Ok(_)))
    }
}

/// The magnetometer's reference field: from `--field-ut`, else from the model at `--location`.
struct FieldReference {
    /// Magnitude in µT, if known.
    ut: Option<f64>,
    /// The World Magnetic Model's field at `--location` today, if a location was given.
    model: Option<LocalField>,
}

fn row_major(m: &imucal::fit::Mat3) -> Vec<f64> {
    (0..3)
        .flat_map(|r| (0..3).map(move |c| m[(r, c)]))
        .collect()
}

fn requested(args: &FitArgs, recording: &Recording) -> anyhow::Result<Vec<Sensor>> {
    let wanted = match args.sensor {
        SensorChoice::Accel => vec![Sensor::Accel],
        SensorChoice::Gyro => vec![Sensor::Gyro],
        SensorChoice::Mag => vec![Sensor::Mag],
        SensorChoice::All => recording.sensors(),
    };
    for sensor in &wanted {
        if !recording.has(*sensor) {
            bail!(
                "`{}` has no {sensor} data (columns {}); choose another --sensor",
                recording.source.display(),
                sensor.columns().join(" ")
            );
        }
    }
    if wanted.is_empty() {
        bail!("`{}` has no sensor data", recording.source.display());
    }
    Ok(wanted)
}

fn method_for(args: &FitArgs, sensor: Sensor) -> anyhow::Result<Method> {
    let offered: &[Method] = match sensor {
        Sensor::Accel => &methods::ACCEL_METHODS,
        Sensor::Gyro => &methods::GYRO_METHODS,
        Sensor::Mag => &methods::MAG_METHODS,
    };
    let Some(name) = &args.method else {
        return Ok(offered[0]);
    };
    let method = methods::method_by_name(name).with_context(|| {
        let all: Vec<&str> = methods::ALL_METHODS.iter().map(|m| m.name()).collect();
        format!("unknown method `{name}`; choose one of {}", all.join(", "))
    })?;
    if !offered.contains(&method) {
        let names: Vec<&str> = offered.iter().map(|m| m.name()).collect();
        bail!(
            "method `{name}` does not apply to the {sensor}; for the {sensor} choose one of {}",
            names.join(", ")
        );
    }
    Ok(method)
}

/// Expected relative residual of a norm fit from the pose noise: the standard error of each
/// pose mean divided by its distance from the offset.
fn pose_noise_floor(poses: &[Pose], fit: &Fit) -> Option<f64> {
    let values: Vec<f64> = poses
        .iter()
        .map(|p| {
            let se = (p.var_of_mean().sum() / 3.0).sqrt();
            se / (p.mean - fit.cal.b).norm()
        })
        .filter(|v| v.is_finite())
        .collect();
    (!values.is_empty())
        .then(|| (values.iter().map(|v| v * v).sum::<f64>() / values.len() as f64).sqrt())
}

/// Fit one sensor that passed the input checks with `method` (`None`: the default chain).
fn fit_sensor(
    args: &FitArgs,
    recording: &Recording,
    still: Option<&StillReport>,
    field: &FieldReference,
    sensor: Sensor,
    method: Option<Method>,
) -> SensorResult {
    let mut result = SensorResult::not_yet_fitted(sensor, recording);
    match sensor {
        Sensor::Accel | Sensor::Gyro => {
            let Some(still) = still else {
                result.fit = Err("still intervals are needed for this sensor".to_string());
                return result;
            };
            let poses = still.poses(sensor);
            result.n_poses = poses.len();
            result.n_samples = poses.iter().map(|p| p.n).sum();
            let fit = if sensor == Sensor::Accel {
                result.output_unit = "m/s²".to_string();
                let (fit, note) = match method {
                    Some(m) => (methods::fit_accel(m, &poses, args.gravity), None),
                    None => {
                        methods::default_accel_fit(&poses, args.gravity, still.directions.len())
                    }
                };
                result.notes.extend(note);
                if let Ok(f) = &fit {
                    result.noise_floor = pose_noise_floor(&poses, f);
                }
                fit
            } else {
                let (scale, unit) = match (recording.units.to_si(Sensor::Gyro), args.gyro_scale) {
                    (Some(s), _) | (None, Some(s)) => (s, "rad/s"),
                    (None, None) => (1.0, "counts (no --gyro-scale given)"),
                };
                result.output_unit = unit.to_string();
                match method.unwrap_or(Method::GyroBias) {
                    Method::GyroScale => gyro_scale_fit(recording, still, args.gravity, scale),
                    m => methods::fit_gyro(m, &poses, scale),
                }
            };
            result.fit = fit.map_err(|e| e.to_string());
        }
        Sensor::Mag => {
            let all = recording.samples(Sensor::Mag).unwrap_or(&[]);
            let points: Vec<Vec3> = methods::thin(all, args.max_mag_samples);
            result.n_samples = points.len();
            result.output_unit = match field.ut {
                Some(_) => "µT".to_string(),
                None => "field = 1".to_string(),
            };
            result.field_model = field.model;
            let fit = methods::fit_mag(
                method.unwrap_or(Method::Lm),
                &points,
                field.ut.unwrap_or(1.0),
            );
            if let (Ok(f), Some(model), Some(to_ut)) =
                (&fit, &field.model, recording.units.mag.to_si())
            {
                // Mean distance of the raw readings from the fitted offset: the sphere's radius.
                let radius = points.iter().map(|p| (p - f.cal.b).norm()).sum::<f64>()
                    / points.len().max(1) as f64;
                let check = RadiusCheck::new(radius * to_ut, model);
                result.notes.push(check.sentence());
                result.radius_check = Some(check);
            }
            result.fit = fit.map_err(|e| e.to_string());
        }
    }
    result
}

/// Tedaldi's gyroscope scale: gravity directions from the default accelerometer fit, then the
/// motions between the holds.
fn gyro_scale_fit(
    recording: &Recording,
    still: &StillReport,
    gravity: f64,
    scale: f64,
) -> Result<Fit, FitError> {
    let accel_poses = still.poses(Sensor::Accel);
    let (accel, _) = methods::default_accel_fit(&accel_poses, gravity, still.directions.len());
    imucal::still::motions::fit_gyro_scale_recording(recording, still, &accel?.cal, scale)
}

/// Rotate the magnetometer fit into the accelerometer frame from the still holds that have
/// both sensors: calibrated gravity directions against calibrated field means.
fn align_mag(still: &StillReport, accel: &Fit, mag: &Fit) -> Result<Alignment, String> {
    let (gravity, field): (Vec<Vec3>, Vec<Vec3>) = still
        .intervals
        .iter()
        .filter_map(|i| {
            Some((
                accel.cal.apply(&i.accel.as_ref()?.mean),
                mag.cal.apply(&i.mag.as_ref()?.mean),
            ))
        })
        .unzip();
    fit_alignment(&gravity, &field).map_err(|e| e.to_string())
}

/// Rotation angle and axis of an alignment, with the angle's one-sigma uncertainty (the
/// rotation-vector covariance projected on the axis; a left perturbation `exp([δw]×)·R` changes
/// the angle by `axis·δw` to first order).
fn angle_axis(alignment: &Alignment) -> (f64, Vec3, Option<f64>) {
    let rotation = Rotation3::from_matrix_unchecked(alignment.rotation);
    let (axis, angle) = rotation
        .axis_angle()
        .map_or((Vec3::z(), 0.0), |(axis, angle)| (axis.into_inner(), angle));
    let std = alignment.covariance.as_ref().and_then(|c| {
        (c.nrows() >= 3 && c.ncols() >= 3).then(|| {
            let block = c.fixed_view::<3, 3>(0, 0);
            (axis.transpose() * block * axis)[(0, 0)].max(0.0).sqrt()
        })
    });
    (angle, axis, std)
}

fn alignment_json(outcome: &Result<Alignment, String>) -> Value {
    match outcome {
        Err(e) => json!({"error": e, "applied": false}),
        Ok(al) => {
            let (angle, axis, angle_std) = angle_axis(al);
            let rows: Vec<Vec<f64>> = (0..3)
                .map(|r| (0..3).map(|c| al.rotation[(r, c)]).collect())
                .collect();
            json!({
                "applied": true,
                "rotation": rows,
                "angle_deg": angle.to_degrees(),
                "angle_std_deg": angle_std.map(f64::to_degrees),
                "axis": [axis.x, axis.y, axis.z],
                "dip_deg": al.dip.to_degrees(),
                "dip_std_deg": al.dip_std.to_degrees(),
                "rms": al.rms,
            })
        }
    }
}

/// A short judgement of a fit: residual against the noise floor, and held-out error against fit error.
fn verdict(result: &SensorResult, fit: &Fit) -> String {
    let mut parts = Vec::new();
    if let Some(floor) = result.noise_floor.filter(|f| *f > 0.0) {
        let ratio = fit.rms / floor;
        if ratio <= 3.0 {
            parts.push(format!(
                "residual is at the noise floor ({ratio:.1}× the pose noise)"
            ));
        } else {
            parts.push(format!(
                "residual is {ratio:.0}× the pose noise: the model misses something (temperature, non-linearity, motion during holds)"
            ));
        }
    }
    if let Some(loo) = fit.loo_rms {
        if fit.rms > 0.0 && loo > 3.0 * fit.rms {
            parts.push(format!(
                "held-out error is {:.1}× the fit error: more poses are needed",
                loo / fit.rms
            ));
        } else {
            parts.push("held-out error agrees with the fit error".to_string());
        }
    }
    if result.sensor == Sensor::Mag {
        parts.push(format!(
            "{} samples over the sphere; no noise floor for moving samples",
            result.n_samples
        ));
    }
    if parts.is_empty() {
        "fitted".to_string()
    } else {
        parts.join("; ")
    }
}

fn to_json(result: &SensorResult) -> Value {
    let note = (!result.notes.is_empty()).then(|| result.notes.join("; "));
    let mut object = match &result.fit {
        Err(e) => json!({"error": e, "n_poses": result.n_poses, "n_samples": result.n_samples}),
        Ok(fit) => json!({
            "method": fit.method.name(),
            "A": row_major(&fit.cal.a),
            "b": [fit.cal.b.x, fit.cal.b.y, fit.cal.b.z],
            "rms": fit.rms,
            "loo_rms": fit.loo_rms,
            "n_poses": result.n_poses,
            "n_samples": result.n_samples,
            "param_std": fit.std.map(|s| json!({
                "A": result.a_std_applies().then(|| row_major(&s.a)),
                "b": [s.b.x, s.b.y, s.b.z],
            })),
            "reference": fit.reference,
            "input_unit": result.input_unit,
            "output_unit": result.output_unit,
            "condition_number": fit.condition_number,
            "iterations": fit.iterations,
            "verdict": verdict(result, fit),
            "note": note,
        }),
    };
    if let Some(map) = object.as_object_mut() {
        if let Some(alignment) = &result.alignment {
            map.insert("alignment".into(), alignment_json(alignment));
        }
        if let Some(model) = &result.field_model {
            map.insert("field_model".into(), json!(model));
        }
        if let Some(check) = &result.radius_check {
            map.insert("radius_check".into(), json!(check));
        }
    }
    object
}

/// A number with 7 significant digits: fixed point for ordinary magnitudes, scientific for
/// very small or large ones (calibrations from raw counts have entries like 2.4e-3).
fn number(value: f64) -> String {
    let magnitude = value.abs();
    if value == 0.0 || (1e-2..1e5).contains(&magnitude) {
        format!("{value:.6}")
    } else {
        format!("{value:.6e}")
    }
}

fn with_std(value: f64, std: Option<f64>) -> String {
    match std {
        Some(s) => format!("{:>14} ± {s:<9.2e}", number(value)),
        None => format!("{:>14}            ", number(value)),
    }
}

fn print_alignment(outcome: &Result<Alignment, String>) {
    match outcome {
        Err(e) => println!(
            "  not aligned to the accelerometer ({e}); A is left in the magnetometer's own frame"
        ),
        Ok(al) => {
            let (angle, axis, angle_std) = angle_axis(al);
            let angle_std =
                angle_std.map_or("n/a".to_string(), |s| format!("{:.2}°", s.to_degrees()));
            println!(
                "  aligned to the accelerometer: rotated {:.2}° ± {angle_std} about ({:.3}, {:.3}, {:.3}); dip {:.2}° ± {:.2}°; A is in the accelerometer frame (its uncertainty is the rotation's)",
                angle.to_degrees(),
                axis.x,
                axis.y,
                axis.z,
                al.dip.to_degrees(),
                al.dip_std.to_degrees()
            );
        }
    }
}

fn print_table(recording: &Recording, still: Option<&StillReport>, results: &[SensorResult]) {
    println!("{}", recording.source.display());
    if let Some(still) = still {
        println!("  {}", still.summary());
    }
    for result in results {
        println!();
        for note in &result.notes {
            println!("{}: {note}", result.sensor);
        }
        let fit = match &result.fit {
            Err(e) => {
                println!("{}: not fitted: {e}", result.sensor);
                continue;
            }
            Ok(fit) => fit,
        };
        let rms_unit = if result.sensor == Sensor::Gyro {
            result.output_unit.as_str()
        } else {
            "relative"
        };
        println!(
            "{} — method {} — {} poses, {} samples — {} → {} (y = A·(x − b))",
            result.sensor,
            fit.method.name(),
            result.n_poses,
            result.n_samples,
            result.input_unit,
            result.output_unit
        );
        let a_std = fit.std.filter(|_| result.a_std_applies());
        for r in 0..3 {
            let a: Vec<String> = (0..3)
                .map(|c| with_std(fit.cal.a[(r, c)], a_std.map(|s| s.a[(r, c)])))
                .collect();
            println!(
                "  A[{r}] {}   b[{r}] {}",
                a.join(" "),
                with_std(fit.cal.b[r], fit.std.map(|s| s.b[r]))
            );
        }
        let loo = fit
            .loo_rms
            .map_or("n/a".to_string(), |l| format!("{l:.3e}"));
        println!(
            "  RMS {:.3e} ({rms_unit})   leave-one-out RMS {loo}   condition {:.1e}",
            fit.rms, fit.condition_number
        );
        if let Some(alignment) = &result.alignment {
            print_alignment(alignment);
        }
        println!("  verdict: {}", verdict(result, fit));
    }
}

/// Still intervals with the holds that cannot be used left out; refuses (for every sensor
/// that needs them) when none is found or none is usable. Returns warnings.
fn still_intervals(
    args: &FitArgs,
    recording: &Recording,
) -> Result<(StillReport, Vec<String>), String> {
    let mut still = find_still(recording, &super::still_options(&args.input))
        .map_err(|e| format!("still intervals could not be found: {e}"))?;
    input_checks::require_still(recording, &still, args.input.min_hold)
        .map_err(|e| e.to_string())?;
    let warnings = input_checks::screen_holds(recording, &mut still, args.input.direction_angle)
        .map_err(|e| e.to_string())?;
    Ok((still, warnings))
}

/// The magnetometer reference: `--field-ut`, else the model's field at `--location` today.
fn field_reference(args: &FitArgs, location: Option<&Location>) -> anyhow::Result<FieldReference> {
    let model = location
        .map(geomag::local_field_today)
        .transpose()
        .context("the field at --location could not be modelled")?;
    Ok(FieldReference {
        ut: args.field_ut.or(model.map(|m| m.total_ut)),
        model,
    })
}

/// Run the command.
pub fn run(args: &FitArgs) -> anyhow::Result<()> {
    if !(args.gravity.is_finite() && args.gravity > 0.0) {
        bail!(
            "--gravity {} is not a positive number of m/s²",
            args.gravity
        );
    }
    if let Some(h) = args.field_ut {
        if !(h.is_finite() && h > 0.0) {
            bail!("--field-ut {h} is not a positive field magnitude");
        }
    }
    if let Some(s) = args.gyro_scale {
        if !(s.is_finite() && s > 0.0) {
            bail!("--gyro-scale {s} is not a positive number of rad/s per count");
        }
    }
    let recording = super::load(&args.input)?;
    let sensors = requested(args, &recording)?;
    // A wrong --method is an argument error: report it before anything about the data.
    let chosen: Vec<Option<Method>> = sensors
        .iter()
        .map(|s| {
            args.method
                .as_ref()
                .map(|_| method_for(args, *s))
                .transpose()
        })
        .collect::<anyhow::Result<_>>()?;
    let field = if sensors.contains(&Sensor::Mag) {
        field_reference(args, args.location.as_ref())?
    } else {
        FieldReference {
            ut: args.field_ut,
            model: None,
        }
    };

    // Input checks: a refusal concerns only the sensor(s) it names.
    let mut refusals: Vec<(Sensor, String)> = Vec::new();
    let mut warnings = Vec::new();
    if let (true, Some(accel)) = (sensors.contains(&Sensor::Accel), &recording.accel) {
        if let Err(e) = input_checks::check_accel_unit(accel, recording.units.accel) {
            refusals.push((Sensor::Accel, e.to_string()));
        }
    }
    if sensors.contains(&Sensor::Mag) {
        let all = recording.samples(Sensor::Mag).unwrap_or(&[]);
        let points = methods::thin(all, args.max_mag_samples);
        // Only a field stated on the command line is refused when the data contradict it; a
        // modelled one is compared with the fitted radius instead.
        let checked = input_checks::check_mag_coverage(&points).and_then(|()| {
            input_checks::check_mag_field(&points, recording.units.mag, args.field_ut)
        });
        match checked {
            Ok(w) => warnings.extend(w),
            Err(e) => refusals.push((Sensor::Mag, e.to_string())),
        }
    }
    let inertial: Vec<Sensor> = sensors
        .iter()
        .copied()
        .filter(|s| *s != Sensor::Mag)
        .collect();
    let still = if inertial.is_empty() {
        None
    } else {
        match still_intervals(args, &recording) {
            Ok((still, w)) => {
                warnings.extend(w);
                Some(still)
            }
            Err(reason) => {
                refusals.extend(inertial.iter().map(|s| (*s, reason.clone())));
                None
            }
        }
    };
    if let Some(still) = &still {
        if inertial.contains(&Sensor::Gyro) {
            if let Err(e) = input_checks::check_gyro_unit(&recording, still) {
                refusals.push((Sensor::Gyro, e.to_string()));
            }
        }
        if inertial.contains(&Sensor::Accel) {
            if let Err(e) = input_checks::check_accel_poses(still) {
                refusals.push((Sensor::Accel, e.to_string()));
            }
        }
    }
    for warning in &warnings {
        eprintln!("imucal: warning: {warning}");
    }

    let mut results: Vec<SensorResult> = sensors
        .iter()
        .zip(&chosen)
        .map(
            |(sensor, method)| match refusals.iter().find(|(s, _)| s == sensor) {
                Some((_, reason)) => SensorResult::refused(*sensor, &recording, reason.clone()),
                None => fit_sensor(args, &recording, still.as_ref(), &field, *sensor, *method),
            },
        )
        .collect();

    // Magnetometer into the accelerometer frame, when both were fitted.
    let accel_fit = results
        .iter()
        .find(|r| r.sensor == Sensor::Accel)
        .and_then(|r| r.fit.as_ref().ok().cloned());
    let accel_requested = sensors.contains(&Sensor::Accel);
    if let Some(mag) = results.iter_mut().find(|r| r.sensor == Sensor::Mag) {
        if let (true, Ok(mag_fit)) = (accel_requested, &mut mag.fit) {
            let outcome = match (&accel_fit, &still) {
                (Some(accel_fit), Some(still)) => align_mag(still, accel_fit, mag_fit),
                _ => Err("the accelerometer was not fitted".to_string()),
            };
            if let Ok(alignment) = &outcome {
                mag_fit.cal = alignment.apply_to(&mag_fit.cal);
            }
            mag.alignment = Some(outcome);
        }
    }

    if args.json {
        let object: serde_json::Map<String, Value> = results
            .iter()
            .map(|r| (r.sensor.name().to_string(), to_json(r)))
            .collect();
        println!("{}", serde_json::to_string_pretty(&Value::Object(object))?);
    } else {
        print_table(&recording, still.as_ref(), &results);
    }
    let failed: Vec<String> = results
        .iter()
        .filter_map(|r| r.fit.as_ref().err().map(|e| format!("{}: {e}", r.sensor)))
        .collect();
    if !failed.is_empty() {
        bail!(
            "{} could not be fitted ({})",
            if failed.len() == 1 {
                "one sensor"
            } else {
                "some sensors"
            },
            failed.join("; ")
        );
    }
    Ok(())
}
