//! The error reply a device sends in place of the expected response body.

use core::fmt;

use serde::{Deserialize, Serialize};

use crate::validate::reason::InvalidParamsReason;

/// An error reply from the device, in place of the expected response body.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum ErrorCode {
    /// The host's protocol major version differs from the device's.
    VersionMismatch {
        /// The device's protocol major version.
        device_major: u16,
        /// The device's protocol minor version.
        device_minor: u16,
    },
    /// The request decoded far enough to read its sequence id, but its kind is unknown to this
    /// firmware (sent by a host with a newer minor version).
    UnknownRequest,
    /// The request could not be decoded.
    Malformed,
    /// A request field is out of range (for example a decimation of zero).
    InvalidArgument,
    /// The device is busy with another operation (for example a pose capture).
    Busy,
    /// A sensor needed for the request is not fitted on this board.
    SensorMissing,
    /// The board did not stay still long enough within the timeout.
    NotStill,
    /// The operation did not finish within its timeout.
    Timeout,
    /// A sensor reading hit its full-scale limit during the capture.
    Saturated,
    /// The CRC sent with a parameter set or commit does not match the set.
    CrcMismatch {
        /// The CRC given in the request.
        received: u32,
        /// The CRC of the set as the device computed or holds it.
        computed: u32,
    },
    /// A commit was requested but no parameter set is staged.
    NothingStaged,
    /// The parameter set failed validation.
    InvalidParams(InvalidParamsReason),
    /// Writing or erasing the parameter flash failed.
    FlashError,
}

impl ErrorCode {
    /// A sentence the host can print: the cause and what to try.
    pub fn describe(&self) -> &'static str {
        match self {
            Self::VersionMismatch { .. } => {
                "the device speaks a different protocol major version; update the firmware or the host tool so they match"
            }
            Self::UnknownRequest => {
                "the firmware does not know this request; it is older than the host tool, so update the firmware"
            }
            Self::Malformed => {
                "the device could not decode the request; check that nothing else is writing to the serial port"
            }
            Self::InvalidArgument => "a request argument is out of range; check the command's options",
            Self::Busy => {
                "the device is busy with another operation; wait for it to finish or stop the stream, then retry"
            }
            Self::SensorMissing => "the board has no such sensor; leave that sensor out of the command",
            Self::NotStill => {
                "the board was not held still long enough; rest it on a firm surface and retry"
            }
            Self::Timeout => "the operation timed out; retry, or allow a longer timeout",
            Self::Saturated => {
                "a sensor reached its full-scale limit; move more gently or away from magnets, then retry"
            }
            Self::CrcMismatch { .. } => {
                "the parameter set arrived damaged or changed; write it again"
            }
            Self::NothingStaged => "no parameter set is staged; write the parameters before committing",
            Self::InvalidParams(reason) => reason.describe(),
            Self::FlashError => {
                "writing the parameter flash failed; retry, and if it persists the flash may be worn or faulty"
            }
        }
    }
}

impl fmt::Display for ErrorCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::VersionMismatch {
                device_major,
                device_minor,
            } => write!(
                f,
                "device protocol {device_major}.{device_minor}: {}",
                self.describe()
            ),
            Self::CrcMismatch { received, computed } => write!(
                f,
                "CRC {received:#010x} sent, {computed:#010x} computed: {}",
                self.describe()
            ),
            Self::InvalidParams(reason) => write!(f, "parameter set refused: {reason}"),
            _ => f.write_str(self.describe()),
        }
    }
}

impl core::error::Error for ErrorCode {}
