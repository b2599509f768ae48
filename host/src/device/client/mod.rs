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
//!
//! Files: this one (connection, handshake, the request with its retry policy), `link` (framing,
//! reads and writes with deadlines), `params` (parameter transfer), `capture` (pose capture),
//! `stream` (sample stream and events).

use std::collections::VecDeque;
use std::io::{Read, Write};
use std::time::{Duration, Instant};

use imucal_protocol::{
    check_hello, DeviceStatus, ErrorCode, Event, FrameDecoder, LogMessage, ParamStatus,
    ProtocolVersion, RequestBody, ResponseBody, Welcome, MAX_FRAME, PROTOCOL_VERSION,
};
use serialport::SerialPort;

use super::samples::GapTracker;
use super::{open_port, DeviceError};

pub(super) mod capture;
mod link;
mod params;
pub use params::WriteReport;
mod stream;

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
    /// Frames that arrived and passed their checks.
    pub good_frames: u64,
    /// Stream samples that arrived.
    pub received_samples: u64,
}

impl LinkStats {
    /// Of the frames that arrived, the fraction that failed their checks (0 when none
    /// arrived).
    pub fn frame_error_rate(&self) -> f64 {
        let frames = self.frame_errors + self.good_frames;
        if frames == 0 {
            0.0
        } else {
            self.frame_errors as f64 / frames as f64
        }
    }

    /// Of the stream samples the board sent, the fraction lost in transit (0 when none were
    /// sent).
    pub fn sample_loss_rate(&self) -> f64 {
        let sent = self.lost_samples + self.received_samples;
        if sent == 0 {
            0.0
        } else {
            self.lost_samples as f64 / sent as f64
        }
    }

    /// A sentence naming a noisy link, with its measured loss, when the counters show one (a
    /// sample loss of [`NOISY_SAMPLE_LOSS`] or more, or frames failing their checks as
    /// [`Self::shows_noisy_link`] says); `None` otherwise.
    pub fn noisy_link_note(&self) -> Option<String> {
        let loss = self.sample_loss_rate();
        if loss < NOISY_SAMPLE_LOSS && !self.shows_noisy_link() {
            return None;
        }
        let mut measured = Vec::new();
        if self.lost_samples > 0 {
            measured.push(format!(
                "{} of {} stream samples lost ({:.1} %)",
                self.lost_samples,
                self.lost_samples + self.received_samples,
                100.0 * loss
            ));
        }
        if self.frame_errors > 0 {
            measured.push(format!(
                "{} of {} frames failed their check ({:.2} %)",
                self.frame_errors,
                self.frame_errors + self.good_frames,
                100.0 * self.frame_error_rate()
            ));
        }
        Some(format!(
            "the serial link is noisy: {}; try another USB cable, plug the board in directly \
             instead of through a hub, and check the baud rate (115200)",
            measured.join(", ")
        ))
    }

    /// Whether the frames that failed their checks show a link that loses or corrupts bytes:
    /// at least one in a thousand of those that arrived, and either a good frame besides (an
    /// imucal board is there) or three bad ones. A request left unanswered on a link this
    /// noisy was lost on the way, not ignored.
    pub fn shows_noisy_link(&self) -> bool {
        self.frame_errors >= 1
            && (self.good_frames >= 1 || self.frame_errors >= 3)
            && self.frame_error_rate() >= 1e-3
    }
}

/// A fraction of stream samples lost in transit that is the link's doing, not a slow reader's:
/// a working USB serial link loses none.
pub const NOISY_SAMPLE_LOSS: f64 = 0.01;

/// Most bytes kept of what arrived before the handshake, to tell a board that prints text.
const HEARD_LIMIT: usize = 8192;

/// A caller's receiver of events, set with [`DeviceClient::set_event_handler`].
pub type EventHandler = Box<dyn FnMut(&Event) + Send>;

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
    /// The first bytes read before the handshake completed (at most [`HEARD_LIMIT`]); emptied
    /// once connected.
    heard: Vec<u8>,
    connected: bool,
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
            heard: Vec::new(),
            connected: false,
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
            Err(DeviceError::NoAnswer { bad_frames, .. }) => self
                .exchange(&hello, self.options.reply_timeout, 1)
                .map_err(|_| self.why_no_answer("Ping", self.options.connect_tries, bad_frames))?,
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
        self.connected = true;
        self.heard = Vec::new();
        Ok(())
    }

    /// The error for `request` left unanswered after `tries`: a MotionCal sketch when the port
    /// printed its lines, a noisy link when the frames that arrived show one, else no answer.
    pub(super) fn why_no_answer(
        &self,
        request: &'static str,
        tries: u32,
        bad_frames: u64,
    ) -> DeviceError {
        if !self.connected {
            if let Some(tag) = crate::compat::motioncal::sketch_tag_in(&self.heard) {
                return DeviceError::MotionCalSketch {
                    port: self.port.clone(),
                    tag,
                };
            }
        }
        let stats = self.stats;
        if stats.shows_noisy_link() {
            return DeviceError::NoisyLink {
                port: self.port.clone(),
                request,
                tries,
                bad: stats.frame_errors,
                frames: stats.frame_errors + stats.good_frames,
                rate: 100.0 * stats.frame_error_rate(),
            };
        }
        DeviceError::NoAnswer {
            port: self.port.clone(),
            request,
            tries,
            bad_frames,
        }
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
