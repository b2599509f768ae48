//! Transport: sequence ids, framing and sending of requests, and the read loop that decodes
//! frames, matches replies to the waiting request and dispatches events. Reads and writes never
//! wait past a deadline, whatever another program does to the port.

use std::io::{ErrorKind, Read, Write};
use std::time::{Duration, Instant};

use imucal_protocol::{
    encode_frame, DeviceMessage, Event, Request, RequestBody, ResponseBody, MAX_FRAME,
};

use super::{deadline_after, request_name, DeviceClient};
use crate::device::DeviceError;

impl<L: Read + Write> DeviceClient<L> {
    /// The next request's sequence id.
    pub(super) fn take_seq(&mut self) -> u16 {
        let seq = self.next_seq;
        self.next_seq = self.next_seq.wrapping_add(1);
        seq
    }

    /// Sends `body` up to `tries` times (same `seq`), waiting `timeout` for each; the flag
    /// says whether it was resent.
    pub(super) fn exchange(
        &mut self,
        body: &RequestBody,
        timeout: Duration,
        tries: u32,
    ) -> Result<(ResponseBody, bool), DeviceError> {
        let seq = self.take_seq();
        let tries = tries.max(1);
        let bad_before = self.stats.frame_errors;
        for attempt in 0..tries {
            if attempt > 0 {
                self.stats.retries += 1;
            }
            self.send_request(seq, body)?;
            if let Some(reply) = self.wait_reply(seq, deadline_after(timeout))? {
                return Ok((reply, attempt > 0));
            }
        }
        Err(self.why_no_answer(
            request_name(body),
            tries,
            self.stats.frame_errors.saturating_sub(bad_before),
        ))
    }

    pub(super) fn send_request(&mut self, seq: u16, body: &RequestBody) -> Result<(), DeviceError> {
        let mut frame = [0u8; MAX_FRAME];
        let request = Request {
            seq,
            body: body.clone(),
        };
        let len = encode_frame(&request, &mut frame).map_err(|cause| DeviceError::Encode {
            port: self.port.clone(),
            request: request_name(body),
            cause,
        })?;
        self.send_bytes(frame.get(..len).unwrap_or(&frame))
    }

    /// Writes all of `bytes`, waiting for room at most a reply timeout (the port is
    /// non-blocking, so a full buffer answers `WouldBlock` instead of stalling).
    pub(super) fn send_bytes(&mut self, bytes: &[u8]) -> Result<(), DeviceError> {
        let deadline = deadline_after(self.options.reply_timeout);
        let mut rest = bytes;
        while !rest.is_empty() {
            match self.link.write(rest) {
                Ok(0) => {
                    let cause = std::io::Error::new(ErrorKind::WriteZero, "the port took no bytes");
                    return Err(DeviceError::from_io(&self.port, cause));
                }
                Ok(n) => rest = rest.get(n..).unwrap_or_default(),
                Err(e) if is_transient(e.kind()) && Instant::now() < deadline => {
                    std::thread::sleep(Duration::from_millis(1));
                }
                Err(cause) => return Err(DeviceError::from_io(&self.port, cause)),
            }
        }
        self.link
            .flush()
            .map_err(|cause| DeviceError::from_io(&self.port, cause))
    }

    /// Reads until the reply with `seq` arrives (returned) or `deadline` passes (`None`).
    pub(super) fn wait_reply(
        &mut self,
        seq: u16,
        deadline: Instant,
    ) -> Result<Option<ResponseBody>, DeviceError> {
        loop {
            if let Some(reply) = self.pump(Some(seq), deadline)? {
                return Ok(Some(reply));
            }
            if Instant::now() >= deadline {
                return Ok(None);
            }
        }
    }

    /// Decodes buffered bytes, reading the link once when the buffer is empty. Returns the
    /// reply with `seq` if it completes; dispatches events; counts bad frames and stale
    /// replies. Returns after at most one read so callers can check their deadlines.
    pub(super) fn pump(
        &mut self,
        seq: Option<u16>,
        deadline: Instant,
    ) -> Result<Option<ResponseBody>, DeviceError> {
        if self.rx_pos >= self.rx.len() {
            self.rx.clear();
            self.rx_pos = 0;
            if !self.read_some(deadline)? {
                return Ok(None);
            }
        }
        while let Some(&byte) = self.rx.get(self.rx_pos) {
            self.rx_pos += 1;
            let message = match self.decoder.push(byte) {
                None => continue,
                Some(frame) => frame.and_then(imucal_protocol::decode_payload::<DeviceMessage>),
            };
            match message {
                Err(_) => self.stats.frame_errors += 1,
                Ok(DeviceMessage::Event(event)) => {
                    self.stats.good_frames += 1;
                    self.dispatch(event);
                }
                Ok(DeviceMessage::Response(response)) => {
                    self.stats.good_frames += 1;
                    if Some(response.seq) == seq {
                        return Ok(Some(response.body));
                    }
                    self.stats.stale_replies += 1;
                }
            }
        }
        Ok(None)
    }

    /// Reads one chunk from the link into the buffer; `false` when nothing arrived.
    fn read_some(&mut self, deadline: Instant) -> Result<bool, DeviceError> {
        let mut chunk = [0u8; 1024];
        match self.link.read(&mut chunk) {
            Ok(0) => {
                // Nothing now; avoid spinning on a link without a read timeout.
                if Instant::now() < deadline {
                    std::thread::sleep(Duration::from_millis(1));
                }
                Ok(false)
            }
            Ok(n) => {
                let bytes = chunk.get(..n).unwrap_or(&chunk);
                if !self.connected && self.heard.len() < super::HEARD_LIMIT {
                    let room = super::HEARD_LIMIT - self.heard.len();
                    self.heard
                        .extend_from_slice(bytes.get(..room.min(n)).unwrap_or(bytes));
                }
                self.rx.extend_from_slice(bytes);
                Ok(true)
            }
            Err(e) if is_transient(e.kind()) => Ok(false),
            Err(cause) => Err(DeviceError::from_io(&self.port, cause)),
        }
    }

    fn dispatch(&mut self, event: Event) {
        if let Event::StillnessChanged { still, .. } = event {
            self.still = Some(still);
        }
        if let Some(handler) = self.handler.as_mut() {
            handler(&event);
            return;
        }
        if self.events.len() >= self.options.event_queue_limit {
            self.events.pop_front();
            self.stats.dropped_events += 1;
        }
        self.events.push_back(event);
    }
}

/// Errors of a read or write that mean "nothing now, try again": a poll timeout, a
/// non-blocking port with nothing to read or no room, or a signal.
fn is_transient(kind: ErrorKind) -> bool {
    matches!(
        kind,
        ErrorKind::TimedOut | ErrorKind::WouldBlock | ErrorKind::Interrupted
    )
}
