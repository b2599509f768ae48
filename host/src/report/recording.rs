//! A report of a recording: the pipeline's calibration ([`crate::pipeline`]) laid out as
//! [`ReportData`] — pose means and magnetometer samples before and after, the parameters, the
//! chain's choice and the checks' findings.

use crate::fit::{Fit, Vec3};
use crate::geomag::LocalField;
use crate::pipeline::methods::thin_indices;
use crate::pipeline::{CheckedInput, InputOptions, RecordingCalibration, SensorOutcome};
use crate::recording::Sensor;

use super::{ellipsoid_shape, AccelPoses, MagSamples, ReportData, SensorParameters};

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
        verdict_level: "fitted".to_string(),
        ..ReportData::default()
    };
    data.notes.extend(calibration.warnings.iter().cloned());
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
                data.verdict.push(format!("{name} not fitted: {e}"));
                continue;
            }
        };
        data.parameters.push(parameters(name, outcome, fit));
        match outcome.sensor {
            Sensor::Accel => accel_poses(&mut data, input, calibration, fit),
            Sensor::Mag => mag_samples(&mut data, input, options, outcome, fit),
            Sensor::Gyro => {}
        }
    }
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
    });
    data.verdict.push(format!(
        "accelerometer: residual RMS {:.2e} of g over {} poses",
        fit.rms,
        means.len()
    ));
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
    let points = &input.mag_points;
    let index = thin_indices(mag.samples.len(), options.max_mag_samples);
    let temps = input
        .recording
        .temp_c
        .as_ref()
        .filter(|t| t.len() == mag.samples.len());
    data.mag = Some(MagSamples {
        raw: points.clone(),
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
        counted: points.clone(),
    });
    data.verdict.push(format!(
        "magnetometer: residual RMS {:.2e} of the field over {} samples",
        fit.rms,
        points.len()
    ));
}
