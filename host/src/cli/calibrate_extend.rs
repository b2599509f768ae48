//! `imucal calibrate --analyze`: the residual analysis of the session's poses, and the extended
//! set (the effects it accepts as the firmware's terms) written and checked at rest.

use std::path::PathBuf;

use anyhow::Context;
use imucal::analysis::report;
use imucal::device::DeviceClient;
use imucal::device::ParamsFile;
use imucal::session::{
    analyse_poses, extend_set, rest_errors, stream_for, RestErrors, SessionOptions, SessionOutcome,
};
use imucal_protocol::StreamKind;
use imucal_protocol::{CalibrationSet, ParamStatus};

use super::write_policy::{WriteDecision, WritePolicy};

/// How `--analyze` ended: which set the board holds afterwards.
pub(super) enum Closed {
    /// The board keeps the base set (nothing to add, or the extended set declined).
    BaseStays,
    /// Neither set was written (the base set was not): the extended set is the session's
    /// saved set, `params.json`, the one `imucal flash` would write.
    SavedNotWritten(Box<CalibrationSet>),
    /// The extended set's verdict kept it off the board; the path of the saved set.
    RefusedPoor(PathBuf),
    /// The extended set is on the board.
    Written {
        /// The set written (boxed: a whole parameter set beside the small variants).
        set: Box<CalibrationSet>,
        /// The store's state after the commit.
        status: ParamStatus,
        /// The errors at rest with it, or why they could not be measured (the set is on the
        /// board either way, so the caller records it before reporting this).
        rest: anyhow::Result<RestErrors>,
    },
}

/// `--analyze`: the residual analysis of the poses, and the extended set written and checked at
/// rest when it adds anything and `policy` allows its verdict.
pub(super) fn close_the_loop(
    client: &mut DeviceClient,
    options: &SessionOptions,
    outcome: &SessionOutcome,
    dir: &std::path::Path,
    json: bool,
    policy: WritePolicy,
) -> anyhow::Result<Closed> {
    let analysis = analyse_poses(&outcome.poses, options.gravity_mps2);
    std::fs::write(
        dir.join("analysis.json"),
        serde_json::to_string_pretty(&report::to_json(&analysis))?,
    )
    .with_context(|| format!("could not write {}", dir.join("analysis.json").display()))?;
    let text = report::to_text(&analysis);
    if !json {
        say!(
            "\nResidual analysis of the {} poses:\n{text}",
            outcome.poses.len()
        );
    }
    let extended = extend_set(&outcome.fit.set, &analysis);
    // The report shows the analysis and the terms it added as the session screen did.
    let mut shown = text;
    shown.push_str(&if extended.extended() {
        format!("Extended terms added: {}\n", extended.added.join(", "))
    } else {
        "The analysis accepted no effect the firmware applies; the base set stays.\n".to_string()
    });
    for effect in &extended.left_out {
        shown.push_str(&format!(
            "{effect} was accepted but the firmware has no term for it; not written\n"
        ));
    }
    let text_path = dir.join(imucal::report::ANALYSIS_TEXT_FILE);
    std::fs::write(&text_path, shown)
        .with_context(|| format!("could not write {}", text_path.display()))?;
    for effect in &extended.left_out {
        say!("Note: {effect} was accepted but the firmware has no term for it; not written");
    }
    if !extended.extended() {
        say!("The analysis accepted no effect the firmware applies; the base set stays.");
        return Ok(Closed::BaseStays);
    }
    say!("Extended terms added: {}", extended.added.join(", "));
    let base_path = dir.join("params-base.json");
    std::fs::write(
        &base_path,
        ParamsFile::from(&outcome.fit.set)
            .bound_to(client.welcome())
            .to_json(),
    )
    .with_context(|| format!("could not write {}", base_path.display()))?;
    let params_path = dir.join("params.json");
    std::fs::write(
        &params_path,
        ParamsFile::from(&extended.set)
            .bound_to(client.welcome())
            .to_json(),
    )
    .with_context(|| format!("could not write {}", params_path.display()))?;
    if !outcome.written {
        say!(
            "The base set was not written, so neither is the extended one; `imucal flash {}` \
             writes it",
            params_path.display()
        );
        return Ok(Closed::SavedNotWritten(Box::new(extended.set)));
    }
    // The extended terms come from the same poses, so the base fit's verdict is theirs too.
    let question = format!("Write the extended set to the board on {}", outcome.port);
    match policy.decide(outcome.fit.verdict.level, &question) {
        WriteDecision::Write => {}
        WriteDecision::Declined | WriteDecision::NoOneToAsk => {
            say!("The extended set was not written; the board keeps the base set");
            return Ok(Closed::BaseStays);
        }
        WriteDecision::RefusedPoor => return Ok(Closed::RefusedPoor(params_path)),
    }
    let status = client.write_params_verified(&extended.set)?;
    say!(
        "Extended set written, committed, read back and compared: CRC {:#010x} (store \
         sequence {})",
        status.active_crc,
        status.active_seq
    );
    let rest = stream_for(
        client,
        StreamKind::Calibrated,
        options.rest_measure_s,
        options.read_timeout,
    )
    .map_err(anyhow::Error::from)
    .and_then(|samples| {
        rest_errors(&samples, outcome.fit.gravity_mps2, outcome.fit.field_ut)
            .context("no calibrated samples arrived for the check at rest")
    });
    Ok(Closed::Written {
        set: Box::new(extended.set),
        status,
        rest,
    })
}
