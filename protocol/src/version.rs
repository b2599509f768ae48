//! Protocol and firmware version numbers and the compatibility rule applied at `Hello`.

use serde::{Deserialize, Serialize};

use crate::error_code::ErrorCode;

/// A protocol version: peers with the same `major` interoperate; `minor` only adds messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct ProtocolVersion {
    /// Incremented on any change that an older peer would decode wrongly.
    pub major: u16,
    /// Incremented when messages or enum variants are appended.
    pub minor: u16,
}

/// Major version of the protocol implemented by this crate.
/// 3: `ErrorCounters` gained the data-ready counters (repeated, missed, magnetometer repeats
/// and overruns), which an older peer would decode wrongly.
pub const PROTOCOL_MAJOR: u16 = 3;
/// Minor version of the protocol implemented by this crate.
/// 1: `InvalidParamsReason::MirroredAxes` appended.
pub const PROTOCOL_MINOR: u16 = 1;
/// The protocol version implemented by this crate.
pub const PROTOCOL_VERSION: ProtocolVersion = ProtocolVersion {
    major: PROTOCOL_MAJOR,
    minor: PROTOCOL_MINOR,
};

/// Version of the firmware running on a device (semantic versioning).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct FirmwareVersion {
    /// Major version.
    pub major: u16,
    /// Minor version.
    pub minor: u16,
    /// Patch level.
    pub patch: u16,
}

/// The compatibility rule, applied by both ends of the `Hello`/`Welcome` exchange.
///
/// The device calls it with its own version and the one in the host's `Hello`, and replies with
/// the error instead of `Welcome` on mismatch; the host calls it with the version in `Welcome`
/// (or meets the error reply). Versions are compatible when the majors are equal. On success the
/// result is the version both ends may use: the common major and the smaller minor, so neither
/// side sends a message the other cannot know. On mismatch the error carries the device's version
/// so the host can say which side to update.
pub fn check_hello(
    device: ProtocolVersion,
    host: ProtocolVersion,
) -> Result<ProtocolVersion, ErrorCode> {
    if device.major == host.major {
        Ok(ProtocolVersion {
            major: device.major,
            minor: device.minor.min(host.minor),
        })
    } else {
        Err(ErrorCode::VersionMismatch {
            device_major: device.major,
            device_minor: device.minor,
        })
    }
}
