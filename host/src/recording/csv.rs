//! Reader for the CSV recording format (`ARCHITECTURE.md`, "Recording format"): a header line
//! of named columns in any order (`t_s`, `ax ay az`, `gx gy gz`, `mx my mz`, `temp_c`, and an
//! optional `pose` or `segment` label; a name may carry its unit in brackets or parentheses,
//! `ax [m/s2]`, see [`super::column_names`]), then one row per sample. Lines starting with `#` are
//! comments. The file is read once, line by line (see [`super::lines`]): memory holds the
//! numbers kept, not the text.

use std::path::Path;

use super::lines::LineReader;
use super::mapping;
use super::rows::{
    content, parse_block, rows_without_a_number, Block, Columns, LabelInterner, Layout, Part, Role,
    ONE_ROW_ADVICE,
};
use super::units::MagUnit;
use super::{
    column_names, display, LabelKind, Labels, LoadOptions, MagStream, Recording, RecordingError,
    Sensor, Units,
};
use crate::fit::Vec3;

/// A parsed header: where each known column sits.
struct Header {
    names: Vec<String>,
    time: Option<usize>,
    temp: Option<usize>,
    label: Option<(usize, LabelKind)>,
    sensors: Vec<(Sensor, [usize; 3])>,
    /// Per sensor, the column whose name gives its unit (`ax [g]`), already checked to be a unit
    /// imucal reads and the one the sensor's other columns give, if they give one.
    unit_columns: Vec<(Sensor, usize)>,
    ignored: Vec<String>,
}

/// The units a header may write after the names of the columns that are not sensor readings.
fn other_units(base: &str) -> Option<(&'static [&'static str], &'static str)> {
    match base {
        "t_s" => Some((&["s"], "s")),
        "temp_c" => Some((&["°c", "ºc", "c", "degc", "celsius"], "°C")),
        _ => None,
    }
}

fn parse_header(path: &Path, line: &str) -> Result<Header, RecordingError> {
    let names: Vec<String> = line
        .split(',')
        .map(|s| s.trim().trim_matches('"').to_ascii_lowercase())
        .collect();
    // Each column's name without the unit written after it (`ax [m/s2]` is column `ax`).
    let split: Vec<(&str, Option<&str>)> =
        names.iter().map(|n| column_names::split_unit(n)).collect();
    let known = |n: &str| {
        matches!(n, "t_s" | "temp_c" | "pose" | "segment")
            || Sensor::ALL.iter().any(|s| s.columns().contains(&n))
    };
    for (i, name) in names.iter().enumerate() {
        let base = split[i].0;
        let same = |j: usize| names[j] == *name || (known(base) && split[j].0 == base);
        if let Some(j) = (0..i).find(|&j| same(j)) {
            return Err(RecordingError::DuplicateColumn {
                path: display(path),
                column: if names[j] == *name {
                    name.clone()
                } else {
                    format!("{base}` (as `{}` and `{name}`)", names[j])
                },
            });
        }
    }
    let find = |n: &str| split.iter().position(|(base, _)| *base == n);
    let unknown_unit = |i: usize, accepted: &'static str| RecordingError::UnknownUnit {
        path: display(path),
        column: names[i].clone(),
        unit: split[i].1.unwrap_or("").to_string(),
        accepted,
        fix: match split[i].0 {
            "t_s" => {
                "a time column in another unit is read through a mapping that names its unit: \
                 `--columns t_ms=<column>,…` (or t_us, t_ns) with every other column to read"
            }
            "temp_c" | "pose" | "segment" => "leave the unit out of the name",
            _ => {
                "write one it reads in the brackets, or leave the unit out of the name and give \
                 it with --accel-unit, --gyro-unit or --mag-unit"
            }
        },
    };
    let mut sensors = Vec::new();
    let mut unit_columns = Vec::new();
    for sensor in Sensor::ALL {
        let cols = sensor.columns();
        let idx = cols.map(find);
        match idx {
            [Some(x), Some(y), Some(z)] => {
                sensors.push((sensor, [x, y, z]));
                let mut first: Option<(usize, Units)> = None;
                for i in [x, y, z] {
                    let Some(unit) = split[i].1 else { continue };
                    let read = Units::default()
                        .with_symbol(sensor, unit)
                        .ok_or_else(|| unknown_unit(i, Units::spellings(sensor)))?;
                    match first {
                        None => first = Some((i, read)),
                        Some((j, other)) if other.symbol(sensor) != read.symbol(sensor) => {
                            return Err(RecordingError::MixedUnits {
                                path: display(path),
                                first: names[j].clone(),
                                second: names[i].clone(),
                            });
                        }
                        Some(_) => {}
                    }
                }
                unit_columns.extend(first.map(|(i, _)| (sensor, i)));
            }
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
    // The other columns read may carry their own unit, which must be the one the name says.
    for (i, (base, unit)) in split.iter().enumerate() {
        let Some(unit) = unit else { continue };
        if Sensor::ALL.iter().any(|s| s.columns().contains(base)) {
            continue;
        }
        let written = unit.to_lowercase().replace(' ', "");
        match other_units(base) {
            Some((spellings, accepted)) if !spellings.contains(&written.as_str()) => {
                return Err(unknown_unit(i, accepted));
            }
            None if known(base) => return Err(unknown_unit(i, "none: it holds labels")),
            _ => {}
        }
    }
    let label = find("pose")
        .map(|i| (i, LabelKind::Pose))
        .or_else(|| find("segment").map(|i| (i, LabelKind::Segment)));
    let ignored = names
        .iter()
        .zip(&split)
        .filter(|(_, (base, _))| !known(base))
        .map(|(name, _)| name.clone())
        .collect();
    Ok(Header {
        time: find("t_s"),
        temp: find("temp_c"),
        label,
        sensors,
        unit_columns,
        ignored,
        names,
    })
}

/// The units of a file with `header`: those `options` give, each sensor's replaced by the one
/// its column names write unless the user stated another, which is refused.
fn resolve_units(
    path: &Path,
    header: &Header,
    options: &LoadOptions,
) -> Result<Units, RecordingError> {
    column_names::units_from_names(
        path,
        &header.names,
        &header.unit_columns,
        options.units,
        &options.units_stated,
    )
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

/// True for lines the CSV format skips: blank lines and `#` comments.
pub(super) fn is_skipped(line: &str) -> bool {
    let line = content(line);
    line.is_empty() || line.starts_with('#')
}

/// What each column of `header` holds.
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

/// Bytes of input parsed at a time (in two halves, one per thread): large enough that starting
/// the second thread costs well under 1 % of the block's parsing, small enough to stay in cache.
const BLOCK_BYTES: usize = 1 << 20;

/// The refusal of a header that names imucal's columns with another delimiter than the comma
/// (semicolon or tab, as spreadsheets in many locales write), with the `--columns` mapping that
/// reads it; `None` when it does not.
fn other_delimiter(path: &Path, header_line: &str) -> Option<RecordingError> {
    let (delimiter, shown) = [(';', ";"), ('\t', "tab")]
        .into_iter()
        .find(|(d, _)| header_line.contains(*d))?;
    let header = parse_header(path, &header_line.replace(delimiter, ",")).ok()?;
    if header.sensors.is_empty() {
        return None;
    }
    let mapped: Vec<String> = header
        .names
        .iter()
        .filter(|name| mapping::is_target(name))
        .map(|name| format!("{name}={name}"))
        .collect();
    Some(RecordingError::OtherDelimiter {
        path: display(path),
        delimiter: shown.to_string(),
        mapping: mapped.join(","),
    })
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
        return Err(other_delimiter(path, header_line).unwrap_or_else(|| {
            RecordingError::NoSensor {
                path: display(path),
                header: header_line.chars().take(80).collect(),
            }
        }));
    }
    let path_text = display(path);
    let layout = Layout {
        path: &path_text,
        names: &header.names,
        roles: column_roles(&header),
        sensors: header.sensors.len(),
        time: header.time.is_some(),
        temp: header.temp.is_some(),
        label: header.label.map(|(_, kind)| kind),
    };
    let mut columns = Columns::new(&layout);
    let mut parts = [Part::new(&layout), Part::new(&layout)];
    let input_bytes = lines.input_len();
    let mut reserved = false;
    loop {
        let first_line = lines.line_no() + 1;
        let Some((offset, bytes)) = lines.next_block(BLOCK_BYTES)? else {
            break;
        };
        let block = Block {
            bytes,
            first_line,
            offset,
        };
        let block_len = bytes.len();
        let count = match parse_block(&layout, &block, &mut parts, &mut columns) {
            Err(RecordingError::BadNumber {
                path,
                line,
                column,
                text,
                ..
            }) => {
                // How much of the column is like that value decides the advice: a row to mend,
                // or a column that holds no readings at all.
                let skip = line.saturating_sub(first_line);
                let rest = bytes
                    .split_inclusive(|&b| b == b'\n')
                    .skip(skip)
                    .flatten()
                    .copied()
                    .collect::<Vec<u8>>();
                let index = header.names.iter().position(|n| *n == column);
                let advice = match index {
                    Some(index) => bad_number_advice(lines, &rest, index, columns.rows == 0, line),
                    None => ONE_ROW_ADVICE.to_string(),
                };
                return Err(RecordingError::BadNumber {
                    path,
                    line,
                    column,
                    text,
                    advice,
                });
            }
            other => other?,
        };
        lines.count_lines(count);
        if !reserved && columns.rows > 0 {
            // Rows of a file are alike in length: reserve for all of them at once (from the
            // first block's bytes per row) rather than copying every column as it doubles.
            reserved = true;
            if let Some(total) = input_bytes {
                let per_row = (block_len / columns.rows).max(1) as u64;
                let expected = (total / per_row).min(1 << 32) as usize;
                columns.reserve((expected + expected / 8).saturating_sub(columns.rows));
            }
        }
    }
    if columns.rows == 0 {
        return Err(RecordingError::NoRows {
            path: display(path),
        });
    }
    let sensors = header
        .sensors
        .iter()
        .map(|(s, _)| *s)
        .zip(columns.sensors)
        .collect();
    Ok(Table {
        header,
        time: columns.time,
        temp: columns.temp,
        labels: columns.labels.map(LabelInterner::finish),
        sensors,
        rows: columns.rows,
    })
}

/// Rows past a value that is not a number read to judge its column: enough to tell a column
/// that holds nothing from a few bad rows, without reading a huge file to its end.
const BAD_COLUMN_SCAN_ROWS: usize = 1_000_000;

/// The advice for a value that is not a number at line `line` in column `index`: `rest` is its
/// block from that line on, `lines` the rest of the input; `first_row` when no row before it
/// was read. The count stops at a later fault of the input (an unreadable block, a line too
/// long): the value's own error is the one to report.
fn bad_number_advice(
    lines: &mut LineReader<'_>,
    rest: &[u8],
    index: usize,
    first_row: bool,
    line: usize,
) -> String {
    let (mut rows, mut bad) = rows_without_a_number(rest, index, BAD_COLUMN_SCAN_ROWS);
    while rows < BAD_COLUMN_SCAN_ROWS {
        let Ok(Some((_, bytes))) = lines.next_block(BLOCK_BYTES) else {
            break;
        };
        let (r, b) = rows_without_a_number(bytes, index, BAD_COLUMN_SCAN_ROWS - rows);
        rows += r;
        bad += b;
    }
    let whole = if rows >= BAD_COLUMN_SCAN_ROWS {
        format!("the {rows} rows read from there on")
    } else {
        format!("all {rows} rows from there to the end")
    };
    match (bad == rows && rows > 1, first_row) {
        (true, true) => format!(
            "no row holds a number there ({whole}): the column holds no readings; leave it out \
             of the file, or read the file with --columns mapping only the columns that do"
        ),
        (true, false) => format!(
            "no row holds a number there from line {line} on ({whole}): the sensor stopped \
             recording; cut the file before line {line}"
        ),
        _ if bad > 1 => format!(
            "{bad} of the {rows} rows from there on hold no number in that column; correct or \
             delete those rows"
        ),
        _ => ONE_ROW_ADVICE.to_string(),
    }
}

/// Row times: `t_s`, or index / rate, or the index itself.
fn row_times(time: Option<Vec<f64>>, rows: usize, rate_hz: Option<f64>) -> (Vec<f64>, bool) {
    match (time, rate_hz) {
        (Some(t), _) => (t, false),
        (None, Some(rate)) => ((0..rows).map(|i| i as f64 / rate).collect(), false),
        (None, None) => ((0..rows).map(|i| i as f64).collect(), true),
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
    let units = resolve_units(path, &table.header, options)?;
    let time_from_file = table.time.is_some();
    let (time, time_is_index) = row_times(table.time, table.rows, options.rate_hz);
    let mut recording = Recording {
        source: path.to_path_buf(),
        time_is_index,
        time_from_file,
        accel: None,
        gyro: None,
        temp_c: table.temp,
        mag: None,
        labels: table.labels,
        ignored_columns: table.header.ignored,
        units,
        time,
        read_as_imutk: false,
        repeated_rows: 0,
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
                    temp_c: None,
                })
            }
        }
    }
    Ok(recording)
}

/// Read a magnetometer file with its own clock (`t_s, mx, my, mz`, other columns ignored), with
/// the unit of its samples (a unit its header writes, or the one `options` give).
pub(super) fn load_mag_stream(
    path: &Path,
    options: &LoadOptions,
) -> Result<(MagStream, MagUnit), RecordingError> {
    let table = read_table(path, &mut LineReader::open(path)?, None)?;
    let unit = resolve_units(path, &table.header, options)?.mag;
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
    let stream = MagStream {
        source: path.to_path_buf(),
        time,
        samples,
        temp_c: table.temp,
    };
    Ok((stream, unit))
}
