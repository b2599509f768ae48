//! Valid frames with hostile contents, one class per test, through the whole device: each
//! asserts the exact reply (`ErrorCode`) and that the previously committed set stays active,
//! also across a reboot.
//!
//! The validation bounds are those of `imucal_protocol::validate`: finite values, RMS gain of
//! `A` within `GAIN_LIMITS`, Frobenius condition number `κ_F ≤ 30`, offsets within the sensor's
//! full-scale range, extended terms bounded over `|ΔT| ≤ 125 °C` with `T_ref` in −55…125 °C.

mod bench;

use bench::*;
use imucal_protocol::validate::{
    condition_frobenius, MAX_CONDITION_FROBENIUS, MAX_DELTA_T_C, MAX_G_SENSITIVITY,
    REFERENCE_TEMP_RANGE_C,
};
use imucal_protocol::{
    BiasTemperature, CalibrationSet, ErrorCode, InvalidParamsReason, Nonlinearity, ParamField,
    RequestBody, ResponseBody, SensorKind, MAX_FRAME, PARAMS_FORMAT_VERSION, PROTOCOL_VERSION,
};

/// A bench with `fitted_set()` committed (active sequence 1).
fn bench_with_good_set() -> (Bench, CalibrationSet) {
    let mut bench = Bench::new();
    let good = fitted_set();
    assert!(matches!(
        bench.write_and_commit(&good),
        ResponseBody::ParamStatus(_)
    ));
    (bench, good)
}

/// The device still reports `good` as active with sequence 1, and so does it after a reboot.
fn assert_still_active(bench: Bench, good: &CalibrationSet) {
    let mut bench = bench;
    for _ in 0..2 {
        assert_eq!(bench.get_params(), *good);
        let ResponseBody::Status(status) = bench.request(RequestBody::Status) else {
            panic!("Status request failed");
        };
        assert_eq!((status.active_crc, status.active_seq), (good.crc32(), 1));
        bench = bench.reboot();
    }
}

/// Write `set` with its correct CRC; the reply must be `InvalidParams(reason)`, and a commit of
/// that CRC must then find nothing staged.
fn assert_rejected(bench: &mut Bench, set: &CalibrationSet, reason: InvalidParamsReason) {
    assert_rejected_as(bench, set, |r| *r == reason);
}

/// As [`assert_rejected`], for a reason that `expected` accepts.
fn assert_rejected_as(
    bench: &mut Bench,
    set: &CalibrationSet,
    expected: impl Fn(&InvalidParamsReason) -> bool,
) {
    let crc = set.crc32();
    let reply = bench.request(RequestBody::WriteParams { set: *set, crc });
    assert!(
        matches!(&reply, ResponseBody::Error(ErrorCode::InvalidParams(r)) if expected(r)),
        "{reply:?} for {set:?}"
    );
    assert_eq!(
        bench.request(RequestBody::CommitParams { crc }),
        ResponseBody::Error(ErrorCode::NothingStaged)
    );
}

/// Makes a set invalid, given the accelerometer range and the temperature span.
type Corruption = fn(&mut CalibrationSet, f32, f32);

fn diag(x: f32, y: f32, z: f32) -> [[f32; 3]; 3] {
    [[x, 0.0, 0.0], [0.0, y, 0.0], [0.0, 0.0, z]]
}

#[test]
fn nan_or_infinity_in_any_of_the_107_float_fields_is_rejected_as_non_finite() {
    let (mut bench, good) = bench_with_good_set();
    let field_count = float_fields(&mut full_set()).len();
    // Per sensor A, b, t_ref_c, bias polynomial, scale temperature, non-linearity.
    assert_eq!(field_count, 3 * (9 + 3 + 1 + 9 + 3 + 6) + 9 + 2 + 3);
    let mut rejected = 0;
    for index in 0..field_count {
        for value in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            let mut set = full_set();
            *float_fields(&mut set).swap_remove(index) = value;
            assert_rejected_as(&mut bench, &set, |r| {
                matches!(r, InvalidParamsReason::NonFinite(_))
            });
            rejected += 1;
        }
    }
    assert_eq!(rejected, 321);
    // The unmodified set with every term present is valid, so each rejection was the value's.
    assert!(matches!(
        bench.request(RequestBody::WriteParams {
            set: full_set(),
            crc: full_set().crc32()
        }),
        ResponseBody::ParamStatus(_)
    ));
    assert_still_active(bench, &good);
}

#[test]
fn huge_zero_and_tiny_scales_are_rejected_as_gain_out_of_range() {
    let (mut bench, good) = bench_with_good_set();
    for scale in [0.0, 1.0e-30, 0.1, 2.5, 1.0e3, 1.0e30, f32::MAX, -1.0e30] {
        let mut set = good;
        set.accel.a = diag(scale, scale, scale);
        let reason = InvalidParamsReason::GainOutOfRange(SensorKind::Accel);
        assert_rejected(&mut bench, &set, reason);
    }
    // The magnetometer's window (0.005 … 4) admits a unit-field fit but not 1/500.
    let mut set = good;
    set.mag.a = diag(0.002, 0.002, 0.002);
    let reason = InvalidParamsReason::GainOutOfRange(SensorKind::Mag);
    assert_rejected(&mut bench, &set, reason);
    assert_still_active(bench, &good);
}

#[test]
fn a_negative_scale_of_plausible_size_is_accepted_as_a_reflection() {
    // The LSM9DS1 magnetometer frame is a reflection of the accelerometer frame (its X axis is
    // reversed), so a fit that maps one into the other has det A < 0 and must be accepted.
    let mut bench = Bench::new();
    let mut set = fitted_set();
    set.mag.a[0] = set.mag.a[0].map(|v| -v);
    assert!(matches!(
        bench.write_and_commit(&set),
        ResponseBody::ParamStatus(_)
    ));
    assert_eq!(bench.reboot().get_params(), set);
}

#[test]
fn singular_matrices_are_rejected_as_ill_conditioned() {
    let (mut bench, good) = bench_with_good_set();
    let singular = [
        // Two equal rows.
        [[1.0, 0.2, 0.0], [1.0, 0.2, 0.0], [0.0, 0.0, 1.0]],
        // A zero column (one axis ignored).
        [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]],
        // Rank one with a plausible gain.
        [[1.0, 1.0, 1.0], [1.0, 1.0, 1.0], [0.0, 0.0, 0.0]],
    ];
    for a in singular {
        let mut set = good;
        set.gyro.a = a;
        let reason = InvalidParamsReason::IllConditioned(SensorKind::Gyro);
        assert_rejected(&mut bench, &set, reason);
    }
    assert_still_active(bench, &good);
}

/// `diag(s, s, s/r)` has `κ_F = √((2 + 1/r²)(2 + r²))`; the stretch ratio `r` giving `κ_F = k`.
fn stretch_for_condition(k: f64) -> f64 {
    // κ_F² = 5 + 2r² + 2/r², a quadratic in r²; take the root above 1.
    let c = (k * k - 5.0) / 2.0;
    ((c + (c * c - 4.0).sqrt()) / 2.0).sqrt()
}

#[test]
fn condition_number_just_below_the_bound_is_accepted_and_just_above_is_rejected() {
    let (mut bench, good) = bench_with_good_set();
    // 0.1 % either side of κ_F = 30: far outside f32 rounding of the entries (≈ 1e-7).
    let matrix = |k: f64| {
        let r = stretch_for_condition(k) as f32;
        diag(1.2, 1.2, 1.2 / r)
    };
    let above = matrix(MAX_CONDITION_FROBENIUS * 1.001);
    let below = matrix(MAX_CONDITION_FROBENIUS * 0.999);
    let kappa_above = condition_frobenius(&above);
    let kappa_below = condition_frobenius(&below);
    assert!((kappa_above / MAX_CONDITION_FROBENIUS - 1.001).abs() < 1e-5);
    assert!((kappa_below / MAX_CONDITION_FROBENIUS - 0.999).abs() < 1e-5);

    let mut set = good;
    set.accel.a = above;
    let reason = InvalidParamsReason::IllConditioned(SensorKind::Accel);
    assert_rejected(&mut bench, &set, reason);
    assert_still_active(bench, &good);

    let (mut bench, _) = bench_with_good_set();
    set.accel.a = below;
    assert!(matches!(
        bench.write_and_commit(&set),
        ResponseBody::ParamStatus(_)
    ));
    assert_eq!(bench.get_params(), set);
}

#[test]
fn offsets_beyond_the_sensor_range_are_rejected() {
    let (mut bench, good) = bench_with_good_set();
    let s = scales();
    let ranges = [s.accel_range_mps2, s.gyro_range_rads, s.mag_range_ut];
    for (sensor, range) in ranges.iter().enumerate() {
        for axis in 0..3 {
            for sign in [1.0, -1.0] {
                let mut set = good;
                let target = [&mut set.accel, &mut set.gyro, &mut set.mag];
                // 0.1 % beyond full scale: well above f32 resolution (6e-8 relative).
                target.into_iter().nth(sensor).expect("three sensors").b[axis] =
                    sign * range * 1.001;
                let reason = InvalidParamsReason::OffsetOutOfRange(SensorKind::ALL[sensor]);
                assert_rejected(&mut bench, &set, reason);
            }
        }
    }
    // Exactly at full scale is still accepted (a sensor may be offset that far and still read).
    let mut at_range = good;
    at_range.gyro.b = [s.gyro_range_rads, 0.0, -s.gyro_range_rads];
    let crc = at_range.crc32();
    assert!(matches!(
        bench.request(RequestBody::WriteParams { set: at_range, crc }),
        ResponseBody::ParamStatus(_)
    ));
    assert_still_active(bench, &good);
}

#[test]
fn extended_terms_beyond_their_limits_are_rejected() {
    let (mut bench, good) = bench_with_good_set();
    let range = scales().accel_range_mps2;
    let dt = MAX_DELTA_T_C;
    let bias = |c1: f32| {
        Some(BiasTemperature {
            coeffs: [[c1, 0.0, 0.0], [0.0; 3], [0.0; 3]],
        })
    };
    use InvalidParamsReason::{ExtendedTermOutOfRange, ReferenceTemperatureOutOfRange};
    let cases: [(&str, Corruption, InvalidParamsReason); 7] = [
        (
            "bias shift 1 % beyond range at 125 °C",
            |s, range, dt| {
                s.accel.bias_temp = Some(BiasTemperature {
                    coeffs: [
                        [0.0; 3],
                        [0.0; 3],
                        [1.01 * range / (dt * dt * dt), 0.0, 0.0],
                    ],
                })
            },
            ExtendedTermOutOfRange(ParamField::BiasTemperature(SensorKind::Accel)),
        ),
        (
            "scale change 51 % at 125 °C",
            |s, _, dt| s.accel.scale_temp = Some([0.0, 0.51 / dt, 0.0]),
            ExtendedTermOutOfRange(ParamField::ScaleTemperature(SensorKind::Accel)),
        ),
        (
            "non-linearity 51 % at full scale",
            |s, range, _| {
                s.accel.nonlinearity = Some(Nonlinearity {
                    quadratic: [0.0; 3],
                    cubic: [0.0, 0.0, 0.51 / (range * range)],
                })
            },
            ExtendedTermOutOfRange(ParamField::Nonlinearity(SensorKind::Accel)),
        ),
        (
            "g-sensitivity 1 % above the limit",
            |s, _, _| {
                let mut k = [[0.0; 3]; 3];
                k[1][2] = -MAX_G_SENSITIVITY * 1.01;
                s.gyro_g_sensitivity = Some(k)
            },
            ExtendedTermOutOfRange(ParamField::GyroGSensitivity),
        ),
        (
            "reference temperature 10³⁰ °C",
            |s, _, _| {
                s.mag.t_ref_c = 1.0e30;
                s.mag.bias_temp = Some(BiasTemperature {
                    coeffs: [[0.0; 3], [0.0; 3], [1.0e-9, 0.0, 0.0]],
                })
            },
            ReferenceTemperatureOutOfRange(SensorKind::Mag),
        ),
        (
            "reference temperature just above the die range",
            |s, _, _| {
                s.gyro.t_ref_c = REFERENCE_TEMP_RANGE_C.1 + 0.5;
                s.gyro.bias_temp = Some(BiasTemperature {
                    coeffs: [[1.0e-4, 0.0, 0.0], [0.0; 3], [0.0; 3]],
                })
            },
            ReferenceTemperatureOutOfRange(SensorKind::Gyro),
        ),
        (
            "reference temperature just below the die range, without any temperature term",
            |s, _, _| s.gyro.t_ref_c = REFERENCE_TEMP_RANGE_C.0 - 0.5,
            ReferenceTemperatureOutOfRange(SensorKind::Gyro),
        ),
    ];
    for (what, corrupt, reason) in cases {
        let mut set = good;
        corrupt(&mut set, range, dt);
        let crc = set.crc32();
        assert_eq!(
            bench.request(RequestBody::WriteParams { set, crc }),
            ResponseBody::Error(ErrorCode::InvalidParams(reason)),
            "{what}"
        );
    }
    // At the edges of the die range the same polynomial is accepted.
    for t_ref_c in [REFERENCE_TEMP_RANGE_C.0, REFERENCE_TEMP_RANGE_C.1] {
        let mut set = good;
        set.gyro.t_ref_c = t_ref_c;
        set.gyro.bias_temp = bias(1.0e-4);
        let crc = set.crc32();
        assert!(matches!(
            bench.request(RequestBody::WriteParams { set, crc }),
            ResponseBody::ParamStatus(_)
        ));
    }
    assert_still_active(bench, &good);
}

#[test]
fn an_unsupported_format_version_is_rejected() {
    let (mut bench, good) = bench_with_good_set();
    for version in [0, PARAMS_FORMAT_VERSION + 1, u16::MAX] {
        let mut set = good;
        set.format_version = version;
        let reason = InvalidParamsReason::UnsupportedFormat { found: version };
        assert_rejected(&mut bench, &set, reason);
    }
    assert_still_active(bench, &good);
}

#[test]
fn a_write_whose_crc_does_not_match_its_set_is_a_crc_mismatch() {
    let (mut bench, good) = bench_with_good_set();
    let mut newer = good;
    newer.accel.b[0] = 0.2;
    for bit in [0, 13, 31] {
        let received = newer.crc32() ^ (1 << bit);
        assert_eq!(
            bench.request(RequestBody::WriteParams {
                set: newer,
                crc: received
            }),
            ResponseBody::Error(ErrorCode::CrcMismatch {
                received,
                computed: newer.crc32()
            })
        );
    }
    assert_still_active(bench, &good);
}

#[test]
fn a_commit_with_a_wrong_crc_or_nothing_staged_changes_nothing() {
    let (mut bench, good) = bench_with_good_set();
    assert_eq!(
        bench.request(RequestBody::CommitParams { crc: good.crc32() }),
        ResponseBody::Error(ErrorCode::NothingStaged)
    );
    let mut newer = good;
    newer.mag.b[2] = 75.0;
    let crc = newer.crc32();
    assert!(matches!(
        bench.request(RequestBody::WriteParams { set: newer, crc }),
        ResponseBody::ParamStatus(_)
    ));
    assert_eq!(
        bench.request(RequestBody::CommitParams { crc: crc ^ 1 }),
        ResponseBody::Error(ErrorCode::CrcMismatch {
            received: crc ^ 1,
            computed: crc
        })
    );
    assert_still_active(bench, &good);
}

/// A payload whose request body is variant `variant` (postcard varint) followed by `tail`.
fn unknown_variant_payload(seq: u16, variant: u32, tail: &[u8]) -> Vec<u8> {
    let mut payload = request_payload(seq, &RequestBody::Status);
    payload.pop(); // the Status tag
    let mut v = variant;
    loop {
        let byte = (v & 0x7F) as u8;
        v >>= 7;
        if v == 0 {
            payload.push(byte);
            break;
        }
        payload.push(byte | 0x80);
    }
    payload.extend_from_slice(tail);
    payload
}

#[test]
fn unknown_request_variants_are_answered_unknown_request_with_their_seq() {
    let (mut bench, good) = bench_with_good_set();
    // RequestBody has 10 variants (0…9); anything above is from a newer host.
    for (seq, variant) in [
        (1u16, 10u32),
        (300, 11),
        (40_000, 127),
        (65_535, 128),
        (0, u32::MAX),
    ] {
        for tail in [&[][..], &[1, 2, 3], &[0xFF; 20]] {
            let mut frame = vec![0];
            frame.extend(frame_payload(&unknown_variant_payload(seq, variant, tail)));
            assert_eq!(
                bench.exchange(&frame),
                Some((seq, ResponseBody::Error(ErrorCode::UnknownRequest)))
            );
        }
    }
    // An unknown StreamKind (2) inside a known request: the body does not decode either.
    let mut payload = request_payload(9, &RequestBody::StopStream);
    payload.pop();
    payload.extend([3, 2, 1]); // StartStream, kind 2, decimation 1
    assert_eq!(
        bench.exchange(&frame_payload(&payload)),
        Some((9, ResponseBody::Error(ErrorCode::UnknownRequest)))
    );
    // A seq that is not a valid u16 varint cannot be echoed: dropped and counted.
    let errors_before = bench.device.error_counters().rx_frame_errors;
    assert_eq!(
        bench.exchange(&frame_payload(&[0xFF, 0xFF, 0xFF, 0x01])),
        None
    );
    assert_eq!(
        bench.device.error_counters().rx_frame_errors,
        errors_before + 1
    );
    assert_still_active(bench, &good);
}

#[test]
fn hello_with_another_protocol_major_is_a_version_mismatch() {
    let (mut bench, good) = bench_with_good_set();
    let mismatch = ResponseBody::Error(ErrorCode::VersionMismatch {
        device_major: PROTOCOL_VERSION.major,
        device_minor: PROTOCOL_VERSION.minor,
    });
    for (major, minor) in [
        (0, 0),
        (PROTOCOL_VERSION.major + 1, 0),
        (u16::MAX, u16::MAX),
    ] {
        let reply = bench.request(RequestBody::Hello {
            protocol_major: major,
            protocol_minor: minor,
        });
        assert_eq!(reply, mismatch, "host {major}.{minor}");
    }
    // Same major, newer minor: compatible.
    let reply = bench.request(RequestBody::Hello {
        protocol_major: PROTOCOL_VERSION.major,
        protocol_minor: u16::MAX,
    });
    assert!(matches!(reply, ResponseBody::Welcome(_)), "{reply:?}");
    assert_still_active(bench, &good);
}

#[test]
fn sequence_ids_wrap_around_and_are_echoed() {
    let (mut bench, good) = bench_with_good_set();
    for seq in [65_533u16, 65_534, 65_535, 0, 1, 2] {
        let frame = request_frame(seq, &RequestBody::Ping(u32::from(seq)));
        assert_eq!(
            bench.exchange(&frame),
            Some((seq, ResponseBody::Pong(u32::from(seq))))
        );
    }
    assert_still_active(bench, &good);
}

#[test]
fn max_size_frames_are_served_and_one_byte_more_is_dropped() {
    let (mut bench, good) = bench_with_good_set();
    // A payload without zeros of p bytes encodes to p + 4 (CRC) + ⌈(p+4)/254⌉ code bytes, if the
    // CRC has no zero byte either; search for a tail that makes the body exactly `len` bytes.
    let body_of_len = |len: usize| -> Vec<u8> {
        for salt in 1..=255u8 {
            for p in (len - 10)..len {
                let mut payload = unknown_variant_payload(77, 10, &[]);
                payload.resize(p, salt);
                let frame = frame_payload(&payload);
                if frame.len() == len + 1 {
                    return frame;
                }
            }
        }
        panic!("no payload encodes to {len} bytes");
    };
    // The receive buffer holds MAX_FRAME bytes besides the delimiter.
    let largest = body_of_len(MAX_FRAME);
    assert_eq!(
        bench.exchange(&largest),
        Some((77, ResponseBody::Error(ErrorCode::UnknownRequest)))
    );
    let errors_before = bench.device.error_counters().rx_frame_errors;
    let oversize = body_of_len(MAX_FRAME + 1);
    assert_eq!(bench.exchange(&oversize), None);
    assert_eq!(
        bench.device.error_counters().rx_frame_errors,
        errors_before + 1
    );
    // The largest real request: every optional term and a ten-byte creation time.
    let mut biggest = full_set();
    biggest.created_unix_s = u64::MAX;
    let frame = request_frame(
        5,
        &RequestBody::WriteParams {
            set: biggest,
            crc: u32::MAX,
        },
    );
    assert!(frame.len() <= MAX_FRAME, "{} bytes", frame.len());
    assert_eq!(
        bench.exchange(&frame),
        Some((
            5,
            ResponseBody::Error(ErrorCode::CrcMismatch {
                received: u32::MAX,
                computed: biggest.crc32()
            })
        ))
    );
    // Service continues after the overflow.
    assert_eq!(bench.request(RequestBody::Ping(1)), ResponseBody::Pong(1));
    assert_still_active(bench, &good);
}

#[test]
fn zero_length_and_crc_only_frames_draw_no_reply() {
    let (mut bench, good) = bench_with_good_set();
    let errors_before = bench.device.error_counters().rx_frame_errors;
    // Empty frames (bare delimiters) are skipped silently: no reply, no error.
    assert_eq!(bench.exchange(&[0; 1000]), None);
    assert_eq!(bench.device.error_counters().rx_frame_errors, errors_before);
    // Shorter than a CRC, and a CRC over an empty payload: dropped and counted.
    assert_eq!(bench.exchange(&[0x02, 0x11, 0x00]), None);
    assert_eq!(bench.exchange(&frame_payload(&[])), None);
    assert_eq!(
        bench.device.error_counters().rx_frame_errors,
        errors_before + 2
    );
    assert_eq!(bench.request(RequestBody::Ping(2)), ResponseBody::Pong(2));
    assert_still_active(bench, &good);
}
