//! `imucal export`: a parameter file as a C header, a Rust module or versioned JSON.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::{Args, ValueEnum};
use imucal::compat::{self, encode_packet, AdafruitCalibration};
use imucal::device::ParamsFile;
use imucal::export::{export_checked_as, ExportFormat, SensorNotes};
use imucal_protocol::{CalibrationSet, SensorCalibration};

use super::write_policy::{check_outputs, Output};

/// Examples shown by `imucal export --help`.
pub const EXAMPLES: &str = "Examples:\n  \
    imucal export session/params.json --format c-header -o imucal_calibration.h\n  \
    imucal export params.json --format rust -o src/imu_calibration.rs\n  \
    imucal export params.json --format json\n  \
    imucal export params.json --format motioncal -o cal.bin\n  \
    imucal export params.json --format adafruit-json -o sensor_calib.json";

/// Output format flag.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ExportFormatArg {
    /// C99 header: `static const float` arrays and `static inline` apply functions.
    CHeader,
    /// Rust: `pub const` arrays and `pub fn` apply functions.
    Rust,
    /// JSON, schema `imucal-calibration-export` version 2 (docs/PARAMS_FORMAT.md).
    Json,
    /// MotionCal's 68-byte calibration packet (binary, needs `-o`), as Adafruit's sketch
    /// receives it.
    Motioncal,
    /// `sensor_calib.json` of Adafruit's `Adafruit_Sensor_Calibration` flash/SD backend.
    AdafruitJson,
}

/// Arguments of `imucal export`.
#[derive(Debug, Args)]
pub struct ExportArgs {
    /// Parameter file (`params.json` written by `imucal calibrate` or `imucal fit --params-out`).
    pub params: PathBuf,
    /// What to generate.
    #[arg(long, value_enum, default_value = "c-header")]
    pub format: ExportFormatArg,
    /// Write to this file instead of standard output.
    #[arg(long, short = 'o')]
    pub out: Option<PathBuf>,
    /// Replace the -o file when it exists (the parameter file read is never replaced).
    #[arg(long)]
    pub force: bool,
}

/// Run the command.
pub fn run(args: &ExportArgs) -> anyhow::Result<()> {
    if let Some(out) = &args.out {
        check_outputs(
            &[Output::File(out)],
            std::slice::from_ref(&args.params),
            args.force,
        )?;
    }
    let params = ParamsFile::load(&args.params)?;
    let shown = args.params.display().to_string();
    if let Some(why) = params.holds_nothing() {
        anyhow::bail!("`{shown}` is not exported: {why}");
    }
    let set = params.to_calibration_set(&shown)?;
    let raw_inputs = params.non_nominal_inputs();
    let adafruit = matches!(
        args.format,
        ExportFormatArg::Motioncal | ExportFormatArg::AdafruitJson
    );
    if adafruit && !raw_inputs.is_empty() {
        let which: Vec<String> = raw_inputs
            .iter()
            .map(|(sensor, unit)| format!("{sensor} in {unit}"))
            .collect();
        anyhow::bail!(
            "`{shown}` is not exported for Adafruit_Sensor_Calibration: its calibration takes \
             raw readings ({}), but the library applies its offsets and matrix to readings in \
             m/s², rad/s and µT; fit a recording in those units (e.g. `imucal record` from the \
             board, or --accel-unit g / --gyro-unit dps / --mag-unit gauss with --field-ut)",
            which.join(", ")
        );
    }
    for (sensor, unit) in &raw_inputs {
        say!(
            "imucal: note: the {sensor} calibration takes raw readings in {unit}, not the nominal \
             unit (the export says so)"
        );
    }
    let uncalibrated = params.left_out();
    for (sensor, why) in &uncalibrated {
        say!(
            "imucal: note: `{shown}` has no {sensor} calibration ({why}); it is exported as the \
             identity and marked as not calibrated"
        );
    }
    let name = args
        .params
        .file_name()
        .map_or(shown.clone(), |n| n.to_string_lossy().into_owned());
    let format = match args.format {
        ExportFormatArg::CHeader => ExportFormat::CHeader,
        ExportFormatArg::Rust => ExportFormat::Rust,
        ExportFormatArg::Json => ExportFormat::Json,
        ExportFormatArg::Motioncal | ExportFormatArg::AdafruitJson => {
            let mag_calibrated = !uncalibrated.iter().any(|(sensor, _)| *sensor == "mag");
            return export_adafruit(&set, mag_calibrated, args);
        }
    };
    // Sensors calibrated in raw counts have no nominal unit: the board's limits apply only to
    // the others (`flash` refuses such files outright).
    let mut checked = set;
    for (raw, cal) in [
        (&params.accel, &mut checked.accel),
        (&params.gyro, &mut checked.gyro),
        (&params.mag, &mut checked.mag),
    ] {
        if raw.input_unit.is_some() {
            *cal = SensorCalibration::identity();
        }
    }
    let uncalibrated: Vec<(&str, &str)> = uncalibrated
        .iter()
        .map(|(sensor, why)| (*sensor, why.as_str()))
        .collect();
    let notes = SensorNotes {
        raw_inputs: &raw_inputs,
        uncalibrated: &uncalibrated,
    };
    let text = export_checked_as(&set, &checked, format, &name, notes)
        .map_err(|reason| anyhow::anyhow!("`{shown}` is not exported: {reason}"))?;
    write_output(args.out.as_deref(), text.as_bytes())
}

/// The Adafruit library's forms: what it can apply of `set`, and a note of what it cannot.
/// Without a magnetometer calibration the field is the library's own default, not the
/// parameter file's placeholder.
fn export_adafruit(
    set: &CalibrationSet,
    mag_calibrated: bool,
    args: &ExportArgs,
) -> anyhow::Result<()> {
    let mut conversion = AdafruitCalibration::from_set(set)?;
    if !mag_calibrated {
        conversion.calibration.mag_field = compat::adafruit::LIBRARY_DEFAULT_FIELD_UT;
        say!(
            "imucal: note: the field is the library's default of {} µT, as the magnetometer \
             is not calibrated",
            compat::adafruit::LIBRARY_DEFAULT_FIELD_UT
        );
    }
    say_part!("{}", compat::limitations(set, &[])?.describe());
    if args.format == ExportFormatArg::AdafruitJson {
        let text = conversion.calibration.to_sensor_calib_json();
        return write_output(args.out.as_deref(), text.as_bytes());
    }
    let Some(out) = args.out.as_deref() else {
        return Err(super::UsageError(
            "the MotionCal packet is binary; name a file with `-o cal.bin`".into(),
        )
        .into());
    };
    write_output(Some(out), &encode_packet(&conversion.calibration)?)
}

/// Writes `bytes` to `out`, or to standard output.
fn write_output(out: Option<&Path>, bytes: &[u8]) -> anyhow::Result<()> {
    match out {
        Some(path) => {
            std::fs::write(path, bytes).with_context(|| {
                format!("cannot write `{}`; check the directory", path.display())
            })?;
            say!("wrote {}", path.display());
        }
        None => std::io::stdout()
            .write_all(bytes)
            .context("cannot write to standard output")?,
    }
    Ok(())
}
