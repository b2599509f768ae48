//! Recordings in other tools' formats on the command line: MotionCal `Raw:` logs
//! (`--format motioncal`, or detected) and delimited files read through `--columns`.

use anyhow::Context;
use imucal::recording::mapping::{self, ColumnMapping};
use imucal::recording::{motioncal, Recording, Units};

use super::args::{FormatArg, InputArgs};

/// The recording when the arguments ask for an imported format; `None` when the ordinary
/// readers apply (they also find a MotionCal log by its `Raw:` lines).
pub fn load(input: &InputArgs, units: Units) -> anyhow::Result<Option<Recording>> {
    let path = &input.recording;
    if let Some(columns) = &input.columns {
        let mapping: ColumnMapping = columns.parse()?;
        return mapping::load(path, &mapping, units, &input.units_stated(), input.rate)
            .map(Some)
            .map_err(|e| {
                super::read_error(
                    e.is_option_conflict(),
                    e,
                    "the recording could not be read with the column mapping",
                )
            });
    }
    // `--format auto` finds a MotionCal log in the ordinary reader, which reads a file and
    // standard input alike.
    if input.format != FormatArg::Motioncal {
        return Ok(None);
    }
    motioncal::load(path, input.rate)
        .map(Some)
        .context("the MotionCal log could not be read")
}
