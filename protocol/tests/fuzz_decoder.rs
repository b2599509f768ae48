//! Seeded fuzz storm of the frame decoder: over 10⁶ frames — valid requests and device
//! messages (full sample batches, log lines, hostile floats), the same mutated, random bytes,
//! empty frames and frames at and beyond the size limit — fed in random chunks.
//!
//! Checked: no panic; the decoder never holds more than its buffer; every valid frame that
//! follows a delimiter comes out with exactly its payload, whatever garbage preceded it; no
//! corrupted frame yields a payload other than an intact frame's; every payload that decodes
//! re-encodes to the same bytes; the postcard decoders and `Request::peek_seq` survive every
//! payload. Run with `--nocapture` to see the figures.

use std::collections::BTreeMap;
use std::time::Instant;

use imucal_protocol::*;

const FRAMES: usize = 1_000_000;
const SEED: u64 = 0x0DDB_A11C_0FFE_E123;

/// xorshift64*: small, fast, deterministic.
struct Rng(u64);

impl Rng {
    fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }

    fn byte(&mut self) -> u8 {
        self.next_u64() as u8
    }

    fn f32(&mut self) -> f32 {
        match self.below(4) {
            0 => [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -0.0, f32::MAX][self.below(5)],
            _ => f32::from_bits(self.next_u64() as u32),
        }
    }

    fn i16(&mut self) -> i16 {
        self.next_u64() as i16
    }
}

/// Postcard bytes of a value (NaN-safe comparison).
fn bytes_of<T: serde::Serialize>(value: &T) -> Vec<u8> {
    let mut buffer = [0u8; 2 * MAX_FRAME];
    postcard::to_slice(value, &mut buffer)
        .expect("every message fits twice a frame")
        .to_vec()
}

fn frame_of<T: serde::Serialize>(value: &T) -> Vec<u8> {
    let mut buffer = [0u8; MAX_FRAME];
    let len = encode_frame(value, &mut buffer).expect("every message fits a frame");
    buffer[..len].to_vec()
}

fn random_set(rng: &mut Rng) -> CalibrationSet {
    let mut set = CalibrationSet::identity();
    set.created_unix_s = rng.next_u64();
    for sensor in [&mut set.accel, &mut set.gyro, &mut set.mag] {
        sensor.a = [[rng.f32(), rng.f32(), rng.f32()]; 3];
        sensor.b = [rng.f32(), rng.f32(), rng.f32()];
        sensor.t_ref_c = rng.f32();
        if rng.below(2) == 0 {
            sensor.bias_temp = Some(BiasTemperature {
                coeffs: [[rng.f32(); 3]; 3],
            });
            sensor.scale_temp = Some([rng.f32(); 3]);
            sensor.nonlinearity = Some(Nonlinearity {
                quadratic: [rng.f32(); 3],
                cubic: [rng.f32(); 3],
            });
        }
    }
    if rng.below(2) == 0 {
        set.gyro_g_sensitivity = Some([[rng.f32(); 3]; 3]);
    }
    set
}

fn random_request(rng: &mut Rng) -> Request {
    let body = match rng.below(10) {
        0 => RequestBody::Hello {
            protocol_major: rng.next_u64() as u16,
            protocol_minor: rng.next_u64() as u16,
        },
        1 => RequestBody::Ping(rng.next_u64() as u32),
        2 => RequestBody::Status,
        3 => RequestBody::StartStream {
            kind: StreamKind::Calibrated,
            decimation: rng.next_u64() as u16,
        },
        4 => RequestBody::StopStream,
        5 => RequestBody::CapturePose {
            min_still_ms: rng.next_u64() as u32,
            thresholds: StillThresholds {
                accel_std_mps2: rng.f32(),
                gyro_std_rads: rng.f32(),
            },
            timeout_ms: rng.next_u64() as u32,
        },
        6 => RequestBody::GetParams,
        7 => RequestBody::WriteParams {
            set: random_set(rng),
            crc: rng.next_u64() as u32,
        },
        8 => RequestBody::CommitParams {
            crc: rng.next_u64() as u32,
        },
        _ => RequestBody::ResetParams,
    };
    Request {
        seq: rng.next_u64() as u16,
        body,
    }
}

fn random_device_message(rng: &mut Rng) -> DeviceMessage {
    let header = BatchHeader {
        first_index: rng.next_u64() as u32,
        t0_us: rng.next_u64() >> 1,
        tick_us: 1 + rng.below(1000) as u32,
    };
    let event = match rng.below(5) {
        0 => {
            // Full batches are the largest frames the device sends.
            let mut batch = SampleBatch::new(header);
            for i in 0..RAW_BATCH_CAPACITY {
                let sample = RawSample {
                    accel: [rng.i16(), rng.i16(), rng.i16()],
                    gyro: [rng.i16(), rng.i16(), rng.i16()],
                    mag: [rng.i16(), rng.i16(), rng.i16()],
                    temp: rng.i16(),
                };
                let t = header.t0_us + i as u64 * u64::from(header.tick_us);
                batch.push(&sample, t).expect("the batch has room");
            }
            Event::SampleBatch(batch)
        }
        1 => {
            let mut batch = CalibratedBatch::new(header);
            for i in 0..CALIBRATED_BATCH_CAPACITY {
                let sample = CalibratedSample {
                    accel: [rng.f32(), rng.f32(), rng.f32()],
                    gyro: [rng.f32(), rng.f32(), rng.f32()],
                    mag: [rng.f32(), rng.f32(), rng.f32()],
                    temp_c: rng.f32(),
                };
                let t = header.t0_us + i as u64 * u64::from(header.tick_us);
                batch.push(&sample, t).expect("the batch has room");
            }
            Event::CalibratedBatch(batch)
        }
        2 => {
            let text: String = (0..rng.below(200))
                .map(|_| char::from_u32(rng.below(0x11_0000) as u32).unwrap_or('\u{FFFD}'))
                .collect();
            Event::Log(LogMessage::new(LogLevel::Warn, &text))
        }
        3 => Event::StillnessChanged {
            still: rng.below(2) == 0,
            t_ms: rng.next_u64(),
        },
        _ => {
            return DeviceMessage::Response(Response {
                seq: rng.next_u64() as u16,
                body: match rng.below(3) {
                    0 => ResponseBody::Params(random_set(rng)),
                    1 => ResponseBody::Error(ErrorCode::CrcMismatch {
                        received: rng.next_u64() as u32,
                        computed: rng.next_u64() as u32,
                    }),
                    _ => ResponseBody::Pong(rng.next_u64() as u32),
                },
            })
        }
    };
    DeviceMessage::Event(event)
}

fn mutate(rng: &mut Rng, frame: &mut Vec<u8>) {
    for _ in 0..1 + rng.below(3) {
        if frame.is_empty() {
            return;
        }
        let at = rng.below(frame.len());
        match rng.below(6) {
            0 => frame[at] ^= 1 << rng.below(8),
            1 => frame[at] = rng.byte(),
            2 => frame.insert(at, rng.byte()),
            3 => {
                frame.remove(at);
            }
            4 => frame.truncate(at),
            _ => {
                if let Some(last) = frame.last_mut() {
                    *last = rng.byte() | 1; // lost delimiter
                }
            }
        }
    }
}

/// Every payload must survive both decoders; one that decodes must re-encode to itself.
fn check_payload(payload: &[u8], figures: &mut BTreeMap<&'static str, usize>) {
    let _ = Request::peek_seq(payload);
    if let Ok(request) = decode_payload::<Request>(payload) {
        assert_eq!(bytes_of(&request), payload);
        *figures.entry("payload decodes as request").or_default() += 1;
    }
    if let Ok(message) = decode_payload::<DeviceMessage>(payload) {
        assert_eq!(bytes_of(&message), payload);
        *figures
            .entry("payload decodes as device message")
            .or_default() += 1;
    }
}

#[test]
fn a_million_frames_in_random_chunks_decode_exactly_or_are_reported() {
    let started = Instant::now();
    let mut rng = Rng(SEED);
    let mut decoder = FrameDecoder::<MAX_FRAME>::new();
    let mut figures: BTreeMap<&'static str, usize> = BTreeMap::new();
    let mut total_bytes = 0usize;
    // Original payloads of recent frames: a mutated frame that only lost its delimiter is
    // completed intact by a later delimiter.
    let mut recent: Vec<Vec<u8>> = Vec::new();

    for _ in 0..FRAMES {
        let (kind, bytes, valid_payload) = match rng.below(10) {
            0..=2 => {
                let (payload, frame) = if rng.below(2) == 0 {
                    let m = random_request(&mut rng);
                    (bytes_of(&m), frame_of(&m))
                } else {
                    let m = random_device_message(&mut rng);
                    (bytes_of(&m), frame_of(&m))
                };
                assert!(frame.len() <= MAX_FRAME);
                let mut bytes = vec![0];
                bytes.extend(frame);
                ("valid", bytes, Some(payload))
            }
            3..=5 => {
                let (payload, mut frame) = if rng.below(2) == 0 {
                    let m = random_request(&mut rng);
                    (bytes_of(&m), frame_of(&m))
                } else {
                    let m = random_device_message(&mut rng);
                    (bytes_of(&m), frame_of(&m))
                };
                mutate(&mut rng, &mut frame);
                recent.push(payload);
                ("mutated", frame, None)
            }
            6..=7 => {
                let len = rng.below(700);
                let bytes = (0..len)
                    .map(|_| if rng.below(40) == 0 { 0 } else { rng.byte() })
                    .collect();
                ("random", bytes, None)
            }
            8 => ("empty", vec![0; 1 + rng.below(3)], None),
            _ => {
                // Non-zero bodies around the buffer size: they fit (and fail the CRC) or overflow.
                let len = MAX_FRAME - 2 + rng.below(5);
                let mut bytes: Vec<u8> = (0..len).map(|_| rng.byte() | 1).collect();
                bytes.push(0);
                ("size limit", bytes, None)
            }
        };
        *figures.entry(kind).or_default() += 1;
        total_bytes += bytes.len();

        // Feed in random chunks.
        let mut completed: Vec<Result<Vec<u8>, FrameError>> = Vec::new();
        let mut rest = &bytes[..];
        while !rest.is_empty() {
            let take = (1 + rng.below(300)).min(rest.len());
            let (chunk, tail) = rest.split_at(take);
            rest = tail;
            for &byte in chunk {
                if let Some(frame) = decoder.push(byte) {
                    completed.push(frame.map(<[u8]>::to_vec));
                }
                assert!(decoder.pending() <= MAX_FRAME);
            }
        }

        for result in &completed {
            match result {
                Ok(payload) => {
                    check_payload(payload, &mut figures);
                    // Only an intact frame may come out: this one, or an earlier valid frame
                    // completed late; anything else would be a CRC collision.
                    let known = valid_payload.as_ref() == Some(payload) || recent.contains(payload);
                    assert!(known, "a corrupted {kind} frame decoded as {payload:?}");
                }
                Err(error) => {
                    *figures
                        .entry(match error {
                            FrameError::Overflow => "error: overflow",
                            FrameError::Cobs => "error: cobs",
                            FrameError::TooShort => "error: too short",
                            FrameError::Crc => "error: crc",
                            FrameError::Decode => "error: decode",
                        })
                        .or_default() += 1;
                }
            }
        }
        if let Some(payload) = valid_payload {
            assert_eq!(
                completed.last(),
                Some(&Ok(payload.clone())),
                "a valid frame after a delimiter must decode exactly"
            );
        }
        if recent.len() > 8 {
            recent.remove(0);
        }
        // Random payload bytes straight into the postcard decoders.
        if rng.below(4) == 0 {
            let len = rng.below(MAX_PAYLOAD);
            let payload: Vec<u8> = (0..len).map(|_| rng.byte()).collect();
            check_payload(&payload, &mut figures);
        }
    }
    let elapsed = started.elapsed().as_secs_f64();
    eprintln!("decoder storm: {FRAMES} frames, {total_bytes} bytes, {elapsed:.1} s");
    eprintln!("{figures:?}");
    assert!(figures.get("valid").copied().unwrap_or(0) > FRAMES / 4);
    for error in [
        "error: overflow",
        "error: cobs",
        "error: too short",
        "error: crc",
    ] {
        assert!(
            figures.get(error).copied().unwrap_or(0) > 0,
            "never saw {error}"
        );
    }
}
