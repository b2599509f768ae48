//! imucal wire protocol: the messages, value types and framing shared by the IMU firmware and
//! the host tool. `no_std`, no heap, no `unsafe`.
//!
//! # Frame format
//!
//! Each message is encoded with [postcard], followed by the CRC-32 (ISO-HDLC, the Ethernet/zlib
//! CRC) of those payload bytes, little-endian. The payload and CRC together are COBS-encoded,
//! which removes every 0x00, and the frame ends with one 0x00 delimiter:
//!
//! ```text
//! COBS( postcard(message) ‖ crc32_le(postcard(message)) ) ‖ 0x00
//! ```
//!
//! An encoded frame is at most [`MAX_FRAME`] bytes including the delimiter, so a payload is at
//! most [`MAX_PAYLOAD`] bytes. [`encode_frame`] writes into a caller's buffer; [`FrameDecoder`]
//! takes the stream in any chunks, reports corrupt, truncated or oversize frames as
//! [`FrameError`]s and resynchronises at the next 0x00.
//!
//! # Message flow
//!
//! The host sends [`HostMessage`] (= [`Request`]); the device sends [`DeviceMessage`]: either
//! a [`Response`] to a request, echoing its `seq`, or an unsolicited [`Event`] (sample batches,
//! stillness changes, log lines). Each direction thus decodes a single type. A failed request is
//! answered with [`ResponseBody::Error`] carrying an [`ErrorCode`]; a frame the device cannot
//! decode at all gets no answer (the host times out and retries), but one whose `seq` can still be
//! read ([`Request::peek_seq`]) is answered with `UnknownRequest`.
//!
//! A session starts with `Hello` → `Welcome`, which reports the device's protocol and firmware
//! versions, unique id, sensor set and [`SensorScales`] (count-to-unit factors, ranges, rate).
//! Pose capture (`CapturePose` → [`PoseStats`]) averages still data on the device. Parameters are
//! written in two steps: `WriteParams` stages a whole [`CalibrationSet`] with its CRC, and
//! `CommitParams` with the same CRC makes it active.
//!
//! # Calibration model and validation
//!
//! [`CalibrationSet`] documents the model every implementation computes, including the one ΔT
//! rule (clamp to ±[`MAX_DELTA_T_C`]); [`model::apply`] is its reference implementation and
//! [`validate()`] the check that the firmware applies before storing a set and the host before
//! flashing or exporting one, so both refuse the same sets with the same [`InvalidParamsReason`].
//!
//! # Versioning
//!
//! [`PROTOCOL_VERSION`] is `major.minor`. Messages and enum variants are only ever appended in a
//! minor version; any other change raises the major. [`check_hello`] is the rule both ends apply:
//! equal majors are compatible and use the smaller minor; otherwise the device answers `Hello`
//! with `ErrorCode::VersionMismatch` carrying its version. [`CalibrationSet::format_version`]
//! versions the stored parameter layout separately.
//!
//! # Wire size of sample streams
//!
//! postcard writes an `i16` as a zigzag varint of up to 3 bytes, so a [`SampleBatch`] instead
//! stores each sample as 22 fixed bytes: 10 little-endian `i16` (3 accel, 3 gyro, 3 mag, temp) and
//! a `u16` time offset in ticks after the batch's start. Worst case for a full batch of
//! [`RAW_BATCH_CAPACITY`] = 20 samples:
//!
//! ```text
//! enum tags (DeviceMessage::Event, Event::SampleBatch)          2
//! header: first_index u32 ≤ 5, t0_us u64 ≤ 10, tick_us u32 ≤ 5  20
//! sample count (varint, < 128)                                   1
//! 20 samples × 22                                              440
//! payload                                                      463
//! + CRC-32                                                       4   → 467
//! + COBS overhead ⌊467 / 254⌋ + 1                                2   → 469
//! + delimiter                                                    1   → 470 ≤ MAX_FRAME = 512
//! per sample: 470 / 20 = 23.5 bytes ≤ 24
//! ```
//!
//! A [`CalibratedBatch`] carries `f32` values (4 fixed bytes each) plus a varint `u16` offset:
//! at most 43 bytes per sample; 10 samples make at most 2 + 20 + 1 + 430 + 4 + 2 + 1 = 460 bytes.
#![no_std]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

#[cfg(test)]
extern crate std;

pub mod error;
pub mod error_code;
pub mod feed;
pub mod frame;
pub mod math;
pub mod messages;
pub mod model;
pub mod params;
pub mod sample;
pub mod validate;
pub mod version;

pub use error::{BatchError, EncodeError, FrameError};
pub use error_code::ErrorCode;
pub use feed::{FeedDecoder, FeedFrame, MAX_FEED_FRAME};
pub use frame::{
    decode_payload, encode_frame, max_frame_len, FrameDecoder, Messages, CRC_BYTES, MAX_FRAME,
    MAX_PAYLOAD,
};
pub use messages::{
    DeviceId, DeviceMessage, DeviceStatus, ErrorCounters, Event, HostMessage, LogLevel, LogMessage,
    ParamStatus, PoseStats, Request, RequestBody, Response, ResponseBody, StillThresholds,
    StreamKind, Welcome, LOG_TEXT_MAX,
};
pub use model::{apply, apply_sensor, delta_t_c, NominalSample};
pub use params::{
    BiasTemperature, CalibrationSet, FitResiduals, Nonlinearity, ReferenceMagnitudes,
    SensorCalibration, SensorKind, IDENTITY_T_REF_C, PARAMS_FORMAT_VERSION, PARAMS_MAX_ENCODED,
};
pub use sample::{
    Batch, BatchEntry, BatchHeader, CalibratedBatch, CalibratedSample, PackedSample, RawSample,
    SampleBatch, SensorScales, SensorSet, TimedCalibrated, CALIBRATED_BATCH_CAPACITY,
    PACKED_SAMPLE_BYTES, RAW_BATCH_CAPACITY,
};
pub use validate::{
    validate, validate_for_ranges, FullScale, InvalidParamsReason, ParamField, MAX_DELTA_T_C,
};
pub use version::{
    check_hello, FirmwareVersion, ProtocolVersion, PROTOCOL_MAJOR, PROTOCOL_MINOR, PROTOCOL_VERSION,
};
