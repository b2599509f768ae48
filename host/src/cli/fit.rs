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

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{bail, Context};
use imucal::device::ParamsFile;
use imucal::fit::alignment::Alignment;
use imucal::fit::{Mat3, Method, Vec3};
use imucal::history::{CalibrationRecord, RecordSource};
use imucal::pipeline::chain::CandidateOutcome;
use imucal::pipeline::methods::method_for_sensor;
use imucal::pipeline::{
    check_and_calibrate, parameter_sigma, params_file, FitOptions, RecordingCalibration,
    SensorOutcome,
};
use imucal::recording::{Recording, Sensor};
use nalgebra::Rotation3;
use serde_json::{json, Value};

use imucal::report::gain::{gain, gain_text_of, Estimated};

use super::args::{FitArgs, SensorChoice};
use super::write_policy::{check_outputs, Output};
use super::UsageError;

/// A 3×3 matrix as rows, the layout of the parameter file.
fn rows(m: &Mat3) -> [[f64; 3]; 3] {
    [0, 1, 2].map(|r| [0, 1, 2].map(|c| m[(r, c)]))
}

/// The one sensor `--sensor` names; `None` for every sensor of the recording.
fn chosen_sensor(choice: SensorChoice) -> Option<Sensor> {
    match choice {
        SensorChoice::Accel => Some(Sensor::Accel),
        SensorChoice::Gyro => Some(Sensor::Gyro),
        SensorChoice::Mag => Some(Sensor::Mag),
        SensorChoice::All => None,
    }
}

fn requested(args: &FitArgs, recording: &Recording) -> anyhow::Result<Vec<Sensor>> {
    let wanted = match chosen_sensor(args.sensor) {
        Some(sensor) => vec![sensor],
        None => recording.sensors(),
    };
    for sensor in &wanted {
        let from_stdin = args.input.recording.as_os_str() == "-";
        if *sensor == Sensor::Mag && from_stdin && !recording.has(Sensor::Mag) {
            // The sibling `<name>_mag.csv` is looked for next to a file, and stdin has no name.
            bail!(
                "standard input has no mag data (columns {}), and a magnetometer file next to \
                 it (`<name>_mag.csv` beside a recording file) cannot be found for standard \
                 input; name that file with --mag-file, or choose another --sensor",
                sensor.columns().join(" ")
            );
        }
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

/// The method `name` for each of `sensors`. With every sensor of the recording (no --sensor),
/// it applies to the sensors it is a method for and the others keep their default (said in a
/// note); a sensor named with --sensor must take it.
fn methods_for(
    name: &str,
    sensors: &[Sensor],
    all_sensors: bool,
) -> anyhow::Result<Vec<(Sensor, Method)>> {
    let each: Vec<(Sensor, Result<Method, String>)> = sensors
        .iter()
        .map(|s| (*s, method_for_sensor(name, *s)))
        .collect();
    let applies: Vec<(Sensor, Method)> = each
        .iter()
        .filter_map(|(s, m)| m.as_ref().ok().map(|m| (*s, *m)))
        .collect();
    let first_refusal = each.iter().find_map(|(_, m)| m.as_ref().err());
    match first_refusal {
        None => Ok(applies),
        Some(why) if !all_sensors || applies.is_empty() => Err(UsageError(why.clone()).into()),
        Some(_) => {
            let others: Vec<&str> = each
                .iter()
                .filter(|(_, m)| m.is_err())
                .map(|(s, _)| s.name())
                .collect();
            say!(
                "imucal: note: --method {name} is fitted to the {}; the {} {} the default \
                 (choose the sensor with --sensor)",
                applies
                    .iter()
                    .map(|(s, _)| s.name())
                    .collect::<Vec<_>>()
                    .join(" and "),
                others.join(" and "),
                if others.len() == 1 { "keeps" } else { "keep" }
            );
            Ok(applies)
        }
    }
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

pub(super) fn to_json(result: &SensorOutcome) -> Value {
    let note = (!result.notes.is_empty()).then(|| result.notes.join("; "));
    let mut object = match &result.fit {
        Err(e) => json!({"error": e, "n_poses": result.n_poses, "n_samples": result.n_samples}),
        Ok(fit) => json!({
            "method": fit.method.name(),
            "A": rows(&fit.cal.a),
            "b": [fit.cal.b.x, fit.cal.b.y, fit.cal.b.z],
            "rms": fit.rms,
            "loo_rms": fit.loo_rms,
            "n_poses": result.n_poses,
            "n_samples": result.n_samples,
            "param_std": fit.std.map(|s| json!({
                "A": result.a_std_applies().then(|| rows(&s.a)),
                "b": [s.b.x, s.b.y, s.b.z],
            })),
            "reference": fit.reference,
            "input_unit": result.input_unit,
            "output_unit": result.output_unit,
            "condition_number": fit.condition_number,
            "iterations": fit.iterations,
            "termination": fit.termination.map(|t| t.name()),
            "coverage_factor": fit.coverage_factor,
            "noise_test": result.noise_test.map(|t| json!({
                "chi2": t.chi2,
                "dof": t.dof,
                "p_value": t.p_value,
                "consistent": t.consistent(),
            })),
            "verdict": result.verdict(),
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
        if let Some(chain) = &result.chain {
            map.insert("default_chain".into(), chain_json(chain));
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

fn alignment_text(out: &mut String, outcome: &Result<Alignment, String>) {
    match outcome {
        Err(e) => {
            _ = writeln!(
            out,
            "  not aligned to the accelerometer ({e}); A is left in the magnetometer's own frame"
        )
        }
        Ok(al) => {
            let (angle, axis, angle_std) = angle_axis(al);
            let angle_std =
                angle_std.map_or("n/a".to_string(), |s| format!("{:.2}°", s.to_degrees()));
            _ = writeln!(out,
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

/// The fit's table as `fit` prints it.
pub(super) fn print_table(calibration: &RecordingCalibration) {
    print!("{}", table_text(calibration));
}

/// The fit's table: per sensor its notes, parameters, residuals and verdict.
pub(super) fn table_text(calibration: &RecordingCalibration) -> String {
    let mut out = String::new();
    let file = params_file(calibration);
    _ = writeln!(out, "{}", calibration.provenance.source);
    if let Some(still) = &calibration.still_summary {
        _ = writeln!(out, "  {still}");
    }
    for result in &calibration.sensors {
        out.push('\n');
        for note in &result.notes {
            _ = writeln!(out, "{}: {note}", result.sensor);
        }
        let fit = match &result.fit {
            Err(_) => {
                // The reason is the error at the end (standard error), said once.
                _ = writeln!(
                    out,
                    "{}: not fitted (the reason follows at the end)",
                    result.sensor
                );
                continue;
            }
            Ok(fit) => fit,
        };
        let rms_unit = match (result.sensor, fit.method) {
            // Tedaldi's residuals are the angles left over each turn.
            (Sensor::Gyro, Method::GyroScale) => "rad, angle per turn",
            (Sensor::Gyro, _) => result.output_unit.as_str(),
            _ => "relative",
        };
        _ = writeln!(
            out,
            "{} — method {} — {}, {} — {} → {} (y = A·(x − b))",
            result.sensor,
            fit.method.name(),
            imucal::words::counted(result.n_poses, "pose"),
            imucal::words::counted(result.n_samples, "sample"),
            result.input_unit,
            result.output_unit
        );
        let a_std = fit.std.filter(|_| result.a_std_applies());
        for r in 0..3 {
            let a: Vec<String> = (0..3)
                .map(|c| with_std(fit.cal.a[(r, c)], a_std.map(|s| s.a[(r, c)])))
                .collect();
            _ = writeln!(
                out,
                "  A[{r}] {}   b[{r}] {}",
                a.join(" "),
                with_std(fit.cal.b[r], fit.std.map(|s| s.b[r]))
            );
        }
        if let Some(g) = result
            .to_nominal
            .filter(|_| !result.output_unit.contains("field"))
            .and_then(|k| gain(&fit.cal.a, k))
        {
            let estimated = Estimated::of(&fit.cal.a);
            _ = writeln!(out, "  {}", gain_text_of(&g, 3, estimated));
        }
        // The parameter file holds the fit for the board's nominal input unit: its numbers are
        // printed too, so that the table and the file show the same calibration.
        let (written, unit) = match result.sensor {
            Sensor::Accel => (&file.accel, "m/s²"),
            Sensor::Gyro => (&file.gyro, "rad/s"),
            Sensor::Mag => (&file.mag, "µT"),
        };
        let same = (0..3).all(|r| {
            written.b[r] == fit.cal.b[r] && (0..3).all(|c| written.a[r][c] == fit.cal.a[(r, c)])
        });
        if !file.not_fitted.contains_key(result.sensor.name()) && !same {
            _ = writeln!(
                out,
                "  as the parameter file holds it, for input in {unit}:"
            );
            for (r, row) in written.a.iter().enumerate() {
                let a: Vec<String> = row.iter().map(|v| format!("{:>14}", number(*v))).collect();
                _ = writeln!(
                    out,
                    "  A[{r}] {}   b[{r}] {:>14}",
                    a.join(" "),
                    number(written.b[r])
                );
            }
        }
        let loo = fit
            .loo_rms
            .map_or("n/a".to_string(), |l| format!("{l:.3e}"));
        _ = writeln!(
            out,
            "  RMS {:.3e} ({rms_unit})   leave-one-out RMS {loo}   condition {:.1e}",
            fit.rms, fit.condition_number
        );
        if let Some(alignment) = &result.alignment {
            alignment_text(&mut out, alignment);
        }
        _ = writeln!(out, "  verdict: {}", result.verdict().unwrap_or_default());
    }
    out
}

/// The default chain's candidates and choice, for `--json`.
fn chain_json(chain: &imucal::pipeline::ChainChoice) -> Value {
    let candidates: Vec<Value> = chain
        .candidates
        .iter()
        .map(|c| {
            let (status, detail, lopo_rms) = match &c.outcome {
                CandidateOutcome::Refused(e) => ("refused", Some(e.as_str()), None),
                CandidateOutcome::NotValidated(e) => ("not_validated", Some(e.as_str()), None),
                CandidateOutcome::Scored { lopo_rms, .. } => ("scored", None, Some(*lopo_rms)),
            };
            json!({
                "method": c.method.name(),
                "unknowns": imucal::pipeline::chain::unknowns(c.method),
                "status": status,
                "detail": detail,
                "lopo_rms": lopo_rms,
            })
        })
        .collect();
    json!({
        "chosen": chain.fit.method.name(),
        "rule": "leave-one-pose-out norm error, simplest model within one standard error of the \
                 best; min/max and axis-aligned enter as their mean unless a paired t test \
                 (two-sided, 5 %) tells them apart",
        "pair_test": chain.pair.map(|t| json!({
            "folds": t.folds,
            "t": if t.t.is_finite() { Some(t.t) } else { None },
            "p_value": t.p_value,
        })),
        "reason": chain.reason,
        "candidates": candidates,
    })
}

/// Write the parameter file (checked as an output before the fit), unless it would hold no
/// sensor at all: a file of identities would only overwrite a board's calibration. Returns the
/// file written.
fn write_params(file: ParamsFile, path: &Path) -> anyhow::Result<Option<ParamsFile>> {
    let left_out: Vec<String> = file
        .not_fitted
        .iter()
        .map(|(sensor, why)| format!("{sensor} ({why})"))
        .collect();
    if let Some(why) = file.holds_nothing() {
        say!("imucal: {} was not written: {why}", path.display());
        return Ok(None);
    }
    std::fs::write(path, file.to_json())
        .with_context(|| format!("could not write the parameter file `{}`", path.display()))?;
    let shown = path.display();
    // A board applies its set to m/s², rad/s and µT: a fit of raw counts is for export only.
    let raw: Vec<String> = file
        .non_nominal_inputs()
        .iter()
        .map(|(sensor, unit)| format!("{sensor} ({unit})"))
        .collect();
    let next = if raw.is_empty() {
        format!("`imucal export {shown} --format c-header` or `imucal flash {shown}` use it")
    } else {
        format!(
            "`imucal export {shown} --format c-header` uses it (not `imucal flash`: {} takes \
             raw readings, and a board applies its set to m/s², rad/s and µT)",
            raw.join(", ")
        )
    };
    say!(
        "imucal: wrote {shown}{}; {next}",
        if left_out.is_empty() {
            String::new()
        } else {
            format!(
                "; not in it (flashing keeps the board's own; export writes identity): {}",
                left_out.join("; ")
            )
        }
    );
    Ok(Some(file))
}

/// Sensors that were fitted but cannot go into the parameter file `file` (a gyroscope left in
/// counts, a magnetometer normalised to 1), each with the reason.
fn fitted_but_not_written(
    calibration: &RecordingCalibration,
    file: &ParamsFile,
    path: &Path,
) -> Vec<String> {
    calibration
        .sensors
        .iter()
        .filter(|outcome| outcome.fit.is_ok() && outcome.alignment_failure().is_none())
        .filter_map(|outcome| {
            let why = file.not_fitted.get(outcome.sensor.name())?;
            Some(format!(
                "{} fitted but not written to {}: {why}",
                outcome.sensor.name(),
                path.display()
            ))
        })
        .collect()
}

/// Record the fit written by --params-out in the history, with its parameters' uncertainty
/// (the fleet weighs a board's distance from the others by it).
fn record_fit(
    args: &FitArgs,
    file: ParamsFile,
    calibration: &RecordingCalibration,
) -> anyhow::Result<()> {
    let recording = &args.input.recording;
    let named = args
        .device
        .clone()
        .or_else(|| file.provenance.as_ref().and_then(|p| p.device_id.clone()));
    let device = match named {
        Some(device) => device,
        // Every piped recording would be one board `recording:-`, compared with the others.
        None if recording.as_os_str() == "-" => {
            say!(
                "imucal: note: not recorded in the calibration history: a recording read from \
                 standard input names no board; pass --device ID to record it"
            );
            return Ok(());
        }
        None => {
            let stem = recording.file_stem().unwrap_or(recording.as_os_str());
            format!(
                "{}{}",
                imucal::history::RECORDING_DEVICE_PREFIX,
                stem.to_string_lossy()
            )
        }
    };
    let crc = file
        .to_calibration_set(&recording.display().to_string())
        .map_or(0, |set| set.crc32());
    let mut record = CalibrationRecord::new(&device, RecordSource::Fit, file, crc);
    record.sigma = parameter_sigma(calibration);
    super::history::record(&args.history, record)
}

/// Run the command.
pub fn run(args: &FitArgs) -> anyhow::Result<()> {
    if let Some(path) = &args.params_out {
        if path.as_os_str() == "-" {
            bail!(
                "--params-out - would write a file named `-`: name a file (to see the fit on \
                 standard output, use --json)"
            );
        }
        check_outputs(
            &[Output::File(path)],
            &super::input_paths(&args.input),
            args.force,
        )?;
        super::history::check_before_writing(&args.history)?;
    }
    let references = super::references(&args.reference)?;
    // A method named for one sensor is checked before the data are read.
    if let (Some(name), Some(sensor)) = (&args.method, chosen_sensor(args.sensor)) {
        methods_for(name, &[sensor], false)?;
    }
    let recording = super::load(
        &args.input,
        args.reference.gyro_scale,
        chosen_sensor(args.sensor),
    )?;
    let sensors = requested(args, &recording)?;
    // A wrong --method is an argument error: report it before anything about the data.
    let methods: Vec<(Sensor, Method)> = match &args.method {
        None => Vec::new(),
        Some(name) => methods_for(name, &sensors, args.sensor == SensorChoice::All)?,
    };
    let options = FitOptions {
        references: Some(references),
        location: args.reference.location,
        methods,
        device_id: args.device.clone(),
    };
    let (input, calibration) = check_and_calibrate(
        recording,
        &sensors,
        &super::input_options(&args.input, &args.reference),
        args.reference.field_ut,
        &options,
    )?;
    for warning in &input.warnings {
        say!("imucal: warning: {warning}");
    }
    if args.json {
        let object: serde_json::Map<String, Value> = calibration
            .sensors
            .iter()
            .map(|r| (r.sensor.name().to_string(), to_json(r)))
            .collect();
        println!("{}", serde_json::to_string_pretty(&Value::Object(object))?);
    } else {
        print_table(&calibration);
    }
    // Recorded once the parameter file holds the fit; a failure is returned last.
    let mut failed = calibration.failures();
    let recorded = match &args.params_out {
        Some(path) => {
            let file = params_file(&calibration);
            // The bounds every path that writes a set applies: here they warn, as `flash` and
            // `calibrate` refuse such a file without --accept-outlier.
            for finding in imucal::history::part_limits::beyond_part_limits_of(&file) {
                say!(
                    "imucal: warning: {}{}",
                    finding.phrase(),
                    if finding.refuses {
                        "; `imucal flash` refuses this file without --accept-outlier"
                    } else {
                        ""
                    }
                );
            }
            // A fit that cannot go into the file fails the command when nothing else does (a
            // partial file says in its `not_fitted` what it leaves out).
            if file.holds_nothing().is_some() {
                failed.extend(fitted_but_not_written(&calibration, &file, path));
            }
            match write_params(file, path)? {
                Some(file) => record_fit(args, file, &calibration),
                None => Ok(()),
            }
        }
        None => Ok(()),
    };
    if !failed.is_empty() {
        bail!("{}", failed.join("; "));
    }
    recorded
}
