//! Reader for the plain-text format of IMU-TK (Tedaldi, Pretto & Menegatti, ICRA 2014; the
//! `imu_tk::importAsciiData` reader): one file per sensor, one sample per line as
//! `timestamp x y z`, separated by spaces (or by commas). The accelerometer file is the main
//! file; a gyroscope file must pair with it row by row, as in the IMU-TK test data.

use std::path::Path;

use super::{display, LoadOptions, Recording, RecordingError};
use crate::fit::Vec3;

fn numbers(line: &str) -> Option<[f64; 4]> {
    let mut out = [0.0; 4];
    let mut fields = line
        .split(|c: char| c.is_whitespace() || c == ',')
        .filter(|s| !s.is_empty());
    for (i, slot) in out.iter_mut().enumerate() {
        // Time stamps may be large (nanoseconds since an epoch); sensor values may not.
        let limit = if i == 0 {
            f64::MAX
        } else {
            super::MAX_SENSOR_MAGNITUDE
        };
        *slot = fields
            .next()?
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite() && v.abs() <= limit)?;
    }
    fields.next().is_none().then_some(out)
}

fn is_comment(line: &str) -> bool {
    line.is_empty() || line.starts_with('%') || line.starts_with('#')
}

/// True when the first data line of `path` is four numbers (no header of names).
pub(super) fn looks_like_imutk(path: &Path) -> Result<bool, RecordingError> {
    let text = super::read_text(path)?;
    for line in text.lines() {
        let line = line.trim();
        if is_comment(line) {
            continue;
        }
        return Ok(numbers(line).is_some());
    }
    Ok(false)
}

/// Read one IMU-TK triad file: time stamps (scaled to seconds) and samples.
pub fn read_triad(path: &Path, time_scale: f64) -> Result<(Vec<f64>, Vec<Vec3>), RecordingError> {
    let text = super::read_text(path)?;
    let mut time = Vec::new();
    let mut samples = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if is_comment(line) {
            continue;
        }
        let [t, x, y, z] = numbers(line).ok_or_else(|| RecordingError::ImutkLine {
            path: display(path),
            line: i + 1,
            text: line.chars().take(80).collect(),
        })?;
        let t = t * time_scale;
        if let Some(&previous) = time.last() {
            if t < previous {
                return Err(RecordingError::TimeBackwards {
                    path: display(path),
                    line: i + 1,
                    time: t,
                    previous,
                });
            }
        }
        time.push(t);
        samples.push(Vec3::new(x, y, z));
    }
    if time.is_empty() {
        return Err(RecordingError::NoRows {
            path: display(path),
        });
    }
    Ok((time, samples))
}

/// Read an IMU-TK accelerometer file and, if given, its gyroscope file.
pub(super) fn load(path: &Path, options: &LoadOptions) -> Result<Recording, RecordingError> {
    let scale = options.imutk_time_scale.unwrap_or(1.0);
    let (time, accel) = read_triad(path, scale)?;
    let gyro = match &options.gyro_file {
        None => None,
        Some(gyro_path) => {
            let (gyro_time, gyro) = read_triad(gyro_path, scale)?;
            let unpaired = |detail: String| RecordingError::Unpaired {
                first: display(path),
                second: display(gyro_path),
                detail,
            };
            if gyro_time.len() != time.len() {
                return Err(unpaired(format!(
                    "{} accelerometer rows but {} gyroscope rows",
                    time.len(),
                    gyro_time.len()
                )));
            }
            let rate = super::median_rate(&time).unwrap_or(1.0);
            if let Some((row, (a, g))) = time
                .iter()
                .zip(&gyro_time)
                .enumerate()
                .find(|(_, (a, g))| (*a - *g).abs() > 0.5 / rate)
            {
                return Err(unpaired(format!(
                    "row {} has time {a} s in one and {g} s in the other",
                    row + 1
                )));
            }
            Some(gyro)
        }
    };
    Ok(Recording {
        source: path.to_path_buf(),
        time,
        time_is_index: false,
        accel: Some(accel),
        gyro,
        temp_c: None,
        mag: None,
        labels: None,
        ignored_columns: Vec::new(),
        units: options.units,
    })
}
