//! Reader for MotionCal-style serial logs: the lines `Raw:ax,ay,az,gx,gy,gz,mx,my,mz` that the
//! PJRC/Adafruit calibration sketches print for MotionCal, nine integers per line.
//!
//! The counts are converted as a board is read live (`imucal record`/`stream` of a sketch
//! board), by the one conversion both share, [`SketchReading::from_counts`] with Adafruit's
//! scaling (its calibration sketch writes `int(a·8192/9.8)` for `a` in m/s², rad/s·(180/π)·16
//! and µT·10): accelerometer 8192 counts per 9.8 m/s², gyroscope 16 counts per °/s,
//! magnetometer 10 counts per µT. The recording is in m/s², rad/s and µT.
//! Other lines of such a log (`Uni:`, `Ori:`, `Cal1:`, `Cal2:`, text) are skipped. The log has
//! no time stamps: rows are timed by `--rate`, or counted when no rate is given.

use std::io::Read;
use std::path::Path;

use super::lines::LineReader;
use super::mapping::ImportError;
use super::{AccelUnit, GyroUnit, MagStream, MagUnit, Recording, Units};
use crate::compat::motioncal::{RawAccelScaling, SketchReading};
use crate::fit::Vec3;

/// How the counts of a saved log are scaled: as live readings of a sketch board are.
const SCALING: RawAccelScaling = RawAccelScaling::AdafruitSketch;

/// The prefix of a raw-data line.
const RAW_PREFIX: &str = "Raw:";

/// Largest magnitude of a field: MotionCal's counts are 16-bit, so anything beyond 32-bit range
/// is a corrupted line rather than a reading.
const MAX_COUNTS: f64 = 4_294_967_296.0;

/// True when some line of `text` starts with `Raw:` (MotionCal log detection).
pub fn looks_like_motioncal(text: &str) -> bool {
    text.lines()
        .take(200)
        .any(|line| line.trim_start().starts_with(RAW_PREFIX))
}

/// Parses one `Raw:` payload into nine numbers, or says which field is wrong.
fn parse_raw(payload: &str) -> Result<[f64; 9], (usize, String)> {
    let fields: Vec<&str> = payload.split(',').map(str::trim).collect();
    if fields.len() != 9 {
        return Err((fields.len(), String::new()));
    }
    let mut values = [0.0; 9];
    for (slot, field) in values.iter_mut().zip(&fields) {
        *slot = field
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite() && v.abs() < MAX_COUNTS)
            .ok_or_else(|| (9, (*field).to_string()))?;
    }
    Ok(values)
}

/// True when the first [`SNIFF_BYTES`] of the file at `path` hold a `Raw:` line; `false` when it
/// cannot be read (the ordinary readers then say why). Reads only that much, so a large
/// recording is not read twice and a device or pipe is not drained.
pub fn file_looks_like_motioncal(path: &Path) -> bool {
    let Ok(file) = std::fs::File::open(path) else {
        return false;
    };
    let mut head = Vec::with_capacity(SNIFF_BYTES);
    if file
        .take(SNIFF_BYTES as u64)
        .read_to_end(&mut head)
        .is_err()
    {
        return false;
    }
    looks_like_motioncal(&String::from_utf8_lossy(&head))
}

/// Bytes of a file inspected by [`file_looks_like_motioncal`]: 200 lines of a log.
pub const SNIFF_BYTES: usize = 16 * 1024;

/// Reads a MotionCal log from text; `path` names it in errors and in the recording.
pub fn parse(text: &str, path: &Path, rate_hz: Option<f64>) -> Result<Recording, ImportError> {
    let mut lines = LineReader::new(Box::new(text.as_bytes()), path.display().to_string());
    parse_lines(&mut lines, path, rate_hz)
}

/// True when the first [`SNIFF_BYTES`] of `lines` hold a `Raw:` line, read without consuming
/// them, so that standard input is told apart as a file is ([`file_looks_like_motioncal`]).
pub(super) fn lines_look_like_motioncal(
    lines: &mut LineReader<'_>,
) -> Result<bool, super::RecordingError> {
    let head = lines.peek(SNIFF_BYTES)?;
    Ok(looks_like_motioncal(&String::from_utf8_lossy(head)))
}

/// Reads a MotionCal log line by line from `lines`.
pub(super) fn parse_lines(
    lines: &mut LineReader<'_>,
    path: &Path,
    rate_hz: Option<f64>,
) -> Result<Recording, ImportError> {
    if let Some(rate) = rate_hz {
        if !(rate.is_finite() && rate > 0.0) {
            return Err(ImportError::BadRate(rate));
        }
    }
    let shown = path.display().to_string();
    let mut accel = Vec::new();
    let mut gyro = Vec::new();
    let mut mag = Vec::new();
    while let Some((line_no, line)) = lines.next_line()? {
        let Some(payload) = line.trim().strip_prefix(RAW_PREFIX) else {
            continue;
        };
        let v = parse_raw(payload).map_err(|(found, field)| ImportError::RawLine {
            path: shown.clone(),
            line: line_no,
            found,
            field,
        })?;
        let reading = SketchReading::from_counts(v, SCALING);
        accel.push(Vec3::from(reading.accel));
        gyro.push(Vec3::from(reading.gyro));
        mag.push(Vec3::from(reading.mag));
    }
    if accel.is_empty() {
        return Err(ImportError::NoRawLines { path: shown });
    }
    let time: Vec<f64> = (0..accel.len())
        .map(|i| rate_hz.map_or(i as f64, |rate| i as f64 / rate))
        .collect();
    Ok(Recording {
        source: path.to_path_buf(),
        time_is_index: rate_hz.is_none(),
        time_from_file: false,
        accel: Some(accel),
        gyro: Some(gyro),
        temp_c: None,
        mag: Some(MagStream {
            source: path.to_path_buf(),
            time: time.clone(),
            samples: mag,
            temp_c: None,
        }),
        time,
        labels: None,
        ignored_columns: Vec::new(),
        units: Units {
            accel: AccelUnit::Mps2,
            gyro: GyroUnit::Rads,
            mag: MagUnit::Ut,
        },
        read_as_imutk: false,
        repeated_rows: 0,
    })
}

/// Reads a MotionCal log file (or standard input for `-`), once, line by line.
pub fn load(path: &Path, rate_hz: Option<f64>) -> Result<Recording, ImportError> {
    parse_lines(&mut LineReader::open(path)?, path, rate_hz)
}
