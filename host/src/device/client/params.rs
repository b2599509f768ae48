//! Parameter transfer: read the active set, stage a set under the host's CRC, commit, reset,
//! and the verified write and reset that read the active set back and compare it value by value.

use std::io::{Read, Write};

use imucal_protocol::{CalibrationSet, ParamStatus, RequestBody, ResponseBody};

use super::DeviceClient;
use crate::device::DeviceError;

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
    /// back and compare CRC and every value.
    pub fn write_params_verified(
        &mut self,
        set: &CalibrationSet,
    ) -> Result<ParamStatus, DeviceError> {
        let crc = set.crc32();
        self.stage_params(set)?;
        let committed = self.commit_params(crc)?;
        if committed.active_crc != crc {
            return Err(DeviceError::VerifyFailed {
                port: self.port.clone(),
                detail: format!(
                    "active CRC {:#010x} after commit, {crc:#010x} written",
                    committed.active_crc
                ),
            });
        }
        self.verify_active(set)?;
        Ok(committed)
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
