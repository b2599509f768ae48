//! The `imucal` command line: argument parsing and thin commands over the library.

pub mod analyze;
pub mod args;
mod board;
pub mod calibrate;
pub mod calibrate_batch;
mod calibrate_extend;
pub mod calibrate_motioncal;
mod calibrate_sim;
mod calibrate_view;
pub mod device;
pub mod device_stream;
pub mod export;
pub mod fit;
pub mod fleet;
pub mod history;
pub mod import;
pub mod params;
pub mod report;
pub mod still;
mod values;
mod write_policy;

use std::path::{Path, PathBuf};

use clap::ValueEnum;
use imucal::pipeline::{InputOptions, ReferenceError, References};
use imucal::recording::{
    AccelUnit, Format, GyroUnit, LoadOptions, MagUnit, Recording, Sensor, Units,
};
use imucal::still::StillOptions;

use args::{
    AccelUnitArg, FormatArg, GyroUnitArg, InputArgs, MagUnitArg, ReferenceArgs, TimeUnitArg,
};

/// An option value, or a combination of options, the command cannot run with, found after
/// parsing: it ends the command with exit status 2, the status of clap's own usage errors.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct UsageError(pub String);

impl From<ReferenceError> for UsageError {
    fn from(error: ReferenceError) -> Self {
        Self(error.to_string())
    }
}

/// The recording file a path names: the file itself, or a directory's recording ([`directory_recording`])
/// (so every command that reads a recording takes a session of `imucal calibrate` alike).
pub fn recording_file(path: &Path) -> anyhow::Result<PathBuf> {
    if !path.is_dir() {
        return Ok(path.to_path_buf());
    }
    if let Some(candidate) = directory_recording(path) {
        return Ok(candidate);
    }
    let shown = path.display();
    // `calibrate` keeps only the poses it averaged, not the stream they came from.
    if path.join("poses.json").is_file() {
        anyhow::bail!(
            "`{shown}` is a session directory of `imucal calibrate` that holds its poses \
             (poses.json) but no recording (recording.csv); this command reads a continuous \
             recording, so study the session with `imucal analyze {shown}` or `imucal report \
             {shown}`, or pass a recording file"
        );
    }
    anyhow::bail!(
        "`{shown}` is a directory without a recording.csv; pass a recording file, or a session \
         directory of `imucal calibrate` that holds one"
    )
}

/// The recording a directory holds: `recording.csv`, or the `readings.csv` every reading of a
/// MotionCal sketch session is saved in (also when it stopped early).
pub fn directory_recording(dir: &Path) -> Option<PathBuf> {
    ["recording.csv", imucal::session::motioncal::READINGS_FILE]
        .into_iter()
        .map(|name| dir.join(name))
        .find(|path| path.is_file())
}

/// Read the recording named on the command line (a file, or a session directory's);
/// `gyro_scale` is `--gyro-scale` for the commands that take it, said to be moot when it is;
/// `only` the one sensor the command uses, `None` for every sensor the recording has.
pub fn load(
    input: &InputArgs,
    gyro_scale: Option<f64>,
    only: Option<Sensor>,
) -> anyhow::Result<Recording> {
    let units = Units {
        accel: match input.accel_unit.unwrap_or(AccelUnitArg::Mps2) {
            AccelUnitArg::Mps2 => AccelUnit::Mps2,
            AccelUnitArg::G => AccelUnit::G,
            AccelUnitArg::Counts => AccelUnit::Counts,
        },
        gyro: match input.gyro_unit.unwrap_or(GyroUnitArg::Rads) {
            GyroUnitArg::Rads => GyroUnit::Rads,
            GyroUnitArg::Dps => GyroUnit::Dps,
            GyroUnitArg::Counts => GyroUnit::Counts,
        },
        mag: match input.mag_unit.unwrap_or(MagUnitArg::Ut) {
            MagUnitArg::Ut => MagUnit::Ut,
            MagUnitArg::Gauss => MagUnit::Gauss,
            MagUnitArg::Counts => MagUnit::Counts,
        },
    };
    let recording = read(input, units, only)?;
    warn_moot_options(input, &recording, units, gyro_scale);
    Ok(recording)
}

/// The recording as the input options read it; `only` as for [`load`].
fn read(input: &InputArgs, units: Units, only: Option<Sensor>) -> anyhow::Result<Recording> {
    if let Some(recording) = import::load(input, units)? {
        return Ok(recording);
    }
    let options = LoadOptions {
        units,
        units_stated: input.units_stated(),
        rate_hz: input.rate,
        mag_file: input.mag_file.clone(),
        no_mag_sibling: input.no_mag_sibling,
        format: match input.format {
            FormatArg::Auto => Format::Auto,
            FormatArg::Csv => Format::Csv,
            FormatArg::Imutk => Format::Imutk,
            // Read by `import::load` above.
            FormatArg::Motioncal => Format::Auto,
        },
        gyro_file: input.gyro_file.clone(),
        imutk_time_scale: Some(match input.imutk_time_unit.unwrap_or(TimeUnitArg::S) {
            TimeUnitArg::S => 1.0,
            TimeUnitArg::Ms => 1e-3,
            TimeUnitArg::Us => 1e-6,
            TimeUnitArg::Ns => 1e-9,
        }),
    };
    let recording = Recording::load(&recording_file(&input.recording)?, &options)
        .map_err(|e| read_error(e.is_option_conflict(), e, "the recording could not be read"))?;
    // Options that the file makes moot are said to be so, not silently dropped.
    if input.rate.is_some() && recording.time_from_file {
        say!("imucal: warning: --rate is ignored: the recording has its own time stamps");
    }
    refuse_unread_sensor(input, &recording, only)?;
    if !recording.ignored_columns.is_empty() {
        // A trailing delimiter leaves a column without a name: say so rather than nothing.
        let named: Vec<String> = recording
            .ignored_columns
            .iter()
            .map(|name| match name.trim() {
                "" => "a column without a name (a trailing or doubled comma in the header)"
                    .to_string(),
                _ => name.clone(),
            })
            .collect();
        say!(
            "imucal: note: not read from {}: {}",
            input.recording.display(),
            named.join(", ")
        );
    }
    Ok(recording)
}

/// The error of a recording that could not be read, with `context`: a usage error (exit
/// status 2) when an option contradicts the file (`conflict`), since the command line is what
/// the user fixes then.
pub fn read_error(
    conflict: bool,
    error: impl std::error::Error + Send + Sync + 'static,
    context: &str,
) -> anyhow::Error {
    if conflict {
        UsageError(format!("{context}: {error}")).into()
    } else {
        anyhow::Error::new(error).context(context.to_string())
    }
}

/// Refuses a recording that lacks a sensor the command uses while columns that look like that
/// sensor's axes (`AccX`, `acc_x`) were left unread: run on, the command would succeed on the
/// other sensors and the lost one would show only as its absence, which is easily taken for a
/// board without that sensor. An error names the columns and the two ways to read them.
fn refuse_unread_sensor(
    input: &InputArgs,
    recording: &Recording,
    only: Option<Sensor>,
) -> anyhow::Result<()> {
    for sensor in Sensor::ALL {
        if recording.has(sensor) || only.is_some_and(|s| s != sensor) {
            continue;
        }
        let unread: Vec<&String> = recording
            .ignored_columns
            .iter()
            .filter(|name| imucal::recording::column_names::looks_like_axis(name) == Some(sensor))
            .collect();
        if unread.is_empty() {
            continue;
        }
        let shown: Vec<String> = unread.iter().map(|n| format!("`{n}`")).collect();
        let [x, y, z] = sensor.columns();
        let mapping = match unread.as_slice() {
            [a, b, c] => format!("`--columns {x}={a},{y}={b},{z}={c},...`"),
            _ => format!("`--columns {x}=...,{y}=...,{z}=...`"),
        };
        anyhow::bail!(
            "`{}` has no {sensor} data that imucal reads, but its column{} {} look{} like \
             {sensor} axes and {} not read: imucal reads the {sensor} from columns named \
             `{x} {y} {z}` (a unit may follow in brackets, e.g. `{x} [{}]`); rename the columns \
             so, or read the file through a column mapping that names every column to read, \
             e.g. {mapping}",
            input.recording.display(),
            if unread.len() == 1 { "" } else { "s" },
            shown.join(", "),
            if unread.len() == 1 { "s" } else { "" },
            if unread.len() == 1 { "was" } else { "were" },
            match sensor {
                Sensor::Accel => "m/s2",
                Sensor::Gyro => "dps",
                Sensor::Mag => "uT",
            },
        );
    }
    Ok(())
}

/// Says which options given for the input the recording makes moot (a unit of a sensor it
/// does not have or whose unit its format fixes, the IMU-TK time unit for another format, a
/// gyroscope scale for data not in counts): a user who gives one expects it to act.
fn warn_moot_options(
    input: &InputArgs,
    recording: &Recording,
    asked: Units,
    gyro_scale: Option<f64>,
) {
    let shown = input.recording.display();
    let given = [
        (
            Sensor::Accel,
            "--accel-unit",
            input.accel_unit.map(value_name),
        ),
        (Sensor::Gyro, "--gyro-unit", input.gyro_unit.map(value_name)),
        (Sensor::Mag, "--mag-unit", input.mag_unit.map(value_name)),
    ];
    for (sensor, flag, value) in given {
        let Some(value) = value else {
            continue;
        };
        if !recording.has(sensor) {
            let read_as = match &input.columns {
                Some(_) => format!("--columns maps no {sensor} columns of `{shown}`"),
                None => format!(
                    "`{shown}` has no {sensor} data (columns {})",
                    sensor.columns().join(" ")
                ),
            };
            say!("imucal: warning: {flag} {value} is ignored: {read_as}");
        } else if recording.units.symbol(sensor) != asked.symbol(sensor) {
            say!(
                "imucal: warning: {flag} {value} is ignored: the format of `{shown}` gives its \
                 {sensor} data in {}",
                recording.units.symbol(sensor)
            );
        }
    }
    if let (Some(unit), false) = (input.imutk_time_unit, recording.read_as_imutk) {
        say!(
            "imucal: warning: --imutk-time-unit {} is ignored: it is the unit of IMU-TK time \
             stamps, and `{shown}` was not read as IMU-TK text",
            value_name(unit)
        );
    }
    let Some(scale) = gyro_scale else {
        return;
    };
    if !recording.has(Sensor::Gyro) {
        say!("imucal: warning: --gyro-scale {scale} is ignored: `{shown}` has no gyro data");
    } else if !recording.units.is_counts(Sensor::Gyro) {
        say!(
            "imucal: warning: --gyro-scale {scale} is ignored: it converts counts to rad/s, and \
             the gyroscope data are in {}; give --gyro-unit counts for data in counts, or leave \
             --gyro-scale out",
            recording.units.symbol(Sensor::Gyro)
        );
    }
}

/// A flag value as it is typed.
fn value_name(value: impl ValueEnum) -> String {
    value
        .to_possible_value()
        .map_or_else(String::new, |v| v.get_name().to_string())
}

/// The files a command reads for `input`: the recording (or a session directory's files), its
/// magnetometer and gyroscope files. An output that is one of them is refused.
pub fn input_paths(input: &InputArgs) -> Vec<PathBuf> {
    let recording = &input.recording;
    let mut paths = vec![recording.clone()];
    if recording.is_dir() {
        paths.extend(
            [
                "recording.csv",
                "poses.json",
                "params.json",
                "params-base.json",
            ]
            .map(|name| recording.join(name)),
        );
    }
    let mag = match &input.mag_file {
        Some(path) => Some(path.clone()),
        // The sibling of the file read: a session directory's is `recording_mag.csv` in it.
        None if !input.no_mag_sibling => recording_file(recording)
            .ok()
            .and_then(|file| imucal::recording::sibling_mag_file(&file)),
        None => None,
    };
    paths.extend(mag);
    paths.extend(input.gyro_file.clone());
    paths
}

/// How the pipeline forms its input, from the command line.
pub fn input_options(input: &InputArgs, reference: &ReferenceArgs) -> InputOptions {
    InputOptions {
        still: still_options(input),
        max_mag_samples: reference.max_mag_samples,
    }
}

/// The reference values, range-checked.
pub fn references(reference: &ReferenceArgs) -> Result<References, UsageError> {
    Ok(References::checked(
        reference.gravity,
        reference.field_ut,
        reference.gyro_scale,
    )?)
}

/// Still-detection settings from the command line.
pub fn still_options(input: &InputArgs) -> StillOptions {
    StillOptions {
        window_s: input.window,
        min_hold_s: input.min_hold,
        margin: input.still_margin,
        direction_angle_deg: input.direction_angle,
        ..StillOptions::default()
    }
}
