//! Shared proptest strategies and helpers for the protocol tests.
#![allow(dead_code, reason = "each test binary uses a different subset")]

use imucal_protocol::*;
use proptest::prelude::*;
use serde::Serialize;

/// Any `f32` bit pattern, with the extremes (±0, ±∞, NaN, limits, subnormals) made frequent.
pub fn any_f32() -> impl Strategy<Value = f32> {
    prop_oneof![
        3 => any::<u32>().prop_map(f32::from_bits),
        1 => prop::sample::select(vec![
            0.0f32,
            -0.0,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            f32::from_bits(0xFFFF_FFFF),
            f32::MAX,
            f32::MIN,
            f32::MIN_POSITIVE,
            f32::from_bits(1),
            f32::EPSILON,
        ]),
        2 => -1.0e3f32..1.0e3,
    ]
}

pub fn vec3() -> impl Strategy<Value = [f32; 3]> {
    prop::array::uniform3(any_f32())
}

pub fn mat3() -> impl Strategy<Value = [[f32; 3]; 3]> {
    prop::array::uniform3(vec3())
}

pub fn raw_sample() -> impl Strategy<Value = RawSample> {
    (
        prop::array::uniform3(any::<i16>()),
        prop::array::uniform3(any::<i16>()),
        prop::array::uniform3(any::<i16>()),
        any::<i16>(),
    )
        .prop_map(|(accel, gyro, mag, temp)| RawSample {
            accel,
            gyro,
            mag,
            temp,
        })
}

pub fn sensor_scales() -> impl Strategy<Value = SensorScales> {
    prop::array::uniform9(any_f32()).prop_map(|v| SensorScales {
        accel_mps2_per_count: v[0],
        gyro_rads_per_count: v[1],
        mag_ut_per_count: v[2],
        temp_c_per_count: v[3],
        temp_offset_c: v[4],
        accel_range_mps2: v[5],
        gyro_range_rads: v[6],
        mag_range_ut: v[7],
        sample_rate_hz: v[8],
    })
}

pub fn sensor_calibration() -> BoxedStrategy<SensorCalibration> {
    (
        mat3(),
        vec3(),
        any_f32(),
        prop::option::of(mat3()),
        prop::option::of(vec3()),
        prop::option::of((vec3(), vec3())),
    )
        .prop_map(
            |(a, b, t_ref_c, bias_temp, scale_temp, nonlinearity)| SensorCalibration {
                a,
                b,
                t_ref_c,
                bias_temp: bias_temp.map(|coeffs| BiasTemperature { coeffs }),
                scale_temp,
                nonlinearity: nonlinearity
                    .map(|(quadratic, cubic)| Nonlinearity { quadratic, cubic }),
            },
        )
        .boxed()
}

pub fn calibration_set() -> BoxedStrategy<CalibrationSet> {
    (
        any::<u16>(),
        any::<u64>(),
        sensor_calibration(),
        sensor_calibration(),
        sensor_calibration(),
        prop::option::of(mat3()),
        prop::array::uniform5(any_f32()),
    )
        .prop_map(
            |(format_version, created_unix_s, accel, gyro, mag, gyro_g_sensitivity, f)| {
                CalibrationSet {
                    format_version,
                    created_unix_s,
                    accel,
                    gyro,
                    mag,
                    gyro_g_sensitivity,
                    reference: ReferenceMagnitudes {
                        gravity_mps2: f[0],
                        field_ut: f[1],
                    },
                    residuals: FitResiduals {
                        accel_rms: f[2],
                        gyro_rms: f[3],
                        mag_rms: f[4],
                    },
                }
            },
        )
        .boxed()
}

pub fn still_thresholds() -> impl Strategy<Value = StillThresholds> {
    (any_f32(), any_f32()).prop_map(|(accel_std_mps2, gyro_std_rads)| StillThresholds {
        accel_std_mps2,
        gyro_std_rads,
    })
}

pub fn stream_kind() -> impl Strategy<Value = StreamKind> {
    prop_oneof![Just(StreamKind::Raw), Just(StreamKind::Calibrated)]
}

pub fn request_body() -> BoxedStrategy<RequestBody> {
    prop_oneof![
        (any::<u16>(), any::<u16>()).prop_map(|(protocol_major, protocol_minor)| {
            RequestBody::Hello {
                protocol_major,
                protocol_minor,
            }
        }),
        any::<u32>().prop_map(RequestBody::Ping),
        Just(RequestBody::Status),
        (stream_kind(), any::<u16>())
            .prop_map(|(kind, decimation)| RequestBody::StartStream { kind, decimation }),
        Just(RequestBody::StopStream),
        (any::<u32>(), still_thresholds(), any::<u32>()).prop_map(
            |(min_still_ms, thresholds, timeout_ms)| RequestBody::CapturePose {
                min_still_ms,
                thresholds,
                timeout_ms,
            }
        ),
        Just(RequestBody::GetParams),
        (calibration_set(), any::<u32>())
            .prop_map(|(set, crc)| RequestBody::WriteParams { set, crc }),
        any::<u32>().prop_map(|crc| RequestBody::CommitParams { crc }),
        Just(RequestBody::ResetParams),
    ]
    .boxed()
}

pub fn request() -> BoxedStrategy<Request> {
    (any::<u16>(), request_body())
        .prop_map(|(seq, body)| Request { seq, body })
        .boxed()
}

pub fn invalid_params_reason() -> impl Strategy<Value = InvalidParamsReason> {
    let sensor = || prop::sample::select(SensorKind::ALL.to_vec());
    let field = prop_oneof![
        sensor().prop_map(ParamField::Matrix),
        sensor().prop_map(ParamField::ReferenceTemperature),
        sensor().prop_map(ParamField::Nonlinearity),
        Just(ParamField::GyroGSensitivity),
        Just(ParamField::Residuals),
    ];
    prop_oneof![
        field.clone().prop_map(InvalidParamsReason::NonFinite),
        sensor().prop_map(InvalidParamsReason::IllConditioned),
        sensor().prop_map(InvalidParamsReason::OffsetOutOfRange),
        sensor().prop_map(InvalidParamsReason::GainOutOfRange),
        sensor().prop_map(InvalidParamsReason::ReferenceTemperatureOutOfRange),
        field.prop_map(InvalidParamsReason::ExtendedTermOutOfRange),
        any::<u16>().prop_map(|found| InvalidParamsReason::UnsupportedFormat { found }),
        sensor().prop_map(InvalidParamsReason::MirroredAxes),
    ]
}

pub fn error_code() -> BoxedStrategy<ErrorCode> {
    prop_oneof![
        (any::<u16>(), any::<u16>()).prop_map(|(device_major, device_minor)| {
            ErrorCode::VersionMismatch {
                device_major,
                device_minor,
            }
        }),
        prop::sample::select(vec![
            ErrorCode::UnknownRequest,
            ErrorCode::Malformed,
            ErrorCode::InvalidArgument,
            ErrorCode::Busy,
            ErrorCode::SensorMissing,
            ErrorCode::NotStill,
            ErrorCode::Timeout,
            ErrorCode::Saturated,
            ErrorCode::NothingStaged,
            ErrorCode::FlashError,
        ]),
        (any::<u32>(), any::<u32>())
            .prop_map(|(received, computed)| ErrorCode::CrcMismatch { received, computed }),
        invalid_params_reason().prop_map(ErrorCode::InvalidParams),
    ]
    .boxed()
}

pub fn welcome() -> BoxedStrategy<Welcome> {
    (
        any::<u16>(),
        any::<u16>(),
        prop::array::uniform3(any::<u16>()),
        any::<[u8; 16]>(),
        prop::array::uniform4(any::<bool>()),
        sensor_scales(),
    )
        .prop_map(
            |(protocol_major, protocol_minor, fw, id, s, scales)| Welcome {
                protocol_major,
                protocol_minor,
                firmware_version: FirmwareVersion {
                    major: fw[0],
                    minor: fw[1],
                    patch: fw[2],
                },
                device_id: DeviceId(id),
                sensors: SensorSet {
                    accel: s[0],
                    gyro: s[1],
                    mag: s[2],
                    temp: s[3],
                },
                scales,
            },
        )
        .boxed()
}

pub fn pose_stats() -> BoxedStrategy<PoseStats> {
    (
        any::<u32>(),
        prop::array::uniform6(vec3()),
        prop::array::uniform3(any_f32()),
        any::<u32>(),
    )
        .prop_map(|(n, v, t, duration_ms)| PoseStats {
            n,
            accel_mean: v[0],
            accel_var: v[1],
            gyro_mean: v[2],
            gyro_var: v[3],
            mag_mean: v[4],
            mag_var: v[5],
            temp_mean_c: t[0],
            temp_min_c: t[1],
            temp_max_c: t[2],
            duration_ms,
        })
        .boxed()
}

pub fn device_status() -> BoxedStrategy<DeviceStatus> {
    (
        any::<u64>(),
        prop::option::of(stream_kind()),
        any::<bool>(),
        any::<u32>(),
        any::<u32>(),
        prop::array::uniform8(any::<u32>()),
    )
        .prop_map(
            |(uptime_ms, streaming, still, active_crc, active_seq, e)| DeviceStatus {
                uptime_ms,
                streaming,
                still,
                active_crc,
                active_seq,
                errors: ErrorCounters {
                    rx_frame_errors: e[0],
                    dropped_samples: e[1],
                    sensor_errors: e[2],
                    flash_errors: e[3],
                    repeated_samples: e[4],
                    missed_samples: e[5],
                    mag_repeats: e[6],
                    mag_overruns: e[7],
                },
            },
        )
        .boxed()
}

pub fn response_body() -> BoxedStrategy<ResponseBody> {
    prop_oneof![
        welcome().prop_map(ResponseBody::Welcome),
        any::<u32>().prop_map(ResponseBody::Pong),
        device_status().prop_map(ResponseBody::Status),
        Just(ResponseBody::Ack),
        pose_stats().prop_map(ResponseBody::PoseStats),
        calibration_set().prop_map(ResponseBody::Params),
        (any::<u32>(), any::<u32>(), prop::option::of(any::<u32>())).prop_map(
            |(active_crc, active_seq, staged_crc)| ResponseBody::ParamStatus(ParamStatus {
                active_crc,
                active_seq,
                staged_crc,
            })
        ),
        error_code().prop_map(ResponseBody::Error),
    ]
    .boxed()
}

pub fn batch_header() -> impl Strategy<Value = BatchHeader> {
    (any::<u32>(), any::<u64>(), 1u32..=u32::MAX).prop_map(|(first_index, t0_us, tick_us)| {
        BatchHeader {
            first_index,
            t0_us,
            tick_us,
        }
    })
}

/// A raw batch filled with samples at non-decreasing offsets (given in ticks).
pub fn sample_batch() -> BoxedStrategy<SampleBatch> {
    (
        batch_header(),
        prop::collection::vec((raw_sample(), any::<u16>()), 0..=RAW_BATCH_CAPACITY),
    )
        .prop_map(|(header, samples)| {
            let mut batch = SampleBatch::new(header);
            for (sample, ticks) in samples {
                let t_us = header.time_us(ticks);
                // Offsets whose time saturates at u64::MAX cannot be expressed; skip them.
                let _ = batch.push(&sample, t_us);
            }
            batch
        })
        .boxed()
}

pub fn calibrated_sample() -> impl Strategy<Value = CalibratedSample> {
    (vec3(), vec3(), vec3(), any_f32()).prop_map(|(accel, gyro, mag, temp_c)| CalibratedSample {
        accel,
        gyro,
        mag,
        temp_c,
    })
}

pub fn calibrated_batch() -> BoxedStrategy<CalibratedBatch> {
    (
        batch_header(),
        prop::collection::vec(
            (calibrated_sample(), any::<u16>()),
            0..=CALIBRATED_BATCH_CAPACITY,
        ),
    )
        .prop_map(|(header, samples)| {
            let mut batch = CalibratedBatch::new(header);
            for (sample, ticks) in samples {
                let _ = batch.push(&sample, header.time_us(ticks));
            }
            batch
        })
        .boxed()
}

pub fn log_message() -> BoxedStrategy<LogMessage> {
    (
        prop::sample::select(vec![
            LogLevel::Debug,
            LogLevel::Info,
            LogLevel::Warn,
            LogLevel::Error,
        ]),
        ".{0,120}",
    )
        .prop_map(|(level, text)| LogMessage::new(level, &text))
        .boxed()
}

pub fn event() -> BoxedStrategy<Event> {
    prop_oneof![
        sample_batch().prop_map(Event::SampleBatch),
        calibrated_batch().prop_map(Event::CalibratedBatch),
        (any::<bool>(), any::<u64>())
            .prop_map(|(still, t_ms)| Event::StillnessChanged { still, t_ms }),
        log_message().prop_map(Event::Log),
    ]
    .boxed()
}

pub fn device_message() -> BoxedStrategy<DeviceMessage> {
    prop_oneof![
        (any::<u16>(), response_body())
            .prop_map(|(seq, body)| DeviceMessage::Response(Response { seq, body })),
        event().prop_map(DeviceMessage::Event),
    ]
    .boxed()
}

/// Encodes one message as a frame into a fresh vector.
pub fn frame<T: Serialize>(msg: &T) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME];
    let len = encode_frame(msg, &mut buf).expect("every protocol message fits MAX_FRAME");
    buf[..len].to_vec()
}

/// The postcard encoding, used to compare messages bit for bit (floats included).
pub fn postcard_bytes<T: Serialize>(msg: &T) -> Vec<u8> {
    let mut buf = [0u8; MAX_PAYLOAD];
    postcard::to_slice(msg, &mut buf)
        .expect("every protocol message fits MAX_PAYLOAD")
        .to_vec()
}

/// Feeds `bytes` to a fresh decoder and collects everything it yields.
pub fn decode_all<T: serde::de::DeserializeOwned>(bytes: &[u8]) -> Vec<Result<T, FrameError>> {
    let mut decoder: FrameDecoder = FrameDecoder::new();
    decoder.messages(bytes).collect()
}
