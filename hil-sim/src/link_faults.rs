//! A fault-injecting serial link between the pseudo-terminal and the simulated board: byte drops
//! and bit flips at a per-byte rate, whole frames sent twice or held back, a board that speaks
//! another protocol major, and tampering with parameter sets in otherwise valid frames.
//!
//! Both directions go through a [`FaultyLink`]. Bytes are cut into frames at the COBS delimiter
//! (0); each complete frame first passes the protocol stage (version shim and parameter
//! tampering, which decode and re-encode valid frames), then the frame stage (duplicate with
//! probability `dup_rate`, hold back by `delay` with probability `delay_rate`; a held frame is
//! overtaken by later ones, as a late USB packet is), then the byte stage: each byte is dropped
//! with probability `drop_rate`, else one of its bits is flipped with probability `flip_rate`.
//! Every draw comes from one ChaCha8 stream per direction seeded from the board's seed, so the same
//! byte stream meets the same faults.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use imucal_protocol::{
    check_hello, encode_frame, CalibrationSet, DeviceMessage, ErrorCode, Event, FrameDecoder,
    LogLevel, LogMessage, ProtocolVersion, Request, RequestBody, Response, ResponseBody, MAX_FRAME,
    PROTOCOL_VERSION,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::error::SimError;

/// A frame longer than this without a delimiter is passed on as it is (it cannot be valid).
const MAX_PARTIAL: usize = 2 * MAX_FRAME;

/// Postcard variant index of `DeviceMessage::Response` (replies are decoded, events are not).
const RESPONSE_VARIANT: u8 = 0;

/// A change made to a parameter set inside a valid frame, standing for a corruption that frame
/// CRCs cannot catch (a faulty bridge, or a bit flipped in the board's memory).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ParamTamper {
    /// Flip bit `bit` (0…31) of `accel.a[0][0]` in every `WriteParams` and replace its CRC field
    /// by the changed set's CRC: the board stages a set the host did not send, and echoes its CRC.
    RestageFlipped {
        /// Bit of the `f32` to flip.
        bit: u8,
    },
    /// As [`Self::RestageFlipped`], and the `staged_crc` in the reply is rewritten to the CRC the
    /// host sent, so the echo looks right and only the board's commit check remains.
    RestageFlippedHideEcho {
        /// Bit of the `f32` to flip.
        bit: u8,
    },
    /// Flip bit `bit` of `accel.a[0][0]` in every `Params` reply (the read-back after a commit).
    FlipReadBack {
        /// Bit of the `f32` to flip.
        bit: u8,
    },
    /// From the first `CommitParams` the host sends, pass `skip` replies, then garble the next
    /// `lose` (their frames fail the host's check): answers lost in or after a commit that the
    /// board carried out.
    LoseRepliesAfterCommit {
        /// Replies passed intact first (0: the commit's own reply is lost).
        skip: u8,
        /// Replies garbled after those.
        lose: u8,
    },
}

/// Which faults a [`FaultyLink`] injects; [`LinkFaults::default`] injects none.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LinkFaults {
    /// Probability that a byte is lost, per byte and direction.
    pub drop_rate: f64,
    /// Probability that one bit of a byte is flipped, per byte and direction.
    pub flip_rate: f64,
    /// Probability that a frame is sent twice, per frame and direction.
    pub dup_rate: f64,
    /// Probability that a frame is held back by [`Self::delay`], per frame and direction.
    pub delay_rate: f64,
    /// How long a delayed frame is held back (wall time).
    pub delay: Duration,
    /// Close the pseudo-terminal this long (wall time) after the board starts serving.
    pub vanish_after: Option<Duration>,
    /// Speak this protocol major in the `Hello`/`Welcome` exchange instead of the firmware's own.
    pub protocol_major: Option<u16>,
    /// Tamper with parameter sets in valid frames.
    pub param_tamper: Option<ParamTamper>,
}

impl LinkFaults {
    /// Whether any fault or shim is switched on (otherwise the link is a plain pipe).
    pub fn is_active(&self) -> bool {
        self.drop_rate > 0.0
            || self.flip_rate > 0.0
            || self.dup_rate > 0.0
            || (self.delay_rate > 0.0 && !self.delay.is_zero())
            || self.vanish_after.is_some()
            || self
                .protocol_major
                .is_some_and(|m| m != PROTOCOL_VERSION.major)
            || self.param_tamper.is_some()
    }

    /// Check that every rate is a probability and every bit index fits an `f32`.
    pub fn validate(&self) -> Result<(), SimError> {
        for (name, rate) in [
            ("drop rate", self.drop_rate),
            ("flip rate", self.flip_rate),
            ("duplicate rate", self.dup_rate),
            ("delay rate", self.delay_rate),
        ] {
            if !(rate.is_finite() && (0.0..=1.0).contains(&rate)) {
                return Err(SimError::InvalidSetting {
                    name,
                    value: rate,
                    requirement: "a probability from 0 to 1",
                });
            }
        }
        if let Some(
            ParamTamper::RestageFlipped { bit }
            | ParamTamper::RestageFlippedHideEcho { bit }
            | ParamTamper::FlipReadBack { bit },
        ) = self.param_tamper
        {
            if bit > 31 {
                return Err(SimError::InvalidSetting {
                    name: "tampered bit",
                    value: f64::from(bit),
                    requirement: "a bit index of an f32, 0 to 31",
                });
            }
        }
        Ok(())
    }
}

/// Faults injected in one direction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DirectionStats {
    /// Complete frames that entered the link.
    pub frames: u64,
    /// Bytes dropped.
    pub bytes_dropped: u64,
    /// Bytes with a flipped bit.
    pub bits_flipped: u64,
    /// Frames sent twice.
    pub frames_duplicated: u64,
    /// Frames held back.
    pub frames_delayed: u64,
}

/// Faults injected so far.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FaultStats {
    /// From the host to the board.
    pub to_device: DirectionStats,
    /// From the board to the host.
    pub to_host: DirectionStats,
    /// `Hello`s answered with `VersionMismatch` by the version shim.
    pub hellos_refused: u64,
    /// Parameter sets or echoes changed by [`ParamTamper`].
    pub params_tampered: u64,
    /// Whether the port was closed on purpose.
    pub vanished: bool,
}

/// One direction: its random stream, the unfinished frame, held frames and bytes ready to go.
#[derive(Debug)]
struct Lane {
    rng: ChaCha8Rng,
    partial: Vec<u8>,
    held: Vec<(Instant, Vec<u8>)>,
    ready: VecDeque<u8>,
    stats: DirectionStats,
}

impl Lane {
    fn new(seed: u64) -> Self {
        Self {
            rng: ChaCha8Rng::seed_from_u64(seed),
            partial: Vec::new(),
            held: Vec::new(),
            ready: VecDeque::new(),
            stats: DirectionStats::default(),
        }
    }

    /// Bytes of complete frames cut from `bytes` (each ends with its delimiter); an unfinished
    /// frame stays for the next call.
    fn frames(&mut self, bytes: &[u8]) -> Vec<Vec<u8>> {
        let mut out = Vec::new();
        for &byte in bytes {
            self.partial.push(byte);
            if byte == 0 || self.partial.len() >= MAX_PARTIAL {
                out.push(std::mem::take(&mut self.partial));
            }
        }
        self.stats.frames += out.len() as u64;
        out
    }

    /// The frame and byte stages (see the module documentation).
    fn send(&mut self, frame: &[u8], faults: &LinkFaults, now: Instant) {
        let copies = if self.rng.gen_bool(faults.dup_rate) {
            self.stats.frames_duplicated += 1;
            2
        } else {
            1
        };
        for _ in 0..copies {
            let bytes = self.corrupt(frame, faults);
            if !faults.delay.is_zero() && self.rng.gen_bool(faults.delay_rate) {
                self.stats.frames_delayed += 1;
                self.held.push((now + faults.delay, bytes));
            } else {
                self.ready.extend(bytes);
            }
        }
    }

    fn corrupt(&mut self, frame: &[u8], faults: &LinkFaults) -> Vec<u8> {
        let mut out = Vec::with_capacity(frame.len());
        for &byte in frame {
            if self.rng.gen_bool(faults.drop_rate) {
                self.stats.bytes_dropped += 1;
            } else if self.rng.gen_bool(faults.flip_rate) {
                self.stats.bits_flipped += 1;
                out.push(byte ^ (1 << self.rng.gen_range(0..8)));
            } else {
                out.push(byte);
            }
        }
        out
    }

    /// Move held frames whose time has come to the ready bytes, then take them all.
    fn take(&mut self, now: Instant) -> Vec<u8> {
        let mut index = 0;
        while let Some((due, _)) = self.held.get(index) {
            if *due <= now {
                let (_, bytes) = self.held.remove(index);
                self.ready.extend(bytes);
            } else {
                index += 1;
            }
        }
        self.ready.drain(..).collect()
    }

    fn pending(&self) -> usize {
        self.ready.len() + self.held.iter().map(|(_, b)| b.len()).sum::<usize>()
    }
}

/// `frame` with one bit of a middle byte flipped (never into a delimiter), so that it fails
/// its check.
fn garbled(mut frame: Vec<u8>) -> Vec<u8> {
    let middle = frame.len() / 2;
    if let Some(byte) = frame.get_mut(middle) {
        *byte ^= if *byte == 0x10 { 0x20 } else { 0x10 };
    }
    frame
}

/// Payload of a complete frame (CRC checked), or `None` when it is not a valid frame.
fn payload_of(frame: &[u8]) -> Option<Vec<u8>> {
    let mut decoder = FrameDecoder::<MAX_FRAME>::new();
    let mut payload = None;
    for &byte in frame {
        if let Some(result) = decoder.push(byte) {
            payload = result.ok().map(<[u8]>::to_vec);
        }
    }
    payload
}

fn frame_of<T: serde::Serialize>(message: &T) -> Option<Vec<u8>> {
    let mut buffer = [0u8; MAX_FRAME];
    let len = encode_frame(message, &mut buffer).ok()?;
    buffer.get(..len).map(<[u8]>::to_vec)
}

fn flip_accel_bit(set: &mut CalibrationSet, bit: u8) {
    let value = &mut set.accel.a[0][0];
    *value = f32::from_bits(value.to_bits() ^ (1u32 << (bit & 31)));
}

/// The link with faults in both directions (see the module documentation).
#[derive(Debug)]
pub struct FaultyLink {
    faults: LinkFaults,
    to_device: Lane,
    to_host: Lane,
    hellos_refused: u64,
    params_tampered: u64,
    /// Seq and host CRC of tampered writes whose echo is to be rewritten.
    hidden_echoes: Vec<(u16, u32)>,
    /// Replies still to pass and then to garble, once a commit armed
    /// [`ParamTamper::LoseRepliesAfterCommit`].
    losing: Option<(u8, u8)>,
    /// Whether that tamper has been armed (it arms once).
    losing_armed: bool,
    notes: Vec<String>,
}

impl FaultyLink {
    /// A link injecting `faults`, its random streams derived from `seed`.
    pub fn new(faults: LinkFaults, seed: u64) -> Result<Self, SimError> {
        faults.validate()?;
        // Distinct constants keep the two directions' streams independent of each other and of
        // the board's own draws from `seed`.
        Ok(Self {
            faults,
            to_device: Lane::new(seed ^ 0x6c69_6e6b_2d74_6f64),
            to_host: Lane::new(seed ^ 0x6c69_6e6b_2d74_6f68),
            hellos_refused: 0,
            params_tampered: 0,
            hidden_echoes: Vec::new(),
            losing: None,
            losing_armed: false,
            notes: Vec::new(),
        })
    }

    /// The faults injected.
    pub fn faults(&self) -> &LinkFaults {
        &self.faults
    }

    /// Change the parameter tampering from now on (`None` stops it).
    pub fn set_param_tamper(&mut self, tamper: Option<ParamTamper>) {
        self.faults.param_tamper = tamper;
        self.losing = None;
        self.losing_armed = false;
    }

    /// Bytes from the host, at wall time `now`.
    pub fn push_from_host(&mut self, bytes: &[u8], now: Instant) {
        for frame in self.to_device.frames(bytes) {
            let frame = self.host_frame(frame, now);
            if let Some(frame) = frame {
                self.to_device.send(&frame, &self.faults, now);
            }
        }
    }

    /// Bytes from the board, at wall time `now`.
    pub fn push_from_device(&mut self, bytes: &[u8], now: Instant) {
        for frame in self.to_host.frames(bytes) {
            let frame = self.device_frame(frame);
            self.to_host.send(&frame, &self.faults, now);
        }
    }

    /// Bytes due for the board at `now`.
    pub fn take_for_device(&mut self, now: Instant) -> Vec<u8> {
        self.to_device.take(now)
    }

    /// Bytes due for the host at `now`.
    pub fn take_for_host(&mut self, now: Instant) -> Vec<u8> {
        self.to_host.take(now)
    }

    /// Bytes on their way to the host (ready or held back).
    pub fn pending_for_host(&self) -> usize {
        self.to_host.pending()
    }

    /// Faults injected so far.
    pub fn stats(&self) -> FaultStats {
        FaultStats {
            to_device: self.to_device.stats,
            to_host: self.to_host.stats,
            hellos_refused: self.hellos_refused,
            params_tampered: self.params_tampered,
            vanished: false,
        }
    }

    /// What the board side noticed (a refused `Hello`), as sentences, oldest first.
    pub fn take_notes(&mut self) -> Vec<String> {
        std::mem::take(&mut self.notes)
    }

    /// The protocol stage for a frame from the host: `None` when the shim answered it itself.
    fn host_frame(&mut self, frame: Vec<u8>, now: Instant) -> Option<Vec<u8>> {
        let speaks_other_major = self
            .faults
            .protocol_major
            .filter(|&major| major != PROTOCOL_VERSION.major);
        if speaks_other_major.is_none() && self.faults.param_tamper.is_none() {
            return Some(frame);
        }
        let Some(Ok(mut request)) =
            payload_of(&frame).map(|p| imucal_protocol::decode_payload::<Request>(&p))
        else {
            return Some(frame);
        };
        match (
            &mut request.body,
            speaks_other_major,
            self.faults.param_tamper,
        ) {
            (
                RequestBody::Hello {
                    protocol_major,
                    protocol_minor,
                },
                Some(major),
                _,
            ) => {
                let board = ProtocolVersion { major, minor: 0 };
                let host = ProtocolVersion {
                    major: *protocol_major,
                    minor: *protocol_minor,
                };
                match check_hello(board, host) {
                    Err(code) => {
                        self.refuse_hello(request.seq, board, host, code, now);
                        return None;
                    }
                    // A host of the board's major: the firmware underneath checks its own
                    // version, so hand it that one; its Welcome is rewritten on the way back.
                    Ok(_) => {
                        *protocol_major = PROTOCOL_VERSION.major;
                        *protocol_minor = PROTOCOL_VERSION.minor;
                    }
                }
            }
            (
                RequestBody::WriteParams { set, crc },
                _,
                Some(
                    ParamTamper::RestageFlipped { bit }
                    | ParamTamper::RestageFlippedHideEcho { bit },
                ),
            ) => {
                let host_crc = *crc;
                flip_accel_bit(set, bit);
                *crc = set.crc32();
                self.params_tampered += 1;
                if matches!(
                    self.faults.param_tamper,
                    Some(ParamTamper::RestageFlippedHideEcho { .. })
                ) {
                    self.hidden_echoes.push((request.seq, host_crc));
                }
            }
            (
                RequestBody::CommitParams { .. },
                _,
                Some(ParamTamper::LoseRepliesAfterCommit { skip, lose }),
            ) => {
                if !self.losing_armed {
                    self.losing_armed = true;
                    self.losing = Some((skip, lose));
                }
                return Some(frame);
            }
            _ => return Some(frame),
        }
        frame_of(&request).or(Some(frame))
    }

    fn refuse_hello(
        &mut self,
        seq: u16,
        board: ProtocolVersion,
        host: ProtocolVersion,
        code: ErrorCode,
        now: Instant,
    ) {
        self.hellos_refused += 1;
        let sentence = format!(
            "refused Hello: the host speaks imucal protocol {}.{}, this board speaks {}.{}",
            host.major, host.minor, board.major, board.minor
        );
        let log = DeviceMessage::Event(Event::Log(LogMessage::new(LogLevel::Error, &sentence)));
        let reply = DeviceMessage::Response(Response {
            seq,
            body: ResponseBody::Error(code),
        });
        for message in [log, reply] {
            if let Some(frame) = frame_of(&message) {
                self.to_host.send(&frame, &self.faults, now);
            }
        }
        self.notes.push(sentence);
    }

    /// The protocol stage for a frame from the board.
    fn device_frame(&mut self, frame: Vec<u8>) -> Vec<u8> {
        let welcome_major = self
            .faults
            .protocol_major
            .filter(|&major| major != PROTOCOL_VERSION.major);
        let rewrites_replies = welcome_major.is_some()
            || self.losing.is_some()
            || !self.hidden_echoes.is_empty()
            || matches!(
                self.faults.param_tamper,
                Some(ParamTamper::FlipReadBack { .. })
            );
        if !rewrites_replies {
            return frame;
        }
        let Some(payload) = payload_of(&frame) else {
            return frame;
        };
        if payload.first() != Some(&RESPONSE_VARIANT) {
            return frame;
        }
        let Ok(DeviceMessage::Response(mut response)) =
            imucal_protocol::decode_payload::<DeviceMessage>(&payload)
        else {
            return frame;
        };
        match self.losing {
            Some((skip, lose)) if skip > 0 => self.losing = Some((skip - 1, lose)),
            Some((_, lose)) if lose > 0 => {
                self.losing = Some((0, lose - 1));
                self.params_tampered += 1;
                return garbled(frame);
            }
            Some(_) => self.losing = None,
            None => {}
        }
        match (&mut response.body, welcome_major, self.faults.param_tamper) {
            (ResponseBody::Welcome(welcome), Some(major), _) => {
                welcome.protocol_major = major;
                welcome.protocol_minor = 0;
            }
            (ResponseBody::Params(set), _, Some(ParamTamper::FlipReadBack { bit })) => {
                flip_accel_bit(set, bit);
                self.params_tampered += 1;
            }
            (ResponseBody::ParamStatus(status), _, _) => {
                let seq = response.seq;
                let Some(index) = self.hidden_echoes.iter().position(|(s, _)| *s == seq) else {
                    return frame;
                };
                let (_, host_crc) = self.hidden_echoes.swap_remove(index);
                status.staged_crc = Some(host_crc);
            }
            _ => return frame,
        }
        frame_of(&DeviceMessage::Response(response)).unwrap_or(frame)
    }
}
