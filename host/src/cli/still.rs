//! `imucal still`: list the still intervals of a recording and the directions they cover.

use imucal::fit::Vec3;
use imucal::input_checks::time_stamp_warnings;
use imucal::pipeline::{check_input, still_intervals, InputOptions};
use imucal::recording::{Recording, Sensor};
use imucal::still::StillReport;
use serde_json::{json, Value};

use super::args::StillArgs;

fn triple(v: &Vec3) -> [f64; 3] {
    [v.x, v.y, v.z]
}

/// `why` as the command's error, once `warnings` are printed: they may be why nothing was found.
fn said_then(warnings: &[String], why: String) -> anyhow::Error {
    for warning in warnings {
        say!("imucal: warning: {warning}");
    }
    anyhow::Error::msg(why)
}

/// The still intervals of `recording` with the warnings to print, through the checks `fit`,
/// `analyze` and `report` make (the same pipeline function: the same intervals, screened alike,
/// the same warnings). A magnetometer-only recording has its holds found from the field's
/// variance, without the inertial checks.
fn checked_still(
    recording: Recording,
    options: InputOptions,
) -> anyhow::Result<(Recording, StillReport, Vec<String>)> {
    let sensors: Vec<Sensor> = [Sensor::Accel, Sensor::Gyro]
        .into_iter()
        .filter(|s| recording.has(*s))
        .collect();
    if sensors.is_empty() {
        let mut warnings = if recording.time_from_file {
            time_stamp_warnings(&recording.time)
        } else {
            Vec::new()
        };
        let (report, still_warnings) =
            still_intervals(&recording, &options.still).map_err(|why| said_then(&warnings, why))?;
        warnings.extend(still_warnings);
        return Ok((recording, report, warnings));
    }
    let input = check_input(recording, &sensors, &options, None);
    let mut warnings = input.warnings.clone();
    let Some(report) = input.still.clone() else {
        let why = input.refusals.iter().find_map(|(_, reason)| {
            (!input.unit_refusals.iter().any(|(_, u)| u == reason)).then(|| reason.clone())
        });
        return Err(said_then(
            &warnings,
            why.unwrap_or_else(|| "still intervals could not be found".to_string()),
        ));
    };
    // This command lists the holds all the same, in the declared units, and says what the
    // other commands refuse a sensor for.
    for (sensor, problem) in &input.refusals {
        let unit = input.unit_refusals.iter().any(|(s, _)| s == sensor);
        warnings.push(format!(
            "{problem} (fit, analyze and report refuse the sensor for this{})",
            if unit {
                "; the figures below are in the declared unit"
            } else {
                ""
            }
        ));
    }
    Ok((input.recording, report, warnings))
}

/// Run the command.
pub fn run(args: &StillArgs) -> anyhow::Result<()> {
    let recording = super::load(&args.input, None, None)?;
    let options = InputOptions {
        still: super::still_options(&args.input),
        ..InputOptions::default()
    };
    let (recording, report, warnings) = checked_still(recording, options)?;
    for warning in &warnings {
        say!("imucal: warning: {warning}");
    }
    if args.json {
        let intervals: Vec<_> = report
            .intervals
            .iter()
            .map(|i| {
                json!({
                    "number": i.number, "t_start": i.t_start, "t_end": i.t_end, "label": i.label,
                    "label_name": i.label_name.as_ref().map(|l| l.text.clone()),
                    "direction": i.direction,
                    "accel_mean": i.accel.as_ref().map(|p| triple(&p.mean)),
                    "gyro_mean": i.gyro.as_ref().map(|p| triple(&p.mean)),
                    "mag_mean": i.mag.as_ref().map(|p| triple(&p.mean)),
                    "n": i.accel.as_ref().or(i.gyro.as_ref()).or(i.mag.as_ref()).map(|p| p.n),
                    "temp_c": i.temp.map(|t| json!({"mean": t.mean, "min": t.min, "max": t.max})),
                })
            })
            .collect();
        let noise: Vec<_> = report
            .noise
            .iter()
            .map(|n| {
                json!({"sensor": n.sensor.name(), "sigma": triple(&n.sigma),
                "unit": recording.units.symbol(n.sensor), "margin": n.margin})
            })
            .collect();
        // The means and noise are in the data's own units, which this names per sensor.
        let units: serde_json::Map<String, Value> = Sensor::ALL
            .iter()
            .filter(|s| recording.samples(**s).is_some())
            .map(|s| {
                (
                    format!("{}_mean", s.name()),
                    json!(recording.units.symbol(*s)),
                )
            })
            .collect();
        let directions: Vec<_> = report.directions.iter().map(triple).collect();
        // The window in the unit `--window` takes, and in rows as the detector used it.
        let window_s = report.window_s(&recording);
        let out = json!({
            "intervals": intervals, "directions": directions, "noise": noise,
            "units": units, "window_s": window_s, "window_samples": report.window,
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    println!("{}: {}", recording.source.display(), report.summary());
    for n in &report.noise {
        println!(
            "  {} noise σ = [{:.4}, {:.4}, {:.4}] {} per sample; stillness margin {:.1} over the χ² test",
            n.sensor,
            n.sigma.x,
            n.sigma.y,
            n.sigma.z,
            recording.units.symbol(n.sensor),
            n.margin
        );
    }
    // The mean shown is the accelerometer's, or the first sensor the recording has.
    let shown = [Sensor::Accel, Sensor::Mag, Sensor::Gyro]
        .into_iter()
        .find(|s| recording.samples(*s).is_some())
        .unwrap_or(Sensor::Accel);
    println!(
        "{:>3} {:>9} {:>9} {:>6} {:>6} {:>4}  {} mean ({})",
        "#",
        "t_start",
        "t_end",
        "dur",
        "label",
        "dir",
        shown.name(),
        recording.units.symbol(shown)
    );
    for i in &report.intervals {
        let label = i
            .label_name
            .as_ref()
            .map_or("-".to_string(), |l| l.text.clone());
        let dir = i.direction.map_or("-".to_string(), |d| d.to_string());
        let pose = match shown {
            Sensor::Accel => i.accel.as_ref(),
            Sensor::Mag => i.mag.as_ref(),
            Sensor::Gyro => i.gyro.as_ref(),
        };
        let mean = pose.map_or("-".to_string(), |p| {
            format!("[{:.4}, {:.4}, {:.4}]", p.mean.x, p.mean.y, p.mean.z)
        });
        println!(
            "{:>3} {:>9.2} {:>9.2} {:>6.1} {label:>6} {dir:>4}  {mean}",
            i.number,
            i.t_start,
            i.t_end,
            i.duration()
        );
    }
    Ok(())
}
