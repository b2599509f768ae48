//! Recordings in other tools' formats on the command line: MotionCal `Raw:` logs
//! (`--format motioncal`, or detected) and delimited files read through `--columns`.

use anyhow::Context;
use imucal::recording::mapping::{self, ColumnMapping};
use imucal::recording::{motioncal, Recording, Units};

use super::args::{FormatArg, InputArgs};

/// The recording when the arguments ask for an imported format (or `--format auto` finds a
/// MotionCal log); `None` when the ordinary readers apply.
pub fn load(input: &InputArgs, units: Units) -> anyhow::Result<Option<Recording>> {
    let path = &input.recording;
    if let Some(columns) = &input.columns {
        let mapping: ColumnMapping = columns.parse()?;
        return mapping::load(path, &mapping, units, &input.units_stated(), input.rate)
            .map(Some)
            .context("the recording could not be read with the column mapping");
    }
    let motioncal = match input.format {
        FormatArg::Motioncal => true,
        // A directory or unreadable file is left to the ordinary readers' messages.
        FormatArg::Auto if path.is_file() => motioncal::file_looks_like_motioncal(path),
        _ => false,
    };
    if !motioncal {
        return Ok(None);
    }
    motioncal::load(path, input.rate)
        .map(Some)
        .context("the MotionCal log could not be read")
}
