//! Reader for the CSV recording format (`ARCHITECTURE.md`, "Recording format"): a header line
//! of named columns in any order (`t_s`, `ax ay az`, `gx gy gz`, `mx my mz`, `temp_c`, and an
//! optional `pose` or `segment` label), then one row per sample. Lines starting with `#` are
//! comments. The file is read once, line by line (see [`super::lines`]): memory holds the
//! numbers kept, not the text.

use std::collections::HashMap;
use std::path::Path;

use super::lines::LineReader;
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

/// Rows of a CSV file as columns of numbers (labels interned as they are read).
struct Table {
    header: Header,
    time: Option<Vec<f64>>,
    temp: Option<Vec<f64>>,
    labels: Option<Labels>,
    sensors: Vec<(Sensor, Vec<Vec3>)>,
    rows: usize,
}

/// Text of a line as the CSV reader sees it: without a byte-order mark or surrounding blanks.
fn content(line: &str) -> &str {
    line.trim_start_matches('\u{feff}').trim()
}

/// True for lines the CSV format skips: blank lines and `#` comments.
pub(super) fn is_skipped(line: &str) -> bool {
    let line = content(line);
    line.is_empty() || line.starts_with('#')
}

/// What a column of the header holds.
#[derive(Debug, Clone, Copy)]
enum Role {
    Time,
    Temp,
    Label,
    /// A sensor value: index `3·sensor + axis` into one row's readings.
    Reading(usize),
    Ignored,
}

fn column_roles(header: &Header) -> Vec<Role> {
    let mut roles = vec![Role::Ignored; header.names.len()];
    let mut set = |col: Option<usize>, role: Role| {
        if let Some(slot) = col.and_then(|c| roles.get_mut(c)) {
            *slot = role;
        }
    };
    set(header.time, Role::Time);
    set(header.temp, Role::Temp);
    set(header.label.map(|(c, _)| c), Role::Label);
    for (k, (_, cols)) in header.sensors.iter().enumerate() {
        for (axis, col) in cols.iter().enumerate() {
            set(Some(*col), Role::Reading(3 * k + axis));
        }
    }
    roles
}

/// The comma-separated fields of a row (what `str::split(',')` yields), found with a byte
/// search: a comma is one byte in UTF-8, so every piece is itself valid text.
fn fields(row: &str) -> impl Iterator<Item = &str> {
    let mut rest = Some(row);
    std::iter::from_fn(move || {
        let text = rest?;
        match memchr::memchr(b',', text.as_bytes()) {
            Some(at) => {
                rest = text.get(at + 1..);
                text.get(..at)
            }
            None => {
                rest = None;
                Some(text)
            }
        }
    })
}

/// A field as a finite number.
fn parse_number(text: &str) -> Option<f64> {
    super::decimal::parse_finite(text)
}

/// Read the rows after `header_line` (the first line that is not skipped, if any) from `lines`.
fn read_table(
    path: &Path,
    lines: &mut LineReader<'_>,
    header_line: Option<(usize, String)>,
) -> Result<Table, RecordingError> {
    let header_line = match header_line {
        Some((_, line)) => line,
        None => loop {
            match lines.next_line()? {
                Some((_, l)) if is_skipped(l) => {}
                Some((_, l)) => break l.to_string(),
                None => {
                    return Err(RecordingError::Empty {
                        path: display(path),
                    })
                }
            }
        },
    };
    let header_line = content(&header_line);
    let header = parse_header(path, header_line)?;
    if header.sensors.is_empty() {
        return Err(RecordingError::NoSensor {
            path: display(path),
            header: header_line.chars().take(80).collect(),
        });
    }
    let mut time = header.time.map(|_| Vec::new());
    let mut temp = header.temp.map(|_| Vec::new());
    let mut labels = header.label.map(|(_, kind)| LabelInterner::new(kind));
    let mut sensors: Vec<(Sensor, Vec<Vec3>)> = header
        .sensors
        .iter()
        .map(|(s, _)| (*s, Vec::new()))
        .collect();
    let roles = column_roles(&header);
    // One row's sensor values, in the order of `header.sensors`.
    let mut readings = vec![0.0; 3 * header.sensors.len()];
    let mut rows = 0;
    let input_bytes = lines.input_len();
    while let Some((line_no, line)) = lines.next_line()? {
        let body = content(line);
        if body.is_empty() || body.starts_with('#') {
            continue;
        }
        let mut found = 0;
        for (col, text) in fields(body).enumerate() {
            found += 1;
            let Some(role) = roles.get(col) else { continue };
            if let Role::Label = role {
                if let Some(l) = labels.as_mut() {
                    l.push(text.trim());
                }
                continue;
            }
            if let Role::Ignored = role {
                continue;
            }
            // ASCII blanks are the usual padding; other Unicode spaces take the slower trim.
            let value = parse_number(text.trim_ascii())
                .or_else(|| parse_number(text.trim()))
                .ok_or_else(|| RecordingError::BadNumber {
                    path: display(path),
                    line: line_no,
                    column: header.names[col].clone(),
                    text: text.trim().to_string(),
                })?;
            match *role {
                Role::Time => {
                    let t = time.get_or_insert_with(Vec::new);
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
                Role::Temp => temp.get_or_insert_with(Vec::new).push(value),
                Role::Reading(slot) => {
                    if value.abs() > MAX_SENSOR_MAGNITUDE {
                        return Err(RecordingError::OutOfRange {
                            path: display(path),
                            line: line_no,
                            column: header.names[col].clone(),
                            value,
                            limit: MAX_SENSOR_MAGNITUDE,
                        });
                    }
                    readings[slot] = value;
                }
                Role::Label | Role::Ignored => {}
            }
        }
        if found != header.names.len() {
            return Err(RecordingError::FieldCount {
                path: display(path),
                line: line_no,
                expected: header.names.len(),
                found,
            });
        }
        for (k, (_, out)) in sensors.iter_mut().enumerate() {
            out.push(Vec3::new(
                readings[3 * k],
                readings[3 * k + 1],
                readings[3 * k + 2],
            ));
        }
        if rows == 0 {
            // Rows of a file are alike in length: reserve for all of them at once rather than
            // copying every column as it doubles.
            if let Some(total) = input_bytes {
                let expected = (total / (line.len() as u64 + 1)).min(1 << 32) as usize;
                let more = expected + expected / 8;
                for v in time.iter_mut().chain(temp.iter_mut()) {
                    v.reserve(more);
                }
                for (_, v) in sensors.iter_mut() {
                    v.reserve(more);
                }
            }
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
        labels: labels.map(LabelInterner::finish),
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

/// Builds [`Labels`] row by row, storing each distinct text once.
struct LabelInterner {
    kind: LabelKind,
    names: Vec<String>,
    index: HashMap<String, usize>,
    per_row: Vec<Option<usize>>,
}

impl LabelInterner {
    fn new(kind: LabelKind) -> Self {
        Self {
            kind,
            names: Vec::new(),
            index: HashMap::new(),
            per_row: Vec::new(),
        }
    }

    fn push(&mut self, text: &str) {
        let label = if text.is_empty() || text == "-" {
            None
        } else if let Some(&i) = self.index.get(text) {
            Some(i)
        } else {
            self.names.push(text.to_string());
            self.index.insert(text.to_string(), self.names.len() - 1);
            Some(self.names.len() - 1)
        };
        self.per_row.push(label);
    }

    fn finish(self) -> Labels {
        Labels {
            kind: self.kind,
            names: self.names,
            per_row: self.per_row,
        }
    }
}

/// Read a CSV recording from `lines`, whose first line that is not skipped may already have been
/// taken out (`header_line`).
pub(super) fn load(
    path: &Path,
    lines: &mut LineReader<'_>,
    header_line: Option<(usize, String)>,
    options: &LoadOptions,
) -> Result<Recording, RecordingError> {
    let table = read_table(path, lines, header_line)?;
    let (time, time_is_index) = row_times(table.time, table.rows, options.rate_hz);
    let mut recording = Recording {
        source: path.to_path_buf(),
        time_is_index,
        accel: None,
        gyro: None,
        temp_c: table.temp,
        mag: None,
        labels: table.labels,
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
    let table = read_table(path, &mut LineReader::open(path)?, None)?;
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

#[cfg(test)]
mod tests {
    use super::fields;

    #[test]
    fn fields_split_a_row_exactly_as_str_split_on_commas() {
        for row in [
            "",
            ",",
            "1,2,3",
            ",a,,b,",
            " 1.5 , -2 ,\u{e9}t\u{e9},x",
            "no commas",
        ] {
            let expected: Vec<&str> = row.split(',').collect();
            assert_eq!(fields(row).collect::<Vec<_>>(), expected, "{row:?}");
        }
    }
}
