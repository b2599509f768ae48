//! Reader for the plain-text format of IMU-TK (Tedaldi, Pretto & Menegatti, ICRA 2014; the
//! `imu_tk::importAsciiData` reader): one file per sensor, one sample per line as
//! `timestamp x y z`, separated by spaces (or by commas). The accelerometer file is the main
//! file; a gyroscope file must pair with it row by row, as in the IMU-TK test data.

use std::path::Path;

use super::lines::LineReader;
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
        *slot = super::decimal::parse_finite(fields.next()?).filter(|v| v.abs() <= limit)?;
    }
    fields.next().is_none().then_some(out)
}

/// True for lines IMU-TK skips: blank lines and `%` or `#` comments.
pub(super) fn is_comment(line: &str) -> bool {
    let line = line.trim();
    line.is_empty() || line.starts_with('%') || line.starts_with('#')
}

/// True when `line` is a data line of this format (four numbers, no names).
pub(super) fn is_triad_line(line: &str) -> bool {
    numbers(line.trim()).is_some()
}

/// Read one IMU-TK triad file: time stamps (scaled to seconds) and samples.
pub fn read_triad(path: &Path, time_scale: f64) -> Result<(Vec<f64>, Vec<Vec3>), RecordingError> {
    read_triad_lines(path, &mut LineReader::open(path)?, None, time_scale)
}

/// [`read_triad`] on `lines`, whose first data line may already have been taken out (`first`).
fn read_triad_lines(
    path: &Path,
    lines: &mut LineReader<'_>,
    first: Option<(usize, String)>,
    time_scale: f64,
) -> Result<(Vec<f64>, Vec<Vec3>), RecordingError> {
    let mut time = Vec::new();
    let mut samples = Vec::new();
    let mut push = |line_no: usize, line: &str| -> Result<(), RecordingError> {
        let line = line.trim();
        if is_comment(line) {
            return Ok(());
        }
        let [t, x, y, z] = numbers(line).ok_or_else(|| RecordingError::ImutkLine {
            path: display(path),
            line: line_no,
            text: line.chars().take(80).collect(),
        })?;
        let t = t * time_scale;
        if let Some(&previous) = time.last() {
            if t < previous {
                return Err(RecordingError::TimeBackwards {
                    path: display(path),
                    line: line_no,
                    time: t,
                    previous,
                });
            }
        }
        time.push(t);
        samples.push(Vec3::new(x, y, z));
        Ok(())
    };
    if let Some((line_no, line)) = &first {
        push(*line_no, line)?;
    }
    while let Some((line_no, line)) = lines.next_line()? {
        push(line_no, line)?;
    }
    if time.is_empty() {
        return Err(RecordingError::NoRows {
            path: display(path),
        });
    }
    Ok((time, samples))
}

/// Read an IMU-TK accelerometer file from `lines` (its first data line possibly already taken
/// out as `first`) and, if given, its gyroscope file.
pub(super) fn load(
    path: &Path,
    lines: &mut LineReader<'_>,
    first: Option<(usize, String)>,
    options: &LoadOptions,
) -> Result<Recording, RecordingError> {
    let scale = options.imutk_time_scale.unwrap_or(1.0);
    let (time, accel) = read_triad_lines(path, lines, first, scale)?;
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
        time_from_file: true,
        accel: Some(accel),
        gyro,
        temp_c: None,
        mag: None,
        labels: None,
        ignored_columns: Vec::new(),
        units: options.units,
        read_as_imutk: true,
        repeated_rows: 0,
    })
}
