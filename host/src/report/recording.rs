//! A report of a recording: the pipeline's calibration ([`crate::pipeline`]) laid out as
//! [`ReportData`] — pose means and magnetometer samples before and after, the parameters, the
//! chain's choice and the checks' findings.

use crate::fit::{Fit, Vec3};
use crate::geomag::LocalField;
use crate::pipeline::calibration::once_per_reason;
use crate::pipeline::methods::thin_indices;
use crate::pipeline::{CheckedInput, InputOptions, RecordingCalibration, SensorOutcome};
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
    options: &InputOptions,
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
            Sensor::Mag => mag_samples(&mut data, input, options, outcome, fit),
            Sensor::Gyro => gyro_poses(&mut data, input, outcome, fit),
        }
    }
    // The headline says how much of what was asked for is in the report.
    data.verdict_level = match (not_fitted.len(), calibration.sensors.len()) {
        (0, _) => "fitted",
        (n, all) if n < all => "partly fitted",
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
        labels: pose_labels(input, Sensor::Accel),
    });
    data.verdict.push(format!(
        "accelerometer: residual RMS {:.2e} of g over {} poses",
        fit.rms,
        means.len()
    ));
}

/// Name of each still pose of `sensor`: the side that points up (from the accelerometer's
/// mean), with the recording's own label when it has one.
fn pose_labels(input: &CheckedInput, sensor: Sensor) -> Vec<String> {
    let Some(still) = &input.still else {
        return Vec::new();
    };
    let labels = still
        .intervals
        .iter()
        .filter(|i| i.pose(sensor).is_some())
        .map(|i| {
            let side = i
                .accel
                .as_ref()
                .map_or("pose".to_string(), |a| up_label(&a.mean));
            match i.label {
                Some(label) => format!("{side} (pose {label})"),
                None => side,
            }
        })
        .collect();
    numbered(labels)
}

/// The gyroscope's still poses before and after its fit, °/s; left out when the data's unit
/// has no known factor to rad/s (raw counts without `--gyro-scale`).
fn gyro_poses(data: &mut ReportData, input: &CheckedInput, outcome: &SensorOutcome, fit: &Fit) {
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
        labels: pose_labels(input, Sensor::Gyro),
        scale_fit: Vec::new(),
    });
}

fn mag_samples(
    data: &mut ReportData,
    input: &CheckedInput,
    options: &InputOptions,
    outcome: &SensorOutcome,
    fit: &Fit,
) {
    let Some(mag) = &input.recording.mag else {
        return;
    };
    let points = input.mag_points();
    let index = thin_indices(mag.samples.len(), options.max_mag_samples);
    let temps = input
        .recording
        .temp_c
        .as_ref()
        .filter(|t| t.len() == mag.samples.len());
    data.mag = Some(MagSamples {
        raw: points.to_vec(),
        calibrated: points.iter().map(|p| fit.cal.apply(p)).collect(),
        time_s: index
            .iter()
            .filter_map(|i| mag.time.get(*i).copied())
            .collect(),
        temp_c: temps.map(|t| index.iter().filter_map(|i| t.get(*i).copied()).collect()),
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
