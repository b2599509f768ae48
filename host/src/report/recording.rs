//! A report of a recording: the pipeline's calibration ([`crate::pipeline`]) laid out as
//! [`ReportData`] — pose means and magnetometer samples before and after, the parameters, the
//! chain's choice and the checks' findings.

use crate::fit::{Calibration, Fit, Vec3};
use crate::geomag::LocalField;
use crate::pipeline::calibration::once_per_reason;
use crate::pipeline::{CheckedInput, RecordingCalibration, SensorOutcome};
use crate::recording::Sensor;

use super::{
    ellipsoid_shape, numbered, up_label, AccelPoses, GyroPoses, MagSamples, ReportData,
    SensorParameters,
};

fn parameters(name: &str, outcome: &SensorOutcome, fit: &Fit) -> SensorParameters {
    SensorParameters {
        name: format!("{name} ({})", fit.method.name()),
        unit_in: outcome.input_unit.to_string(),
        unit_out: outcome.output_unit.clone(),
        a: fit.cal.a,
        b: fit.cal.b,
        std: fit.std.filter(|_| outcome.a_std_applies()),
        to_nominal: outcome
            .to_nominal
            .filter(|_| !outcome.output_unit.contains("field")),
    }
}

/// What the report shows of `calibration`, fitted from `input`.
pub fn from_calibration(
    input: &CheckedInput,
    calibration: &RecordingCalibration,
    field: Option<&LocalField>,
) -> ReportData {
    let mut data = ReportData {
        source: calibration.provenance.source.clone(),
        ..ReportData::default()
    };
    data.notes.extend(calibration.warnings.iter().cloned());
    let mut not_fitted: Vec<(&str, String)> = Vec::new();
    for outcome in &calibration.sensors {
        let name = match outcome.sensor {
            Sensor::Accel => "accelerometer",
            Sensor::Gyro => "gyroscope",
            Sensor::Mag => "magnetometer",
        };
        data.notes
            .extend(outcome.notes.iter().map(|n| format!("{name}: {n}")));
        let fit = match &outcome.fit {
            Ok(fit) => fit,
            Err(e) => {
                not_fitted.push((name, e.clone()));
                continue;
            }
        };
        data.parameters.push(parameters(name, outcome, fit));
        if let Some(verdict) = outcome.verdict() {
            data.verdict.push(format!("{name}: {verdict}"));
        }
        match outcome.sensor {
            Sensor::Accel => accel_poses(&mut data, input, calibration, fit),
            Sensor::Mag => mag_samples(&mut data, input, outcome, fit),
            Sensor::Gyro => gyro_poses(&mut data, input, calibration, outcome, fit),
        }
    }
    // The headline says how much of what was asked for is in the report.
    // and whether the fits found something to act on (each sensor's line below says what).
    let findings = calibration.sensors.iter().any(|o| o.has_findings());
    data.verdict_level = match (not_fitted.len(), calibration.sensors.len(), findings) {
        (0, _, false) => "fitted",
        (0, _, true) => "fitted, with findings",
        (n, all, _) if n < all => "partly fitted",
        _ => "not fitted",
    }
    .to_string();
    data.verdict.splice(0..0, not_fitted_once(&not_fitted));
    if let (Some(field), Some(mag)) = (field, calibration.sensor(Sensor::Mag)) {
        if mag.radius_check.is_none() && mag.fit.is_ok() {
            data.notes.push(format!(
                "the magnetometer's unit is counts, so its radius cannot be compared with {} µT",
                field.total_ut
            ));
        }
    }
    data
}

/// One sentence per distinct reason a sensor was not fitted, naming every sensor it stopped
/// (the accelerometer and gyroscope share the still intervals, so often the same reason).
pub fn not_fitted_once(failures: &[(&str, String)]) -> Vec<String> {
    let reasons: Vec<(&str, String)> = failures
        .iter()
        .map(|(name, reason)| (*name, format!("not fitted: {reason}")))
        .collect();
    once_per_reason(&reasons)
}

fn accel_poses(
    data: &mut ReportData,
    input: &CheckedInput,
    calibration: &RecordingCalibration,
    fit: &Fit,
) {
    let Some(still) = &input.still else {
        return;
    };
    let gravity = calibration.gravity_mps2;
    let means: Vec<Vec3> = still.poses(Sensor::Accel).iter().map(|p| p.mean).collect();
    // Raw readings in m/s²; counts are scaled so that their mean norm is g.
    let scale = input
        .recording
        .units
        .to_si(Sensor::Accel)
        .unwrap_or_else(|| {
            gravity / (means.iter().map(|m| m.norm()).sum::<f64>() / means.len().max(1) as f64)
        });
    let temp_c = still
        .intervals
        .iter()
        .filter(|i| i.accel.is_some())
        .map(|i| i.temp.map(|t| t.mean))
        .collect();
    data.accel = Some(AccelPoses {
        raw_mps2: means.iter().map(|m| m * scale).collect(),
        calibrated: means.iter().map(|m| fit.cal.apply(m)).collect(),
        temp_c,
        gravity,
        labels: pose_labels(input, Sensor::Accel, Some(&fit.cal)),
    });
    data.verdict.push(format!(
        "accelerometer: residual RMS {:.2e} of g over {} poses",
        fit.rms,
        means.len()
    ));
}

/// Name of each still pose of `sensor`: the side that points up (from the accelerometer's
/// mean, through its calibration when there is one: raw counts sit on an offset that would make
/// every pose "+X+Y+Z up"), with the recording's own label when it has one.
fn pose_labels(input: &CheckedInput, sensor: Sensor, accel: Option<&Calibration>) -> Vec<String> {
    let Some(still) = &input.still else {
        return Vec::new();
    };
    let labels = still
        .intervals
        .iter()
        .filter(|i| i.pose(sensor).is_some())
        .map(|i| {
            let side = i.accel.as_ref().map_or("pose".to_string(), |a| {
                up_label(&accel.map_or(a.mean, |cal| cal.apply(&a.mean)))
            });
            format!("{side}{}", i.label_phrase())
        })
        .collect();
    numbered(labels)
}

/// The gyroscope's still poses before and after its fit, °/s; left out when the data's unit
/// has no known factor to rad/s (raw counts without `--gyro-scale`).
fn gyro_poses(
    data: &mut ReportData,
    input: &CheckedInput,
    calibration: &RecordingCalibration,
    outcome: &SensorOutcome,
    fit: &Fit,
) {
    let (Some(still), Some(to_rad)) = (&input.still, outcome.to_nominal) else {
        return;
    };
    // The output is in rad/s unless no scale was known.
    if outcome.output_unit != "rad/s" {
        return;
    }
    let means: Vec<Vec3> = still.poses(Sensor::Gyro).iter().map(|p| p.mean).collect();
    if means.is_empty() {
        return;
    }
    let degrees = |v: Vec3| [v.x, v.y, v.z].map(f64::to_degrees);
    data.gyro = Some(GyroPoses {
        raw_dps: means.iter().map(|m| degrees(m * to_rad)).collect(),
        calibrated_dps: means.iter().map(|m| degrees(fit.cal.apply(m))).collect(),
        labels: pose_labels(
            input,
            Sensor::Gyro,
            calibration
                .sensor(Sensor::Accel)
                .and_then(|o| o.fit.as_ref().ok())
                .map(|f| &f.cal),
        ),
        scale_fit: Vec::new(),
    });
}

/// How far past the first or last temperature reading its value still stands, s: a die's
/// temperature moves over seconds to minutes, so two clocks' ends a sample apart share it.
const TEMPERATURE_HOLD_S: f64 = 1.0;

/// `values` (at the non-decreasing `times`) linearly interpolated at `t`; the end value within
/// [`TEMPERATURE_HOLD_S`] past either end, `None` farther out.
fn interpolate_at(times: &[f64], values: &[f64], t: f64) -> Option<f64> {
    let after = times.partition_point(|x| *x < t);
    let end = |i: usize| {
        let (time, value) = (times.get(i)?, values.get(i)?);
        ((time - t).abs() <= TEMPERATURE_HOLD_S).then_some(*value)
    };
    let Some(before) = after.checked_sub(1) else {
        return end(0);
    };
    let (Some(&t1), Some(&v1)) = (times.get(after), values.get(after)) else {
        return end(before);
    };
    let (&t0, &v0) = (times.get(before)?, values.get(before)?);
    if t1 == t {
        return Some(v1);
    }
    Some(v0 + (v1 - v0) * (t - t0) / (t1 - t0))
}

fn mag_samples(data: &mut ReportData, input: &CheckedInput, outcome: &SensorOutcome, fit: &Fit) {
    let Some(mag) = &input.recording.mag else {
        return;
    };
    let points = input.mag_points();
    let index = input.mag_point_indices();
    let time_s: Vec<f64> = index
        .iter()
        .filter_map(|i| mag.time.get(*i).copied())
        .collect();
    let recording = &input.recording;
    let at_samples = |temps: &Vec<f64>| -> Option<Vec<f64>> {
        index.iter().map(|i| temps.get(*i).copied()).collect()
    };
    let (temp_c, temp_note) = match (&mag.temp_c, &recording.temp_c) {
        // The magnetometer file's own temperature column.
        (Some(own), _) => (at_samples(own), None),
        // The magnetometer's columns are the main file's: its rows' temperatures.
        (None, Some(temps)) if mag.time == recording.time => (at_samples(temps), None),
        // A file of its own without one: the main file's temperature at its times.
        (None, Some(temps)) => (
            time_s
                .iter()
                .map(|t| interpolate_at(&recording.time, temps, *t))
                .collect(),
            Some(
                "The magnetometer's file has no temperature column: the temperature shown is \
                 the main file's (its sensor's die), interpolated at the magnetometer's times."
                    .to_string(),
            ),
        ),
        (None, None) => (None, None),
    };
    data.mag = Some(MagSamples {
        raw: points.to_vec(),
        calibrated: points.iter().map(|p| fit.cal.apply(p)).collect(),
        time_s,
        // The magnetometer on the main file's rows is numbered as they are; a file of its own
        // has its own time column.
        time_is_index: recording.time_is_index && mag.time == recording.time,
        temp_c,
        temp_note,
        field: fit.reference,
        raw_unit: outcome.input_unit.to_string(),
        calibrated_unit: outcome.output_unit.clone(),
        ellipsoid: ellipsoid_shape(&fit.cal.a, fit.reference).map(|s| (fit.cal.b, s)),
        counted: points.to_vec(),
    });
    data.verdict.push(format!(
        "magnetometer: residual RMS {:.2e} of the field over {} samples",
        fit.rms,
        points.len()
    ));
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::{check_input, InputOptions};
    use crate::recording::{LoadOptions, Recording};

    #[test]
    fn the_main_files_temperature_is_read_at_the_magnetometers_times() {
        let times = [0.0, 1.0, 2.0];
        let temps = [20.0, 21.0, 23.0];
        assert_eq!(interpolate_at(&times, &temps, 1.5), Some(22.0));
        assert_eq!(interpolate_at(&times, &temps, 1.0), Some(21.0));
        // Within a second of either end the end's value stands; beyond, nothing was measured.
        assert_eq!(interpolate_at(&times, &temps, 2.4), Some(23.0));
        assert_eq!(interpolate_at(&times, &temps, -0.5), Some(20.0));
        assert_eq!(interpolate_at(&times, &temps, 3.5), None);
        assert_eq!(interpolate_at(&[], &[], 1.0), None);
    }

    #[test]
    fn screened_magnetometer_samples_keep_their_own_times() {
        let path = std::env::temp_dir().join(format!(
            "imucal-report-mag-indices-{}.csv",
            std::process::id()
        ));
        let mut text = Vec::new();
        crate::synthetic::write_long_recording(20_000, &mut text).expect("written to memory");
        std::fs::write(&path, text).expect("temporary file");
        let mut recording = Recording::load(&path, &LoadOptions::default()).expect("reads back");
        let _ = std::fs::remove_file(&path);
        let mag = recording.mag.as_mut().expect("a magnetometer");
        mag.samples[5000] *= 40.0;
        let sensors = recording.sensors();
        let input = check_input(recording, &sensors, &InputOptions::default(), None);
        let (points, indices) = (input.mag_points(), input.mag_point_indices());
        let recorded = &input.recording.mag.as_ref().expect("kept").samples;
        assert_eq!(
            points.len(),
            recorded.len() - 1,
            "the spike was screened out"
        );
        assert_eq!(points.len(), indices.len());
        assert!(!indices.contains(&5000));
        // Before, the report paired the kept samples with the first times of the stream, one
        // sample off after the spike.
        assert!(indices.iter().zip(points).all(|(&i, p)| recorded[i] == *p));
    }

    #[test]
    fn a_reason_shared_by_two_sensors_is_said_once_naming_both() {
        let failures = [
            (
                "accelerometer",
                "still intervals could not be found".to_string(),
            ),
            (
                "gyroscope",
                "still intervals could not be found".to_string(),
            ),
            ("magnetometer", "too few samples".to_string()),
        ];
        let sentences = not_fitted_once(&failures);
        assert_eq!(
            sentences,
            [
                "accelerometer and gyroscope not fitted: still intervals could not be found",
                "magnetometer not fitted: too few samples"
            ]
        );
    }
}
