//! Sensor feed: how a simulated or recorded world drives an emulated IMU, one frame per sample.
//!
//! A board without a real sensor (the QEMU board reads it on its UART1) receives [`FeedFrame`]s
//! in this crate's frame format (postcard, CRC-32, COBS, 0x00 delimiter; see [`crate::frame`]).
//! A `Scales` frame comes first (the emulated chip's configuration; the firmware waits for it at
//! boot as it would probe a chip), then one `Sample` frame per output-data-rate tick, stamped
//! with the simulated world time. Feeders (the simulator, `xtask`'s QEMU test) and the board
//! share this one definition. It is not part of the host ↔ device protocol and is versioned with
//! the crate, not by [`crate::PROTOCOL_VERSION`].

use serde::{Deserialize, Serialize};

use crate::{encode_frame, EncodeError, FrameDecoder, FrameError, RawSample, SensorScales};

/// One message of the sensor feed.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum FeedFrame {
    /// Configuration of the emulated chip: sensitivities, ranges and output data rate.
    Scales(SensorScales),
    /// One sample as the chip would produce it.
    Sample {
        /// Simulated world time at which the sample was taken, µs since the feed began.
        t_us: u64,
        /// The sample in chip counts.
        sample: RawSample,
    },
}

/// Largest encoded feed frame, delimiter included: a `Scales` frame is 1 tag byte + 9 × 4 bytes,
/// plus 4 CRC bytes, 1 COBS code byte and the delimiter (43); a `Sample` frame is at most
/// 1 + 10 (u64 varint) + 10 × 3 (i16 zigzag varints) + 4 + 1 + 1 = 47.
pub const MAX_FEED_FRAME: usize = 48;

/// Encodes `frame` into `out` (at least [`MAX_FEED_FRAME`] bytes); returns the bytes written.
pub fn encode(frame: &FeedFrame, out: &mut [u8]) -> Result<usize, EncodeError> {
    encode_frame(frame, out)
}

/// Reassembles [`FeedFrame`]s from the byte stream, one byte at a time.
#[derive(Debug, Clone, Default)]
pub struct FeedDecoder {
    frames: FrameDecoder<MAX_FEED_FRAME>,
}

impl FeedDecoder {
    /// An empty decoder, waiting for the start of a frame.
    pub const fn new() -> Self {
        Self {
            frames: FrameDecoder::new(),
        }
    }

    /// Takes one byte; when it ends a frame, returns the message or why the frame was dropped.
    pub fn push(&mut self, byte: u8) -> Option<Result<FeedFrame, FrameError>> {
        self.frames
            .push(byte)
            .map(|payload| payload.and_then(crate::decode_payload::<FeedFrame>))
    }
}
