//! Recordings of IMU data read from files: the CSV recording format of `ARCHITECTURE.md`
//! ("Recording format") and the plain-text format of IMU-TK (one file per sensor).
//!
//! A [`Recording`] keeps the values exactly as read together with their [`Units`]; it never
//! rescales. The magnetometer may run on its own clock (a sibling `<name>_mag.csv` file), so it
//! is held as a separate [`MagStream`] with its own time stamps.

pub mod column_names;
mod csv;
mod decimal;
mod imutk;
pub mod lines;
pub mod mapping;
pub mod motioncal;
mod rows;
pub mod units;

use std::path::{Path, PathBuf};

use crate::fit::Vec3;
pub use units::{AccelUnit, GyroUnit, MagUnit, Sensor, Units, STANDARD_GRAVITY};

/// Why a recording could not be read. Each message names the file (and line and column where
/// there is one) and says how to fix the problem.
#[derive(Debug, thiserror::Error)]
pub enum RecordingError {
    /// The file could not be opened or read.
    #[error("cannot read `{path}`: {cause}; check the path and that the file is readable")]
    Io {
        /// File concerned.
        path: String,
        /// Operating-system error (kept out of the error chain so it is printed once).
        cause: std::io::Error,
    },
    /// The file is not UTF-8 text (a binary file, an image, or text in another encoding).
    #[error("`{path}` is not a text recording: {detail}; a recording is a UTF-8 CSV text file, so export or save it as CSV (UTF-8)")]
    NotText {
        /// File concerned.
        path: String,
        /// What was found instead of text.
        detail: String,
    },
    /// A line is longer than any recording's line can be (a file without line breaks).
    #[error("`{path}` line {line} is longer than {limit} bytes; a recording has one short line per sample, so this is not a recording (or its line breaks were lost)")]
    LineTooLong {
        /// File concerned.
        path: String,
        /// 1-based line number.
        line: usize,
        /// Longest line accepted, in bytes.
        limit: usize,
    },
    /// A sensor value is finite but too large to be any sensor's reading.
    #[error("`{path}` line {line}, column `{column}`: {value:e} is larger than any sensor reading (limit {limit:e} in magnitude); correct or delete that row")]
    OutOfRange {
        /// File concerned.
        path: String,
        /// 1-based line number.
        line: usize,
        /// Column name.
        column: String,
        /// The value read.
        value: f64,
        /// Largest magnitude accepted.
        limit: f64,
    },
    /// The file holds no header line.
    #[error("`{path}` is empty: a recording starts with a header line naming its columns (e.g. `t_s,ax,ay,az`)")]
    Empty {
        /// File concerned.
        path: String,
    },
    /// A header names some but not all columns of a sensor.
    #[error("`{path}`, header: column `{present}` is present but `{missing}` is not; a sensor needs all three of its columns")]
    IncompleteSensor {
        /// File concerned.
        path: String,
        /// A column that is present.
        present: &'static str,
        /// The column that is missing.
        missing: &'static str,
    },
    /// A header names the same column twice.
    #[error("`{path}`, header: column `{column}` appears twice; rename or remove one of them")]
    DuplicateColumn {
        /// File concerned.
        path: String,
        /// The repeated column name.
        column: String,
    },
    /// A column name carries a unit imucal does not read for that column.
    #[error("`{path}`, header: column `{column}` gives its unit as `{unit}`, which imucal does not read for that column (the units read there: {accepted}); {fix}")]
    UnknownUnit {
        /// File concerned.
        path: String,
        /// The column name as written.
        column: String,
        /// The unit as written.
        unit: String,
        /// The units accepted for that column.
        accepted: &'static str,
        /// What to do instead, for that column.
        fix: &'static str,
    },
    /// The columns of one sensor name different units.
    #[error("`{path}`, header: columns `{first}` and `{second}` give different units, but a sensor's three columns share one; correct the header")]
    MixedUnits {
        /// File concerned.
        path: String,
        /// One column name as written.
        first: String,
        /// A column of the same sensor naming another unit.
        second: String,
    },
    /// A unit option disagrees with the unit the header writes for that sensor.
    #[error("`{path}`, header: column `{column}` says the {sensor} data are in {header_unit}, but {flag} says {given}; correct the header if it is wrong, or leave {flag} out and the header's unit is used")]
    UnitDisagrees {
        /// File concerned.
        path: String,
        /// The column whose name gives the unit.
        column: String,
        /// The sensor.
        sensor: Sensor,
        /// The header's unit.
        header_unit: &'static str,
        /// The option that gave the other unit.
        flag: &'static str,
        /// The option's unit.
        given: &'static str,
    },
    /// A MotionCal serial log (found by [`Format::Auto`]) that could not be read.
    #[error(transparent)]
    MotionCal(Box<mapping::ImportError>),
    /// A header names no sensor column at all.
    #[error("`{path}`, header: no sensor columns found (expected some of `ax ay az`, `gx gy gz`, `mx my mz`); header was `{header}`; name the columns in the first line, e.g. `t_s,ax,ay,az,gx,gy,gz`, or read the file as it is with --columns (any delimiter, e.g. `--columns t_ms=Time,ax=AccX,ay=AccY,az=AccZ`)")]
    NoSensor {
        /// File concerned.
        path: String,
        /// The header line as read.
        header: String,
    },
    /// A header whose names are right but separated by another delimiter than the comma.
    #[error("`{path}`, header: the columns are separated by `{delimiter}`, not by commas; read the file as it is with `--columns {mapping}` (each column mapped to itself; that option reads any delimiter), or write it with commas")]
    OtherDelimiter {
        /// File concerned.
        path: String,
        /// The delimiter the header uses.
        delimiter: String,
        /// A `--columns` mapping of the columns it names.
        mapping: String,
    },
    /// A field is not a finite number.
    #[error("`{path}` line {line}, column `{column}`: `{text}` is not a finite number; {advice}")]
    BadNumber {
        /// File concerned.
        path: String,
        /// 1-based line number.
        line: usize,
        /// Column name.
        column: String,
        /// The offending text.
        text: String,
        /// What to do, from how many rows of the column are like it.
        advice: String,
    },
    /// A row has a different number of fields than the header.
    #[error("`{path}` line {line}: {found} fields but the header names {expected} columns; every row needs one value per column")]
    FieldCount {
        /// File concerned.
        path: String,
        /// 1-based line number.
        line: usize,
        /// Number of columns in the header.
        expected: usize,
        /// Number of fields in the row.
        found: usize,
    },
    /// Time stamps go backwards.
    #[error("`{path}` line {line}: time {time} s is earlier than the previous row's {previous} s; sort the rows by time")]
    TimeBackwards {
        /// File concerned.
        path: String,
        /// 1-based line number.
        line: usize,
        /// This row's time.
        time: f64,
        /// The previous row's time.
        previous: f64,
    },
    /// Every row has the same time stamp: the time cannot order or space the samples.
    #[error("`{path}`: the time column reads {time} s on every one of its {rows} rows, so it says nothing about when each sample was taken; fix the logger's clock, or read the file without it (`--columns` mapping every column but the time to itself) and give the sample rate with --rate")]
    TimeConstant {
        /// File concerned.
        path: String,
        /// The one time stamp.
        time: f64,
        /// Rows read.
        rows: usize,
    },
    /// A file holds a header but no data rows.
    #[error("`{path}` has a header but no data rows")]
    NoRows {
        /// File concerned.
        path: String,
    },
    /// Two files that must pair sample by sample do not.
    #[error("`{first}` and `{second}` do not pair sample by sample: {detail}; give files recorded together")]
    Unpaired {
        /// First file.
        first: String,
        /// Second file.
        second: String,
        /// What differs.
        detail: String,
    },
    /// The magnetometer file found beside the recording (read without being asked for) is bad.
    #[error("{cause} (`{path}` was read as the recording's magnetometer because it sits beside it; pass --no-mag-sibling to leave it out)")]
    SiblingMag {
        /// The sibling file.
        path: String,
        /// What is wrong with it.
        cause: Box<RecordingError>,
    },
    /// A gyroscope file was given for a CSV recording, which holds its own columns.
    #[error("`{path}` is a CSV recording, but a separate gyroscope file was given ({gyro}); that pairs IMU-TK text files only: name the gyroscope columns `gx gy gz` in the CSV, or drop the gyroscope file")]
    GyroFileWithCsv {
        /// The CSV recording.
        path: String,
        /// The gyroscope file given.
        gyro: String,
    },
    /// A sample rate given on the command line is not a positive finite number.
    #[error("sample rate {0} Hz is not a positive finite number; pass e.g. `--rate 100`")]
    BadRate(f64),
    /// An IMU-TK text line does not hold a time stamp and three values.
    #[error("`{path}` line {line}: expected `timestamp x y z` (4 numbers separated by spaces or commas), found `{text}`")]
    ImutkLine {
        /// File concerned.
        path: String,
        /// 1-based line number.
        line: usize,
        /// The line as read.
        text: String,
    },
}

impl RecordingError {
    /// Add `by` to the line number of an error about one line (for text parsed in pieces, each
    /// counting its lines from 1).
    pub(crate) fn shift_line(&mut self, by: usize) {
        match self {
            Self::LineTooLong { line, .. }
            | Self::OutOfRange { line, .. }
            | Self::BadNumber { line, .. }
            | Self::FieldCount { line, .. }
            | Self::TimeBackwards { line, .. }
            | Self::ImutkLine { line, .. } => *line += by,
            _ => {}
        }
    }
}

/// How a label column divides the rows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LabelKind {
    /// `pose`: each label is one static hold; rows labelled alike are averaged together.
    Pose,
    /// `segment`: labels name sections (separate recordings or phases); still intervals are
    /// detected inside each section and never across a boundary.
    Segment,
}

impl LabelKind {
    /// The name of the column that carries labels of this kind (`pose` or `segment`).
    pub fn column(self) -> &'static str {
        match self {
            LabelKind::Pose => "pose",
            LabelKind::Segment => "segment",
        }
    }
}

/// A label column (`pose` or `segment`). Empty fields and `-` mean "no label".
#[derive(Debug, Clone, PartialEq)]
pub struct Labels {
    /// Whether the labels are poses or sections.
    pub kind: LabelKind,
    /// Distinct label texts in order of first appearance.
    pub names: Vec<String>,
    /// Per row: index into `names`, or `None` for an unlabelled row.
    pub per_row: Vec<Option<usize>>,
}

impl Labels {
    /// Integer value of a label for [`crate::fit::Pose::label`]: the text itself when it is an
    /// integer, otherwise its index in `names`.
    pub fn value(&self, index: usize) -> i64 {
        self.names
            .get(index)
            .and_then(|name| name.parse::<i64>().ok())
            .unwrap_or(index as i64)
    }
}

/// Magnetometer samples with their own time stamps.
#[derive(Debug, Clone, PartialEq)]
pub struct MagStream {
    /// File the samples came from.
    pub source: PathBuf,
    /// Time of each sample in seconds, on the same time base as the main stream.
    pub time: Vec<f64>,
    /// Readings in the file's units.
    pub samples: Vec<Vec3>,
    /// Temperature per sample in °C from a `temp_c` column of the magnetometer's own file, if
    /// it has one (`None` for magnetometer columns of the main file: theirs is the main file's).
    pub temp_c: Option<Vec<f64>>,
}

/// One recording: sensor streams as read, their units and time stamps.
#[derive(Debug, Clone, PartialEq)]
pub struct Recording {
    /// Main file.
    pub source: PathBuf,
    /// Time of each row in seconds. Without a `t_s` column: row index / rate, or the row index
    /// itself when no rate was given (then `time_is_index` is set).
    pub time: Vec<f64>,
    /// True when `time` counts rows rather than seconds.
    pub time_is_index: bool,
    /// True when `time` was read from the file (a given sample rate is then not used).
    pub time_from_file: bool,
    /// Accelerometer readings per row, if present.
    pub accel: Option<Vec<Vec3>>,
    /// Gyroscope readings per row, if present.
    pub gyro: Option<Vec<Vec3>>,
    /// Die temperature per row in °C, if present.
    pub temp_c: Option<Vec<f64>>,
    /// Magnetometer readings (same rows as the main file, or a file with its own clock).
    pub mag: Option<MagStream>,
    /// `pose` or `segment` labels, if present.
    pub labels: Option<Labels>,
    /// Columns of the header that were not read: not part of the format, or replaced by
    /// another file.
    pub ignored_columns: Vec<String>,
    /// Units of the sensor columns.
    pub units: Units,
    /// True when the main file was read as IMU-TK text, whose time stamps are in the unit
    /// [`LoadOptions::imutk_time_scale`] gives (other formats name theirs).
    pub read_as_imutk: bool,
    /// Rows left out because they repeated the row before them exactly, time stamp and every
    /// value (a logger that wrote a sample twice): counted twice, a sample would shrink every
    /// noise estimate and σ it enters.
    pub repeated_rows: usize,
}

/// File format of a recording.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Format {
    /// Decide from the first lines: a MotionCal serial log when a `Raw:` line is among them
    /// ([`motioncal::looks_like_motioncal`]), else a header of names means CSV, four numbers
    /// mean IMU-TK.
    #[default]
    Auto,
    /// CSV with a header line of column names.
    Csv,
    /// IMU-TK text: `timestamp x y z` per line, the main file being the accelerometer.
    Imutk,
}

/// How to read a recording.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LoadOptions {
    /// Units of the sensor columns.
    pub units: Units,
    /// Sensors whose unit in `units` the user stated (rather than left at the default). For the
    /// others, a unit the header writes after a column name (`ax [g]`) is used; a stated unit
    /// the header contradicts is refused rather than either being guessed right.
    pub units_stated: Vec<Sensor>,
    /// Sample rate for files without a `t_s` column (ignored when `t_s` exists).
    pub rate_hz: Option<f64>,
    /// Magnetometer file with its own clock. When `None`, a sibling `<stem>_mag.csv` is used
    /// if the main file has no magnetometer columns and such a file exists.
    pub mag_file: Option<PathBuf>,
    /// Do not look for a sibling magnetometer file.
    pub no_mag_sibling: bool,
    /// Format of the main file.
    pub format: Format,
    /// IMU-TK only: the gyroscope file paired row by row with the accelerometer file.
    pub gyro_file: Option<PathBuf>,
    /// IMU-TK only: seconds per time-stamp unit (1 for seconds, 1e-6 for microseconds).
    pub imutk_time_scale: Option<f64>,
}

impl RecordingError {
    /// Whether the error is an option that contradicts the file (a unit option against the
    /// unit the header writes), which the user fixes in the command line, not in the file.
    pub fn is_option_conflict(&self) -> bool {
        match self {
            Self::UnitDisagrees { .. } => true,
            Self::SiblingMag { cause, .. } => cause.is_option_conflict(),
            Self::MotionCal(cause) => cause.is_option_conflict(),
            _ => false,
        }
    }
}

impl Recording {
    /// Read a recording with the given options (see [`LoadOptions`]).
    pub fn load(path: &Path, options: &LoadOptions) -> Result<Self, RecordingError> {
        if let Some(rate) = options.rate_hz {
            if !(rate.is_finite() && rate > 0.0) {
                return Err(RecordingError::BadRate(rate));
            }
        }
        let mut lines = lines::LineReader::open(path)?;
        // A MotionCal serial log is told from its first lines, read once: a file and standard
        // input alike.
        if options.format == Format::Auto && motioncal::lines_look_like_motioncal(&mut lines)? {
            return motioncal::parse_lines(&mut lines, path, options.rate_hz)
                .map_err(|e| RecordingError::MotionCal(Box::new(e)));
        }
        let first = first_data_line(&mut lines, options.format)?;
        let format = match options.format {
            Format::Auto => match &first {
                Some((_, line)) if imutk::is_triad_line(line) => Format::Imutk,
                _ => Format::Csv,
            },
            other => other,
        };
        if let (Format::Csv | Format::Auto, Some(gyro)) = (format, &options.gyro_file) {
            return Err(RecordingError::GyroFileWithCsv {
                path: display(path),
                gyro: display(gyro),
            });
        }
        let mut recording = match format {
            Format::Imutk => imutk::load(path, &mut lines, first, options)?,
            _ => csv::load(path, &mut lines, first, options)?,
        };
        if let (true, [first, .., last]) = (recording.time_from_file, recording.time.as_slice()) {
            if first == last {
                return Err(RecordingError::TimeConstant {
                    path: display(path),
                    time: *first,
                    rows: recording.time.len(),
                });
            }
        }
        // Before a magnetometer of its own file is added: one on the main rows is compared
        // and thinned with them.
        recording.repeated_rows = recording.drop_repeated_rows();
        if recording.mag.is_none() {
            let sibling = || {
                let ok = !options.no_mag_sibling && path.as_os_str() != lines::STDIN_PATH;
                ok.then(|| sibling_mag_file(path).filter(|p| p.is_file()))
                    .flatten()
            };
            if let Some(mag_path) = &options.mag_file {
                let (stream, unit) = csv::load_mag_stream(mag_path, options)?;
                (recording.mag, recording.units.mag) = (Some(stream), unit);
            } else if let Some(mag_path) = sibling() {
                let (stream, unit) = csv::load_mag_stream(&mag_path, options).map_err(|cause| {
                    RecordingError::SiblingMag {
                        path: display(&mag_path),
                        cause: Box::new(cause),
                    }
                })?;
                (recording.mag, recording.units.mag) = (Some(stream), unit);
            }
        } else if let Some(mag_path) = &options.mag_file {
            // An explicit file replaces magnetometer columns of the main file; they are then
            // columns not read, and said to be.
            let (stream, unit) = csv::load_mag_stream(mag_path, options)?;
            (recording.mag, recording.units.mag) = (Some(stream), unit);
            recording.ignored_columns.push(format!(
                "the magnetometer columns (replaced by --mag-file {})",
                display(mag_path)
            ));
        }
        Ok(recording)
    }

    /// Leave out every row that repeats the row before it exactly: the same time stamp read
    /// from the file and the same value in every column. Returns how many were left out.
    fn drop_repeated_rows(&mut self) -> usize {
        let n = self.time.len();
        if !self.time_from_file || n < 2 {
            return 0;
        }
        let same3 = |v: Option<&[Vec3]>, i: usize| {
            v.is_none_or(|x| {
                x[i].iter()
                    .zip(x[i - 1].iter())
                    .all(|(a, b)| a.to_bits() == b.to_bits())
            })
        };
        let mag_on_rows = self
            .mag
            .as_ref()
            .filter(|m| m.time.len() == n)
            .map(|m| m.samples.as_slice());
        let keep: Vec<bool> = (0..n)
            .map(|i| {
                i == 0
                    || self.time[i].to_bits() != self.time[i - 1].to_bits()
                    || !same3(self.accel.as_deref(), i)
                    || !same3(self.gyro.as_deref(), i)
                    || !same3(mag_on_rows, i)
                    || self
                        .temp_c
                        .as_ref()
                        .is_some_and(|t| t[i].to_bits() != t[i - 1].to_bits())
                    || self
                        .labels
                        .as_ref()
                        .is_some_and(|l| l.per_row.get(i) != l.per_row.get(i - 1))
            })
            .collect();
        let dropped = keep.iter().filter(|k| !**k).count();
        if dropped == 0 {
            return 0;
        }
        fn retain<T>(v: &mut Vec<T>, keep: &[bool]) {
            let mut i = 0;
            v.retain(|_| {
                i += 1;
                keep[i - 1]
            });
        }
        retain(&mut self.time, &keep);
        for column in [&mut self.accel, &mut self.gyro].into_iter().flatten() {
            retain(column, &keep);
        }
        if let Some(t) = &mut self.temp_c {
            retain(t, &keep);
        }
        if let Some(l) = &mut self.labels {
            retain(&mut l.per_row, &keep);
        }
        if let Some(m) = self.mag.as_mut().filter(|m| m.time.len() == n) {
            retain(&mut m.time, &keep);
            retain(&mut m.samples, &keep);
            if let Some(t) = &mut m.temp_c {
                retain(t, &keep);
            }
        }
        dropped
    }

    /// Number of rows of the main stream.
    pub fn len(&self) -> usize {
        self.time.len()
    }

    /// True when the main stream holds no rows.
    pub fn is_empty(&self) -> bool {
        self.time.is_empty()
    }

    /// Whether the recording carries `sensor`.
    pub fn has(&self, sensor: Sensor) -> bool {
        match sensor {
            Sensor::Accel => self.accel.is_some(),
            Sensor::Gyro => self.gyro.is_some(),
            Sensor::Mag => self.mag.is_some(),
        }
    }

    /// Sensors present, in the usual order.
    pub fn sensors(&self) -> Vec<Sensor> {
        Sensor::ALL.into_iter().filter(|s| self.has(*s)).collect()
    }

    /// Samples of a row-synchronous sensor (accelerometer or gyroscope), or the magnetometer
    /// stream's samples.
    pub fn samples(&self, sensor: Sensor) -> Option<&[Vec3]> {
        match sensor {
            Sensor::Accel => self.accel.as_deref(),
            Sensor::Gyro => self.gyro.as_deref(),
            Sensor::Mag => self.mag.as_ref().map(|m| m.samples.as_slice()),
        }
    }

    /// Per axis, the smallest non-zero step between consecutive readings of `sensor`: the
    /// resolution the readings are written with (a count, or the last decimal a logger
    /// writes), at most. Infinite on an axis that never changes or for a sensor not recorded.
    pub fn quantum(&self, sensor: Sensor) -> Vec3 {
        let mut step = Vec3::repeat(f64::INFINITY);
        for w in self.samples(sensor).unwrap_or_default().windows(2) {
            for k in 0..3 {
                let size = (w[1][k] - w[0][k]).abs();
                if size > 0.0 && size < step[k] {
                    step[k] = size;
                }
            }
        }
        step
    }

    /// Median sample rate of the main stream in Hz (from time stamps), if it can be told.
    pub fn rate_hz(&self) -> Option<f64> {
        median_rate(&self.time)
    }
}

/// A time step longer than this many median steps, and than [`PAUSE_MIN_S`], is a pause in the
/// recording (a logger stopped, files joined), not its sampling.
const PAUSE_STEPS: f64 = 10.0;

/// Shortest time step that counts as a pause, s (still detection splits sections there too).
const PAUSE_MIN_S: f64 = 1.0;

/// Median rate in Hz of a time series (robust to the bursty host time stamps of some loggers).
pub fn median_rate(time: &[f64]) -> Option<f64> {
    // The steps are computed again for each pass rather than kept: one buffer of a long
    // recording's length instead of three.
    let steps = || time.windows(2).map(|w| w[1] - w[0]);
    let mut dt: Vec<f64> = steps().filter(|d| *d > 0.0).collect();
    if dt.is_empty() {
        return None;
    }
    let middle = dt.len() / 2;
    let median = *dt.select_nth_unstable_by(middle, f64::total_cmp).1;
    drop(dt);
    // Bursty loggers (many near-zero steps then a long gap) make the median step misleading;
    // the mean rate is the honest figure then, over the sampling only: pauses are left out, or
    // one long pause would read as a slow rate.
    let pause = (PAUSE_STEPS * median).max(PAUSE_MIN_S);
    let sampled = || steps().filter(move |d| *d <= pause);
    let span: f64 = sampled().sum();
    let mean_rate = if span > 0.0 {
        sampled().count() as f64 / span
    } else {
        (time.len() - 1) as f64 / (time.last()? - time.first()?)
    };
    let median_rate = 1.0 / median;
    if median_rate > 2.0 * mean_rate {
        Some(mean_rate)
    } else {
        Some(median_rate)
    }
}

/// `<dir>/<stem>_mag.csv` for `<dir>/<stem>.csv`.
pub fn sibling_mag_file(path: &Path) -> Option<PathBuf> {
    let stem = path.file_stem()?.to_str()?;
    if stem.ends_with("_mag") {
        return None;
    }
    Some(path.with_file_name(format!("{stem}_mag.csv")))
}

/// Largest magnitude accepted for a sensor value: raw counts of 32-bit converters stay below
/// 4.3e9 and physical readings far below; larger values would overflow the sums of squares
/// that pose statistics are built from.
pub const MAX_SENSOR_MAGNITUDE: f64 = 1e10;

/// The first line that is neither blank nor a comment of `format` (for `Auto`, of either
/// format), which decides the format; `None` when the input ends first.
fn first_data_line(
    lines: &mut lines::LineReader<'_>,
    format: Format,
) -> Result<Option<(usize, String)>, RecordingError> {
    while let Some((line_no, line)) = lines.next_line()? {
        let skipped = match format {
            Format::Csv => csv::is_skipped(line),
            Format::Imutk => imutk::is_comment(line),
            Format::Auto => csv::is_skipped(line) || imutk::is_comment(line),
        };
        if !skipped {
            return Ok(Some((line_no, line.to_string())));
        }
    }
    Ok(None)
}

fn display(path: &Path) -> String {
    path.display().to_string()
}

#[cfg(test)]
mod tests {
    use super::median_rate;

    #[test]
    fn a_long_pause_does_not_change_the_sample_rate() {
        // 100 Hz for 100 s, then a logger paused for 1000 s, then 100 Hz again.
        let time: Vec<f64> = (0..20_000)
            .map(|i| i as f64 * 0.01 + if i >= 10_000 { 1000.0 } else { 0.0 })
            .collect();
        let rate = median_rate(&time).expect("a rate");
        assert!((rate - 100.0).abs() < 1e-6, "{rate}");
    }

    #[test]
    fn bursty_time_stamps_give_the_mean_rate() {
        // Ten samples stamped together every 0.1 s: 100 Hz on average, a median step of ~0.
        let time: Vec<f64> = (0..1000)
            .map(|i| (i / 10) as f64 * 0.1 + (i % 10) as f64 * 1e-6)
            .collect();
        let rate = median_rate(&time).expect("a rate");
        assert!((rate - 100.0).abs() < 1.0, "{rate}");
    }
}
