//! Parameter transfer: read the active set, stage a set under the host's CRC, commit, reset,
//! and the verified write and reset that read the active set back and compare it value by value.

use std::io::{Read, Write};

use imucal_protocol::{CalibrationSet, DeviceStatus, ParamStatus, RequestBody, ResponseBody};

use super::{DeviceClient, LinkStats};
use crate::device::DeviceError;

/// Rounds of a request's own tries when settling a write whose answer was lost: with three
/// tries a round, twelve sends in all.
const SETTLE_ROUNDS: u32 = 4;

/// How a verified write ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WriteReport {
    /// The board's active set after the write: the new set's CRC and its store sequence.
    pub status: ParamStatus,
    /// When an answer was lost in or after the commit and the write was settled by reading the
    /// board again: what happened, as a sentence.
    pub recovered: Option<String>,
}

/// Whether `error` is an answer that did not come (the board may still have acted).
fn is_lost_answer(error: &DeviceError) -> bool {
    matches!(
        error,
        DeviceError::NoAnswer { .. } | DeviceError::NoisyLink { .. }
    )
}

/// The request whose answer `error` lost.
fn lost_request(error: &DeviceError) -> &'static str {
    match error {
        DeviceError::NoAnswer { request, .. } | DeviceError::NoisyLink { request, .. } => request,
        _ => "a request",
    }
}

impl<L: Read + Write> DeviceClient<L> {
    /// The active parameter set.
    pub fn get_params(&mut self) -> Result<CalibrationSet, DeviceError> {
        match self.request(RequestBody::GetParams)? {
            ResponseBody::Params(set) => Ok(set),
            other => Err(self.unexpected("GetParams", &other)),
        }
    }

    /// Stages `set` (CRC computed here) and checks that the board staged that very CRC.
    pub fn stage_params(&mut self, set: &CalibrationSet) -> Result<ParamStatus, DeviceError> {
        // The board's own check, here first: nothing is sent that it would refuse.
        imucal_protocol::validate(set, &self.welcome.scales).map_err(|reason| {
            DeviceError::InvalidParams {
                port: self.port.clone(),
                reason,
            }
        })?;
        let crc = set.crc32();
        let status =
            self.param_request("WriteParams", RequestBody::WriteParams { set: *set, crc })?;
        if status.staged_crc != Some(crc) {
            return Err(DeviceError::StagedCrcMismatch {
                port: self.port.clone(),
                sent: crc,
                echoed: status.staged_crc,
            });
        }
        Ok(status)
    }

    /// Makes the staged set with `crc` active.
    pub fn commit_params(&mut self, crc: u32) -> Result<ParamStatus, DeviceError> {
        self.param_request("CommitParams", RequestBody::CommitParams { crc })
    }

    /// Makes the identity set active.
    pub fn reset_params(&mut self) -> Result<ParamStatus, DeviceError> {
        self.param_request("ResetParams", RequestBody::ResetParams)
    }

    /// Writes `set` to the board and proves it arrived: stage with the host's CRC, refuse to
    /// commit unless the board echoes that CRC as staged, commit, then read the active set
    /// back and compare CRC and every value. An answer lost in or after the commit is settled
    /// as [`Self::write_params_settled`] does.
    pub fn write_params_verified(
        &mut self,
        set: &CalibrationSet,
    ) -> Result<ParamStatus, DeviceError> {
        self.write_params_settled(set).map(|report| report.status)
    }

    /// As [`Self::write_params_verified`], saying whether an answer was lost on the way.
    ///
    /// The commit is the one step whose loss leaves the outcome unknown: the board may have
    /// made the set active and lost only its answer. So when an answer is lost in or after the
    /// commit, contact is re-established (with more tries than one request gets) and the
    /// board's active set identity (CRC, sequence) is read: the new set's, and then it is read
    /// back and compared value by value before success is reported; the previous set's, and
    /// the error says the write did not take; otherwise the error says which state could not
    /// be told. A set is never reported written without the read-back.
    pub fn write_params_settled(
        &mut self,
        set: &CalibrationSet,
    ) -> Result<WriteReport, DeviceError> {
        let crc = set.crc32();
        // The active set and the board's error counters before anything is sent.
        let before = self.status()?;
        let link_before = self.stats;
        // A stage whose answer is lost committed nothing, but the board's state and counters
        // still tell which set is active and whether the link is to blame.
        match self.stage_params(set) {
            Ok(_) => {}
            Err(cause) if is_lost_answer(&cause) => {
                return self.settle(set, &before, link_before, cause)
            }
            Err(cause) => return Err(cause),
        }
        let committed = match self.commit_params(crc) {
            Ok(committed) => committed,
            Err(cause) if is_lost_answer(&cause) => {
                return self.settle(set, &before, link_before, cause)
            }
            Err(cause) => return Err(cause),
        };
        if committed.active_crc != crc {
            return Err(DeviceError::VerifyFailed {
                port: self.port.clone(),
                detail: format!(
                    "active CRC {:#010x} after commit, {crc:#010x} written",
                    committed.active_crc
                ),
            });
        }
        match self.verify_active(set) {
            Ok(()) => Ok(WriteReport {
                status: committed,
                recovered: None,
            }),
            Err(cause) if is_lost_answer(&cause) => self.settle(set, &before, link_before, cause),
            Err(cause) => Err(cause),
        }
    }

    /// After `cause` lost an answer in or after the commit of `set`: which set is active.
    fn settle(
        &mut self,
        set: &CalibrationSet,
        before: &DeviceStatus,
        link_before: LinkStats,
        cause: DeviceError,
    ) -> Result<WriteReport, DeviceError> {
        let crc = set.crc32();
        let port = self.port.clone();
        let now = match self.patiently(Self::status) {
            Ok(now) => now,
            Err(_) => {
                let link = self.link_note(link_before, before, None);
                return Err(DeviceError::WriteUnsettled {
                    port: port.clone(),
                    state: format!(
                        "contact could not be re-established{link}, so the board holds either \
                         the new set (CRC {crc:#010x}) or its previous one (CRC {:#010x}, \
                         sequence {}); run `imucal info --port {port}` to see which, and write \
                         again if it is the previous one",
                        before.active_crc, before.active_seq
                    ),
                    cause: Box::new(cause),
                    committed: None,
                });
            }
        };
        let link = self.link_note(link_before, before, Some(&now));
        let status = ParamStatus {
            active_crc: now.active_crc,
            active_seq: now.active_seq,
            staged_crc: None,
        };
        if now.active_crc == crc {
            return match self.patiently(|client| client.verify_active(set)) {
                Ok(()) => Ok(WriteReport {
                    status,
                    recovered: Some(format!(
                        "an answer from {port} was lost ({cause_request}){link}; contact was \
                         re-established: the new set is active (CRC {crc:#010x}, store \
                         sequence {}) and reading it back matched every value",
                        now.active_seq,
                        cause_request = lost_request(&cause),
                    )),
                }),
                Err(verify @ DeviceError::VerifyFailed { .. }) => Err(verify),
                Err(_) => Err(DeviceError::WriteUnsettled {
                    port: port.clone(),
                    state: format!(
                        "the board's status shows the new set active (CRC {crc:#010x}, store \
                         sequence {}), but it could not be read back to verify its values{link}; \
                         run `imucal params get --port {port} -o check.json` to verify it",
                        now.active_seq
                    ),
                    cause: Box::new(cause),
                    committed: Some(status),
                }),
            };
        }
        if now.active_crc == before.active_crc {
            return Err(DeviceError::WriteUnsettled {
                port,
                state: format!(
                    "contact was re-established: the board kept its previous set (CRC {:#010x}, \
                     store sequence {}), the new set was not committed{link}; write it again",
                    now.active_crc, now.active_seq
                ),
                cause: Box::new(cause),
                committed: None,
            });
        }
        Err(DeviceError::VerifyFailed {
            port,
            detail: format!(
                "after a lost answer the active CRC is {:#010x}, neither the new set's \
                 {crc:#010x} nor the previous {:#010x}",
                now.active_crc, before.active_crc
            ),
        })
    }

    /// `op` retried through lost answers: up to [`SETTLE_ROUNDS`] rounds of its own tries.
    fn patiently<T>(
        &mut self,
        mut op: impl FnMut(&mut Self) -> Result<T, DeviceError>,
    ) -> Result<T, DeviceError> {
        let mut round = 1;
        loop {
            match op(self) {
                Err(error) if is_lost_answer(&error) && round < SETTLE_ROUNDS => round += 1,
                other => return other,
            }
        }
    }

    /// What the link did since `link_before` and `before` (the board's counters, when `now`
    /// was read), as a clause starting with a comma, or empty when nothing failed a check.
    fn link_note(
        &self,
        link_before: LinkStats,
        before: &DeviceStatus,
        now: Option<&DeviceStatus>,
    ) -> String {
        let here = self
            .stats
            .frame_errors
            .saturating_sub(link_before.frame_errors);
        let there = now.map_or(0, |now| {
            now.errors
                .rx_frame_errors
                .saturating_sub(before.errors.rx_frame_errors)
        });
        let mut seen = Vec::new();
        if here > 0 {
            seen.push(format!(
                "{here} frame(s) from the board failed their check here"
            ));
        }
        if there > 0 {
            seen.push(format!(
                "the board counted {there} bad frame(s) from this side"
            ));
        }
        if seen.is_empty() {
            return String::new();
        }
        format!(
            ", and the link is noisy ({}: check the cable and connectors)",
            seen.join("; ")
        )
    }

    /// Makes the identity set active and proves it: the active CRC the board reports and the
    /// set read back are the identity set's.
    pub fn reset_params_verified(&mut self) -> Result<ParamStatus, DeviceError> {
        let identity = CalibrationSet::identity();
        let status = self.reset_params()?;
        if status.active_crc != identity.crc32() {
            return Err(DeviceError::VerifyFailed {
                port: self.port.clone(),
                detail: format!(
                    "active CRC {:#010x} after the reset, {:#010x} is the identity set's",
                    status.active_crc,
                    identity.crc32()
                ),
            });
        }
        self.verify_active(&identity)?;
        Ok(status)
    }

    /// Reads the active set back and compares its CRC and every value with `set`.
    fn verify_active(&mut self, set: &CalibrationSet) -> Result<(), DeviceError> {
        let crc = set.crc32();
        let back = self.get_params()?;
        let differing: Vec<&str> = [
            ("format_version", back.format_version != set.format_version),
            ("created_unix_s", back.created_unix_s != set.created_unix_s),
            ("accel", back.accel != set.accel),
            ("gyro", back.gyro != set.gyro),
            ("mag", back.mag != set.mag),
            (
                "gyro_g_sensitivity",
                back.gyro_g_sensitivity != set.gyro_g_sensitivity,
            ),
            ("reference", back.reference != set.reference),
            ("residuals", back.residuals != set.residuals),
        ]
        .into_iter()
        .filter_map(|(name, differs)| differs.then_some(name))
        .collect();
        if !differing.is_empty() || back.crc32() != crc {
            return Err(DeviceError::VerifyFailed {
                port: self.port.clone(),
                detail: format!(
                    "CRC {:#010x} read, {crc:#010x} written; differing: {}",
                    back.crc32(),
                    if differing.is_empty() {
                        "none by value".to_string()
                    } else {
                        differing.join(", ")
                    }
                ),
            });
        }
        Ok(())
    }

    fn param_request(
        &mut self,
        name: &'static str,
        body: RequestBody,
    ) -> Result<ParamStatus, DeviceError> {
        match self.request(body)? {
            ResponseBody::ParamStatus(status) => Ok(status),
            other => Err(self.unexpected(name, &other)),
        }
    }
}
