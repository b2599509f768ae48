//! Reading a session directory (`summary.json`, `params.json`, the samples) into
//! [`ReportData`].

use std::path::Path;

use serde_json::Value;

use super::format::{
    degrees, extended_terms, gyro_scale_rows, numbered, uncertainty_in_words, up_label,
};
use super::{
    ellipsoid_shape, AccelPoses, GyroPoses, MagSamples, ReportData, ReportError, RestCheck,
    SensorParameters, ANALYSIS_TEXT_FILE,
};
use crate::compat::AdafruitCalibration;
use crate::device::ParamsFile;
use crate::fit::{Mat3, Vec3};
use imucal_protocol::apply_sensor;

pub(super) fn read(path: &Path) -> Result<String, ReportError> {
    std::fs::read_to_string(path).map_err(|cause| ReportError::Read {
        path: path.display().to_string(),
        cause,
    })
}

fn format_error(path: &Path, detail: impl Into<String>) -> ReportError {
    ReportError::Format {
        path: path.display().to_string(),
        detail: detail.into(),
    }
}

fn vec3_of(value: &Value) -> Option<Vec3> {
    let array = value.as_array()?;
    match array.as_slice() {
        [x, y, z] => Some(Vec3::new(x.as_f64()?, y.as_f64()?, z.as_f64()?)),
        _ => None,
    }
}

fn mat3_of(rows: &[[f64; 3]; 3]) -> Mat3 {
    Mat3::from_fn(|r, c| rows[r][c])
}

/// The columns of a session's `mag_samples.csv`.
struct MagColumns {
    time_s: Vec<f64>,
    raw: Vec<Vec3>,
    temp_c: Vec<f64>,
    /// Samples of the positions and tumble phases (every sample without a phase column).
    counted: Vec<Vec3>,
}

/// Reads `mag_samples.csv` (`t_s,mx,my,mz,temp_c,phase`): the samples of the positions and
/// the tumble, which the session's fit and coverage used (not those of the wait at rest, which
/// sit on one direction); every sample without a phase column.
fn read_mag_csv(path: &Path) -> Result<MagColumns, ReportError> {
    let text = read(path)?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines
        .next()
        .unwrap_or_default()
        .split(',')
        .map(str::trim)
        .collect();
    let column = |name: &str| {
        header
            .iter()
            .position(|h| *h == name)
            .ok_or_else(|| format_error(path, format!("the header has no `{name}` column")))
    };
    let [t, mx, my, mz, temp] = [
        column("t_s")?,
        column("mx")?,
        column("my")?,
        column("mz")?,
        column("temp_c")?,
    ];
    let phase = header.iter().position(|h| *h == "phase");
    let mut rows: Vec<(bool, f64, Vec3, f64)> = Vec::new();
    let mut counted = Vec::new();
    for (index, line) in lines.enumerate().filter(|(_, l)| !l.trim().is_empty()) {
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        let number = |k: usize| {
            fields
                .get(k)
                .and_then(|f| f.parse::<f64>().ok())
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    format_error(
                        path,
                        format!("line {} is not five numbers and a phase", index + 2),
                    )
                })
        };
        let phase_name = phase.and_then(|p| fields.get(p)).copied();
        let fitted = phase_name != Some("rest");
        let reading = Vec3::new(number(mx)?, number(my)?, number(mz)?);
        if phase_name != Some("rest") {
            counted.push(reading);
        }
        rows.push((
            fitted,
            number(t)?,
            Vec3::new(number(mx)?, number(my)?, number(mz)?),
            number(temp)?,
        ));
    }
    rows.retain(|r| r.0);
    Ok(MagColumns {
        time_s: rows.iter().map(|r| r.1).collect(),
        raw: rows.iter().map(|r| r.2).collect(),
        temp_c: rows.iter().map(|r| r.3).collect(),
        counted,
    })
}

/// The magnetometer readings of a MotionCal sketch session's `readings.csv` (every reading,
/// still or moving, all counted), labelled with the temperature the sketch's set assumes.
fn sketch_readings(path: &Path) -> Result<MagColumns, ReportError> {
    let recording = crate::recording::Recording::load(path, &Default::default())
        .map_err(|e| format_error(path, e.to_string()))?;
    let raw = recording
        .samples(crate::recording::Sensor::Mag)
        .ok_or_else(|| format_error(path, "it has no magnetometer columns"))?
        .to_vec();
    Ok(MagColumns {
        time_s: recording.time.clone(),
        temp_c: vec![crate::session::motioncal::UNKNOWN_TEMPERATURE_C; raw.len()],
        counted: raw.clone(),
        raw,
    })
}

/// Builds a report from a session directory written by `imucal calibrate`: a finished one, one
/// stopped after its fit (`progress.json`), or one of a MotionCal sketch (`motioncal.json`, no
/// magnetometer samples). What the directory lacks is said in the report's notes, with why.
pub fn from_session_dir(dir: &Path) -> Result<ReportData, ReportError> {
    let params_path = dir.join("params.json");
    let params = ParamsFile::load(&params_path)?;
    let set = params.to_calibration_set(&params_path.display().to_string())?;
    let gravity = params.reference.gravity_mps2;
    let field = params.reference.field_ut;

    // A MotionCal sketch board applies what the Adafruit library holds of the set (offsets, a
    // symmetric soft iron), not the full model: its figures after calibration are that.
    let motioncal_path = dir.join("motioncal.json");
    let motioncal = motioncal_path.is_file();
    let library = if motioncal {
        Some(
            AdafruitCalibration::from_set(&set)
                .map_err(|e| format_error(&params_path, e.to_string()))?
                .calibration,
        )
    } else {
        None
    };
    // The calibrated reading of sensor `k` (0 accel, 1 gyro, 2 mag) as the board computes it.
    let calibrate = |k: usize, x: Vec3, temp_c: f64| -> Vec3 {
        match &library {
            Some(lib) => {
                let mut readings = [[0.0; 3]; 3];
                readings[k] = x.into();
                Vec3::from(lib.apply(readings[0], readings[1], readings[2])[k])
            }
            None => {
                let sensor = [&set.accel, &set.gyro, &set.mag][k];
                Vec3::from(apply_sensor(sensor, x.into(), temp_c))
            }
        }
    };

    let poses_path = dir.join("poses.json");
    let poses: Value = serde_json::from_str(&read(&poses_path)?)
        .map_err(|e| format_error(&poses_path, e.to_string()))?;
    let mut raw = Vec::new();
    let mut temp = Vec::new();
    let mut labels = Vec::new();
    let mut gyro_raw = Vec::new();
    for pose in poses.as_array().into_iter().flatten() {
        let stats = &pose["stats"];
        let mean = vec3_of(&stats["accel_mean"])
            .ok_or_else(|| format_error(&poses_path, "a pose has no `stats.accel_mean` triple"))?;
        // A sketch prints no temperature: its poses' 25 °C is a label, not a measurement.
        let t = stats["temp_mean_c"].as_f64().filter(|_| !motioncal);
        labels.push(pose["target"].as_str().map_or_else(
            || up_label(&vec3_of(&pose["target_up"]).unwrap_or(mean)),
            str::to_string,
        ));
        gyro_raw.push(vec3_of(&stats["gyro_mean"]).map(|g| (g, t.unwrap_or(25.0))));
        raw.push(mean);
        temp.push(t);
    }
    let labels = numbered(labels);
    let gyro = gyro_raw.iter().all(Option::is_some).then(|| GyroPoses {
        raw_dps: gyro_raw.iter().flatten().map(|(g, _)| degrees(g)).collect(),
        calibrated_dps: gyro_raw
            .iter()
            .flatten()
            .map(|(g, t)| degrees(&calibrate(1, *g, *t)))
            .collect(),
        labels: labels.clone(),
        scale_fit: Vec::new(),
    });
    let calibrated = raw
        .iter()
        .zip(&temp)
        .map(|(x, t)| calibrate(0, *x, t.unwrap_or(25.0)))
        .collect();
    let accel = (!raw.is_empty()).then_some(AccelPoses {
        raw_mps2: raw,
        calibrated,
        temp_c: temp,
        gravity,
        labels,
    });

    // What the directory lacks, and why, from the files that say what kind of session it was.
    let unfinished = crate::session::load_progress(dir).ok();
    let mut notes = Vec::new();
    if motioncal {
        notes.push(
            "the figures after calibration are what the sketch board applies (the Adafruit \
             library: offsets and a symmetric soft iron), not the full model params.json keeps"
                .to_string(),
        );
    }
    if let Some(progress) = &unfinished {
        notes.push(format!(
            "the session did not finish (progress.json: {}); its check at rest and summary are \
             missing",
            if progress.stopped_because.is_empty() {
                format!("it stopped in stage `{}`", progress.stage)
            } else {
                progress.stopped_because.clone()
            }
        ));
    }
    let mag_path = dir.join("mag_samples.csv");
    let readings_path = dir.join(crate::session::motioncal::READINGS_FILE);
    // A sketch prints no temperature: its readings carry none to plot against.
    let mut mag_temp_recorded = true;
    let mag_columns = if mag_path.is_file() {
        read_mag_csv(&mag_path)?
    } else if motioncal && readings_path.is_file() {
        mag_temp_recorded = false;
        sketch_readings(&readings_path)?
    } else {
        notes.push(if motioncal {
            "readings.csv is missing (sessions with a MotionCal sketch save it from this \
             version on): no magnetometer plots"
                .to_string()
        } else {
            "mag_samples.csv is missing (the session saved no magnetometer samples): no \
             magnetometer plots"
                .to_string()
        });
        MagColumns {
            time_s: Vec::new(),
            raw: Vec::new(),
            temp_c: Vec::new(),
            counted: Vec::new(),
        }
    };
    let MagColumns {
        time_s,
        raw: mag_raw,
        temp_c: mag_temp,
        counted,
    } = mag_columns;
    let mag_calibrated = mag_raw
        .iter()
        .zip(&mag_temp)
        .map(|(x, t)| calibrate(2, *x, *t))
        .collect();
    let mag_a = mat3_of(&params.mag.a);
    let mag = (!mag_raw.is_empty()).then(|| MagSamples {
        raw: mag_raw,
        calibrated: mag_calibrated,
        time_s,
        time_is_index: false,
        temp_c: mag_temp_recorded.then_some(mag_temp),
        temp_note: None,
        field,
        raw_unit: "µT".to_string(),
        calibrated_unit: "µT".to_string(),
        ellipsoid: ellipsoid_shape(&mag_a, field).map(|s| (Vec3::from(params.mag.b), s)),
        counted,
    });

    let mut data = ReportData {
        source: dir.display().to_string(),
        accel,
        gyro: gyro.filter(|g| !g.raw_dps.is_empty()),
        mag,
        extended_terms: extended_terms(&params),
        parameters: [
            ("accelerometer", "m/s²", &params.accel),
            ("gyroscope", "rad/s", &params.gyro),
            ("magnetometer", "µT", &params.mag),
        ]
        .into_iter()
        .map(|(name, unit, s)| SensorParameters {
            name: name.to_string(),
            unit_in: unit.to_string(),
            unit_out: unit.to_string(),
            a: mat3_of(&s.a),
            b: Vec3::from(s.b),
            std: None,
            to_nominal: Some(1.0),
        })
        .collect(),
        analysis: std::fs::read_to_string(dir.join(ANALYSIS_TEXT_FILE)).ok(),
        session_regions_covered: std::fs::read_to_string(dir.join("summary.json"))
            .ok()
            .and_then(|text| serde_json::from_str::<Value>(&text).ok())
            .and_then(|summary| summary["mag_regions_covered"].as_u64()),
        notes,
        ..ReportData::default()
    };
    let summary_path = dir.join("summary.json");
    if let Ok(text) = std::fs::read_to_string(&summary_path) {
        let summary: Value =
            serde_json::from_str(&text).map_err(|e| format_error(&summary_path, e.to_string()))?;
        (data.verdict_level, data.verdict) = verdict_of(&summary);
        // A set that never reached the board is said first, beside the verdict.
        if let Some(why) = summary["not_written_because"].as_str() {
            data.verdict.insert(
                0,
                format!("NOT WRITTEN to the board ({why}): the board keeps its earlier set"),
            );
        }
        if let Some(map) = summary["uncertainties"].as_object() {
            data.uncertainty_notes = map
                .iter()
                .map(|(key, value)| uncertainty_in_words(key, value))
                .collect();
        }
        // With `--analyze` the extended set replaced the base set on the board: both checks.
        let extended =
            summary["on_board_after"].is_object() && summary["on_board_after"] != summary["after"];
        let mut columns = vec![("before (raw)", "before")];
        if extended {
            columns.push(("after, base set", "after"));
            columns.push(("after, extended set (on the board)", "on_board_after"));
        } else {
            columns.push(("after (on the board)", "after"));
        }
        for (label, key) in columns {
            if let Some(check) = RestCheck::of(&summary[key]) {
                data.rest_checks.push((label.to_string(), check));
            }
        }
        if data.rest_checks.is_empty() {
            // Summaries without the before/after objects carry the after-values alone.
            let check = RestCheck {
                accel_mg: summary["accel_rest_error_mg"].as_f64(),
                mag_pct: summary["mag_rest_error_pct"].as_f64(),
                gyro_dps: summary["gyro_rest_error_dps"].as_f64(),
            };
            if check
                .accel_mg
                .or(check.mag_pct)
                .or(check.gyro_dps)
                .is_some()
            {
                data.rest_checks.push(("after".to_string(), check));
            }
        }
        if let Some(gyro) = data.gyro.as_mut() {
            gyro.scale_fit = gyro_scale_rows(&summary["gyro_scale"], &mat3_of(&params.gyro.a));
        }
    } else if motioncal {
        // A MotionCal sketch session keeps its verdict in motioncal.json; the sketch has no
        // calibrated stream, so there is no check at rest.
        let summary: Value = serde_json::from_str(&read(&motioncal_path)?)
            .map_err(|e| format_error(&motioncal_path, e.to_string()))?;
        (data.verdict_level, data.verdict) = verdict_of(&summary);
        data.notes.push(
            "a session with a MotionCal sketch: the verdict is motioncal.json's, and there is no \
             check at rest (the sketch streams no calibrated readings)"
                .to_string(),
        );
    } else {
        data.verdict_level = "unknown".to_string();
        if unfinished.is_none() {
            data.notes
                .push("summary.json is missing: no verdict from the session".to_string());
        }
    }
    Ok(data)
}

/// The verdict's level and reasons as a session's summary (or `motioncal.json`) holds them.
fn verdict_of(summary: &Value) -> (String, Vec<String>) {
    let level = summary["verdict"]["level"]
        .as_str()
        .unwrap_or("unknown")
        .to_string();
    let reasons = summary["verdict"]["reasons"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(|r| r.as_str().map(str::to_string))
        .collect();
    (level, reasons)
}
