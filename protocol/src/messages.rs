//! Message types: host requests, device responses and unsolicited device events.

use heapless::String;
use serde::{Deserialize, Serialize};

use crate::error_code::ErrorCode;
use crate::params::CalibrationSet;
use crate::sample::{CalibratedBatch, SampleBatch, SensorScales, SensorSet};
use crate::version::{FirmwareVersion, ProtocolVersion, PROTOCOL_VERSION};

/// Maximum length of a [`LogMessage`] text, bytes of UTF-8.
pub const LOG_TEXT_MAX: usize = 96;

/// A request from the host; the device answers with a [`Response`] carrying the same `seq`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Request {
    /// Sequence id chosen by the host, echoed in the reply.
    pub seq: u16,
    /// What is requested.
    pub body: RequestBody,
}

impl Request {
    /// Reads just the sequence id from a request payload whose body may not decode (a request
    /// kind unknown to this version), so that the device can still answer `UnknownRequest`.
    pub fn peek_seq(payload: &[u8]) -> Option<u16> {
        postcard::take_from_bytes::<u16>(payload)
            .ok()
            .map(|(seq, _)| seq)
    }
}

/// Everything the host sends to the device.
pub type HostMessage = Request;

/// How a device streams samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum StreamKind {
    /// Raw counts, as [`Event::SampleBatch`].
    Raw,
    /// Calibrated nominal units, as [`Event::CalibratedBatch`].
    Calibrated,
}

/// Stillness thresholds: the board counts as still while the windowed standard deviation of
/// every accelerometer and every gyroscope axis stays below these.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StillThresholds {
    /// Accelerometer standard deviation limit, m/s².
    pub accel_std_mps2: f32,
    /// Gyroscope standard deviation limit, rad/s.
    pub gyro_std_rads: f32,
}

/// The body of a [`Request`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[allow(
    clippy::large_enum_variant,
    reason = "no heap to box into; messages are built in place and encoded whole"
)]
pub enum RequestBody {
    /// Opens a session; answered by [`ResponseBody::Welcome`] or a `VersionMismatch` error.
    Hello {
        /// The host's protocol major version.
        protocol_major: u16,
        /// The host's protocol minor version.
        protocol_minor: u16,
    },
    /// Liveness check; answered by [`ResponseBody::Pong`] with the same value.
    Ping(u32),
    /// Answered by [`ResponseBody::Status`].
    Status,
    /// Starts streaming sample batches as events; answered by [`ResponseBody::Ack`].
    StartStream {
        /// Raw or calibrated samples.
        kind: StreamKind,
        /// Send every `decimation`-th sample (≥ 1).
        decimation: u16,
    },
    /// Stops streaming; answered by [`ResponseBody::Ack`].
    StopStream,
    /// Waits for the board to be still for `min_still_ms`, averages the still samples, and
    /// answers with [`ResponseBody::PoseStats`] or `NotStill`, `Timeout`, `Saturated`.
    CapturePose {
        /// Minimum duration of still data to average, ms.
        min_still_ms: u32,
        /// What counts as still.
        thresholds: StillThresholds,
        /// Give up after this long, ms.
        timeout_ms: u32,
    },
    /// Answered by [`ResponseBody::Params`] with the active set.
    GetParams,
    /// Stages a whole set; the device recomputes the CRC and rejects a mismatch. Answered by
    /// [`ResponseBody::ParamStatus`].
    WriteParams {
        /// The set to stage.
        set: CalibrationSet,
        /// [`CalibrationSet::crc32`] of `set`.
        crc: u32,
    },
    /// Makes the staged set with this CRC active, power-safely. Answered by
    /// [`ResponseBody::ParamStatus`].
    CommitParams {
        /// CRC of the staged set, as given in `WriteParams`.
        crc: u32,
    },
    /// Makes the identity set active. Answered by [`ResponseBody::ParamStatus`].
    ResetParams,
}

impl RequestBody {
    /// A `Hello` carrying this crate's protocol version.
    pub const fn hello() -> Self {
        Self::Hello {
            protocol_major: PROTOCOL_VERSION.major,
            protocol_minor: PROTOCOL_VERSION.minor,
        }
    }
}

/// A device's unique identifier (chip UID, zero-padded to 16 bytes).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
pub struct DeviceId(pub [u8; 16]);

impl DeviceId {
    /// An id from a 64-bit unique number (stored little-endian in the first 8 bytes).
    pub fn from_u64(id: u64) -> Self {
        let mut bytes = [0u8; 16];
        for (slot, byte) in bytes.iter_mut().zip(id.to_le_bytes()) {
            *slot = byte;
        }
        Self(bytes)
    }
}

impl core::fmt::Display for DeviceId {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        self.0.iter().try_for_each(|b| write!(f, "{b:02x}"))
    }
}

/// The device's answer to `Hello`: who it is and how to read its samples.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Welcome {
    /// The device's protocol major version.
    pub protocol_major: u16,
    /// The device's protocol minor version.
    pub protocol_minor: u16,
    /// The firmware version.
    pub firmware_version: FirmwareVersion,
    /// The device's unique id.
    pub device_id: DeviceId,
    /// Sensors fitted on the board.
    pub sensors: SensorSet,
    /// Count-to-unit factors, full-scale ranges and the sample rate (`scales.sample_rate_hz`).
    pub scales: SensorScales,
}

impl Welcome {
    /// The device's protocol version.
    pub fn protocol_version(&self) -> ProtocolVersion {
        ProtocolVersion {
            major: self.protocol_major,
            minor: self.protocol_minor,
        }
    }
}

/// Statistics of one still pose, in nominal units before calibration (counts × scale).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PoseStats {
    /// Number of samples averaged.
    pub n: u32,
    /// Accelerometer mean, m/s².
    pub accel_mean: [f32; 3],
    /// Accelerometer variance, (m/s²)².
    pub accel_var: [f32; 3],
    /// Gyroscope mean, rad/s.
    pub gyro_mean: [f32; 3],
    /// Gyroscope variance, (rad/s)².
    pub gyro_var: [f32; 3],
    /// Magnetometer mean, µT.
    pub mag_mean: [f32; 3],
    /// Magnetometer variance, µT².
    pub mag_var: [f32; 3],
    /// Mean die temperature, °C.
    pub temp_mean_c: f32,
    /// Lowest die temperature, °C.
    pub temp_min_c: f32,
    /// Highest die temperature, °C.
    pub temp_max_c: f32,
    /// Time spanned by the averaged samples, ms.
    pub duration_ms: u32,
}

/// State of the parameter store after a parameter request.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct ParamStatus {
    /// CRC of the active set.
    pub active_crc: u32,
    /// Sequence number of the active set in the store (increments on each commit).
    pub active_seq: u32,
    /// CRC of the staged set, if one awaits commit.
    pub staged_crc: Option<u32>,
}

/// Counters of problems seen since power-up (saturating).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
pub struct ErrorCounters {
    /// Received frames dropped (COBS, CRC, overflow or decode errors).
    pub rx_frame_errors: u32,
    /// Samples dropped because the link could not keep up.
    pub dropped_samples: u32,
    /// Failed sensor reads.
    pub sensor_errors: u32,
    /// Failed flash operations.
    pub flash_errors: u32,
}

/// The device's state, answered to `Status`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct DeviceStatus {
    /// Time since power-up, ms.
    pub uptime_ms: u64,
    /// The stream running, if any.
    pub streaming: Option<StreamKind>,
    /// Whether the board is currently still.
    pub still: bool,
    /// CRC of the active parameter set.
    pub active_crc: u32,
    /// Sequence number of the active parameter set.
    pub active_seq: u32,
    /// Error counters.
    pub errors: ErrorCounters,
}

/// The body of a [`Response`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[allow(
    clippy::large_enum_variant,
    reason = "no heap to box into; messages are built in place and encoded whole"
)]
pub enum ResponseBody {
    /// Answer to `Hello`.
    Welcome(Welcome),
    /// Answer to `Ping`, echoing its value.
    Pong(u32),
    /// Answer to `Status`.
    Status(DeviceStatus),
    /// Answer to `StartStream` and `StopStream`.
    Ack,
    /// Answer to `CapturePose`.
    PoseStats(PoseStats),
    /// Answer to `GetParams`: the active set.
    Params(CalibrationSet),
    /// Answer to `WriteParams`, `CommitParams` and `ResetParams`.
    ParamStatus(ParamStatus),
    /// The request failed.
    Error(ErrorCode),
}

/// A reply to the [`Request`] with the same `seq`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Response {
    /// The request's sequence id.
    pub seq: u16,
    /// The answer.
    pub body: ResponseBody,
}

/// Severity of a [`LogMessage`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum LogLevel {
    /// Fine detail.
    Debug,
    /// Normal operation.
    Info,
    /// Something unexpected that the device handled.
    Warn,
    /// Something failed.
    Error,
}

/// A short log line from the device.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct LogMessage {
    /// Severity.
    pub level: LogLevel,
    /// Text, truncated by the device to [`LOG_TEXT_MAX`] bytes.
    pub text: String<LOG_TEXT_MAX>,
}

impl LogMessage {
    /// A log line from `text`, cut at a character boundary to fit [`LOG_TEXT_MAX`] bytes.
    pub fn new(level: LogLevel, text: &str) -> Self {
        let mut out = String::new();
        for c in text.chars() {
            if out.push(c).is_err() {
                break;
            }
        }
        Self { level, text: out }
    }
}

/// An unsolicited message from the device.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Event {
    /// Raw samples from a `Raw` stream.
    SampleBatch(SampleBatch),
    /// Calibrated samples from a `Calibrated` stream.
    CalibratedBatch(CalibratedBatch),
    /// The stillness detector changed state.
    StillnessChanged {
        /// Whether the board is now still.
        still: bool,
        /// Device time of the change, ms since power-up.
        t_ms: u64,
    },
    /// A log line.
    Log(LogMessage),
}

/// Everything the device sends to the host.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum DeviceMessage {
    /// A reply to a request.
    Response(Response),
    /// An unsolicited event.
    Event(Event),
}
