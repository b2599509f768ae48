//! `imucal export`: a parameter file as a C header, a Rust module or versioned JSON.

use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, ValueEnum};
use imucal::device::ParamsFile;
use imucal::export::{export, ExportFormat};

/// Examples shown by `imucal export --help`.
pub const EXAMPLES: &str = "Examples:\n  \
    imucal export session/params.json --format c-header -o imucal_calibration.h\n  \
    imucal export params.json --format rust -o src/imu_calibration.rs\n  \
    imucal export params.json --format json";

/// Output format flag.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ExportFormatArg {
    /// C99 header: `static const float` arrays and `static inline` apply functions.
    CHeader,
    /// Rust: `pub const` arrays and `pub fn` apply functions.
    Rust,
    /// JSON, schema `imucal-calibration-export` version 1 (docs/PARAMS_FORMAT.md).
    Json,
}

/// Arguments of `imucal export`.
#[derive(Debug, Args)]
pub struct ExportArgs {
    /// Parameter file (`params.json` written by `imucal calibrate`, format 1).
    pub params: PathBuf,
    /// What to generate.
    #[arg(long, value_enum, default_value = "c-header")]
    pub format: ExportFormatArg,
    /// Write to this file instead of standard output.
    #[arg(long, short = 'o')]
    pub out: Option<PathBuf>,
}

/// Run the command.
pub fn run(args: &ExportArgs) -> anyhow::Result<()> {
    let params = ParamsFile::load(&args.params)?;
    let shown = args.params.display().to_string();
    let set = params.to_calibration_set(&shown)?;
    for sensor in params.non_nominal_inputs() {
        eprintln!("imucal: note: the {sensor} calibration takes raw readings in that unit, not the nominal unit the exported comment states");
    }
    for (sensor, why) in &params.not_fitted {
        eprintln!("imucal: note: `{shown}` has no {sensor} calibration ({why}); it is exported as identity");
    }
    let name = args
        .params
        .file_name()
        .map_or(shown.clone(), |n| n.to_string_lossy().into_owned());
    let format = match args.format {
        ExportFormatArg::CHeader => ExportFormat::CHeader,
        ExportFormatArg::Rust => ExportFormat::Rust,
        ExportFormatArg::Json => ExportFormat::Json,
    };
    let text = export(&set, format, &name);
    match &args.out {
        Some(path) => {
            std::fs::write(path, text).with_context(|| {
                format!("cannot write `{}`; check the directory", path.display())
            })?;
            eprintln!("wrote {}", path.display());
        }
        None => print!("{text}"),
    }
    Ok(())
}
