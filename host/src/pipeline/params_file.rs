//! A [`RecordingCalibration`] as the versioned parameter file (`docs/PARAMS_FORMAT.md`), the
//! same file `calibrate` writes and `export` and `flash` read. Fits are re-expressed for the
//! board's nominal input units (`y = A·(x − b)` with `x = k·x_file`: `A/k`, `k·b`); a sensor
//! whose data has no known scale keeps counts and says so (`input_unit`); a sensor without a
//! usable fit is left out and listed under `not_fitted` with the reason.

use std::collections::BTreeMap;

use crate::device::params_json::{ReferenceJson, ResidualsJson, SensorJson};
use crate::device::{ParamsFile, PARAMS_FILE_FORMAT};
use crate::fit::{Fit, Method};
use crate::recording::Sensor;

use super::calibration::{RecordingCalibration, SensorOutcome};

/// Why a sensor that was asked for is not in the parameter file, or its JSON.
fn sensor_json(
    outcome: Option<&SensorOutcome>,
    calibration: &RecordingCalibration,
) -> Result<SensorJson, String> {
    let Some(outcome) = outcome else {
        return Err("not asked for (see --sensor) or not in the recording".to_string());
    };
    let fit = outcome.fit.as_ref().map_err(Clone::clone)?;
    if let Some(reason) = outcome.alignment_failure() {
        return Err(reason);
    }
    let to_nominal = outcome.to_nominal;
    if outcome.sensor == Sensor::Gyro && outcome.output_unit != "rad/s" {
        return Err(
            "its output would be in counts, not rad/s; pass --gyro-scale (rad/s per count)"
                .to_string(),
        );
    }
    if outcome.sensor == Sensor::Mag && calibration.field_ut.is_none() && to_nominal.is_some() {
        // Normalised output from data in a known unit: the file says field_ut = 1, so the board
        // would read the field as 1 µT. A reference makes the output µT.
        return Err(
            "its output is normalised to 1, not µT; pass --field-ut or --location".to_string(),
        );
    }
    let (a, b, input_unit) = match to_nominal {
        Some(k) => (fit.cal.a / k, fit.cal.b * k, None),
        None => (fit.cal.a, fit.cal.b, Some(outcome.input_unit.to_string())),
    };
    Ok(SensorJson {
        a: [0, 1, 2].map(|r| [0, 1, 2].map(|c| a[(r, c)])),
        b: [b.x, b.y, b.z],
        input_unit,
        ..SensorJson::default()
    })
}

/// One-sigma uncertainty of the parameters [`params_file`] writes, in the file's units and
/// named as the history names them (`accel.b.x`, `mag.A.xy`): each fit's standard deviations
/// re-expressed as its `A` and `b` are. Sensors the file leaves out, and fits without a
/// covariance, give none; nor does a magnetometer's `A` rotated into the accelerometer frame
/// (its uncertainty is then the rotation's, not the fit's).
pub fn parameter_sigma(calibration: &RecordingCalibration) -> BTreeMap<String, f64> {
    const AXES: [&str; 3] = ["x", "y", "z"];
    let mut sigma = BTreeMap::new();
    for outcome in &calibration.sensors {
        if sensor_json(Some(outcome), calibration).is_err() {
            continue;
        }
        let Some(std) = outcome.fit.as_ref().ok().and_then(|f| f.std.as_ref()) else {
            continue;
        };
        let k = outcome.to_nominal.unwrap_or(1.0);
        let name = outcome.sensor.name();
        for (i, row) in AXES.iter().enumerate() {
            sigma.insert(format!("{name}.b.{row}"), std.b[i] * k);
            if outcome.a_std_applies() {
                for (j, col) in AXES.iter().enumerate() {
                    sigma.insert(format!("{name}.A.{row}{col}"), std.a[(i, j)] / k);
                }
            }
        }
    }
    sigma.retain(|_, s| s.is_finite() && *s > 0.0);
    sigma
}

/// RMS of the fit in output units (norm fits are relative to `reference`).
fn residual(outcome: Option<&SensorOutcome>, scale: f64) -> f64 {
    outcome
        .and_then(|o| o.fit.as_ref().ok())
        .filter(|f: &&Fit| f.method != Method::GyroScale)
        .map_or(0.0, |f| f.rms * scale)
}

/// The parameter file of `calibration`.
pub fn params_file(calibration: &RecordingCalibration) -> ParamsFile {
    let mut not_fitted = BTreeMap::new();
    let mut sensor = |s: Sensor| match sensor_json(calibration.sensor(s), calibration) {
        Ok(json) => json,
        Err(reason) => {
            not_fitted.insert(s.name().to_string(), reason);
            SensorJson::default()
        }
    };
    let accel = sensor(Sensor::Accel);
    let gyro = sensor(Sensor::Gyro);
    let mag = sensor(Sensor::Mag);
    let field = calibration.field_ut.unwrap_or(1.0);
    // A sensor left out of the file has no residual in it either (its fit may be in counts).
    let written = |s: Sensor| {
        calibration
            .sensor(s)
            .filter(|_| !not_fitted.contains_key(s.name()))
    };
    ParamsFile {
        format: PARAMS_FILE_FORMAT,
        created_unix_s: calibration.provenance.created_unix_s,
        accel,
        gyro,
        mag,
        gyro_g_sensitivity: None,
        reference: ReferenceJson {
            gravity_mps2: calibration.gravity_mps2,
            field_ut: field,
        },
        residuals: ResidualsJson {
            accel_rms: residual(written(Sensor::Accel), calibration.gravity_mps2),
            gyro_rms: residual(written(Sensor::Gyro), 1.0),
            mag_rms: residual(written(Sensor::Mag), field),
        },
        // The methods and units of the sensors the file holds, not of those it leaves out.
        provenance: Some({
            let mut provenance = calibration.provenance.clone();
            provenance
                .methods
                .retain(|name, _| !not_fitted.contains_key(name));
            provenance
                .input_units
                .retain(|name, _| !not_fitted.contains_key(name));
            provenance
        }),
        not_fitted,
        // A recording names no board; `fit --device` goes into the provenance.
        device: None,
        absent_sensors: Vec::new(),
    }
}
