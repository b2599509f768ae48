//! Errors of talking to a board. Every message is a sentence that names the port, says what
//! happened and what to try.

use imucal_protocol::{ErrorCode, InvalidParamsReason, ParamStatus, ProtocolVersion};

/// Why an operation on a board failed.
#[derive(Debug, thiserror::Error)]
pub enum DeviceError {
    /// The named serial port does not exist.
    #[error("no such port {port}; run `imucal ports` to list the serial ports")]
    NoSuchPort {
        /// The port as given.
        port: String,
    },
    /// Another program holds the port open exclusively.
    #[error("port {port} is in use by another program (close it, e.g. a serial monitor or another imucal), then retry")]
    PortBusy {
        /// The port as given.
        port: String,
    },
    /// The operating system refused access to the port.
    #[error("permission denied opening {port}; add your user to the group owning it (usually `dialout`) and log in again")]
    PermissionDenied {
        /// The port as given.
        port: String,
    },
    /// The port exists but could not be opened or configured.
    #[error("cannot open {port}: {detail}; check that it is a serial port with `imucal ports`")]
    Open {
        /// The port as given.
        port: String,
        /// The operating system's description.
        detail: String,
    },
    /// Listing the serial ports failed.
    #[error("cannot list the serial ports: {detail}; give the port explicitly with --port")]
    Enumerate {
        /// The operating system's description.
        detail: String,
    },
    /// No `--port` was given and no single board could be chosen.
    #[error("{reason}; give the port explicitly with --port (see `imucal ports`)")]
    NoPortChosen {
        /// Why no port was chosen (none found, or several candidates).
        reason: String,
    },
    /// Reading or writing the port failed after it was opened.
    #[error("lost the connection to {port} ({cause}); check the cable and that the board is powered, then retry")]
    Io {
        /// The port.
        port: String,
        /// The operating system's error.
        cause: std::io::Error,
    },
    /// The port disappeared while open: the board was unplugged, reset its USB interface, or
    /// the simulator serving it stopped.
    #[error(
        "the port {port} went away: the board was unplugged or reset; reconnect and run again"
    )]
    PortGone {
        /// The port.
        port: String,
        /// The operating system's error.
        cause: std::io::Error,
    },
    /// The board did not answer a request within its timeout, on every try. When frames that
    /// failed their check arrived meanwhile, the board is there and the link is noisy.
    #[error("{}", no_answer_text(.port, .request, .tries, .bad_frames))]
    NoAnswer {
        /// The port.
        port: String,
        /// The request that went unanswered.
        request: &'static str,
        /// How many times it was sent.
        tries: u32,
        /// Frames that arrived meanwhile and failed their check (CRC, framing).
        bad_frames: u64,
    },
    /// Contact was lost in or after a commit and the board's active set could not be read
    /// back with certainty: the new set may or may not be active.
    #[error("{}; {state}", interrupted_by(.cause))]
    WriteUnsettled {
        /// The port.
        port: String,
        /// What the board's status showed, as a sentence with what to do.
        state: String,
        /// The failure that interrupted the write.
        cause: Box<DeviceError>,
        /// Whether the board's status shows the new set active (its CRC and sequence), though
        /// its values could not be read back.
        committed: Option<ParamStatus>,
    },
    /// The board did not answer imucal's requests, but printed the text lines of a sketch for
    /// MotionCal (`Raw:`, `Uni:`, `Cal1:`/`Cal2:`): it runs such a sketch, not imucal's firmware.
    #[error(
        "{port} runs a MotionCal calibration sketch (it prints `{tag}` lines), not imucal's \
         firmware, so it has no id, parameters or commands to answer; for this board use \
         `imucal calibrate --port {port} --protocol motioncal` (calibrates it and sends the \
         packet), `imucal flash FILE --port {port} --protocol motioncal` (sends a saved \
         motioncal.bin or params.json), `imucal stream --port {port} --protocol motioncal`, \
         and `imucal export FILE --format motioncal -o cal.bin` (or `adafruit-json`) for the \
         sketch's library or `--format c-header` (rust, json) for your own code; or flash \
         imucal's firmware to the board"
    )]
    MotionCalSketch {
        /// The port.
        port: String,
        /// The first tag heard, e.g. `Raw:`.
        tag: &'static str,
    },
    /// The board did not answer, and the frames that did arrive failed their checks: the link
    /// loses or corrupts bytes.
    #[error(
        "no answer from {port} to {request} after {tries} tries, and {bad} of the {frames} frames \
         that arrived failed their check ({rate:.1} %): the serial link is noisy; try another \
         USB cable, plug the board in directly instead of through a hub, and check the baud rate \
         (115200)"
    )]
    NoisyLink {
        /// The port.
        port: String,
        /// The request that went unanswered.
        request: &'static str,
        /// How many times it was sent.
        tries: u32,
        /// Frames that failed their check.
        bad: u64,
        /// Frames that arrived, good and bad.
        frames: u64,
        /// `bad` as a percentage of `frames`.
        rate: f64,
    },
    /// The board speaks an incompatible protocol major version.
    #[error("{port} speaks imucal protocol {}.{}, this imucal speaks {}.{}; {advice}", .device.major, .device.minor, .host.major, .host.minor)]
    VersionMismatch {
        /// The port.
        port: String,
        /// The board's protocol version.
        device: ProtocolVersion,
        /// This tool's protocol version.
        host: ProtocolVersion,
        /// Which side to update.
        advice: &'static str,
    },
    /// The board answered with an error code.
    #[error("{port} refused {request}: {code}")]
    Device {
        /// The port.
        port: String,
        /// The request refused.
        request: &'static str,
        /// The board's error code (its `Display` says what to try).
        code: ErrorCode,
    },
    /// The set fails the protocol's validation for this board, so nothing was sent.
    #[error("not writing to {port}, which would refuse the set: {reason}")]
    InvalidParams {
        /// The port.
        port: String,
        /// Which field broke which bound.
        reason: InvalidParamsReason,
    },
    /// The board answered with a response of the wrong kind.
    #[error("{port} answered {request} with {answer}, which is not a valid answer; update the firmware and imucal to matching versions")]
    UnexpectedAnswer {
        /// The port.
        port: String,
        /// The request sent.
        request: &'static str,
        /// A short description of the answer.
        answer: String,
    },
    /// The board staged a parameter set whose CRC differs from the one sent; nothing was
    /// committed.
    #[error("{port} staged a parameter set with CRC {echoed} although {sent:#010x} was sent, so it was not committed; write it again (check the cable if this repeats)", echoed = fmt_crc(.echoed))]
    StagedCrcMismatch {
        /// The port.
        port: String,
        /// CRC computed on the host and sent.
        sent: u32,
        /// CRC the board reported as staged (`None`: nothing staged).
        echoed: Option<u32>,
    },
    /// The parameters read back after a commit differ from those written.
    #[error("the parameters read back from {port} after the commit differ from those written ({detail}); write them again, and if this repeats the board's flash may be faulty")]
    VerifyFailed {
        /// The port.
        port: String,
        /// What differs.
        detail: String,
    },
    /// A request could not be encoded into a frame (a defect, not a user error).
    #[error("the {request} request for {port} cannot be encoded ({cause}); this is a defect in imucal, please report it")]
    Encode {
        /// The port.
        port: String,
        /// The request.
        request: &'static str,
        /// The encoder's error.
        cause: imucal_protocol::EncodeError,
    },
}

fn no_answer_text(port: &str, request: &str, tries: &u32, bad_frames: &u64) -> String {
    if *bad_frames > 0 {
        format!(
            "no intact answer from {port} to {request} after {tries} tries: {bad_frames} \
             frame(s) arrived that failed their check, so the board is there and the link is \
             noisy; check the cable and connectors (a shorter or shielded cable, away from motors \
             and power lines), then retry"
        )
    } else {
        format!(
            "no answer from {port} to {request} after {tries} tries: is the board running imucal \
             firmware, and is this the right port (`imucal ports`)?"
        )
    }
}

/// What interrupted a write, for [`DeviceError::WriteUnsettled`]: a lost answer is stated
/// plainly, since the board was reached again and its counters say whether the link is to blame.
fn interrupted_by(cause: &DeviceError) -> String {
    match cause {
        DeviceError::NoAnswer {
            port,
            request,
            tries,
            ..
        } => format!("no answer from {port} to {request} after {tries} tries"),
        other => other.to_string(),
    }
}

fn fmt_crc(crc: &Option<u32>) -> String {
    match *crc {
        Some(crc) => format!("{crc:#010x}"),
        None => "none".to_string(),
    }
}

impl DeviceError {
    /// The board's error code, when the board refused a request.
    pub fn device_code(&self) -> Option<ErrorCode> {
        match self {
            Self::Device { code, .. } => Some(*code),
            _ => None,
        }
    }

    /// `Io` or `PortGone` for a failed read or write, by whether the error says the device is
    /// gone (hang-up, EIO, no such device) rather than a transient failure.
    pub(crate) fn from_io(port: &str, cause: std::io::Error) -> Self {
        // EIO, ENXIO, ENODEV: what Linux and macOS return on a removed tty or USB device.
        let gone_os_error = matches!(cause.raw_os_error(), Some(5 | 6 | 19));
        let gone_kind = matches!(
            cause.kind(),
            std::io::ErrorKind::BrokenPipe
                | std::io::ErrorKind::NotConnected
                | std::io::ErrorKind::UnexpectedEof
        );
        if gone_os_error || gone_kind {
            Self::PortGone {
                port: port.to_string(),
                cause,
            }
        } else {
            Self::Io {
                port: port.to_string(),
                cause,
            }
        }
    }

    /// A version-mismatch error with advice on which side to update.
    pub(crate) fn version_mismatch(port: &str, device: ProtocolVersion) -> Self {
        let host = imucal_protocol::PROTOCOL_VERSION;
        let advice = if device.major < host.major {
            "update the board's firmware"
        } else {
            "update imucal (the host tool)"
        };
        Self::VersionMismatch {
            port: port.to_string(),
            device,
            host,
            advice,
        }
    }
}
