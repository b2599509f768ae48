//! Reader for any delimited text file with a header, given a column mapping such as
//! `ax=AccX,ay=AccY,az=AccZ,gx=GyrX,gy=GyrY,gz=GyrZ,t_ms=Timestamp`: each imucal column named
//! on the left is read from the file's column named on the right.
//!
//! Targets are the recording columns `ax ay az gx gy gz mx my mz temp_c`, one time column,
//! `t_s`, `t_ms`, `t_us` or `t_ns` (the suffix gives the file's time unit), and one label
//! column, `pose` (rows labelled alike are one static hold) or `segment` (sections still
//! intervals are detected within). A sensor needs all
//! three of its columns. The delimiter (comma, semicolon or tab) is the one the header uses
//! most. Columns not mapped are ignored; the units of the sensor columns are given separately.
//! Also holds [`ImportError`], the error of both importers in this module's siblings.

use std::path::Path;
use std::str::FromStr;

use super::rows::LabelInterner;
use super::{LabelKind, MagStream, Recording, Sensor, Units};
use crate::fit::Vec3;

/// Why an imported file (a mapped CSV or a MotionCal log) could not be read.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    /// The file could not be read.
    #[error("cannot read `{path}`: {cause}; check the path and that the file is readable")]
    Io {
        /// File concerned.
        path: String,
        /// Operating-system error.
        cause: std::io::Error,
    },
    /// The input is not line-oriented UTF-8 text, or could not be read (see [`super::lines`]),
    /// or a unit in a mapped column's name contradicts a unit option.
    #[error(transparent)]
    Text(#[from] super::RecordingError),
    /// A MotionCal log without any `Raw:` line.
    #[error("`{path}` holds no `Raw:ax,ay,az,gx,gy,gz,mx,my,mz` line; it is not a MotionCal serial log (save the serial monitor output while the calibration sketch runs)")]
    NoRawLines {
        /// File concerned.
        path: String,
    },
    /// A `Raw:` line with the wrong number of fields or a field that is not a number.
    #[error("`{path}` line {line}: a `Raw:` line needs nine integers (ax,ay,az,gx,gy,gz,mx,my,mz){}; delete the garbled line", if field.is_empty() { format!(", found {found}") } else { format!(", `{field}` is not one") })]
    RawLine {
        /// File concerned.
        path: String,
        /// 1-based line number.
        line: usize,
        /// Fields found.
        found: usize,
        /// The field that is not a number (empty when the count is wrong).
        field: String,
    },
    /// A sample rate that is not a positive number.
    #[error("sample rate {0} Hz is not a positive finite number; pass e.g. `--rate 100`")]
    BadRate(f64),
    /// The mapping text is malformed.
    #[error("column mapping `{text}`: {problem}; write it as `ax=AccX,ay=AccY,az=AccZ,t_s=Time` (imucal column = file column)")]
    MappingSyntax {
        /// The mapping as given.
        text: String,
        /// What is wrong.
        problem: String,
    },
    /// A mapped column does not exist in the file.
    #[error("`{path}`: the mapping names column `{column}`, which the header does not have; the header's columns are: {header}")]
    MissingColumn {
        /// File concerned.
        path: String,
        /// The file column asked for.
        column: String,
        /// The header's columns.
        header: String,
    },
    /// The file holds no header line.
    #[error("`{path}` is empty: a header line naming the columns is needed for a column mapping")]
    Empty {
        /// File concerned.
        path: String,
    },
    /// A field is not a finite number.
    #[error("`{path}` line {line}, column `{column}`: `{text}` is not a finite number; correct or delete that row")]
    BadNumber {
        /// File concerned.
        path: String,
        /// 1-based line number.
        line: usize,
        /// File column name.
        column: String,
        /// The offending text.
        text: String,
    },
    /// Time stamps go backwards.
    #[error("`{path}` line {line}: time {time} s is earlier than the previous row's {previous} s; sort the rows by time")]
    TimeBackwards {
        /// File concerned.
        path: String,
        /// 1-based line number.
        line: usize,
        /// This row's time, s.
        time: f64,
        /// The previous row's time, s.
        previous: f64,
    },
    /// A header but no data rows.
    #[error("`{path}` has a header but no data rows")]
    NoRows {
        /// File concerned.
        path: String,
    },
}

impl ImportError {
    /// Whether the error is an option that contradicts the file (see
    /// [`super::RecordingError::is_option_conflict`]).
    pub fn is_option_conflict(&self) -> bool {
        matches!(self, Self::Text(cause) if cause.is_option_conflict())
    }
}

/// Where each imucal column comes from.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ColumnMapping {
    /// File column per sensor axis: `[accel, gyro, mag]`, each `[x, y, z]`.
    pub sensors: [Option<[String; 3]>; 3],
    /// Die temperature column, °C.
    pub temp_c: Option<String>,
    /// Time column and seconds per unit of it.
    pub time: Option<(String, f64)>,
    /// Label column (`pose` or `segment`) and what its labels mean.
    pub labels: Option<(String, LabelKind)>,
}

const TIME_KEYS: [(&str, f64); 4] = [("t_s", 1.0), ("t_ms", 1e-3), ("t_us", 1e-6), ("t_ns", 1e-9)];

/// The label targets of a mapping and what their labels mean.
const LABEL_KEYS: [(&str, LabelKind); 2] =
    [("pose", LabelKind::Pose), ("segment", LabelKind::Segment)];

/// Whether `name` is an imucal column a mapping can name (`ax` … `mz`, `temp_c`, a time key,
/// `pose` or `segment`).
pub(super) fn is_target(name: &str) -> bool {
    TIME_KEYS.iter().any(|(key, _)| *key == name)
        || LABEL_KEYS.iter().any(|(key, _)| *key == name)
        || name == "temp_c"
        || Sensor::ALL.iter().any(|s| s.columns().contains(&name))
}

impl FromStr for ColumnMapping {
    type Err = ImportError;

    /// Parses `target=column` pairs separated by commas.
    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let bad = |problem: String| ImportError::MappingSyntax {
            text: text.to_string(),
            problem,
        };
        let mut axes: [[Option<String>; 3]; 3] = Default::default();
        let mut mapping = ColumnMapping::default();
        // File column → the imucal column it was mapped to: one file column is one quantity.
        let mut sources: Vec<(String, String)> = Vec::new();
        for pair in text.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            let (target, column) = pair
                .split_once('=')
                .ok_or_else(|| bad(format!("`{pair}` has no `=`")))?;
            let (target, column) = (target.trim().to_ascii_lowercase(), column.trim());
            if column.is_empty() {
                return Err(bad(format!("`{target}` is mapped to nothing")));
            }
            let is_label = |t: &str| LABEL_KEYS.iter().any(|(key, _)| *key == t);
            if let Some((_, first)) = sources
                .iter()
                .find(|(c, _)| c == column)
                .filter(|(_, first)| !(is_label(first) && is_label(&target)))
            {
                // (Two label keys on one column are told as two label columns, below.)
                return Err(bad(format!(
                    "file column `{column}` is mapped to both `{first}` and `{target}`; each \
                     imucal column needs its own file column"
                )));
            }
            sources.push((column.to_string(), target.clone()));
            let column = column.to_string();
            if let Some((_, scale)) = TIME_KEYS.iter().find(|(key, _)| *key == target) {
                if mapping.time.is_some() {
                    return Err(bad("two time columns are mapped".to_string()));
                }
                mapping.time = Some((column, *scale));
                continue;
            }
            if target == "temp_c" {
                mapping.temp_c = Some(column);
                continue;
            }
            if let Some((_, kind)) = LABEL_KEYS.iter().find(|(key, _)| *key == target) {
                if mapping.labels.is_some() {
                    return Err(bad(
                        "two label columns are mapped (`pose` or `segment`, one of them)"
                            .to_string(),
                    ));
                }
                mapping.labels = Some((column, *kind));
                continue;
            }
            let slot = Sensor::ALL.iter().enumerate().find_map(|(s, sensor)| {
                sensor
                    .columns()
                    .iter()
                    .position(|c| *c == target)
                    .map(|axis| (s, axis))
            });
            let Some((s, axis)) = slot else {
                return Err(bad(format!(
                    "`{target}` is not an imucal column (use ax ay az gx gy gz mx my mz temp_c, t_s, t_ms, t_us or t_ns for time, and pose or segment for labels)"
                )));
            };
            if axes[s][axis].replace(column).is_some() {
                return Err(bad(format!("`{target}` is mapped twice")));
            }
        }
        for (s, sensor) in Sensor::ALL.iter().enumerate() {
            let [x, y, z] = axes[s].clone();
            match (x, y, z) {
                (Some(x), Some(y), Some(z)) => mapping.sensors[s] = Some([x, y, z]),
                (None, None, None) => {}
                _ => {
                    return Err(bad(format!(
                        "the {sensor} needs all three of `{}`",
                        sensor.columns().join("`, `")
                    )))
                }
            }
        }
        if mapping.sensors.iter().all(Option::is_none) {
            return Err(bad("no sensor column is mapped".to_string()));
        }
        Ok(mapping)
    }
}

/// The delimiter the header uses most: comma, semicolon or tab.
fn delimiter(header: &str) -> char {
    [',', ';', '\t']
        .into_iter()
        .max_by_key(|d| header.matches(*d).count())
        .unwrap_or(',')
}

fn split(line: &str, delimiter: char) -> Vec<&str> {
    line.split(delimiter)
        .map(|f| f.trim().trim_matches('"').trim())
        .collect()
}

/// Reads delimited `text` with `mapping`; `path` names the file in errors and the recording.
///
/// A unit written after a mapped sensor column's name (`AccX [g]`) is that sensor's unit, as
/// in imucal's own CSV, unless the sensor is in `units_stated` (its unit option was given) and
/// the name says another, which is refused.
pub fn parse(
    text: &str,
    path: &Path,
    mapping: &ColumnMapping,
    units: Units,
    units_stated: &[Sensor],
    rate_hz: Option<f64>,
) -> Result<Recording, ImportError> {
    let shown = path.display().to_string();
    if let Some(rate) = rate_hz {
        if !(rate.is_finite() && rate > 0.0) {
            return Err(ImportError::BadRate(rate));
        }
    }
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty() && !l.trim_start().starts_with('#'));
    let (_, header) = lines.next().ok_or_else(|| ImportError::Empty {
        path: shown.clone(),
    })?;
    let delimiter = delimiter(header);
    let names = split(header, delimiter);
    let index_of = |column: &str| -> Result<usize, ImportError> {
        names
            .iter()
            .position(|n| *n == column)
            .or_else(|| names.iter().position(|n| n.eq_ignore_ascii_case(column)))
            .ok_or_else(|| ImportError::MissingColumn {
                path: shown.clone(),
                column: column.to_string(),
                header: names.join(", "),
            })
    };
    let mut sensor_columns: [Option<[usize; 3]>; 3] = [None; 3];
    for (slot, columns) in sensor_columns.iter_mut().zip(&mapping.sensors) {
        if let Some([x, y, z]) = columns {
            *slot = Some([index_of(x)?, index_of(y)?, index_of(z)?]);
        }
    }
    let unit_columns: Vec<(Sensor, usize)> = Sensor::ALL
        .into_iter()
        .zip(sensor_columns)
        .filter_map(|(sensor, columns)| Some((sensor, columns?[0])))
        .collect();
    let owned: Vec<String> = names.iter().map(|n| n.to_string()).collect();
    let units =
        super::column_names::units_from_names(path, &owned, &unit_columns, units, units_stated)?;
    let temp_column = mapping.temp_c.as_deref().map(index_of).transpose()?;
    let time_column = match &mapping.time {
        Some((name, scale)) => Some((index_of(name)?, *scale)),
        None => None,
    };
    let mut labels = match &mapping.labels {
        Some((name, kind)) => Some((index_of(name)?, LabelInterner::new(*kind))),
        None => None,
    };

    let mut samples: [Vec<Vec3>; 3] = Default::default();
    let mut temp = Vec::new();
    let mut time = Vec::new();
    for (index, line) in lines {
        let fields = split(line, delimiter);
        let number = |column: usize| -> Result<f64, ImportError> {
            let text = fields.get(column).copied().unwrap_or("");
            text.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| ImportError::BadNumber {
                    path: shown.clone(),
                    line: index + 1,
                    column: names.get(column).copied().unwrap_or("?").to_string(),
                    text: text.chars().take(40).collect(),
                })
        };
        for (out, columns) in samples.iter_mut().zip(&sensor_columns) {
            if let Some([x, y, z]) = columns {
                out.push(Vec3::new(number(*x)?, number(*y)?, number(*z)?));
            }
        }
        if let Some(column) = temp_column {
            temp.push(number(column)?);
        }
        if let Some((column, interner)) = labels.as_mut() {
            interner.push(fields.get(*column).copied().unwrap_or(""));
        }
        let t = match time_column {
            Some((column, scale)) => number(column)? * scale,
            None => rate_hz.map_or(time.len() as f64, |rate| time.len() as f64 / rate),
        };
        if let Some(&previous) = time.last() {
            if t < previous {
                return Err(ImportError::TimeBackwards {
                    path: shown.clone(),
                    line: index + 1,
                    time: t,
                    previous,
                });
            }
        }
        time.push(t);
    }
    if time.is_empty() {
        return Err(ImportError::NoRows { path: shown });
    }
    let [accel, gyro, mag] = samples;
    let present = |columns: &Option<[usize; 3]>, values: Vec<Vec3>| columns.map(|_| values);
    Ok(Recording {
        source: path.to_path_buf(),
        time_is_index: time_column.is_none() && rate_hz.is_none(),
        time_from_file: time_column.is_some(),
        accel: present(&sensor_columns[0], accel),
        gyro: present(&sensor_columns[1], gyro),
        temp_c: temp_column.map(|_| temp),
        mag: present(&sensor_columns[2], mag).map(|samples| MagStream {
            source: path.to_path_buf(),
            time: time.clone(),
            samples,
            temp_c: None,
        }),
        time,
        labels: labels.map(|(_, interner)| interner.finish()),
        ignored_columns: Vec::new(),
        units,
        read_as_imutk: false,
        repeated_rows: 0,
    })
}

/// Reads a delimited file with `mapping`.
pub fn load(
    path: &Path,
    mapping: &ColumnMapping,
    units: Units,
    units_stated: &[Sensor],
    rate_hz: Option<f64>,
) -> Result<Recording, ImportError> {
    let text = std::fs::read_to_string(path).map_err(|cause| ImportError::Io {
        path: path.display().to_string(),
        cause,
    })?;
    parse(&text, path, mapping, units, units_stated, rate_hz)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_file_column_mapped_to_two_imucal_columns_is_refused_naming_both() {
        let error = "t_s=t,ax=ax,ay=ax,az=az"
            .parse::<ColumnMapping>()
            .expect_err("ay would silently copy ax");
        let text = error.to_string();
        assert!(
            text.contains("file column `ax` is mapped to both `ax` and `ay`"),
            "{text}"
        );
        assert!("t_s=t,ax=a,ay=b,az=c".parse::<ColumnMapping>().is_ok());
    }
}
