//! `imucal calibrate --analyze`: the residual analysis of the session's poses, and the extended
//! set (the effects it accepts as the firmware's terms) written and checked at rest.

use std::path::PathBuf;

use anyhow::Context;
use imucal::analysis::report;
use imucal::analysis::result::RecordingAnalysis;
use imucal::device::DeviceClient;
use imucal::device::ParamsFile;
use imucal::recording::Sensor;
use imucal::session::extend::extended_uncertainties;
use imucal::session::rest::WorseAtRest;
use imucal::session::solve::{verdict_with_terms, Uncertainties};
use imucal::session::{
    analyse_poses, extend_set, rest_errors, stream_for, ExtendedSet, RestErrors, SessionOptions,
    SessionOutcome, Verdict, VerdictLevel,
};
use imucal_protocol::StreamKind;
use imucal_protocol::{CalibrationSet, ParamStatus};

use super::write_policy::{WriteDecision, WritePolicy};

/// How `--analyze` ended: which set the board holds afterwards.
pub(super) enum Closed {
    /// The board keeps the base set (nothing to add, or the extended set declined).
    BaseStays,
    /// Neither set was written (the base set was not): the extended set is the session's
    /// saved set, `params.json`, the one `imucal flash` would write; with its uncertainties.
    SavedNotWritten(Box<CalibrationSet>, Box<Uncertainties>),
    /// The extended set's verdict kept it off the board; the path of the saved set.
    RefusedPoor(PathBuf),
    /// The extended set was written, checked worse at rest than the base set ([`RestErrors::worse_than`])
    /// and gave way to it: the board and `params.json` hold the base set again.
    RevertedAtRest {
        /// The quantities that were worse, one sentence each.
        worse: Vec<String>,
        /// Where the extended set was kept.
        extended_path: PathBuf,
    },
    /// The extended set is on the board.
    Written {
        /// The set written (boxed: a whole parameter set beside the small variants).
        set: Box<CalibrationSet>,
        /// Its uncertainties ([`extended_uncertainties`]).
        uncertainties: Box<Uncertainties>,
        /// Said when it reads worse at rest than the base set, within its uncertainty.
        note: Option<String>,
        /// Its verdict: the base fit's, with the held-out error of the model with the added
        /// terms ([`verdict_with_terms`]).
        verdict: Verdict,
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
    let mut analysis = analyse_poses(&outcome.poses, options.gravity_mps2);
    imucal::session::extend::note_accel_base(&mut analysis, outcome.fit.accel.method);
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
    let verdict = extended_verdict(outcome, &analysis, &extended);
    let uncertainties = Box::new(extended_uncertainties(
        &outcome.fit.uncertainties,
        &extended,
        &analysis,
        outcome.fit.gravity_mps2,
    ));
    // A base set refused for its verdict alone is offered again with the terms that explain
    // what made it poor; one the user declined, or nobody could be asked about, is not.
    let refused_for_verdict = outcome.not_written_because.as_deref() == Some("poor verdict");
    let offered_again = refused_for_verdict && verdict.level != VerdictLevel::Poor;
    if !(outcome.written || offered_again) {
        say!(
            "The base set was not written, so neither is the extended one; `imucal flash {}` \
             writes it",
            params_path.display()
        );
        return Ok(Closed::SavedNotWritten(
            Box::new(extended.set),
            uncertainties,
        ));
    }
    if !outcome.written {
        say!(
            "With the added terms the verdict is {} (the base set's was poor): the extended \
             set is offered in its place",
            verdict.level.name()
        );
    }
    let question = format!("Write the extended set to the board on {}", outcome.port);
    match policy.decide(verdict.level, &question) {
        WriteDecision::Write => {}
        WriteDecision::Declined | WriteDecision::NoOneToAsk => {
            say!("The extended set was not written; the board keeps the set it had");
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
    // Terms the holds supported can still be wrong where the board lies now: a set that checks
    // worse at rest than the base set did on the same board, and worse than it claims, gives
    // way to it; worse within its claim, it stays and that is said.
    let gyro_sigma_dps = uncertainties
        .gyro_bias_dps
        .iter()
        .map(|s| s * s)
        .sum::<f64>()
        .sqrt();
    let worse = match (&rest, outcome.after.as_ref()) {
        (Ok(with_terms), Some(with_base)) => {
            with_terms.worse_than(with_base, [uncertainties.accel_norm_mg, gyro_sigma_dps])
        }
        _ => Vec::new(),
    };
    let list = |items: &[&WorseAtRest]| {
        items
            .iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join("; ")
    };
    let condemned: Vec<&WorseAtRest> = worse.iter().filter(|w| w.beyond_claim).collect();
    if !condemned.is_empty() {
        let worse = list(&condemned);
        say!(
            "The extended set checks worse at rest than the base set and than its own \
             uncertainty: {worse}; the base set is written back"
        );
        let status = client.write_params_verified(&outcome.fit.set)?;
        say!(
            "Base set written back, committed, read back and compared: CRC {:#010x} (store \
             sequence {})",
            status.active_crc,
            status.active_seq
        );
        // params.json names the set on the board; the extended one is kept beside it.
        let extended_path = dir.join("params-extended.json");
        std::fs::rename(&params_path, &extended_path)
            .and_then(|()| std::fs::copy(&base_path, &params_path).map(|_| ()))
            .with_context(|| format!("could not restore {}", params_path.display()))?;
        return Ok(Closed::RevertedAtRest {
            worse: vec![worse],
            extended_path,
        });
    }
    let note = (!worse.is_empty()).then(|| {
        format!(
            "at rest the extended set reads worse than the base set where the board lies now \
             ({}), within three times its own uncertainty: the base set's offsets were fitted \
             with what the added terms now model, so they suit some orientations better and \
             others worse",
            list(&worse.iter().collect::<Vec<_>>())
        )
    });
    if let Some(note) = &note {
        say!("Note: {note}");
    }
    Ok(Closed::Written {
        set: Box::new(extended.set),
        note,
        uncertainties,
        verdict,
        status,
        rest,
    })
}

/// The extended set's verdict: the base fit's with the accelerometer's held-out error of the
/// analysis's final model, when the set carries that model (accelerometer terms added, none of
/// its accepted effects left out for want of a firmware term); else the base fit's. The base
/// fit's figure leaves one pose out, the analysis's whole folds, which leave larger errors: so
/// the base figure is scaled by the analysis's own ratio after/before, like with like.
fn extended_verdict(
    outcome: &SessionOutcome,
    analysis: &RecordingAnalysis,
    extended: &ExtendedSet,
) -> Verdict {
    let carries_accel_model = extended.added.iter().any(|a| a.starts_with("accel"))
        && !extended.left_out.iter().any(|l| l.starts_with("accel"));
    analysis
        .sensors
        .iter()
        .find(|(sensor, _)| *sensor == Sensor::Accel)
        .and_then(|(_, result)| result.as_ref().ok())
        .filter(|_| carries_accel_model)
        .map_or_else(
            || outcome.fit.verdict.clone(),
            |accel| {
                let heldout = match outcome.fit.accel.loo_rms {
                    Some(loo) if accel.heldout_rms_before > 0.0 => {
                        loo * accel.heldout_rms_after / accel.heldout_rms_before
                    }
                    _ => accel.heldout_rms_after,
                };
                verdict_with_terms(&outcome.fit, heldout)
            },
        )
}
