//! Command-line arguments (clap derive). Parsing only; the work is done by the library.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand, ValueEnum};

use super::board::BoardProtocol;
use super::UsageError;

/// IMU calibration: fit calibration models to recordings and inspect still intervals.
#[derive(Debug, Parser)]
#[command(name = "imucal", version, about, propagate_version = true)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// Sub-commands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Fit calibrations of the accelerometer, gyroscope and magnetometer to a recording.
    #[command(
        after_help = "Exit status: 0 when every requested sensor was fitted; 1 when any could \
        not be (standard error says which and why; --params-out still writes the others and \
        lists it under not_fitted) or on any other error; 2 for a usage error. A sensor fitted \
        but left out of the --params-out file because its output is not in the board's unit \
        (counts without --gyro-scale, a field normalised to 1) is said on standard error and \
        listed under not_fitted; that alone fails the command only when the file would then \
        hold nothing.\n\n\
        Examples:\n  \
        imucal fit data/real/imucal_nilspod_ferraris.csv --gyro-unit dps\n  \
        imucal fit data/real/imutk_xsens_multipos.csv --accel-unit counts --gyro-unit counts --sensor accel --method chen --json\n  \
        imucal fit data/real/sf_mpu6050_hmc5883l_full_sphere.csv --sensor mag --mag-unit gauss --field-ut 48.5\n  \
        imucal fit data/real/sf_mpu6050_hmc5883l_full_sphere.csv --sensor mag --mag-unit gauss --location 48.14,11.58   (the field there today)"
    )]
    Fit(FitArgs),
    /// List the still intervals of a recording and the gravity directions they cover.
    ///
    /// The holds are numbered from 1 (`#`; `number` in --json), as every message that names a
    /// hold names it: "hold #3 at 12.0–16.0 s (pose P12)". A hold that fit, analyze and report
    /// leave out keeps its number, and is missing from the table.
    #[command(
        after_help = "Example:\n  imucal still data/real/tsi_mpu6050_multipos.csv --accel-unit counts --gyro-unit counts"
    )]
    Still(StillArgs),
    /// Analyse the residual of the fitted models: noise floor, candidate effects, held-out error.
    #[command(
        after_help = "The base fits are those `imucal fit` gives for the same recording and \
        options, printed the same way; the analysis follows them.\n\n\
        Exit status: 0 when every sensor was fitted and analysed; 1 when any could not be \
        (what could be done is still printed and written, and standard error says which sensor \
        and why) or on any other error; 2 for a usage error.\n\n\
        Example:\n  imucal analyze data/real/tsi_mpu6050_multipos.csv --accel-unit counts --gyro-unit counts"
    )]
    Analyze(AnalyzeArgs),
    /// Board commands: ports, info, flash, stream, record, params.
    #[command(flatten)]
    Device(super::device::DeviceCommand),
    /// Guided calibration of a board (or `--sim`): positions, magnetometer, fit, write, verify.
    #[command(
        after_help = "Examples:\n  imucal calibrate --sim --yes\n  imucal calibrate --port /dev/ttyACM0 --field-ut 48.5\n\n\
        Exit status: 0 when the set is written, verified by reading it back, and meets its \
        targets at rest (its verdict may still be marginal); 1 when it is not written (a poor \
        verdict without --accept-poor, a set past a bound of every common part's datasheet \
        without --accept-outlier, no --yes and no terminal to ask), when it is written but \
        misses its targets at rest (the verdict, summary.json and the history name them), or \
        on an error; 2 for an option value or combination the command cannot run with."
    )]
    Calibrate(CalibrateArgs),
    /// Write an HTML report (plots, parameters, verdict) of a session directory or a recording.
    #[command(after_help = REPORT_EXAMPLES)]
    Report(ReportArgs),
    /// Export a parameter file as a C header, a Rust module or versioned JSON for other firmware.
    #[command(after_help = super::export::EXAMPLES)]
    Export(super::export::ExportArgs),
    /// Every recorded calibration of a board (or all), with each parameter's change in σ units.
    #[command(
        after_help = "Examples:\n  imucal history\n  imucal history 00000000000000000000000000001234 --json\n  imucal history --db postgres://imucal@db.plant/line"
    )]
    History(super::history::HistoryArgs),
    /// Fleet statistics per parameter and the boards far outside the fleet, with likely causes.
    #[command(
        after_help = "Examples:\n  imucal fleet\n  imucal fleet --db sqlite:///srv/line/history.sqlite --json"
    )]
    Fleet(super::fleet::FleetArgs),
}

/// Which sensor(s) to fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum SensorChoice {
    /// Accelerometer.
    Accel,
    /// Gyroscope.
    Gyro,
    /// Magnetometer.
    Mag,
    /// Every sensor the recording has.
    All,
}

/// Accelerometer unit flag.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum AccelUnitArg {
    /// m/s².
    Mps2,
    /// Multiples of standard gravity.
    G,
    /// Raw counts.
    Counts,
}

/// Gyroscope unit flag.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum GyroUnitArg {
    /// rad/s.
    Rads,
    /// Degrees per second.
    Dps,
    /// Raw counts.
    Counts,
}

/// Magnetometer unit flag.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum MagUnitArg {
    /// Microtesla.
    Ut,
    /// Gauss.
    Gauss,
    /// Raw counts.
    Counts,
}

/// File format flag.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum FormatArg {
    /// Decide from the first line.
    Auto,
    /// CSV with a header of column names: `t_s`, `ax ay az`, `gx gy gz`, `mx my mz`, `temp_c`,
    /// and `pose` or `segment` labels (any subset; other columns are not read); a unit may
    /// follow a name in brackets or parentheses, e.g. `ax [m/s2]`, `gx (dps)`.
    Csv,
    /// IMU-TK text (`timestamp x y z` per line; the recording is the accelerometer file).
    Imutk,
    /// MotionCal serial log (`Raw:ax,ay,az,gx,gy,gz,mx,my,mz` lines; detected by `auto` too),
    /// its counts scaled as Adafruit's calibration sketch writes them and as a live sketch
    /// board is read: accelerometer 8192 per 9.8 m/s², gyroscope 16 per °/s, magnetometer 10
    /// per µT.
    Motioncal,
}

/// Time-stamp unit of IMU-TK files.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum TimeUnitArg {
    /// Seconds.
    S,
    /// Milliseconds.
    Ms,
    /// Microseconds.
    Us,
    /// Nanoseconds.
    Ns,
}

/// How to read a recording (shared by every command).
#[derive(Debug, Clone, Args)]
pub struct InputArgs {
    /// Recording file (CSV with a header, or IMU-TK accelerometer text file); `-` reads standard
    /// input, and a FIFO or `<(command)` is read once as a stream.
    pub recording: PathBuf,
    /// Unit of the accelerometer columns (default: the unit a CSV header writes after the column
    /// name, e.g. `ax [g]`, else mps2).
    #[arg(long, value_enum)]
    pub accel_unit: Option<AccelUnitArg>,
    /// Unit of the gyroscope columns (default: the unit a CSV header writes after the column
    /// name, e.g. `gx [dps]`, else rads).
    #[arg(long, value_enum)]
    pub gyro_unit: Option<GyroUnitArg>,
    /// Unit of the magnetometer columns (default: the unit a CSV header writes after the column
    /// name, e.g. `mx [uT]`, else ut).
    #[arg(long, value_enum)]
    pub mag_unit: Option<MagUnitArg>,
    /// Sample rate in Hz for files without a `t_s` column (0.001 Hz to 1 MHz).
    #[arg(long, value_parser = sample_rate)]
    pub rate: Option<f64>,
    /// Magnetometer file with its own clock (default: `<name>_mag.csv` next to the recording, if present).
    #[arg(long)]
    pub mag_file: Option<PathBuf>,
    /// Do not look for a `<name>_mag.csv` file next to the recording.
    #[arg(long)]
    pub no_mag_sibling: bool,
    /// File format.
    #[arg(long, value_enum, default_value = "auto")]
    pub format: FormatArg,
    /// Read any delimited file through a column mapping, imucal column = file column, e.g.
    /// `t_ms=Timestamp,ax=AccX,ay=AccY,az=AccZ` (time keys t_s, t_ms, t_us, t_ns; labels
    /// `pose=Label` for static holds or `segment=Phase` for sections; units by the unit flags).
    #[arg(long)]
    pub columns: Option<String>,
    /// IMU-TK: the gyroscope file paired row by row with the accelerometer file.
    #[arg(long)]
    pub gyro_file: Option<PathBuf>,
    /// IMU-TK: unit of the time stamps (default: s; other formats name their own).
    #[arg(long, value_enum)]
    pub imutk_time_unit: Option<TimeUnitArg>,
    /// Still detection: window length in seconds.
    #[arg(long, default_value_t = 0.5, value_parser = positive)]
    pub window: f64,
    /// Still detection: shortest hold kept, in seconds.
    #[arg(long, default_value_t = 1.0, value_parser = non_negative)]
    pub min_hold: f64,
    /// Still detection: fixed margin over the χ² threshold, from 1 to 256 (default: chosen from
    /// the data).
    #[arg(long, value_parser = margin_in_range)]
    pub still_margin: Option<f64>,
    /// Holds whose gravity directions are within this angle (degrees, more than 0 and less
    /// than 90) count as one direction.
    #[arg(long, default_value_t = 10.0, value_parser = direction_angle)]
    pub direction_angle: f64,
}

impl InputArgs {
    /// The sensors whose unit the user gave with a unit option (a unit written in a column's
    /// name that says another is then refused, not taken).
    pub fn units_stated(&self) -> Vec<imucal::recording::Sensor> {
        use imucal::recording::Sensor;
        [
            (Sensor::Accel, self.accel_unit.is_some()),
            (Sensor::Gyro, self.gyro_unit.is_some()),
            (Sensor::Mag, self.mag_unit.is_some()),
        ]
        .into_iter()
        .filter_map(|(sensor, stated)| stated.then_some(sensor))
        .collect()
    }
}

/// A finite number from `text` that satisfies `ok` (described by `what`), for flag values.
fn number_that(text: &str, ok: impl Fn(f64) -> bool, what: &str) -> Result<f64, String> {
    let value: f64 = text
        .trim()
        .parse()
        .map_err(|_| format!("`{text}` is not a number"))?;
    if value.is_finite() && ok(value) {
        Ok(value)
    } else {
        // As typed: `1e300`, not its 301 digits.
        Err(format!("{} is not {what}", text.trim()))
    }
}

fn positive(text: &str) -> Result<f64, String> {
    number_that(text, |v| v > 0.0, "a positive number")
}

/// `--rate`: beyond 0.001 Hz – 1 MHz no inertial or magnetic sensor samples, so a value
/// outside is a typo (`1e-300` would print holds of 10³⁰⁰ s).
fn sample_rate(text: &str) -> Result<f64, String> {
    number_that(
        text,
        |v| (1e-3..=1e6).contains(&v),
        "a sample rate from 0.001 Hz to 1 MHz",
    )
}

fn non_negative(text: &str) -> Result<f64, String> {
    number_that(text, |v| v >= 0.0, "zero or a positive number")
}

fn margin_in_range(text: &str) -> Result<f64, String> {
    let most = imucal::still::MAX_MARGIN;
    number_that(
        text,
        |v| (1.0..=most).contains(&v),
        &format!("from 1 to {most} (the range the automatic choice takes)"),
    )
}

/// `--sim-temperature`: the simulated board's die temperature.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SimTemperature {
    /// The simulated person's ambient temperature throughout.
    Constant,
    /// A triangle from `low_c` to `high_c` and back every `period_s`.
    Sweep {
        /// Lowest temperature, °C.
        low_c: f64,
        /// Highest temperature, °C.
        high_c: f64,
        /// Seconds per cycle.
        period_s: f64,
    },
}

/// As typed on the command line: `constant` or `sweep:LOW:HIGH:PERIOD`.
impl std::fmt::Display for SimTemperature {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Constant => f.write_str("constant"),
            Self::Sweep {
                low_c,
                high_c,
                period_s,
            } => write!(f, "sweep:{low_c}:{high_c}:{period_s}"),
        }
    }
}

/// `--sim-temperature`: `constant`, `sweep` (10–40 °C every 90 s) or `sweep:LOW:HIGH:PERIOD`.
fn sim_temperature(text: &str) -> Result<SimTemperature, String> {
    if text == "constant" {
        return Ok(SimTemperature::Constant);
    }
    let values: Option<Vec<f64>> = match text.strip_prefix("sweep") {
        Some("") => Some(vec![10.0, 40.0, 90.0]),
        Some(rest) => rest
            .strip_prefix(':')
            .and_then(|r| r.split(':').map(|n| n.parse().ok()).collect()),
        None => None,
    };
    match values.as_deref() {
        Some(&[low_c, high_c, period_s])
            if [low_c, high_c, period_s].iter().all(|v| v.is_finite())
                && low_c < high_c
                && period_s > 0.0 =>
        {
            Ok(SimTemperature::Sweep {
                low_c,
                high_c,
                period_s,
            })
        }
        _ => Err(format!(
            "`{text}` is not understood; give `constant`, `sweep`, or `sweep:LOW:HIGH:PERIOD` \
             with LOW < HIGH in °C and PERIOD > 0 in s, e.g. sweep:10:40:90"
        )),
    }
}

/// `--direction-angle`: below 90°, since adjacent faces of a box (90° apart) must stay distinct
/// directions; the angle is otherwise taken through its cosine, so 400 would act as 40.
fn direction_angle(text: &str) -> Result<f64, String> {
    number_that(
        text,
        |v| v > 0.0 && v < 90.0,
        "an angle in degrees more than 0 and less than 90 (at 90 or more, holds on adjacent \
         faces would count as one direction)",
    )
}

/// `--method`: a method's name, checked here so that a misspelling is a usage error said
/// before any data is read (whether it suits the sensor is checked with the sensor).
fn method_name(text: &str) -> Result<String, String> {
    use imucal::pipeline::methods::{method_by_name, ALL_METHODS};
    if method_by_name(text).is_some() {
        return Ok(text.to_string());
    }
    let all: Vec<&str> = ALL_METHODS.iter().map(|m| m.name()).collect();
    Err(format!(
        "unknown method `{text}`; choose one of {}",
        all.join(", ")
    ))
}

/// `--max-mag-samples`: 0 (every sample) or enough for an ellipsoid fit. A smaller cap would
/// only ever refuse the fit, and its refusal would read as a recording that is too short.
fn sample_cap(text: &str) -> Result<usize, String> {
    let needed = imucal::input_checks::MIN_MAG_SAMPLES;
    let value: usize = text
        .trim()
        .parse()
        .map_err(|_| format!("`{text}` is not a whole number of samples"))?;
    if value == 0 || value >= needed {
        Ok(value)
    } else {
        Err(format!(
            "{value} samples cannot determine an ellipsoid (it needs at least {needed}); give \
             {needed} or more, or 0 for every sample"
        ))
    }
}

/// Reference values and fitting input shared by every command that fits a recording.
#[derive(Debug, Args)]
pub struct ReferenceArgs {
    /// Local gravity in m/s²; accelerometer output is in m/s².
    #[arg(long, default_value_t = imucal::recording::STANDARD_GRAVITY)]
    pub gravity: f64,
    /// Local field magnitude; magnetometer output is in its unit (µT). Without it (and without
    /// --location) the magnetometer output is normalised to 1.
    #[arg(long)]
    pub field_ut: Option<f64>,
    /// Where the recording was made, `LAT,LON[,ALT_M]` (degrees, metres): the World Magnetic
    /// Model's field there today is the magnetometer reference when --field-ut is not given, and
    /// the fitted raw radius is checked against it.
    #[arg(long, value_name = "LAT,LON[,ALT_M]", allow_hyphen_values = true)]
    pub location: Option<imucal::geomag::Location>,
    /// Gyroscope scale in rad/s per count, for `--gyro-unit counts` (with another unit it has
    /// no effect, and a warning says so).
    #[arg(long)]
    pub gyro_scale: Option<f64>,
    /// Magnetometer fits use at most this many samples: runs that repeat one reading within the
    /// noise (a pause) are kept as one sample first, then the rest evenly (0, the default, = all:
    /// the fits take about 0.3 s per 10⁶ samples, and thinning loses held-out accuracy); an
    /// ellipsoid needs at least 12.
    #[arg(long, default_value_t = 0, value_parser = sample_cap)]
    pub max_mag_samples: usize,
}

/// Arguments of `imucal fit`.
#[derive(Debug, Args)]
pub struct FitArgs {
    /// How to read the recording.
    #[command(flatten)]
    pub input: InputArgs,
    /// Reference values.
    #[command(flatten)]
    pub reference: ReferenceArgs,
    /// Which sensor to fit.
    #[arg(long, value_enum, default_value = "all")]
    pub sensor: SensorChoice,
    /// Fitting method (default: the accelerometer model chosen by held-out error, `lm` for the
    /// magnetometer, `gyro-bias` for the gyroscope). One of: gyro-bias, gyro-scale, minmax,
    /// axis-aligned, six-position, chen, li, lm, frosio, merayo. Without --sensor it is fitted
    /// to the sensors it is a method for; the others keep their default.
    #[arg(long, value_parser = method_name)]
    pub method: Option<String>,
    /// Print a JSON object keyed by sensor instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Also write the versioned parameter file (as `imucal calibrate` does) for `imucal export`
    /// and `imucal flash`; sensors not fitted are listed in it with the reason.
    #[arg(long, value_name = "FILE")]
    pub params_out: Option<PathBuf>,
    /// Replace the --params-out file that already exist (an output that is also an input is never
    /// replaced).
    #[arg(long)]
    pub force: bool,
    /// With --params-out: the board the recording came from, its device id as `imucal info`
    /// prints it. It goes into the file's provenance, so `imucal flash` refuses the file on
    /// another board, and names the board in the history (default: the recording's file name).
    #[arg(
        long,
        visible_alias = "device-id",
        value_name = "ID",
        requires = "params_out"
    )]
    pub device: Option<String>,
    /// With --params-out: where to record the fit.
    #[command(flatten)]
    pub history: super::history::RecordArgs,
}

/// Examples shown by `imucal report --help`.
pub const REPORT_EXAMPLES: &str = "Examples:\n  \
    imucal report session-2025-11-21/                      (a directory written by `imucal calibrate -o`)\n  \
    imucal report data/real/sf_mpu6050_hmc5883l_full_sphere.csv --accel-unit g --gyro-unit dps --mag-unit gauss --location 48.14,11.58 -o report/\n  \
    imucal report motioncal_log.txt --format motioncal --rate 100 -o sketch.html     (the report file itself)";

/// Arguments of `imucal report`.
#[derive(Debug, Args)]
pub struct ReportArgs {
    /// The recording (or session directory, given as the positional path) and how to read it.
    #[command(flatten)]
    pub input: InputArgs,
    /// Reference values.
    #[command(flatten)]
    pub reference: ReferenceArgs,
    /// Where to write the report: a path ending in `.html` (or an existing file) is the report
    /// file itself; any other path is a directory that gets `report.html`, created if missing
    /// (default: the session directory, or `<recording>_report`; `recording_report` for a
    /// recording read from standard input).
    #[arg(long, short = 'o', value_name = "FILE.html|DIR")]
    pub out: Option<PathBuf>,
    /// Replace a report file already there.
    #[arg(long)]
    pub force: bool,
    /// History database whose records of the session's board are plotted over time
    /// (default: `$IMUCAL_DB`, else the default file when it exists).
    #[arg(long, value_name = "URL")]
    pub db: Option<String>,
}

/// Arguments of `imucal analyze`.
#[derive(Debug, Args)]
pub struct AnalyzeArgs {
    /// How to read the recording (a recording file or a session directory's recording).
    #[command(flatten)]
    pub input: InputArgs,
    /// Reference values.
    #[command(flatten)]
    pub reference: ReferenceArgs,
    /// Print the JSON document instead of text.
    #[arg(long)]
    pub json: bool,
    /// Write analysis.json, analysis.txt and SVG plots of each accepted effect into this directory.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Session directories only: write the session's parameter set (params-base.json, else
    /// params.json) with the accepted effects added as extended terms to this file.
    ///
    /// Example: imucal analyze imucal-session-1700000000 --write-params extended.json
    ///          imucal flash extended.json
    #[arg(long, verbatim_doc_comment)]
    pub write_params: Option<PathBuf>,
    /// Replace an existing --write-params file, or write into a --report directory that
    /// already holds files.
    #[arg(long)]
    pub force: bool,
}

/// Arguments of `imucal still`.
#[derive(Debug, Args)]
pub struct StillArgs {
    /// How to read the recording.
    #[command(flatten)]
    pub input: InputArgs,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

impl CalibrateArgs {
    /// Whether the board (at --port, or the simulated one) runs a MotionCal sketch.
    pub fn talks_motioncal(&self) -> bool {
        let protocol = if self.sim {
            self.sim_protocol
        } else {
            self.protocol
        };
        protocol == BoardProtocol::Motioncal
    }

    /// Readings per second of a MotionCal sketch board: `--sketch-rate`, else Adafruit's 100.
    pub fn sketch_rate_hz(&self) -> f64 {
        self.sketch_rate.unwrap_or(100.0)
    }

    /// Refuses options that would have no effect in the session the others choose, before a
    /// board is opened: a user who gives one expects it to act.
    pub fn check_combination(&self) -> anyhow::Result<()> {
        anyhow::ensure!(
            self.sim_boards.is_none() || self.sim_protocol != BoardProtocol::Motioncal,
            UsageError(
                "--sim-protocol motioncal with --sim-boards: a batch needs boards running \
                 imucal's firmware (they report an id to record and compare); calibrate a \
                 simulated sketch board alone with --sim --sim-protocol motioncal"
                    .to_string()
            )
        );
        anyhow::ensure!(
            self.sim_faulty == 0 || self.sim_boards.is_some(),
            UsageError(format!(
                "--sim-faulty {} chooses faulty boards among --sim-boards, which is not given; \
                 add --sim-boards N (N ≥ {}) or leave --sim-faulty out",
                self.sim_faulty, self.sim_faulty
            ))
        );
        if let Some(rate) = self.sketch_rate {
            anyhow::ensure!(
                self.talks_motioncal(),
                UsageError(format!(
                    "--sketch-rate {rate} is the reading rate of a MotionCal sketch board, but \
                     this session talks to imucal's firmware, which states its own rate; leave \
                     --sketch-rate out, or add {} motioncal for a sketch board",
                    if self.sim {
                        "--sim-protocol"
                    } else {
                        "--protocol"
                    }
                ))
            );
            // The simulated sketch prints at Adafruit's rate; another stated rate would time
            // its readings wrongly rather than change it.
            anyhow::ensure!(
                !self.sim || rate == 100.0,
                UsageError(format!(
                    "--sketch-rate {rate} states a real sketch board's reading rate; the \
                     simulated sketch prints 100 readings/s, as Adafruit's does; leave \
                     --sketch-rate out with --sim"
                ))
            );
        }
        Ok(())
    }

    /// Whether several boards on one fixture are calibrated together (`--sim-boards`,
    /// `--ports auto`, or more than one `--port`).
    pub fn is_batch(&self) -> bool {
        self.sim_boards.is_some() || self.ports.is_some() || self.port.len() > 1
    }
}

/// `calibrate --speed` unless given: simulated seconds per wall second.
pub const DEFAULT_SPEED: f64 = 15.0;
/// `calibrate --gravity` unless given, m/s² (standard gravity).
pub const DEFAULT_GRAVITY: f64 = 9.806_65;
/// `calibrate --hold` unless given, s.
pub const DEFAULT_HOLD_S: f64 = 1.5;
/// `calibrate --pose-timeout` unless given, s.
pub const DEFAULT_POSE_TIMEOUT_S: f64 = 180.0;
/// `calibrate --mag-timeout` unless given, s.
pub const DEFAULT_MAG_TIMEOUT_S: f64 = 180.0;
/// `calibrate --rest-timeout` unless given, s.
pub const DEFAULT_REST_TIMEOUT_S: f64 = 120.0;

/// Arguments of `imucal calibrate`.
#[derive(Debug, Args)]
#[command(group(clap::ArgGroup::new("simulated").args(["sim", "sim_boards"])))]
pub struct CalibrateArgs {
    /// Serial port of the board (default: the only likely board from `imucal ports`). Repeat it
    /// for boards mounted together on one fixture: they are calibrated as one batch.
    #[arg(long, short = 'p', conflicts_with_all = ["simulated", "ports"])]
    pub port: Vec<String>,
    /// `auto`: calibrate every recognised board (known board or board vendor) as one batch.
    #[arg(long, value_parser = ["auto"], conflicts_with = "simulated")]
    pub ports: Option<String>,
    /// Calibrate the simulated board, started in-process on a pseudo-terminal.
    #[arg(long)]
    pub sim: bool,
    /// Calibrate this many simulated boards as one batch (seeds from --sim-seed on, each with
    /// its own device id, sensor errors and noise).
    #[arg(long, value_parser = clap::value_parser!(u16).range(1..=64))]
    pub sim_boards: Option<u16>,
    /// Simulator: give this many of the --sim-boards a hardware fault (accelerometer axis
    /// offset or gain, a magnet next to the magnetometer, gyroscope noise), the last ones.
    #[arg(long, default_value_t = 0, requires = "sim_boards")]
    pub sim_faulty: u16,
    /// Write a board's parameters even when it is an outlier against its fleet or batch, or past
    /// a bound of every common part's datasheet (a damaged sensor).
    #[arg(long)]
    pub accept_outlier: bool,
    /// Simulator: seed of the board's errors, noise and the simulated person.
    #[arg(long, default_value_t = 1, requires = "simulated", value_parser = super::values::whole_number::<u64>)]
    pub sim_seed: u64,
    /// Simulator: switch a hidden effect on (repeatable), `[sensor.]name[=size]`.
    #[arg(long = "sim-effect", requires = "simulated")]
    pub sim_effects: Vec<String>,
    /// Simulator: sensor chip, lsm9ds1 (Nano 33 BLE Sense) or bmi270 (BMI270 + BMM150, Rev2).
    #[arg(long, value_enum, default_value = "lsm9ds1", requires = "simulated")]
    #[cfg(feature = "sim")]
    pub sim_chip: imucal_hil_sim::board::SensorChip,
    /// Simulator: what the simulated board runs, imucal's firmware or Adafruit's MotionCal
    /// calibration sketch.
    #[arg(long, value_enum, default_value = "imucal", requires = "sim")]
    pub sim_protocol: BoardProtocol,
    /// What the board at --port runs: imucal's firmware, or a sketch that prints MotionCal's
    /// `Raw:`/`Uni:` lines and stores its 68-byte packet (Adafruit_Sensor_Calibration).
    #[arg(long, value_enum, default_value = "imucal", conflicts_with = "sim")]
    pub protocol: BoardProtocol,
    /// MotionCal sketch: readings per second it prints (default: 100, as Adafruit's sketch).
    #[arg(long)]
    pub sketch_rate: Option<f64>,
    /// Simulator: simulated seconds per wall second.
    #[arg(long, default_value_t = DEFAULT_SPEED, requires = "simulated", value_parser = positive)]
    pub speed: f64,
    /// Simulator: the LSM9DS1 converts on its own clock, this relative error off its nominal
    /// output data rates (e.g. -0.005), so reads repeat or miss conversions as on hardware and
    /// the 80 Hz magnetometer repeats under 119 Hz reads. Without it every read is new.
    #[arg(long, requires = "sim", allow_hyphen_values = true)]
    pub sim_odr_error: Option<f64>,
    /// Simulator: die temperature, `constant` (the person's ambient) or `sweep[:LOW:HIGH:PERIOD]`
    /// (°C, °C, s; `sweep` alone is 10–40 °C every 90 s).
    #[arg(long, default_value = "constant", requires = "simulated", value_parser = sim_temperature)]
    pub sim_temperature: SimTemperature,
    /// Capture the twelve positions this many times over (the simulated person repeats them).
    /// Spreading the poses over time and temperature lets `--analyze` see temperature effects;
    /// the accelerometer's analysis needs at least two rounds.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(1..))]
    pub rounds: u8,
    /// After the base fit, analyse the residual of the session's poses; the effects the firmware
    /// can apply (bias temperature polynomial, scale temperature coefficient, non-linearity, gyro
    /// g-sensitivity) that the analysis accepts are added to the set, written, verified and
    /// checked at rest again; the written set is saved as params.json (the base set as
    /// params-base.json) and the analysis as analysis.json. The extended set is judged with
    /// its own model's held-out error: a base set refused as poor for an error the added terms
    /// explain is replaced by the extended set, which is then offered for writing.
    ///
    /// Example: imucal calibrate --sim --sim-temperature sweep
    /// --sim-effect accel.bias_temperature=2 --rounds 3 --analyze --yes
    #[arg(long, verbatim_doc_comment)]
    pub analyze: bool,
    /// Unattended: write a good or marginal calibration without asking, and print plain
    /// progress lines. A poor one is not written (exit code 1) unless --accept-poor. Without
    /// --yes and without a terminal to ask (input from a pipe or a file), nothing is written:
    /// the session is saved and exits 1.
    #[arg(long, short = 'y')]
    pub yes: bool,
    /// Write the calibration even when its verdict is poor (by default a poor calibration is
    /// saved but not written; the prompt's default is then "no").
    #[arg(long)]
    pub accept_poor: bool,
    /// Print the machine-readable summary (JSON) on stdout instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Session directory (default: `imucal-session-<unix time>` here). It is written as the
    /// session goes, so a session stopped early (Ctrl-C, a timeout, a lost board) keeps what
    /// was measured.
    #[arg(long, short = 'o', conflicts_with = "resume")]
    pub out: Option<PathBuf>,
    /// Write the session into a directory that already holds files (by default such a
    /// directory, e.g. an earlier session, is refused before the board is opened).
    #[arg(long, conflicts_with = "resume")]
    pub force: bool,
    /// Continue the unfinished session saved in SESSION_DIR on the same board: the positions
    /// already captured are not asked for again, and the directory is updated.
    #[arg(long, value_name = "SESSION_DIR")]
    pub resume: Option<PathBuf>,
    /// Where to record the calibration.
    #[command(flatten)]
    pub history: super::history::RecordArgs,
    /// Local gravity, m/s².
    #[arg(long, default_value_t = DEFAULT_GRAVITY)]
    pub gravity: f64,
    /// Local field magnitude, µT (e.g. from a geomagnetic model). Without it the magnetometer
    /// keeps its mean sensitivity (with `--sim`: the simulated site's field).
    #[arg(long)]
    pub field_ut: Option<f64>,
    /// Where the board is (latitude, longitude in degrees, optional altitude in m): the World
    /// Magnetic Model's field there today is the magnetometer reference unless --field-ut is given.
    #[arg(long, value_name = "LAT,LON[,ALT_M]", allow_hyphen_values = true)]
    pub location: Option<imucal::geomag::Location>,
    /// Longest still time averaged per position, s. Each position is averaged until the mean
    /// of |a| is as precise as the accelerometer's budget asks, from the noise measured just
    /// before it (at least 0.3 s), and never longer than this.
    #[arg(long, default_value_t = DEFAULT_HOLD_S, value_parser = positive)]
    pub hold: f64,
    /// Longest wait for the next position, s.
    #[arg(long, default_value_t = DEFAULT_POSE_TIMEOUT_S, value_parser = positive)]
    pub pose_timeout: f64,
    /// Longest magnetometer phase, s.
    #[arg(long, default_value_t = DEFAULT_MAG_TIMEOUT_S, value_parser = positive)]
    pub mag_timeout: f64,
    /// Longest wait for the board to lie still at the end, s.
    #[arg(long, default_value_t = DEFAULT_REST_TIMEOUT_S, value_parser = positive)]
    pub rest_timeout: f64,
}

#[cfg(test)]
mod tests {
    use super::{sim_temperature, SimTemperature};

    #[test]
    fn sweep_profiles_are_read_with_defaults_or_given_numbers() {
        let sweep = |low_c, high_c, period_s| SimTemperature::Sweep {
            low_c,
            high_c,
            period_s,
        };
        assert_eq!(sim_temperature("constant"), Ok(SimTemperature::Constant));
        assert_eq!(sim_temperature("sweep"), Ok(sweep(10.0, 40.0, 90.0)));
        assert_eq!(
            sim_temperature("sweep:-5:55.5:120"),
            Ok(sweep(-5.0, 55.5, 120.0))
        );
    }

    #[test]
    fn a_profile_is_written_as_it_is_read_back() {
        for text in ["constant", "sweep", "sweep:-5:55.5:120"] {
            let profile = sim_temperature(text).expect(text);
            assert_eq!(sim_temperature(&profile.to_string()), Ok(profile), "{text}");
        }
    }

    #[test]
    fn malformed_or_inverted_sweeps_are_refused_with_an_example() {
        for bad in [
            "sweepx:1:2:3",
            "sweep:40:10:90",
            "sweep:10:40:0",
            "sweep:10:40",
            "sweep:10:NaN:90",
            "hot",
        ] {
            let error = sim_temperature(bad).expect_err(bad);
            assert!(error.contains("sweep:10:40:90"), "{bad}: {error}");
        }
    }
}
