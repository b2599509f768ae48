//! The board's serial link in memory: the firmware reads and writes it through embedded-io, the
//! outside (a test or the pseudo-terminal pump) through [`LinkEnd`].
//!
//! Like a UART transmitter the link never blocks: when the outgoing buffer holds
//! [`TX_BUFFER_LIMIT`] bytes nobody has taken, a further message is refused whole (the firmware
//! counts it as dropped), so frames are never torn. Both directions are also decoded on the side
//! to observe pose captures, which is how the simulated person knows when a pose was taken.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};

use embedded_io::{ErrorKind, ErrorType, Read, ReadReady, Write};
use imucal_protocol::{
    DeviceMessage, FrameDecoder, PoseStats, Request, RequestBody, ResponseBody, MAX_FRAME,
};

/// Largest number of bytes waiting to leave the board before messages are dropped (64 KiB,
/// about 23 s of raw streaming at 119 Hz and 23.5 bytes per sample).
pub const TX_BUFFER_LIMIT: usize = 64 * 1024;

/// Postcard variant index of `DeviceMessage::Response`.
const RESPONSE_VARIANT: u8 = 0;

/// What has been seen on the link since the board was built (counts survive reboots).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LinkObservations {
    /// `CapturePose` requests that reached the firmware.
    pub capture_requests: u64,
    /// `PoseStats` replies the firmware sent.
    pub poses_captured: u64,
    /// `StartStream` requests that reached the firmware.
    pub stream_starts: u64,
    /// `StopStream` requests that reached the firmware.
    pub stream_stops: u64,
    /// Whether the last stream request was a start: a stop sent while no stream runs (hosts
    /// send one to be sure) leaves the counts unbalanced but this false.
    pub streaming: bool,
    /// The latest `PoseStats` sent.
    pub last_pose: Option<PoseStats>,
    /// Bytes the firmware took from the host.
    pub bytes_to_device: u64,
    /// Bytes the firmware sent to the host.
    pub bytes_from_device: u64,
    /// Messages refused because the outgoing buffer was full.
    pub messages_refused: u64,
}

#[derive(Debug)]
struct Buffers {
    to_device: VecDeque<u8>,
    from_device: VecDeque<u8>,
    request_decoder: FrameDecoder<MAX_FRAME>,
    reply_decoder: FrameDecoder<MAX_FRAME>,
    observed: LinkObservations,
}

/// Both ends of the in-memory link share these buffers.
#[derive(Debug, Clone)]
struct Shared(Arc<Mutex<Buffers>>);

impl Shared {
    fn lock(&self) -> MutexGuard<'_, Buffers> {
        // A panic elsewhere cannot leave the byte queues inconsistent; keep using them.
        self.0.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// The firmware's side of the link (embedded-io `Read + ReadReady + Write`).
#[derive(Debug, Clone)]
pub struct DeviceLink {
    shared: Shared,
}

/// The outside side of the link: bytes for the firmware go in, its bytes come out.
#[derive(Debug, Clone)]
pub struct LinkEnd {
    shared: Shared,
}

/// A new link, as its firmware side and its outside end.
pub fn link_pair() -> (DeviceLink, LinkEnd) {
    let shared = Shared(Arc::new(Mutex::new(Buffers {
        to_device: VecDeque::new(),
        from_device: VecDeque::new(),
        request_decoder: FrameDecoder::new(),
        reply_decoder: FrameDecoder::new(),
        observed: LinkObservations::default(),
    })));
    (
        DeviceLink {
            shared: shared.clone(),
        },
        LinkEnd { shared },
    )
}

impl LinkEnd {
    /// Queue bytes for the firmware (what the host sends).
    pub fn send_to_device(&self, bytes: &[u8]) {
        self.shared.lock().to_device.extend(bytes);
    }

    /// Take every byte the firmware has sent.
    pub fn take_from_device(&self) -> Vec<u8> {
        self.shared.lock().from_device.drain(..).collect()
    }

    /// Number of bytes the firmware has sent that nobody has taken yet.
    pub fn pending_from_device(&self) -> usize {
        self.shared.lock().from_device.len()
    }

    /// Copy up to `out.len()` waiting bytes from the firmware into `out` without removing them.
    pub fn peek_from_device(&self, out: &mut [u8]) -> usize {
        let buffers = self.shared.lock();
        let mut count = 0;
        for (slot, &byte) in out.iter_mut().zip(buffers.from_device.iter()) {
            *slot = byte;
            count += 1;
        }
        count
    }

    /// Remove `count` bytes (or all, if fewer wait) from the firmware's output.
    pub fn consume_from_device(&self, count: usize) {
        let mut buffers = self.shared.lock();
        let count = count.min(buffers.from_device.len());
        buffers.from_device.drain(..count);
    }

    /// Drop everything the firmware has sent after the first `keep` waiting bytes (used when
    /// power fails in the middle of a turn of the main loop: those bytes never left the board).
    pub fn truncate_from_device(&self, keep: usize) {
        self.shared.lock().from_device.truncate(keep);
    }

    /// Discard bytes not yet read by the firmware and any half-received frames, as a reset does
    /// to a UART's receive FIFO.
    pub fn reset_receiver(&self) {
        let mut buffers = self.shared.lock();
        buffers.to_device.clear();
        buffers.request_decoder.reset();
    }

    /// What has been observed so far.
    pub fn observations(&self) -> LinkObservations {
        self.shared.lock().observed
    }
}

impl ErrorType for DeviceLink {
    type Error = ErrorKind;
}

impl ReadReady for DeviceLink {
    fn read_ready(&mut self) -> Result<bool, Self::Error> {
        Ok(!self.shared.lock().to_device.is_empty())
    }
}

impl Read for DeviceLink {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
        let mut guard = self.shared.lock();
        let buffers = &mut *guard;
        let count = buf.len().min(buffers.to_device.len());
        for (slot, byte) in buf.iter_mut().zip(buffers.to_device.drain(..count)) {
            *slot = byte;
            if let Some(Ok(payload)) = buffers.request_decoder.push(byte) {
                match imucal_protocol::decode_payload::<Request>(payload) {
                    Ok(Request {
                        body: RequestBody::CapturePose { .. },
                        ..
                    }) => buffers.observed.capture_requests += 1,
                    Ok(Request {
                        body: RequestBody::StartStream { .. },
                        ..
                    }) => {
                        buffers.observed.stream_starts += 1;
                        buffers.observed.streaming = true;
                    }
                    Ok(Request {
                        body: RequestBody::StopStream,
                        ..
                    }) => {
                        buffers.observed.stream_stops += 1;
                        buffers.observed.streaming = false;
                    }
                    _ => {}
                }
            }
        }
        buffers.observed.bytes_to_device += count as u64;
        Ok(count)
    }
}

impl Write for DeviceLink {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        let mut guard = self.shared.lock();
        let buffers = &mut *guard;
        if buffers.from_device.len() + buf.len() > TX_BUFFER_LIMIT {
            buffers.observed.messages_refused += 1;
            return Err(ErrorKind::OutOfMemory);
        }
        buffers.from_device.extend(buf);
        buffers.observed.bytes_from_device += buf.len() as u64;
        for &byte in buf {
            if let Some(Ok(payload)) = buffers.reply_decoder.push(byte) {
                // Postcard's first byte is the variant; skip decoding the many event frames.
                if payload.first() != Some(&RESPONSE_VARIANT) {
                    continue;
                }
                if let Ok(DeviceMessage::Response(response)) =
                    imucal_protocol::decode_payload::<DeviceMessage>(payload)
                {
                    if let ResponseBody::PoseStats(stats) = response.body {
                        buffers.observed.poses_captured += 1;
                        buffers.observed.last_pose = Some(stats);
                    }
                }
            }
        }
        Ok(buf.len())
    }

    fn flush(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}
