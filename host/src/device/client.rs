//! The request/response client of a board: framing over any `Read + Write` link, sequence ids,
//! per-request timeouts, retries of idempotent requests, and events (sample batches, stillness,
//! log lines) delivered while waiting for replies.
//!
//! Retry policy: `Hello`, `Ping`, `Status`, `GetParams`, `StartStream`, `StopStream` and
//! `ResetParams` leave the same state when repeated and are resent on timeout with the same
//! `seq` (so a late reply to an earlier try also counts). `WriteParams` stages the same set
//! again, so it is idempotent too. `CommitParams` is resent with the same CRC; a lost reply
//! followed by `NothingStaged` on the retry is resolved by asking `Status` whether the set with
//! that CRC is now active. `CapturePose` is resent with the same `seq` only as
//! [`DeviceClient::capture_pose`] describes: a `Busy` answer then shows the capture running, and a
//! `Busy` to the first send makes it wait for the other capture to end.

use std::collections::VecDeque;
use std::io::{ErrorKind, Read, Write};
use std::time::{Duration, Instant};

use imucal_protocol::{
    check_hello, encode_frame, CalibrationSet, DeviceMessage, DeviceStatus, ErrorCode, Event,
    FrameDecoder, LogMessage, ParamStatus, PoseStats, ProtocolVersion, Request, RequestBody,
    ResponseBody, StillThresholds, StreamKind, Welcome, MAX_FRAME, PROTOCOL_VERSION,
};
use serialport::SerialPort;

use super::samples::{GapTracker, SampleChunk};
use super::{open_port, DeviceError};

/// Timeouts and retry counts of a [`DeviceClient`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClientOptions {
    /// How long to wait for the reply to a quick request (ping, status, parameters read).
    pub reply_timeout: Duration,
    /// How long to wait for a request that writes flash (`WriteParams`, `CommitParams`,
    /// `ResetParams`).
    pub flash_timeout: Duration,
    /// Tries of an idempotent request (first send included).
    pub tries: u32,
    /// Pings sent at connect before giving up (a QEMU pty may drop the first bytes).
    pub connect_tries: u32,
    /// Events kept for [`DeviceClient::next_event`] before the oldest are dropped.
    pub event_queue_limit: usize,
}

impl Default for ClientOptions {
    fn default() -> Self {
        Self {
            // A 512-byte frame takes 45 ms at 115200 baud; a reply may queue behind a few
            // sample batches.
            reply_timeout: Duration::from_millis(500),
            flash_timeout: Duration::from_secs(3),
            tries: 3,
            connect_tries: 5,
            event_queue_limit: 4096,
        }
    }
}

/// Counters of what went wrong on the link, for diagnostics.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LinkStats {
    /// Frames dropped: CRC, COBS, overflow or undecodable payload.
    pub frame_errors: u64,
    /// Replies whose `seq` matched no waiting request (late replies to abandoned tries).
    pub stale_replies: u64,
    /// Requests resent after a timeout.
    pub retries: u64,
    /// Events dropped because the queue was full.
    pub dropped_events: u64,
    /// Stream samples lost in transit (gaps in the stream index).
    pub lost_samples: u64,
}

/// What a pose capture is waiting on, reported to the progress callback.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseProgress {
    /// Time since the request was sent.
    pub elapsed: Duration,
    /// The capture's timeout.
    pub timeout: Duration,
    /// Whether the board last reported itself still (`None` until it says).
    pub still: Option<bool>,
}

/// Parameters of a pose capture.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseRequest {
    /// Minimum duration of still data to average.
    pub min_still: Duration,
    /// What counts as still.
    pub thresholds: StillThresholds,
    /// Give up after this long.
    pub timeout: Duration,
}

/// Where a pose capture's resending stands (see [`DeviceClient::capture_pose`]).
#[derive(Debug, Clone, Copy)]
struct CaptureResend {
    /// When the request was last sent.
    sent_at: Instant,
    /// Sends so far, the first included.
    sends: u32,
    /// Resends that may have started a new capture.
    restarts: u32,
    /// Whether a `Busy` since the last send showed the capture running.
    running: bool,
    /// Whether the first send found another capture running, not yet seen to end.
    busy_elsewhere: bool,
    /// Whether a `Busy` answered since the last send.
    busy_answered: bool,
    /// Frame errors counted at the last send.
    frame_errors: u64,
}

/// A caller's receiver of events, set with [`DeviceClient::set_event_handler`].
pub type EventHandler = Box<dyn FnMut(&Event) + Send>;

/// Maximum log lines kept when skipped over by [`DeviceClient::next_samples`].
const LOG_KEEP: usize = 64;

/// A connected board.
///
/// `L` is the byte link; its `read` must return within a short time (an error of kind
/// `TimedOut` or `WouldBlock`, or `Ok(0)`, when nothing arrived), as a port from
/// [`open_port`] does, so that request timeouts can be enforced.
pub struct DeviceClient<L: Read + Write = Box<dyn SerialPort>> {
    link: L,
    port: String,
    options: ClientOptions,
    decoder: FrameDecoder<MAX_FRAME>,
    rx: Vec<u8>,
    rx_pos: usize,
    next_seq: u16,
    welcome: Welcome,
    protocol: ProtocolVersion,
    events: VecDeque<Event>,
    handler: Option<EventHandler>,
    logs: VecDeque<LogMessage>,
    still: Option<bool>,
    gaps: GapTracker,
    stats: LinkStats,
}

impl<L: Read + Write> std::fmt::Debug for DeviceClient<L> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DeviceClient")
            .field("port", &self.port)
            .field("welcome", &self.welcome)
            .field("protocol", &self.protocol)
            .field("stats", &self.stats)
            .finish_non_exhaustive()
    }
}

impl DeviceClient<Box<dyn SerialPort>> {
    /// Opens the serial port `path` and connects with default options.
    pub fn open(path: &str) -> Result<Self, DeviceError> {
        Self::open_with(path, ClientOptions::default())
    }

    /// Opens the serial port `path` and connects with `options`.
    pub fn open_with(path: &str, options: ClientOptions) -> Result<Self, DeviceError> {
        Self::connect(open_port(path)?, path, options)
    }
}

/// A short name of a request, for messages.
fn request_name(body: &RequestBody) -> &'static str {
    match body {
        RequestBody::Hello { .. } => "Hello",
        RequestBody::Ping(_) => "Ping",
        RequestBody::Status => "Status",
        RequestBody::StartStream { .. } => "StartStream",
        RequestBody::StopStream => "StopStream",
        RequestBody::CapturePose { .. } => "CapturePose",
        RequestBody::GetParams => "GetParams",
        RequestBody::WriteParams { .. } => "WriteParams",
        RequestBody::CommitParams { .. } => "CommitParams",
        RequestBody::ResetParams => "ResetParams",
    }
}

/// A short description of a response, for messages.
fn response_name(body: &ResponseBody) -> String {
    match body {
        ResponseBody::Welcome(_) => "Welcome".into(),
        ResponseBody::Pong(v) => format!("Pong({v})"),
        ResponseBody::Status(_) => "Status".into(),
        ResponseBody::Ack => "Ack".into(),
        ResponseBody::PoseStats(_) => "PoseStats".into(),
        ResponseBody::Params(_) => "Params".into(),
        ResponseBody::ParamStatus(_) => "ParamStatus".into(),
        ResponseBody::Error(code) => format!("error {code:?}"),
    }
}

/// The instant `timeout` from now; an absurdly long timeout is cut to a year instead of
/// overflowing.
fn deadline_after(timeout: Duration) -> Instant {
    let now = Instant::now();
    now.checked_add(timeout)
        .or_else(|| now.checked_add(Duration::from_secs(365 * 86_400)))
        .unwrap_or(now)
}

/// A starting sequence id that differs between runs, so that replies to a previous run's
/// requests still in flight do not match.
fn initial_seq() -> u16 {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.subsec_nanos())
        .unwrap_or(0);
    (nanos >> 8) as u16
}

impl<L: Read + Write> DeviceClient<L> {
    /// Connects to the board on `link`: pings (with retries) until it answers, then performs
    /// the `Hello`/`Welcome` handshake and checks the protocol major version.
    ///
    /// `port` names the link in error messages.
    pub fn connect(
        link: L,
        port: impl Into<String>,
        options: ClientOptions,
    ) -> Result<Self, DeviceError> {
        let placeholder = Welcome {
            protocol_major: 0,
            protocol_minor: 0,
            firmware_version: imucal_protocol::FirmwareVersion {
                major: 0,
                minor: 0,
                patch: 0,
            },
            device_id: imucal_protocol::DeviceId::default(),
            sensors: imucal_protocol::SensorSet::default(),
            scales: imucal_protocol::SensorScales {
                accel_mps2_per_count: 0.0,
                gyro_rads_per_count: 0.0,
                mag_ut_per_count: 0.0,
                temp_c_per_count: 0.0,
                temp_offset_c: 0.0,
                accel_range_mps2: 0.0,
                gyro_range_rads: 0.0,
                mag_range_ut: 0.0,
                sample_rate_hz: 0.0,
            },
        };
        let mut client = Self {
            link,
            port: port.into(),
            options,
            decoder: FrameDecoder::new(),
            rx: Vec::new(),
            rx_pos: 0,
            next_seq: initial_seq(),
            welcome: placeholder,
            protocol: PROTOCOL_VERSION,
            events: VecDeque::new(),
            handler: None,
            logs: VecDeque::new(),
            still: None,
            gaps: GapTracker::default(),
            stats: LinkStats::default(),
        };
        client.handshake()?;
        Ok(client)
    }

    fn handshake(&mut self) -> Result<(), DeviceError> {
        // A lone delimiter ends any partial frame the board holds from earlier noise.
        self.send_bytes(&[0])?;
        let ping = RequestBody::Ping(u32::from(self.next_seq));
        let alive = self.exchange(
            &ping,
            self.options.reply_timeout,
            self.options.connect_tries,
        );
        let hello = RequestBody::hello();
        let reply = match alive {
            // Any answer (even an error from a board of another protocol major, which may not
            // know Ping) shows the board is there; Hello then tells the version.
            Ok(_) => self.exchange(&hello, self.options.reply_timeout, self.options.tries)?,
            // Hello is the one request every protocol version keeps; try it once before
            // giving up, in case Ping is what the board does not understand.
            Err(DeviceError::NoAnswer { .. }) => self
                .exchange(&hello, self.options.reply_timeout, 1)
                .map_err(|_| DeviceError::NoAnswer {
                    port: self.port.clone(),
                    request: "Ping",
                    tries: self.options.connect_tries,
                })?,
            Err(e) => return Err(e),
        }
        .0;
        match reply {
            ResponseBody::Welcome(welcome) => {
                self.protocol =
                    check_hello(welcome.protocol_version(), PROTOCOL_VERSION).map_err(|_| {
                        DeviceError::version_mismatch(&self.port, welcome.protocol_version())
                    })?;
                self.welcome = welcome;
            }
            ResponseBody::Error(ErrorCode::VersionMismatch {
                device_major,
                device_minor,
            }) => {
                return Err(DeviceError::version_mismatch(
                    &self.port,
                    ProtocolVersion {
                        major: device_major,
                        minor: device_minor,
                    },
                ))
            }
            other => return Err(self.unexpected("Hello", &other)),
        }
        // Events from before this session (a stream left running) are not the caller's.
        self.events.clear();
        self.logs.clear();
        Ok(())
    }

    /// What the board said about itself at connect.
    pub fn welcome(&self) -> &Welcome {
        &self.welcome
    }

    /// The protocol version both ends use (common major, smaller minor).
    pub fn protocol(&self) -> ProtocolVersion {
        self.protocol
    }

    /// The port name given at connect.
    pub fn port_name(&self) -> &str {
        &self.port
    }

    /// Link problem counters so far.
    pub fn stats(&self) -> LinkStats {
        self.stats
    }

    /// Whether the board last reported itself still (from `StillnessChanged` events).
    pub fn is_still(&self) -> Option<bool> {
        self.still
    }

    /// Sends every later event to `handler` instead of the queue read by
    /// [`Self::next_event`] and [`Self::next_samples`]; `None` returns to queueing.
    pub fn set_event_handler(&mut self, handler: Option<EventHandler>) {
        self.handler = handler;
    }

    /// Log lines from the board skipped over by [`Self::next_samples`], oldest first.
    pub fn drain_logs(&mut self) -> Vec<LogMessage> {
        self.logs.drain(..).collect()
    }

    /// Gives back the link.
    pub fn into_link(self) -> L {
        self.link
    }

    /// Sends `body` and returns the board's reply, with the timeout and retries that suit the
    /// request (see the module docs). An error reply becomes [`DeviceError::Device`].
    pub fn request(&mut self, body: RequestBody) -> Result<ResponseBody, DeviceError> {
        let name = request_name(&body);
        let (timeout, tries) = match &body {
            RequestBody::WriteParams { .. }
            | RequestBody::CommitParams { .. }
            | RequestBody::ResetParams => (self.options.flash_timeout, self.options.tries),
            RequestBody::CapturePose { timeout_ms, .. } => (
                Duration::from_millis(u64::from(*timeout_ms)) + self.options.flash_timeout,
                1,
            ),
            _ => (self.options.reply_timeout, self.options.tries),
        };
        let (reply, resent) = self.exchange(&body, timeout, tries)?;
        match reply {
            ResponseBody::Error(ErrorCode::NothingStaged)
                if resent && matches!(body, RequestBody::CommitParams { .. }) =>
            {
                self.resolve_commit(&body)
            }
            ResponseBody::Error(code) => Err(DeviceError::Device {
                port: self.port.clone(),
                request: name,
                code,
            }),
            other => Ok(other),
        }
    }

    /// After a retried commit answered `NothingStaged`: the first try may have committed and
    /// lost its reply. The board's active CRC tells.
    fn resolve_commit(&mut self, body: &RequestBody) -> Result<ResponseBody, DeviceError> {
        let RequestBody::CommitParams { crc } = *body else {
            return Err(self.unexpected(
                "CommitParams",
                &ResponseBody::Error(ErrorCode::NothingStaged),
            ));
        };
        let status = self.status()?;
        if status.active_crc == crc {
            Ok(ResponseBody::ParamStatus(ParamStatus {
                active_crc: status.active_crc,
                active_seq: status.active_seq,
                staged_crc: None,
            }))
        } else {
            Err(DeviceError::Device {
                port: self.port.clone(),
                request: "CommitParams",
                code: ErrorCode::NothingStaged,
            })
        }
    }

    /// Round-trip time of a ping.
    pub fn ping(&mut self) -> Result<Duration, DeviceError> {
        let nonce = u32::from(self.next_seq).wrapping_mul(2_654_435_761);
        let start = Instant::now();
        match self.request(RequestBody::Ping(nonce))? {
            ResponseBody::Pong(v) if v == nonce => Ok(start.elapsed()),
            other => Err(self.unexpected("Ping", &other)),
        }
    }

    /// The board's state and error counters.
    pub fn status(&mut self) -> Result<DeviceStatus, DeviceError> {
        match self.request(RequestBody::Status)? {
            ResponseBody::Status(status) => Ok(status),
            other => Err(self.unexpected("Status", &other)),
        }
    }

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
        Ok(committed)
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

    /// Asks the board to average a still pose; `progress` is called about every read poll
    /// and on each stillness change while the board waits for stillness and averages.
    ///
    /// A lost request or reply is recovered by resending with the same `seq`: every reply
    /// timeout until a `Busy` answer shows the capture running, then only after a lost frame (at
    /// most `tries − 1` times, each may start a new capture). A `Busy` to the first send (another
    /// capture runs) is waited out by resending until that capture ends.
    pub fn capture_pose(
        &mut self,
        pose: &PoseRequest,
        progress: &mut dyn FnMut(&PoseProgress),
    ) -> Result<PoseStats, DeviceError> {
        let to_ms = |d: Duration| u32::try_from(d.as_millis()).unwrap_or(u32::MAX);
        let body = RequestBody::CapturePose {
            min_still_ms: to_ms(pose.min_still),
            thresholds: pose.thresholds,
            timeout_ms: to_ms(pose.timeout),
        };
        let seq = self.take_seq();
        self.send_request(seq, &body)?;
        let start = Instant::now();
        let one_capture = pose.timeout.saturating_add(self.options.flash_timeout);
        let mut deadline = deadline_after(one_capture);
        let mut resend = CaptureResend {
            sent_at: start,
            sends: 1,
            restarts: 0,
            running: false,
            busy_elsewhere: false,
            busy_answered: false,
            frame_errors: self.stats.frame_errors,
        };
        let reply = loop {
            let waited = self.wait_reply(
                seq,
                deadline.min(Instant::now() + Duration::from_millis(100)),
            )?;
            progress(&PoseProgress {
                elapsed: start.elapsed(),
                timeout: pose.timeout,
                still: self.still,
            });
            match waited {
                // Busy to the first send: another capture runs (perhaps one a resend started
                // just as the previous capture ended); resend until it is over.
                Some(ResponseBody::Error(ErrorCode::Busy)) if resend.sends == 1 => {
                    resend.busy_elsewhere = true;
                    continue;
                }
                // Busy to a resend: the capture an earlier send started is still running.
                Some(ResponseBody::Error(ErrorCode::Busy)) => {
                    resend.running = !resend.busy_elsewhere;
                    resend.busy_answered = true;
                    continue;
                }
                Some(reply) => break reply,
                None => {}
            }
            let now = Instant::now();
            if now >= deadline && resend.busy_elsewhere {
                return Err(DeviceError::Device {
                    port: self.port.clone(),
                    request: "CapturePose",
                    code: ErrorCode::Busy,
                });
            }
            if now >= deadline {
                return Err(DeviceError::NoAnswer {
                    port: self.port.clone(),
                    request: "CapturePose",
                    tries: resend.sends,
                });
            }
            if let Some(restart) = self.capture_resend_due(&resend, now) {
                if resend.busy_elsewhere && resend.sends > 1 && !resend.busy_answered {
                    // The last resend drew no Busy: the other capture is over and ours runs.
                    resend.busy_elsewhere = false;
                    deadline = deadline.max(deadline_after(one_capture));
                }
                if restart {
                    // The board may start a whole new capture.
                    resend.restarts += 1;
                    deadline = deadline.max(deadline_after(one_capture));
                }
                self.stats.retries += 1;
                self.send_request(seq, &body)?;
                resend = CaptureResend {
                    sent_at: now,
                    sends: resend.sends + 1,
                    running: false,
                    busy_answered: false,
                    frame_errors: self.stats.frame_errors,
                    ..resend
                };
            }
        };
        match reply {
            ResponseBody::PoseStats(stats) => Ok(stats),
            ResponseBody::Error(code) => Err(DeviceError::Device {
                port: self.port.clone(),
                request: "CapturePose",
                code,
            }),
            other => Err(self.unexpected("CapturePose", &other)),
        }
    }

    /// Starts a sample stream; batches then arrive as events.
    pub fn start_stream(&mut self, kind: StreamKind, decimation: u16) -> Result<(), DeviceError> {
        self.gaps.reset();
        match self.request(RequestBody::StartStream { kind, decimation })? {
            ResponseBody::Ack => Ok(()),
            other => Err(self.unexpected("StartStream", &other)),
        }
    }

    /// Stops the sample stream. Batches already in flight are discarded.
    pub fn stop_stream(&mut self) -> Result<(), DeviceError> {
        match self.request(RequestBody::StopStream)? {
            ResponseBody::Ack => {
                self.events
                    .retain(|e| !matches!(e, Event::SampleBatch(_) | Event::CalibratedBatch(_)));
                Ok(())
            }
            other => Err(self.unexpected("StopStream", &other)),
        }
    }

    /// The next event, waiting up to `timeout`; `None` when none arrived.
    pub fn next_event(&mut self, timeout: Duration) -> Result<Option<Event>, DeviceError> {
        let deadline = deadline_after(timeout);
        loop {
            if let Some(event) = self.events.pop_front() {
                return Ok(Some(event));
            }
            if Instant::now() >= deadline {
                return Ok(None);
            }
            // No request is waiting: seq None means every reply is stale.
            self.pump(None, deadline)?;
        }
    }

    /// The next batch of stream samples in units, waiting up to `timeout`. Other events are
    /// skipped (stillness still updates [`Self::is_still`]; log lines go to
    /// [`Self::drain_logs`]).
    pub fn next_samples(&mut self, timeout: Duration) -> Result<Option<SampleChunk>, DeviceError> {
        let deadline = deadline_after(timeout);
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            let Some(event) = self.next_event(left)? else {
                return Ok(None);
            };
            let scales = self.welcome.scales;
            match event {
                Event::SampleBatch(batch) => {
                    let lost = self.gaps.observe(batch.header(), batch.len());
                    self.stats.lost_samples += u64::from(lost);
                    return Ok(Some(SampleChunk::from_raw(&batch, &scales, lost)));
                }
                Event::CalibratedBatch(batch) => {
                    let lost = self.gaps.observe(batch.header(), batch.len());
                    self.stats.lost_samples += u64::from(lost);
                    return Ok(Some(SampleChunk::from_calibrated(&batch, lost)));
                }
                Event::Log(line) => {
                    if self.logs.len() >= LOG_KEEP {
                        self.logs.pop_front();
                    }
                    self.logs.push_back(line);
                }
                Event::StillnessChanged { .. } => {}
            }
        }
    }

    /// Streams `kind` for `duration` and returns every sample, calling `on_chunk` per batch
    /// (for progress or writing as it comes). The stream is stopped afterwards, also on error.
    pub fn collect_samples(
        &mut self,
        kind: StreamKind,
        duration: Duration,
        on_chunk: &mut dyn FnMut(&SampleChunk),
    ) -> Result<Vec<super::UnitSample>, DeviceError> {
        self.start_stream(kind, 1)?;
        let mut samples = Vec::new();
        let deadline = deadline_after(duration);
        let result = loop {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                break Ok(());
            }
            match self.next_samples(left) {
                Ok(Some(chunk)) => {
                    on_chunk(&chunk);
                    samples.extend_from_slice(&chunk.samples);
                }
                Ok(None) => break Ok(()),
                Err(e) => break Err(e),
            }
        };
        let stopped = self.stop_stream();
        result?;
        stopped?;
        Ok(samples)
    }

    // ---- link internals ----

    /// Whether a pose capture should be resent now (`Some(true)`: one that may start a new
    /// capture, because the running one may have ended with a lost reply).
    ///
    /// Until a `Busy` has confirmed that the capture runs, the request is resent every reply
    /// timeout: the request or the `Busy` may have been lost. Once confirmed, it is resent only
    /// after a frame was lost (it may have been the reply) and a reply timeout of silence, at most
    /// `tries − 1` times; resending on silence alone could start a second capture just as the
    /// first ends, leaving the board busy for the next one.
    fn capture_resend_due(&self, resend: &CaptureResend, now: Instant) -> Option<bool> {
        if now.saturating_duration_since(resend.sent_at) < self.options.reply_timeout {
            return None;
        }
        if !resend.running {
            return Some(false);
        }
        let reply_may_be_lost = self.stats.frame_errors > resend.frame_errors;
        (reply_may_be_lost && resend.restarts + 1 < self.options.tries.max(1)).then_some(true)
    }

    fn take_seq(&mut self) -> u16 {
        let seq = self.next_seq;
        self.next_seq = self.next_seq.wrapping_add(1);
        seq
    }

    /// Sends `body` up to `tries` times (same `seq`), waiting `timeout` for each; the flag
    /// says whether it was resent.
    fn exchange(
        &mut self,
        body: &RequestBody,
        timeout: Duration,
        tries: u32,
    ) -> Result<(ResponseBody, bool), DeviceError> {
        let seq = self.take_seq();
        let tries = tries.max(1);
        for attempt in 0..tries {
            if attempt > 0 {
                self.stats.retries += 1;
            }
            self.send_request(seq, body)?;
            if let Some(reply) = self.wait_reply(seq, deadline_after(timeout))? {
                return Ok((reply, attempt > 0));
            }
        }
        Err(DeviceError::NoAnswer {
            port: self.port.clone(),
            request: request_name(body),
            tries,
        })
    }

    fn send_request(&mut self, seq: u16, body: &RequestBody) -> Result<(), DeviceError> {
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

    fn send_bytes(&mut self, bytes: &[u8]) -> Result<(), DeviceError> {
        self.link
            .write_all(bytes)
            .and_then(|()| self.link.flush())
            .map_err(|cause| DeviceError::from_io(&self.port, cause))
    }

    /// Reads until the reply with `seq` arrives (returned) or `deadline` passes (`None`).
    fn wait_reply(
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
    fn pump(
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
                Ok(DeviceMessage::Event(event)) => self.dispatch(event),
                Ok(DeviceMessage::Response(response)) => {
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
                self.rx.extend_from_slice(chunk.get(..n).unwrap_or(&chunk));
                Ok(true)
            }
            Err(e)
                if matches!(
                    e.kind(),
                    ErrorKind::TimedOut | ErrorKind::WouldBlock | ErrorKind::Interrupted
                ) =>
            {
                Ok(false)
            }
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

    fn unexpected(&self, request: &'static str, answer: &ResponseBody) -> DeviceError {
        match answer {
            ResponseBody::Error(code) => DeviceError::Device {
                port: self.port.clone(),
                request,
                code: *code,
            },
            other => DeviceError::UnexpectedAnswer {
                port: self.port.clone(),
                request,
                answer: response_name(other),
            },
        }
    }
}
