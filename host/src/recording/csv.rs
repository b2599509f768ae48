//! Reader for the CSV recording format (`ARCHITECTURE.md`, "Recording format"): a header line
//! of named columns in any order (`t_s`, `ax ay az`, `gx gy gz`, `mx my mz`, `temp_c`, and an
//! optional `pose` or `segment` label), then one row per sample. Lines starting with `#` are
//! comments.

use std::path::Path;

use super::{
    display, LabelKind, Labels, LoadOptions, MagStream, Recording, RecordingError, Sensor,
    MAX_SENSOR_MAGNITUDE,
};
use crate::fit::Vec3;

/// A parsed header: where each known column sits.
struct Header {
    names: Vec<String>,
    time: Option<usize>,
    temp: Option<usize>,
    label: Option<(usize, LabelKind)>,
    sensors: Vec<(Sensor, [usize; 3])>,
    ignored: Vec<String>,
}

fn parse_header(path: &Path, line: &str) -> Result<Header, RecordingError> {
    let names: Vec<String> = line
        .split(',')
        .map(|s| s.trim().trim_matches('"').to_ascii_lowercase())
        .collect();
    for (i, name) in names.iter().enumerate() {
        if names[..i].contains(name) {
            return Err(RecordingError::DuplicateColumn {
                path: display(path),
                column: name.clone(),
            });
        }
    }
    let find = |n: &str| names.iter().position(|c| c == n);
    let mut sensors = Vec::new();
    for sensor in Sensor::ALL {
        let cols = sensor.columns();
        let idx = cols.map(find);
        match idx {
            [Some(x), Some(y), Some(z)] => sensors.push((sensor, [x, y, z])),
            [None, None, None] => {}
            _ => {
                let present = cols
                    .iter()
                    .zip(idx)
                    .find(|(_, i)| i.is_some())
                    .map(|(c, _)| *c);
                let missing = cols
                    .iter()
                    .zip(idx)
                    .find(|(_, i)| i.is_none())
                    .map(|(c, _)| *c);
                return Err(RecordingError::IncompleteSensor {
                    path: display(path),
                    present: present.unwrap_or("?"),
                    missing: missing.unwrap_or("?"),
                });
            }
        }
    }
    let label = find("pose")
        .map(|i| (i, LabelKind::Pose))
        .or_else(|| find("segment").map(|i| (i, LabelKind::Segment)));
    let known = |n: &str| {
        matches!(n, "t_s" | "temp_c" | "pose" | "segment")
            || Sensor::ALL.iter().any(|s| s.columns().contains(&n))
    };
    let ignored = names.iter().filter(|n| !known(n)).cloned().collect();
    Ok(Header {
        time: find("t_s"),
        temp: find("temp_c"),
        label,
        sensors,
        ignored,
        names,
    })
}

/// Rows of a CSV file as columns of numbers (label column kept as text).
struct Table {
    header: Header,
    time: Option<Vec<f64>>,
    temp: Option<Vec<f64>>,
    labels: Option<Vec<String>>,
    sensors: Vec<(Sensor, Vec<Vec3>)>,
    rows: usize,
}

fn read_table(path: &Path) -> Result<Table, RecordingError> {
    let text = super::read_text(path)?;
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim_start_matches('\u{feff}').trim()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'));
    let (_, header_line) = lines.next().ok_or_else(|| RecordingError::Empty {
        path: display(path),
    })?;
    let header = parse_header(path, header_line)?;
    if header.sensors.is_empty() {
        return Err(RecordingError::NoSensor {
            path: display(path),
            header: header_line.chars().take(80).collect(),
        });
    }
    let mut time = header.time.map(|_| Vec::new());
    let mut temp = header.temp.map(|_| Vec::new());
    let mut labels = header.label.map(|_| Vec::new());
    let mut sensors: Vec<(Sensor, Vec<Vec3>)> = header
        .sensors
        .iter()
        .map(|(s, _)| (*s, Vec::new()))
        .collect();
    let mut fields: Vec<&str> = Vec::with_capacity(header.names.len());
    let mut rows = 0;
    for (line_no, line) in lines {
        fields.clear();
        fields.extend(line.split(',').map(str::trim));
        if fields.len() != header.names.len() {
            return Err(RecordingError::FieldCount {
                path: display(path),
                line: line_no,
                expected: header.names.len(),
                found: fields.len(),
            });
        }
        let number = |col: usize| -> Result<f64, RecordingError> {
            let text = fields.get(col).copied().unwrap_or("");
            match text.parse::<f64>() {
                Ok(v) if v.is_finite() => Ok(v),
                _ => Err(RecordingError::BadNumber {
                    path: display(path),
                    line: line_no,
                    column: header.names.get(col).cloned().unwrap_or_default(),
                    text: text.to_string(),
                }),
            }
        };
        if let (Some(col), Some(t)) = (header.time, time.as_mut()) {
            let value = number(col)?;
            if let Some(&previous) = t.last() {
                if value < previous {
                    return Err(RecordingError::TimeBackwards {
                        path: display(path),
                        line: line_no,
                        time: value,
                        previous,
                    });
                }
            }
            t.push(value);
        }
        if let (Some(col), Some(v)) = (header.temp, temp.as_mut()) {
            v.push(number(col)?);
        }
        if let (Some((col, _)), Some(v)) = (header.label, labels.as_mut()) {
            v.push(fields.get(col).copied().unwrap_or("").to_string());
        }
        let reading = |col: usize| -> Result<f64, RecordingError> {
            let value = number(col)?;
            if value.abs() > MAX_SENSOR_MAGNITUDE {
                return Err(RecordingError::OutOfRange {
                    path: display(path),
                    line: line_no,
                    column: header.names.get(col).cloned().unwrap_or_default(),
                    value,
                    limit: MAX_SENSOR_MAGNITUDE,
                });
            }
            Ok(value)
        };
        for ((_, cols), (_, out)) in header.sensors.iter().zip(sensors.iter_mut()) {
            out.push(Vec3::new(
                reading(cols[0])?,
                reading(cols[1])?,
                reading(cols[2])?,
            ));
        }
        rows += 1;
    }
    if rows == 0 {
        return Err(RecordingError::NoRows {
            path: display(path),
        });
    }
    Ok(Table {
        header,
        time,
        temp,
        labels,
        sensors,
        rows,
    })
}

/// Row times: `t_s`, or index / rate, or the index itself.
fn row_times(time: Option<Vec<f64>>, rows: usize, rate_hz: Option<f64>) -> (Vec<f64>, bool) {
    match (time, rate_hz) {
        (Some(t), _) => (t, false),
        (None, Some(rate)) => ((0..rows).map(|i| i as f64 / rate).collect(), false),
        (None, None) => ((0..rows).map(|i| i as f64).collect(), true),
    }
}

fn build_labels(kind: LabelKind, texts: Vec<String>) -> Labels {
    let mut names: Vec<String> = Vec::new();
    let per_row = texts
        .into_iter()
        .map(|text| {
            if text.is_empty() || text == "-" {
                return None;
            }
            Some(match names.iter().position(|n| *n == text) {
                Some(i) => i,
                None => {
                    names.push(text);
                    names.len() - 1
                }
            })
        })
        .collect();
    Labels {
        kind,
        names,
        per_row,
    }
}

/// Read a CSV recording.
pub(super) fn load(path: &Path, options: &LoadOptions) -> Result<Recording, RecordingError> {
    let table = read_table(path)?;
    let (time, time_is_index) = row_times(table.time, table.rows, options.rate_hz);
    let mut recording = Recording {
        source: path.to_path_buf(),
        time_is_index,
        accel: None,
        gyro: None,
        temp_c: table.temp,
        mag: None,
        labels: table
            .header
            .label
            .zip(table.labels)
            .map(|((_, kind), texts)| build_labels(kind, texts)),
        ignored_columns: table.header.ignored,
        units: options.units,
        time,
    };
    for (sensor, samples) in table.sensors {
        match sensor {
            Sensor::Accel => recording.accel = Some(samples),
            Sensor::Gyro => recording.gyro = Some(samples),
            Sensor::Mag => {
                recording.mag = Some(MagStream {
                    source: path.to_path_buf(),
                    time: recording.time.clone(),
                    samples,
                })
            }
        }
    }
    Ok(recording)
}

/// Read a magnetometer file with its own clock (`t_s, mx, my, mz`, other columns ignored).
pub(super) fn load_mag_stream(
    path: &Path,
    options: &LoadOptions,
) -> Result<MagStream, RecordingError> {
    let table = read_table(path)?;
    let samples = table
        .sensors
        .into_iter()
        .find(|(s, _)| *s == Sensor::Mag)
        .map(|(_, v)| v)
        .ok_or_else(|| RecordingError::NoSensor {
            path: display(path),
            header: format!(
                "{} (a magnetometer file needs `mx my mz`)",
                table.header.names.join(",")
            ),
        })?;
    let (time, _) = row_times(table.time, table.rows, options.rate_hz);
    Ok(MagStream {
        source: path.to_path_buf(),
        time,
        samples,
    })
}
