//! The device: one `poll()` per main-loop turn samples the IMU on schedule, tracks stillness,
//! runs pose captures and streams, and answers every protocol request.
//!
//! The link is embedded-io 0.6 `Read + ReadReady + Write`. Reading only after `read_ready()`
//! says so keeps `poll()` from ever blocking on input. Writes use `write_all`, which may wait for
//! the transmitter: a full 512-byte frame takes 5.6 ms at 921 600 Bd and far less over USB, inside
//! one sample period at the rates this firmware targets; a link error drops the message and is
//! counted, it never stops the loop.

use embedded_io::{Read, ReadReady, Write};
use embedded_storage::nor_flash::NorFlash;
use imucal_protocol::{
    check_hello, encode_frame, BatchError, BatchHeader, CalibratedBatch, CalibrationSet, DeviceId,
    DeviceMessage, DeviceStatus, ErrorCode, ErrorCounters, Event, FirmwareVersion, FrameDecoder,
    ParamStatus, ProtocolVersion, Request, RequestBody, Response, ResponseBody, SampleBatch,
    SensorSet, StillThresholds, StreamKind, Welcome, MAX_FRAME, PARAMS_MAX_ENCODED,
    PROTOCOL_VERSION, RAW_BATCH_CAPACITY,
};

use crate::apply::Correction;
use crate::imu::{Imu, RawSample, SensorScales};
use crate::pose::{PoseCapture, PoseConfig, PoseFailure, PoseState};
use crate::sampling::ConversionTracker;
use crate::stillness::{StillnessDetector, StillnessThresholds};
use crate::store::ParamStore;

/// A monotonic microsecond clock (e.g. a 32-bit timer extended to 64 bits by the board).
pub trait Clock {
    /// Microseconds since an arbitrary start; never decreases.
    fn now_us(&mut self) -> u64;
}

/// Largest number of received bytes handled per `poll()`, so a flood cannot starve sampling.
const MAX_RX_BYTES_PER_POLL: usize = 256;

/// Who the device is; given by the board.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DeviceInfo {
    /// Unique id of this board (e.g. the MCU's UID).
    pub device_id: DeviceId,
    /// Version of the board firmware.
    pub firmware_version: FirmwareVersion,
    /// Sensors fitted.
    pub sensors: SensorSet,
}

/// Why a [`Device`] could not be built.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DeviceError {
    /// The IMU reports a sample rate the scheduler cannot use.
    InvalidSampleRate(f32),
}

impl core::fmt::Display for DeviceError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::InvalidSampleRate(rate) => write!(
                f,
                "the IMU reports a sample rate of {rate} Hz; configure the driver for a rate between 1 Hz and 100 kHz"
            ),
        }
    }
}

/// A running stream and its batch being filled.
enum Stream {
    Raw(SampleBatch),
    Calibrated(CalibratedBatch),
}

struct StreamState {
    decimation: u16,
    /// Samples since the stream started, for decimation.
    seen: u32,
    /// Samples emitted so far (the next batch's `first_index`).
    emitted: u32,
    /// Batch started (its header's `t0_us` is set from its first sample).
    batch: Stream,
}

/// The firmware core: IMU `I`, byte link `L`, parameter flash `F`, clock `C`, and a stillness
/// window of `W` samples.
pub struct Device<I: Imu, L, F: NorFlash, C: Clock, const W: usize = 64> {
    imu: I,
    link: L,
    store: ParamStore<F>,
    clock: C,
    info: DeviceInfo,
    scales: SensorScales,
    period_us: u64,
    next_sample_us: u64,
    conversions: ConversionTracker,
    boot_us: u64,
    stillness: StillnessDetector<W>,
    still: bool,
    pose: PoseCapture,
    /// Sequence id of the `CapturePose` request being served.
    pose_seq: Option<u16>,
    stream: Option<StreamState>,
    decoder: FrameDecoder<MAX_FRAME>,
    active: CalibrationSet,
    active_crc: u32,
    active_seq: u32,
    correction: Correction,
    staged: Option<(CalibrationSet, u32)>,
    errors: ErrorCounters,
}

impl<I, L, F, C, const W: usize> Device<I, L, F, C, W>
where
    I: Imu,
    L: Read + ReadReady + Write,
    F: NorFlash,
    C: Clock,
{
    /// Build the device and load the stored parameter set.
    ///
    /// A stored set that does not decode or fails validation is ignored: the device starts on
    /// the identity set and reports active sequence 0.
    pub fn new(
        imu: I,
        link: L,
        mut store: ParamStore<F>,
        mut clock: C,
        info: DeviceInfo,
    ) -> Result<Self, DeviceError> {
        let scales = imu.scales();
        let rate = scales.sample_rate_hz;
        if !(1.0..=100_000.0).contains(&rate) {
            return Err(DeviceError::InvalidSampleRate(rate));
        }
        // In range, so the rounding cast is exact enough and cannot overflow.
        let period_us = (1.0e6 / rate + 0.5) as u64;
        let (active, active_seq, correction) = load_active(&mut store, &scales);
        let now = clock.now_us();
        Ok(Self {
            imu,
            link,
            store,
            clock,
            info,
            scales,
            period_us,
            next_sample_us: now,
            conversions: ConversionTracker::new(),
            boot_us: now,
            stillness: StillnessDetector::new(StillnessThresholds::default()),
            still: false,
            pose: PoseCapture::new(),
            pose_seq: None,
            stream: None,
            decoder: FrameDecoder::new(),
            active_crc: active.crc32(),
            active,
            active_seq,
            correction,
            staged: None,
            errors: ErrorCounters::default(),
        })
    }

    /// The active parameter set.
    pub fn active_params(&self) -> &CalibrationSet {
        &self.active
    }

    /// Problems seen since power-up.
    pub fn error_counters(&self) -> ErrorCounters {
        self.errors
    }

    /// Give back the parts (e.g. the flash, to simulate a reboot).
    pub fn into_parts(self) -> (I, L, ParamStore<F>, C) {
        (self.imu, self.link, self.store, self.clock)
    }

    /// One turn of the main loop: handle received bytes, take a sample when one is due, end a
    /// pose capture whose deadline passed. Never blocks on input.
    pub fn poll(&mut self) {
        self.receive();
        let now = self.clock.now_us();
        if now >= self.next_sample_us {
            self.next_sample_us = self.next_sample_us.saturating_add(self.period_us);
            if self.next_sample_us <= now {
                // Fell behind by more than a period: resynchronise instead of bursting.
                self.next_sample_us = now.saturating_add(self.period_us);
            }
            match self.imu.read_with_status() {
                Ok(reading) => {
                    let verdict = self.conversions.account(
                        reading.new_data,
                        now,
                        self.period_us,
                        &mut self.errors,
                    );
                    if verdict.use_sample {
                        self.on_sample(&reading.sample, verdict.mag_is_new, now);
                    }
                }
                Err(_) => {
                    self.errors.sensor_errors = self.errors.sensor_errors.saturating_add(1);
                    crate::log::log_warn!("IMU read failed");
                }
            }
        }
        let state = self.pose.check_deadline(now);
        self.finish_pose(state);
    }

    fn receive(&mut self) {
        let mut buffer = [0u8; 64];
        let mut handled = 0;
        while handled < MAX_RX_BYTES_PER_POLL {
            match self.link.read_ready() {
                Ok(true) => {}
                Ok(false) | Err(_) => return,
            }
            let count = match self.link.read(&mut buffer) {
                Ok(0) | Err(_) => return,
                Ok(count) => count.min(buffer.len()),
            };
            handled += count;
            for &byte in buffer.iter().take(count) {
                let incoming = match self.decoder.push(byte) {
                    None => continue,
                    Some(Err(_)) => Incoming::Garbled,
                    Some(Ok(payload)) => {
                        match imucal_protocol::decode_payload::<Request>(payload) {
                            Ok(request) => Incoming::Request(request),
                            Err(_) => Request::peek_seq(payload)
                                .map_or(Incoming::Garbled, Incoming::Unknown),
                        }
                    }
                };
                match incoming {
                    Incoming::Request(request) => self.handle(request),
                    Incoming::Unknown(seq) => {
                        self.errors.rx_frame_errors = self.errors.rx_frame_errors.saturating_add(1);
                        self.respond(seq, ResponseBody::Error(ErrorCode::UnknownRequest));
                    }
                    Incoming::Garbled => {
                        self.errors.rx_frame_errors = self.errors.rx_frame_errors.saturating_add(1);
                    }
                }
            }
        }
    }

    fn handle(&mut self, request: Request) {
        let seq = request.seq;
        let body = match request.body {
            RequestBody::Hello {
                protocol_major,
                protocol_minor,
            } => {
                let host = ProtocolVersion {
                    major: protocol_major,
                    minor: protocol_minor,
                };
                match check_hello(PROTOCOL_VERSION, host) {
                    Ok(_) => ResponseBody::Welcome(Welcome {
                        protocol_major: PROTOCOL_VERSION.major,
                        protocol_minor: PROTOCOL_VERSION.minor,
                        firmware_version: self.info.firmware_version,
                        device_id: self.info.device_id,
                        sensors: self.info.sensors,
                        scales: self.scales,
                    }),
                    Err(code) => ResponseBody::Error(code),
                }
            }
            RequestBody::Ping(value) => ResponseBody::Pong(value),
            RequestBody::Status => ResponseBody::Status(DeviceStatus {
                uptime_ms: self.clock.now_us().saturating_sub(self.boot_us) / 1000,
                streaming: self.stream.as_ref().map(|s| match s.batch {
                    Stream::Raw(_) => StreamKind::Raw,
                    Stream::Calibrated(_) => StreamKind::Calibrated,
                }),
                still: self.still,
                active_crc: self.active_crc,
                active_seq: self.active_seq,
                errors: self.errors,
            }),
            RequestBody::StartStream { kind, decimation } => self.start_stream(kind, decimation),
            RequestBody::StopStream => {
                self.flush_stream();
                self.stream = None;
                ResponseBody::Ack
            }
            RequestBody::CapturePose {
                min_still_ms,
                thresholds,
                timeout_ms,
            } => match self.start_pose(min_still_ms, thresholds, timeout_ms) {
                // The answer follows when the capture ends.
                Ok(()) => {
                    self.pose_seq = Some(seq);
                    return;
                }
                Err(code) => ResponseBody::Error(code),
            },
            RequestBody::GetParams => ResponseBody::Params(self.active),
            RequestBody::WriteParams { set, crc } => self.stage(set, crc),
            RequestBody::CommitParams { crc } => self.commit(crc),
            RequestBody::ResetParams => match self.activate(CalibrationSet::identity()) {
                Ok(()) => {
                    self.staged = None;
                    self.param_status()
                }
                Err(code) => ResponseBody::Error(code),
            },
        };
        self.respond(seq, body);
    }

    fn start_stream(&mut self, kind: StreamKind, decimation: u16) -> ResponseBody {
        if decimation == 0 {
            return ResponseBody::Error(ErrorCode::InvalidArgument);
        }
        self.flush_stream();
        let header = BatchHeader {
            first_index: 0,
            t0_us: 0,
            tick_us: self.tick_us(decimation),
        };
        self.stream = Some(StreamState {
            decimation,
            seen: 0,
            emitted: 0,
            batch: match kind {
                StreamKind::Raw => Stream::Raw(SampleBatch::new(header)),
                StreamKind::Calibrated => Stream::Calibrated(CalibratedBatch::new(header)),
            },
        });
        ResponseBody::Ack
    }

    /// Tick for batch time offsets: the finest that lets a full batch span fit the `u16` offset,
    /// with 50 % headroom for timing jitter.
    fn tick_us(&self, decimation: u16) -> u32 {
        let span = self
            .period_us
            .saturating_mul(u64::from(decimation))
            .saturating_mul(RAW_BATCH_CAPACITY as u64);
        let tick = (span.saturating_mul(3) / 2)
            .div_ceil(u64::from(u16::MAX))
            .max(1);
        u32::try_from(tick).unwrap_or(u32::MAX)
    }

    fn start_pose(
        &mut self,
        min_still_ms: u32,
        thresholds: StillThresholds,
        timeout_ms: u32,
    ) -> Result<(), ErrorCode> {
        if self.pose_seq.is_some() {
            return Err(ErrorCode::Busy);
        }
        let usable = |limit: f32| limit.is_finite() && limit > 0.0;
        if !usable(thresholds.accel_std_mps2) || !usable(thresholds.gyro_std_rads) {
            return Err(ErrorCode::InvalidArgument);
        }
        if !(self.info.sensors.accel && self.info.sensors.gyro) {
            return Err(ErrorCode::SensorMissing);
        }
        self.stillness.set_thresholds(StillnessThresholds {
            accel_std_mps2: thresholds.accel_std_mps2,
            gyro_std_rads: thresholds.gyro_std_rads,
        });
        let samples = (u64::from(min_still_ms) * 1000)
            .div_ceil(self.period_us)
            .max(1);
        let config = PoseConfig {
            samples: u32::try_from(samples).unwrap_or(u32::MAX),
            timeout_us: u64::from(timeout_ms) * 1000,
        };
        let now = self.clock.now_us();
        self.pose.start(config, &self.scales, now);
        Ok(())
    }

    fn finish_pose(&mut self, state: PoseState) {
        let (Some(seq), PoseState::Done(_) | PoseState::Failed(_)) = (self.pose_seq, state) else {
            return;
        };
        let body = match self.pose.take_outcome() {
            Some(Ok(stats)) => ResponseBody::PoseStats(stats),
            Some(Err(failure)) => {
                crate::log::log_info!("pose capture failed: {}", failure);
                ResponseBody::Error(match failure {
                    PoseFailure::NotStill => ErrorCode::NotStill,
                    PoseFailure::Timeout => ErrorCode::Timeout,
                    PoseFailure::Saturated => ErrorCode::Saturated,
                })
            }
            None => return,
        };
        self.pose_seq = None;
        self.respond(seq, body);
    }

    fn stage(&mut self, set: CalibrationSet, crc: u32) -> ResponseBody {
        let computed = set.crc32();
        if computed != crc {
            return ResponseBody::Error(ErrorCode::CrcMismatch {
                received: crc,
                computed,
            });
        }
        if let Err(reason) = Correction::new(&set, &self.scales) {
            return ResponseBody::Error(ErrorCode::InvalidParams(reason));
        }
        self.staged = Some((set, crc));
        self.param_status()
    }

    fn commit(&mut self, crc: u32) -> ResponseBody {
        let Some((set, staged_crc)) = self.staged else {
            return ResponseBody::Error(ErrorCode::NothingStaged);
        };
        if staged_crc != crc {
            return ResponseBody::Error(ErrorCode::CrcMismatch {
                received: crc,
                computed: staged_crc,
            });
        }
        match self.activate(set) {
            Ok(()) => {
                self.staged = None;
                self.param_status()
            }
            // The staged set stays, so the host may retry the commit.
            Err(code) => ResponseBody::Error(code),
        }
    }

    /// Validate, store power-safely, then switch the hot path to `set`; on any failure the
    /// previous set stays active.
    fn activate(&mut self, set: CalibrationSet) -> Result<(), ErrorCode> {
        let correction = Correction::new(&set, &self.scales).map_err(ErrorCode::InvalidParams)?;
        let mut encoded = [0u8; PARAMS_MAX_ENCODED];
        // Cannot fail: PARAMS_MAX_ENCODED bounds every set's encoding.
        let bytes = postcard::to_slice(&set, &mut encoded).map_err(|_| ErrorCode::FlashError)?;
        match self.store.write(bytes) {
            Ok(sequence) => {
                self.active = set;
                self.active_crc = set.crc32();
                self.active_seq = sequence;
                self.correction = correction;
                Ok(())
            }
            Err(_) => {
                self.errors.flash_errors = self.errors.flash_errors.saturating_add(1);
                crate::log::log_error!("parameter store write failed");
                Err(ErrorCode::FlashError)
            }
        }
    }

    fn param_status(&self) -> ResponseBody {
        ResponseBody::ParamStatus(ParamStatus {
            active_crc: self.active_crc,
            active_seq: self.active_seq,
            staged_crc: self.staged.map(|(_, crc)| crc),
        })
    }

    fn on_sample(&mut self, sample: &RawSample, mag_is_new: bool, now: u64) {
        self.stillness.push(sample);
        let still = self.stillness.is_still(&self.scales);
        if still != self.still {
            self.still = still;
            let t_ms = now.saturating_sub(self.boot_us) / 1000;
            self.send(&DeviceMessage::Event(Event::StillnessChanged {
                still,
                t_ms,
            }));
        }
        let state = self
            .pose
            .update_reading(sample, mag_is_new, still, now, &self.scales);
        self.finish_pose(state);
        self.stream_sample(sample, now);
    }

    fn stream_sample(&mut self, sample: &RawSample, now: u64) {
        let Some(stream) = self.stream.as_mut() else {
            return;
        };
        let take = stream.seen % u32::from(stream.decimation) == 0;
        stream.seen = stream.seen.wrapping_add(1);
        if !take {
            return;
        }
        let calibrated = self.correction.apply(sample);
        // A sample that does not fit (full, or beyond the batch's time span) closes the batch.
        for _ in 0..2 {
            let Some(stream) = self.stream.as_mut() else {
                return;
            };
            if batch_is_empty(&stream.batch) {
                let first_index = stream.emitted;
                set_header(&mut stream.batch, first_index, now);
            }
            let pushed = match &mut stream.batch {
                Stream::Raw(batch) => batch.push(sample, now),
                Stream::Calibrated(batch) => batch.push(&calibrated, now),
            };
            match pushed {
                Ok(()) => {
                    stream.emitted = stream.emitted.wrapping_add(1);
                    if batch_is_full(&stream.batch) {
                        self.flush_stream();
                    }
                    return;
                }
                Err(BatchError::Full | BatchError::SpanExceeded) => self.flush_stream(),
                Err(_) => break,
            }
        }
        self.errors.dropped_samples = self.errors.dropped_samples.saturating_add(1);
    }

    /// Send the partly filled batch, if any, and start an empty one.
    fn flush_stream(&mut self) {
        let Some(stream) = self.stream.as_mut() else {
            return;
        };
        if batch_is_empty(&stream.batch) {
            return;
        }
        let (message, lost) = match &stream.batch {
            Stream::Raw(batch) => (
                DeviceMessage::Event(Event::SampleBatch(batch.clone())),
                batch.len(),
            ),
            Stream::Calibrated(batch) => (
                DeviceMessage::Event(Event::CalibratedBatch(batch.clone())),
                batch.len(),
            ),
        };
        let header = match &stream.batch {
            Stream::Raw(batch) => *batch.header(),
            Stream::Calibrated(batch) => *batch.header(),
        };
        match &mut stream.batch {
            Stream::Raw(batch) => batch.reset(header),
            Stream::Calibrated(batch) => batch.reset(header),
        }
        if !self.send(&message) {
            let lost = u32::try_from(lost).unwrap_or(u32::MAX);
            self.errors.dropped_samples = self.errors.dropped_samples.saturating_add(lost);
        }
    }

    fn respond(&mut self, seq: u16, body: ResponseBody) {
        self.send(&DeviceMessage::Response(Response { seq, body }));
    }

    /// Frame and write one message; `false` when it could not be sent.
    fn send(&mut self, message: &DeviceMessage) -> bool {
        let mut frame = [0u8; MAX_FRAME];
        let Ok(len) = encode_frame(message, &mut frame) else {
            crate::log::log_error!("message does not fit a frame");
            return false;
        };
        let Some(bytes) = frame.get(..len) else {
            return false;
        };
        self.link.write_all(bytes).is_ok() && self.link.flush().is_ok()
    }
}

/// A completed incoming frame, decoded as far as possible.
// Without a heap there is nothing to box the request into; it lives briefly on the stack.
#[allow(clippy::large_enum_variant)]
enum Incoming {
    Request(Request),
    /// Decoded up to its sequence id only: a request kind this firmware does not know.
    Unknown(u16),
    /// Corrupt frame (COBS, CRC, overflow) or undecodable payload.
    Garbled,
}

fn batch_is_empty(batch: &Stream) -> bool {
    match batch {
        Stream::Raw(batch) => batch.is_empty(),
        Stream::Calibrated(batch) => batch.is_empty(),
    }
}

fn batch_is_full(batch: &Stream) -> bool {
    match batch {
        Stream::Raw(batch) => batch.is_full(),
        Stream::Calibrated(batch) => batch.is_full(),
    }
}

fn set_header(batch: &mut Stream, first_index: u32, t0_us: u64) {
    match batch {
        Stream::Raw(batch) => {
            let tick_us = batch.header().tick_us;
            batch.reset(BatchHeader {
                first_index,
                t0_us,
                tick_us,
            });
        }
        Stream::Calibrated(batch) => {
            let tick_us = batch.header().tick_us;
            batch.reset(BatchHeader {
                first_index,
                t0_us,
                tick_us,
            });
        }
    }
}

/// The newest stored set that decodes and validates (an older one when the newest no longer
/// does), else the identity (sequence 0).
fn load_active<F: NorFlash>(
    store: &mut ParamStore<F>,
    scales: &SensorScales,
) -> (CalibrationSet, u32, Correction) {
    let mut buffer = [0u8; PARAMS_MAX_ENCODED];
    let stored = store.load_newest(&mut buffer, |bytes| {
        let set = postcard::from_bytes::<CalibrationSet>(bytes).ok()?;
        Correction::new(&set, scales).ok().map(|c| (set, c))
    });
    match stored {
        Some(((set, correction), sequence)) => (set, sequence, correction),
        None => {
            crate::log::log_warn!("no valid stored parameters; starting on the identity set");
            (CalibrationSet::identity(), 0, Correction::identity(scales))
        }
    }
}
