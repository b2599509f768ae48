//! `imucal fit`: fit each requested sensor of a recording and print a table or JSON.
//!
//! Accelerometer and gyroscope fits use still-interval poses (from a `pose` column or
//! detected); the magnetometer uses all its samples (it needs orientation coverage, which
//! still holds do not give), evenly thinned to a bounded number.

use anyhow::{bail, Context};
use imucal::fit::{Fit, Method, Pose, Vec3};
use imucal::input_checks;
use imucal::recording::{Recording, Sensor};
use imucal::still::{find_still, StillReport};
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
    /// Why a method other than the default was used.
    note: Option<String>,
}

/// Unknowns of the norm model with the upper-triangular gauge: it needs this many distinct
/// directions.
const NORM_MODEL_UNKNOWNS: usize = 9;

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

fn fit_sensor(
    args: &FitArgs,
    recording: &Recording,
    still: Option<&StillReport>,
    sensor: Sensor,
) -> anyhow::Result<SensorResult> {
    let mut method = method_for(args, sensor)?;
    let mut note = None;
    if let (Sensor::Accel, None, Some(still)) = (sensor, &args.method, still) {
        let directions = still.directions.len();
        if directions < NORM_MODEL_UNKNOWNS {
            method = Method::SixPosition;
            note = Some(format!(
                "lm needs at least {NORM_MODEL_UNKNOWNS} distinct directions and {directions} were found, so the six-position method was used"
            ));
        }
    }
    let input_unit = recording.units.symbol(sensor);
    Ok(match sensor {
        Sensor::Accel | Sensor::Gyro => {
            let still = still.context("still intervals are needed for this sensor")?;
            let poses = still.poses(sensor);
            let n_samples = poses.iter().map(|p| p.n).sum();
            let (fit, output_unit) = if sensor == Sensor::Accel {
                (
                    methods::fit_accel(method, &poses, args.gravity),
                    "m/s²".to_string(),
                )
            } else {
                let (scale, unit) = match (recording.units.to_si(Sensor::Gyro), args.gyro_scale) {
                    (Some(s), _) => (s, "rad/s".to_string()),
                    (None, Some(s)) => (s, "rad/s".to_string()),
                    (None, None) => (1.0, "counts (no --gyro-scale given)".to_string()),
                };
                let fit = if method == Method::GyroScale {
                    gyro_scale_fit(recording, still, args.gravity, scale)
                } else {
                    methods::fit_gyro(method, &poses, scale)
                };
                (fit, unit)
            };
            let noise_floor = match (&fit, sensor) {
                (Ok(f), Sensor::Accel) => pose_noise_floor(&poses, f),
                _ => None,
            };
            SensorResult {
                sensor,
                fit: fit.map_err(|e| e.to_string()),
                n_poses: poses.len(),
                n_samples,
                input_unit,
                output_unit,
                noise_floor,
                note,
            }
        }
        Sensor::Mag => {
            let all = recording.samples(Sensor::Mag).unwrap_or(&[]);
            let points: Vec<Vec3> = methods::thin(all, args.max_mag_samples);
            let reference = args.field_ut.unwrap_or(1.0);
            let output_unit = if args.field_ut.is_some() {
                "µT".to_string()
            } else {
                "field = 1".to_string()
            };
            let fit = methods::fit_mag(method, &points, reference);
            SensorResult {
                sensor,
                fit: fit.map_err(|e| e.to_string()),
                n_poses: 0,
                n_samples: points.len(),
                input_unit,
                output_unit,
                noise_floor: None,
                note,
            }
        }
    })
}

/// Tedaldi's gyroscope scale: gravity directions from the default accelerometer fit (lm, or the
/// six-position fit when lm refuses), then the motions between the holds.
fn gyro_scale_fit(
    recording: &Recording,
    still: &StillReport,
    gravity: f64,
    scale: f64,
) -> Result<Fit, imucal::fit::FitError> {
    let accel_poses = still.poses(Sensor::Accel);
    let accel = methods::fit_accel(Method::Lm, &accel_poses, gravity)
        .or_else(|_| methods::fit_accel(Method::SixPosition, &accel_poses, gravity))?;
    imucal::fit::gyro_scale::fit_gyro_scale_recording(recording, still, &accel.cal, scale)
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
    match &result.fit {
        Err(e) => json!({"error": e, "n_poses": result.n_poses, "n_samples": result.n_samples}),
        Ok(fit) => json!({
            "method": fit.method.name(),
            "A": row_major(&fit.cal.a),
            "b": [fit.cal.b.x, fit.cal.b.y, fit.cal.b.z],
            "rms": fit.rms,
            "loo_rms": fit.loo_rms,
            "n_poses": result.n_poses,
            "n_samples": result.n_samples,
            "param_std": fit.std.map(|s| json!({"A": row_major(&s.a), "b": [s.b.x, s.b.y, s.b.z]})),
            "reference": fit.reference,
            "input_unit": result.input_unit,
            "output_unit": result.output_unit,
            "condition_number": fit.condition_number,
            "iterations": fit.iterations,
            "verdict": verdict(result, fit),
            "note": result.note,
        }),
    }
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

fn print_table(recording: &Recording, still: Option<&StillReport>, results: &[SensorResult]) {
    println!("{}", recording.source.display());
    if let Some(still) = still {
        println!("  {}", still.summary());
    }
    for result in results {
        println!();
        if let Some(note) = &result.note {
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
        for r in 0..3 {
            let a: Vec<String> = (0..3)
                .map(|c| with_std(fit.cal.a[(r, c)], fit.std.map(|s| s.a[(r, c)])))
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
        println!("  verdict: {}", verdict(result, fit));
    }
}

/// Checks that need no still intervals: the accelerometer's unit, and the magnetometer's
/// coverage, unit and field magnitude (on the samples the fit will use). Returns warnings.
fn check_inputs(
    args: &FitArgs,
    recording: &Recording,
    sensors: &[Sensor],
) -> anyhow::Result<Vec<String>> {
    let mut warnings = Vec::new();
    if sensors.contains(&Sensor::Accel) {
        if let Some(accel) = &recording.accel {
            input_checks::check_accel_unit(accel, recording.units.accel)?;
        }
    }
    if sensors.contains(&Sensor::Mag) {
        let all = recording.samples(Sensor::Mag).unwrap_or(&[]);
        let points = methods::thin(all, args.max_mag_samples);
        input_checks::check_mag_coverage(&points)?;
        warnings.extend(input_checks::check_mag_field(
            &points,
            recording.units.mag,
            args.field_ut,
        )?);
    }
    Ok(warnings)
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
    for sensor in &sensors {
        method_for(args, *sensor)?;
    }
    let mut warnings = check_inputs(args, &recording, &sensors)?;
    let needs_still = sensors.iter().any(|s| *s != Sensor::Mag);
    let still = if needs_still {
        let mut still = find_still(&recording, &super::still_options(&args.input))
            .context("still intervals could not be found")?;
        input_checks::require_still(&recording, &still, args.input.min_hold)?;
        warnings.extend(input_checks::screen_holds(
            &recording,
            &mut still,
            args.input.direction_angle,
        )?);
        if sensors.contains(&Sensor::Gyro) {
            input_checks::check_gyro_unit(&recording, &still)?;
        }
        if sensors.contains(&Sensor::Accel) {
            input_checks::check_accel_poses(&still)?;
        }
        Some(still)
    } else {
        None
    };
    for warning in &warnings {
        eprintln!("imucal: warning: {warning}");
    }
    let results = sensors
        .iter()
        .map(|s| fit_sensor(args, &recording, still.as_ref(), *s))
        .collect::<anyhow::Result<Vec<_>>>()?;
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
