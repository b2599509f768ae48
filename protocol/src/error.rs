//! Local errors of framing and batching (the error replies carried on the wire are
//! [`crate::error_code::ErrorCode`]).

use core::fmt;

/// Why a received frame was dropped. The decoder resynchronises at the next delimiter.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FrameError {
    /// The frame was longer than the decoder's buffer (or a delimiter was lost).
    Overflow,
    /// The COBS encoding is invalid.
    Cobs,
    /// The frame is too short to hold a CRC.
    TooShort,
    /// The CRC does not match the payload.
    Crc,
    /// The payload is not a valid postcard encoding of the expected type.
    Decode,
}

impl fmt::Display for FrameError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Overflow => "frame longer than the receive buffer",
            Self::Cobs => "invalid COBS encoding",
            Self::TooShort => "frame shorter than its CRC",
            Self::Crc => "CRC mismatch",
            Self::Decode => "payload does not decode as the expected message",
        })
    }
}

impl core::error::Error for FrameError {}

/// Why a message could not be encoded into a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum EncodeError {
    /// The output buffer is too small for the encoded frame.
    BufferFull,
    /// The message cannot be serialised (a length is not known in advance, for example).
    Serialize,
}

impl fmt::Display for EncodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::BufferFull => "output buffer too small for the frame",
            Self::Serialize => "message cannot be serialised",
        })
    }
}

impl core::error::Error for EncodeError {}

/// Why a sample could not be added to a batch.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum BatchError {
    /// The batch holds its maximum number of samples.
    Full,
    /// The batch's tick is zero, so no time offset can be expressed.
    ZeroTick,
    /// The sample's time is before the batch's start time.
    BeforeStart,
    /// The sample's time is more than `u16::MAX` ticks after the batch's start time.
    SpanExceeded,
}

impl fmt::Display for BatchError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Full => "batch is full",
            Self::ZeroTick => "batch tick is zero",
            Self::BeforeStart => "sample time before batch start",
            Self::SpanExceeded => "sample time too far after batch start",
        })
    }
}

impl core::error::Error for BatchError {}
