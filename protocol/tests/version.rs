//! The Hello/Welcome version rule, as applied by both ends.

mod common;

use common::*;
use imucal_protocol::*;

fn v(major: u16, minor: u16) -> ProtocolVersion {
    ProtocolVersion { major, minor }
}

#[test]
fn equal_majors_are_compatible_and_use_the_smaller_minor() {
    assert_eq!(check_hello(v(1, 3), v(1, 5)), Ok(v(1, 3)));
    assert_eq!(check_hello(v(1, 5), v(1, 3)), Ok(v(1, 3)));
    assert_eq!(
        check_hello(PROTOCOL_VERSION, PROTOCOL_VERSION),
        Ok(PROTOCOL_VERSION)
    );
}

#[test]
fn different_majors_fail_with_the_device_version_either_way() {
    let expected = Err(ErrorCode::VersionMismatch {
        device_major: 2,
        device_minor: 7,
    });
    assert_eq!(check_hello(v(2, 7), v(1, 0)), expected);
    assert_eq!(check_hello(v(2, 7), v(3, 0)), expected);
}

#[test]
fn hello_constructor_carries_this_crate_version() {
    assert_eq!(
        RequestBody::hello(),
        RequestBody::Hello {
            protocol_major: PROTOCOL_MAJOR,
            protocol_minor: PROTOCOL_MINOR,
        }
    );
}

/// A device's Hello handling written against the public API: decode, check, reply.
fn device_answer(request_frame: &[u8], device: ProtocolVersion) -> Vec<u8> {
    let mut decoder: FrameDecoder = FrameDecoder::new();
    let mut replies = Vec::new();
    decoder.feed::<HostMessage>(request_frame, |msg| {
        let Ok(Request {
            seq,
            body:
                RequestBody::Hello {
                    protocol_major,
                    protocol_minor,
                },
        }) = msg
        else {
            panic!("expected a Hello, got {msg:?}");
        };
        let body = match check_hello(device, v(protocol_major, protocol_minor)) {
            Ok(_) => ResponseBody::Pong(0),
            Err(e) => ResponseBody::Error(e),
        };
        replies.extend(frame(&DeviceMessage::Response(Response { seq, body })));
    });
    replies
}

#[test]
fn device_answers_hello_of_another_major_with_version_mismatch_echoing_seq() {
    let hello = frame(&Request {
        seq: 9,
        body: RequestBody::Hello {
            protocol_major: PROTOCOL_MAJOR + 1,
            protocol_minor: 0,
        },
    });
    let reply = decode_all::<DeviceMessage>(&device_answer(&hello, PROTOCOL_VERSION));
    let expected = DeviceMessage::Response(Response {
        seq: 9,
        body: ResponseBody::Error(ErrorCode::VersionMismatch {
            device_major: PROTOCOL_MAJOR,
            device_minor: PROTOCOL_MINOR,
        }),
    });
    assert_eq!(reply, vec![Ok(expected)]);
}

#[test]
fn host_detects_incompatible_welcome() {
    let welcome_version = v(PROTOCOL_MAJOR + 1, 2);
    let err = check_hello(welcome_version, PROTOCOL_VERSION).unwrap_err();
    assert!(err
        .to_string()
        .contains(&format!("{}.2", PROTOCOL_MAJOR + 1)));
    assert!(err.describe().contains("update"));
}

#[test]
fn every_error_code_has_a_distinct_actionable_description() {
    let codes = [
        ErrorCode::VersionMismatch {
            device_major: 1,
            device_minor: 0,
        },
        ErrorCode::UnknownRequest,
        ErrorCode::Malformed,
        ErrorCode::InvalidArgument,
        ErrorCode::Busy,
        ErrorCode::SensorMissing,
        ErrorCode::NotStill,
        ErrorCode::Timeout,
        ErrorCode::Saturated,
        ErrorCode::CrcMismatch {
            received: 1,
            computed: 2,
        },
        ErrorCode::NothingStaged,
        ErrorCode::InvalidParams(InvalidParamsReason::NonFinite(ParamField::Reference)),
        ErrorCode::InvalidParams(InvalidParamsReason::IllConditioned(SensorKind::Accel)),
        ErrorCode::InvalidParams(InvalidParamsReason::OffsetOutOfRange(SensorKind::Gyro)),
        ErrorCode::InvalidParams(InvalidParamsReason::GainOutOfRange(SensorKind::Mag)),
        ErrorCode::InvalidParams(InvalidParamsReason::ReferenceTemperatureOutOfRange(
            SensorKind::Mag,
        )),
        ErrorCode::InvalidParams(InvalidParamsReason::ExtendedTermOutOfRange(
            ParamField::GyroGSensitivity,
        )),
        ErrorCode::InvalidParams(InvalidParamsReason::UnsupportedFormat { found: 1 }),
        ErrorCode::InvalidParams(InvalidParamsReason::MirroredAxes(SensorKind::Gyro)),
        ErrorCode::FlashError,
    ];
    let descriptions: std::collections::HashSet<_> = codes.iter().map(|c| c.describe()).collect();
    assert_eq!(descriptions.len(), codes.len());
    for d in descriptions {
        // Each sentence names a cause and, after a separator, what to do.
        assert!(d.contains(';') || d.contains(','), "no remedy in: {d}");
        assert!(d.len() > 30, "too terse: {d}");
    }
}

/// The format-1 layout of a set: `t_ref_c` inside the bias polynomial, none per sensor.
mod format_1 {
    use serde::Serialize;

    #[derive(Serialize)]
    pub struct BiasTemperature {
        pub t_ref_c: f32,
        pub coeffs: [[f32; 3]; 3],
    }

    #[derive(Serialize)]
    pub struct Sensor {
        pub a: [[f32; 3]; 3],
        pub b: [f32; 3],
        pub bias_temp: Option<BiasTemperature>,
        pub scale_temp: Option<[f32; 3]>,
        pub nonlinearity: Option<([f32; 3], [f32; 3])>,
    }

    #[derive(Serialize)]
    pub struct Set {
        pub format_version: u16,
        pub created_unix_s: u64,
        pub sensors: [Sensor; 3],
        pub gyro_g_sensitivity: Option<[[f32; 3]; 3]>,
        pub reference: [f32; 2],
        pub residuals: [f32; 3],
    }
}

#[test]
fn a_format_1_set_is_never_taken_for_a_format_2_one() {
    // Stored by older firmware or sent by an older host: it either fails to decode or decodes
    // to a set that validation refuses by its format version; it is never applied.
    let identity = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let sensor = |with_bias: bool| format_1::Sensor {
        a: identity,
        b: [0.1, -0.2, 0.3],
        bias_temp: with_bias.then_some(format_1::BiasTemperature {
            t_ref_c: 25.0,
            coeffs: [[1e-4; 3], [0.0; 3], [0.0; 3]],
        }),
        scale_temp: None,
        nonlinearity: None,
    };
    for with_bias in [false, true] {
        let old = format_1::Set {
            format_version: 1,
            created_unix_s: 1_763_700_000,
            sensors: [sensor(with_bias), sensor(false), sensor(with_bias)],
            gyro_g_sensitivity: None,
            reference: [9.806_65, 1.0],
            residuals: [0.0; 3],
        };
        let mut buffer = [0u8; PARAMS_MAX_ENCODED];
        let bytes = postcard::to_slice(&old, &mut buffer).expect("encodes");
        if let Ok(set) = postcard::from_bytes::<CalibrationSet>(bytes) {
            let scales = SensorScales {
                accel_mps2_per_count: 6e-4,
                gyro_rads_per_count: 1.5e-4,
                mag_ut_per_count: 0.014,
                temp_c_per_count: 0.0625,
                temp_offset_c: 25.0,
                accel_range_mps2: 19.6,
                gyro_range_rads: 4.36,
                mag_range_ut: 400.0,
                sample_rate_hz: 100.0,
            };
            assert_eq!(
                validate(&set, &scales),
                Err(InvalidParamsReason::UnsupportedFormat { found: 1 })
            );
        }
    }
}
