//! Seeded fuzz storm through the whole device: over 10⁶ frames — random bytes, mutated valid
//! frames, empty and oversize frames, valid frames with hostile contents (NaN/∞ parameters,
//! singular or huge matrices, out-of-range offsets, wrong CRCs, wrong protocol versions) and
//! raw payloads with valid CRCs (unknown variants, truncated or over-long bodies) — fed into one
//! [`Device`](imucal_firmware::device::Device) through `poll()`.
//!
//! A reference model of the parameter protocol predicts every reply and the active set after
//! every frame. Checked after each frame: no panic; no poll reads more than the flood limit or
//! stalls on available input; the active set equals the model's (so it changes only through an
//! intact `CommitParams` whose CRC matches a staged, validated set, or `ResetParams`), passes
//! validation and yields finite output on every corner of the input space; calibrated stream
//! samples are finite. After the storm the device still answers `Ping`. Run with
//! `cargo test --release -p imucal-firmware --test fuzz_device_storm -- --nocapture` to see
//! the figures.

mod bench;

use std::collections::BTreeMap;
use std::time::Instant;

use bench::*;
use imucal_firmware::apply::Correction;
use imucal_protocol::validate;
use imucal_protocol::{
    decode_payload, CalibrationSet, ErrorCode, Event, FrameDecoder, ParamStatus, RawSample,
    Request, RequestBody, ResponseBody, StillThresholds, StreamKind, MAX_FRAME,
    PARAMS_FORMAT_VERSION, PROTOCOL_VERSION,
};

/// Frames in the storm; the issue asks for at least 10⁶.
const FRAMES: usize = 1_000_000;
const SEED: u64 = 0x1A2B_3C4D_5E6F_7081;

/// What the device must make of one frame it completes.
#[derive(Debug)]
#[allow(
    clippy::large_enum_variant,
    reason = "a few per frame, short-lived; boxing would only add noise"
)]
enum Expect {
    /// Decodes as this request.
    Request(Request),
    /// Valid CRC, body undecodable, seq readable: answered `UnknownRequest`.
    Unknown(u16),
    /// Must change nothing and draw no reply (corrupt, truncated, random, empty, oversize).
    Noise,
}

/// The reply the model wants.
#[derive(Debug)]
#[allow(
    clippy::large_enum_variant,
    reason = "a few per frame, short-lived; boxing would only add noise"
)]
enum Want {
    /// Exactly this body.
    Exact(ResponseBody),
    /// A `Welcome` with this firmware's protocol version.
    Welcome,
    /// A `Status` reporting the model's active set.
    Status { active_crc: u32, active_seq: u32 },
}

/// The parameter and pose state the device should be in.
struct Model {
    active: CalibrationSet,
    active_seq: u32,
    staged: Option<(CalibrationSet, u32)>,
    /// Sequence id of a pose capture whose reply is still due.
    pose: Option<u16>,
    /// CRC of the last staged set, reused by commits so that they sometimes match.
    last_crc: u32,
}

impl Model {
    fn status(&self) -> ResponseBody {
        ResponseBody::ParamStatus(ParamStatus {
            active_crc: self.active.crc32(),
            active_seq: self.active_seq,
            staged_crc: self.staged.map(|(_, crc)| crc),
        })
    }

    /// The immediate reply the device must give to `request` (`None` for a pose capture that
    /// started), updating the model.
    fn apply(&mut self, request: &Request) -> Option<Want> {
        let reply = match &request.body {
            RequestBody::Hello { protocol_major, .. } => {
                if *protocol_major == PROTOCOL_VERSION.major {
                    return Some(Want::Welcome);
                }
                ResponseBody::Error(ErrorCode::VersionMismatch {
                    device_major: PROTOCOL_VERSION.major,
                    device_minor: PROTOCOL_VERSION.minor,
                })
            }
            RequestBody::Ping(value) => ResponseBody::Pong(*value),
            RequestBody::Status => {
                return Some(Want::Status {
                    active_crc: self.active.crc32(),
                    active_seq: self.active_seq,
                })
            }
            RequestBody::StartStream { decimation: 0, .. } => {
                ResponseBody::Error(ErrorCode::InvalidArgument)
            }
            RequestBody::StartStream { .. } | RequestBody::StopStream => ResponseBody::Ack,
            RequestBody::CapturePose { thresholds, .. } => {
                let usable = |v: f32| v.is_finite() && v > 0.0;
                if self.pose.is_some() {
                    ResponseBody::Error(ErrorCode::Busy)
                } else if !usable(thresholds.accel_std_mps2) || !usable(thresholds.gyro_std_rads) {
                    ResponseBody::Error(ErrorCode::InvalidArgument)
                } else {
                    self.pose = Some(request.seq);
                    return None;
                }
            }
            RequestBody::GetParams => ResponseBody::Params(self.active),
            RequestBody::WriteParams { set, crc } => {
                let computed = set.crc32();
                if computed != *crc {
                    ResponseBody::Error(ErrorCode::CrcMismatch {
                        received: *crc,
                        computed,
                    })
                } else if let Err(reason) = validate(set, &scales()) {
                    ResponseBody::Error(ErrorCode::InvalidParams(reason))
                } else {
                    self.staged = Some((*set, *crc));
                    self.status()
                }
            }
            RequestBody::CommitParams { crc } => match self.staged {
                None => ResponseBody::Error(ErrorCode::NothingStaged),
                Some((_, staged)) if staged != *crc => {
                    ResponseBody::Error(ErrorCode::CrcMismatch {
                        received: *crc,
                        computed: staged,
                    })
                }
                Some((set, _)) => {
                    self.active = set;
                    self.active_seq += 1;
                    self.staged = None;
                    self.status()
                }
            },
            RequestBody::ResetParams => {
                self.active = CalibrationSet::identity();
                self.active_seq += 1;
                self.staged = None;
                self.status()
            }
        };
        Some(Want::Exact(reply))
    }
}

/// Counters reported at the end.
#[derive(Default)]
struct Figures {
    frames: BTreeMap<&'static str, usize>,
    replies: BTreeMap<String, usize>,
    bytes: usize,
    polls: usize,
    calibrated_samples_checked: usize,
    /// Mutated frames that still decoded: a frame that only lost its delimiter is completed
    /// intact by the next one's; anything else would be a CRC-32 collision (≈ 2⁻³² each).
    noise_that_decoded: usize,
}

fn reply_name(body: &ResponseBody) -> String {
    match body {
        ResponseBody::Error(ErrorCode::InvalidParams(reason)) => {
            // The reason's kind; the field it names varies.
            let reason = format!("{reason:?}");
            let kind = reason.split(['(', ' ']).next().unwrap_or_default();
            format!("InvalidParams({kind})")
        }
        ResponseBody::Error(code) => {
            let name = format!("{code:?}");
            name.split([' ', '{', '(']).next().unwrap_or("").to_string()
        }
        other => {
            let name = format!("{other:?}");
            name.split([' ', '{', '(']).next().unwrap_or("").to_string()
        }
    }
}

/// A random request with hostile contents often enough to reach every rejection.
fn random_request(rng: &mut Rng, model: &mut Model, seq: u16) -> Request {
    let body = match rng.below(100) {
        0..=4 => RequestBody::Hello {
            protocol_major: if rng.chance(0.5) {
                PROTOCOL_VERSION.major
            } else {
                rng.next_u32() as u16
            },
            protocol_minor: rng.next_u32() as u16,
        },
        5..=14 => RequestBody::Ping(rng.next_u32()),
        15..=18 => RequestBody::Status,
        19..=22 => RequestBody::StartStream {
            kind: if rng.chance(0.5) {
                StreamKind::Raw
            } else {
                StreamKind::Calibrated
            },
            decimation: [0, 1, 2, 7, u16::MAX][rng.below(5)],
        },
        23..=27 => RequestBody::StopStream,
        28..=31 => RequestBody::CapturePose {
            min_still_ms: [0, 10, 100, 300, u32::MAX][rng.below(5)],
            thresholds: StillThresholds {
                accel_std_mps2: if rng.chance(0.8) {
                    0.05
                } else {
                    rng.hostile_f32()
                },
                gyro_std_rads: if rng.chance(0.8) {
                    0.01
                } else {
                    rng.hostile_f32()
                },
            },
            timeout_ms: [0, 50, 500, 2_000, u32::MAX][rng.below(5)],
        },
        32..=39 => RequestBody::GetParams,
        40..=71 => {
            let set = random_write_set(rng);
            let crc = if rng.chance(0.1) {
                set.crc32() ^ (1 << rng.below(32))
            } else {
                set.crc32()
            };
            model.last_crc = crc;
            RequestBody::WriteParams { set, crc }
        }
        72..=97 => RequestBody::CommitParams {
            crc: match (rng.below(10), model.staged) {
                (0..=6, Some((_, crc))) => crc,
                (0..=7, _) => model.last_crc,
                _ => rng.next_u32(),
            },
        },
        _ => RequestBody::ResetParams,
    };
    Request { seq, body }
}

/// A set for `WriteParams`: plausible, plausible with one hostile float, or structurally bad.
fn random_write_set(rng: &mut Rng) -> CalibrationSet {
    let mut set = random_plausible_set(rng);
    match rng.below(10) {
        0..=3 => {}
        4..=6 => {
            let fields = float_fields(&mut set);
            let index = rng.below(fields.len());
            let value = rng.hostile_f32();
            if let Some(field) = fields.into_iter().nth(index) {
                *field = value;
            }
        }
        7 => {
            // Singular: one row repeated, or a zero column.
            let which = rng.below(3);
            let sensor = match which {
                0 => &mut set.accel,
                1 => &mut set.gyro,
                _ => &mut set.mag,
            };
            if rng.chance(0.5) {
                sensor.a[2] = sensor.a[0];
            } else {
                for row in &mut sensor.a {
                    row[rng.below(3)] = 0.0;
                }
            }
        }
        8 => {
            let which = rng.below(3);
            let sensor = match which {
                0 => &mut set.accel,
                1 => &mut set.gyro,
                _ => &mut set.mag,
            };
            let factor = [0.0, -1.0, 1.0e-3, 1.0e3, -1.0e30][rng.below(5)];
            for value in sensor.a.iter_mut().flatten() {
                *value *= factor;
            }
            sensor.b[rng.below(3)] *= [1.0, 2.0, -1.0e6][rng.below(3)];
        }
        _ => {
            set.format_version = if rng.chance(0.5) {
                PARAMS_FORMAT_VERSION
            } else {
                rng.next_u32() as u16
            };
            set.created_unix_s = rng.next_u64();
        }
    }
    set
}

/// Corrupt a valid frame: bit flips, byte changes, insertions, deletions, truncation,
/// duplication, a lost or an extra delimiter.
fn mutate(rng: &mut Rng, frame: &mut Vec<u8>) {
    for _ in 0..1 + rng.below(4) {
        if frame.is_empty() {
            return;
        }
        let at = rng.below(frame.len());
        match rng.below(8) {
            0 => frame[at] ^= 1 << rng.below(8),
            1 => frame[at] = rng.byte(),
            2 => frame.insert(at, rng.byte()),
            3 => {
                frame.remove(at);
            }
            4 => frame.truncate(at),
            5 => {
                let end = (at + 1 + rng.below(16)).min(frame.len());
                let copy = frame[at..end].to_vec();
                frame.splice(at..at, copy);
            }
            6 => {
                if let Some(last) = frame.last_mut() {
                    *last = rng.byte() | 1; // the delimiter is lost
                }
            }
            _ => frame.insert(at, 0),
        }
    }
}

/// A payload with a valid CRC that the device cannot decode as a request (or, rarely, can).
fn raw_payload(rng: &mut Rng, seq: u16) -> Vec<u8> {
    let mut valid = request_payload(seq, &random_request(rng, &mut dummy_model(), seq).body);
    match rng.below(5) {
        0 => {
            // Unknown variant: indices past ResetParams, as a varint, then anything.
            let mut payload = request_payload(seq, &RequestBody::Status);
            payload.pop();
            let variant = [10u32, 11, 127, 128, 300, u32::MAX][rng.below(6)];
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
            let len = rng.below(40);
            payload.extend(rng.bytes(len, false));
            payload
        }
        1 => {
            valid.truncate(rng.below(valid.len()));
            valid
        }
        2 => {
            let len = 1 + rng.below(8);
            valid.extend(rng.bytes(len, false));
            valid
        }
        3 => {
            // Over-long varints where counts and tags are read.
            let mut payload = valid[..rng.below(valid.len())].to_vec();
            payload.extend([0xFF; 11]);
            payload
        }
        _ => {
            let len = rng.below(MAX_FRAME - 8);
            rng.bytes(len, false)
        }
    }
}

fn dummy_model() -> Model {
    Model {
        active: CalibrationSet::identity(),
        active_seq: 0,
        staged: None,
        pose: None,
        last_crc: 0,
    }
}

/// The device's output on every corner of the input space must be finite under `set`.
fn assert_finite_on_corners(set: &CalibrationSet) {
    let correction = Correction::new(set, &scales()).expect("the active set validates");
    for sample in corner_samples() {
        let out = correction.apply(&sample);
        let values = out.accel.iter().chain(&out.gyro).chain(&out.mag);
        assert!(
            values.clone().all(|v| v.is_finite()),
            "non-finite output {out:?} for {sample:?} under {set:?}"
        );
    }
}

fn same_set(a: &CalibrationSet, b: &CalibrationSet) -> bool {
    request_payload(0, &RequestBody::WriteParams { set: *a, crc: 0 })
        == request_payload(0, &RequestBody::WriteParams { set: *b, crc: 0 })
}

fn random_sample(rng: &mut Rng) -> RawSample {
    let mut value = || match rng.below(4) {
        0 => i16::MAX,
        1 => i16::MIN,
        _ => rng.next_u32() as i16,
    };
    RawSample {
        accel: [value(), value(), value()],
        gyro: [value(), value(), value()],
        mag: [value(), value(), value()],
        temp: value(),
    }
}

/// What a decoder in the device's state makes of `bytes`: the shadow decoder sees exactly the
/// bytes the device sees, so it knows which frames arrive intact.
fn expectations(shadow: &mut FrameDecoder<MAX_FRAME>, bytes: &[u8]) -> Vec<Expect> {
    let mut out = Vec::new();
    for &byte in bytes {
        match shadow.push(byte) {
            None => {}
            Some(Err(_)) => out.push(Expect::Noise),
            Some(Ok(payload)) => out.push(match decode_payload::<Request>(payload) {
                Ok(request) => Expect::Request(request),
                Err(_) => Request::peek_seq(payload).map_or(Expect::Noise, Expect::Unknown),
            }),
        }
    }
    out
}

fn is_pose_result(body: &ResponseBody) -> bool {
    matches!(
        body,
        ResponseBody::PoseStats(_)
            | ResponseBody::Error(ErrorCode::NotStill | ErrorCode::Timeout | ErrorCode::Saturated)
    )
}

#[test]
fn a_million_hostile_frames_change_parameters_only_through_valid_commits() {
    let started = Instant::now();
    let mut rng = Rng::new(SEED);
    let mut bench = Bench::new();
    let mut shadow = FrameDecoder::<MAX_FRAME>::new();
    let mut model = dummy_model();
    let mut figures = Figures::default();
    let mut checked_seq = 0;
    let mut seq: u16 = 0xFF00; // wraps past u16::MAX early in the storm

    for _ in 0..FRAMES {
        // Now and then the board moves, or sits on a rail, so captures and streams see it all.
        if rng.chance(0.05) {
            bench.sample.set(if rng.chance(0.5) {
                STILL_SAMPLE
            } else {
                random_sample(&mut rng)
            });
        }
        seq = seq.wrapping_add(1);
        let mut intact = None;
        let (kind, bytes) = match rng.below(100) {
            0..=14 => {
                let len = rng.below(700);
                let zeros = rng.chance(0.5);
                ("random bytes", rng.bytes(len, zeros))
            }
            15..=34 => {
                let request = random_request(&mut rng, &mut dummy_model(), seq);
                let mut frame = request_frame(seq, &request.body);
                mutate(&mut rng, &mut frame);
                ("mutated frame", frame)
            }
            35..=37 => ("empty frames", vec![0; 1 + rng.below(4)]),
            38..=39 => {
                // Just fits the receive buffer (and fails its CRC), or overflows it.
                let len = MAX_FRAME - 1 + rng.below(3) * rng.below(300);
                let mut frame: Vec<u8> = (0..len).map(|_| rng.byte() | 1).collect();
                frame.push(0);
                ("max-size frame", frame)
            }
            40..=49 => {
                let mut frame = vec![0];
                frame.extend(frame_payload(&raw_payload(&mut rng, seq)));
                ("raw payload", frame)
            }
            _ => {
                let request = random_request(&mut rng, &mut model, seq);
                // A leading delimiter ends any unfinished garbage, so this frame arrives intact.
                let mut frame = vec![0];
                frame.extend(request_frame(seq, &request.body));
                intact = Some(request);
                ("valid request", frame)
            }
        };
        *figures.frames.entry(kind).or_default() += 1;
        figures.bytes += bytes.len();

        let expects = expectations(&mut shadow, &bytes);
        if let Some(request) = &intact {
            // The frame's own delimiter completes it last. (Its leading one may complete an
            // earlier frame that only lost its delimiter, which then arrives intact too.)
            // Compared as bytes: NaN fields make `PartialEq` false even for identical sets.
            let arrived = match expects.last() {
                Some(Expect::Request(r)) => request_payload(r.seq, &r.body),
                other => panic!("a valid frame arrived as {other:?}"),
            };
            assert_eq!(
                arrived,
                request_payload(request.seq, &request.body),
                "a valid frame must arrive intact"
            );
        }
        let completed = expects.len().saturating_sub(usize::from(intact.is_some()));
        let decoded_garbage = expects
            .iter()
            .take(completed)
            .filter(|e| !matches!(e, Expect::Noise))
            .count();
        if kind != "raw payload" {
            figures.noise_that_decoded += decoded_garbage;
        }
        let mut wanted: Vec<(u16, Want)> = Vec::new();
        for expect in &expects {
            match expect {
                Expect::Request(request) => {
                    if let Some(want) = model.apply(request) {
                        wanted.push((request.seq, want));
                    }
                }
                Expect::Unknown(seq) => wanted.push((
                    *seq,
                    Want::Exact(ResponseBody::Error(ErrorCode::UnknownRequest)),
                )),
                Expect::Noise => {}
            }
        }

        bench.push_bytes(&bytes);
        figures.polls += bench.drain();
        let received = bench.collect();
        assert_eq!(received.bad_frames, 0, "device output must always decode");

        // Replies in order; a pose result may come at any time.
        let mut wanted = wanted.into_iter();
        for (reply_seq, body) in received.responses {
            *figures.replies.entry(reply_name(&body)).or_default() += 1;
            if is_pose_result(&body) && model.pose == Some(reply_seq) {
                model.pose = None;
                continue;
            }
            let Some((want_seq, want)) = wanted.next() else {
                panic!("unexpected reply {body:?} to a {kind}");
            };
            assert_eq!(reply_seq, want_seq, "the reply must echo the seq");
            match (&want, &body) {
                (Want::Welcome, ResponseBody::Welcome(welcome)) => {
                    assert_eq!(welcome.protocol_version(), PROTOCOL_VERSION)
                }
                (
                    Want::Status {
                        active_crc,
                        active_seq,
                    },
                    ResponseBody::Status(status),
                ) => {
                    assert_eq!(
                        (status.active_crc, status.active_seq),
                        (*active_crc, *active_seq)
                    )
                }
                (Want::Exact(ResponseBody::Params(want)), ResponseBody::Params(got)) => {
                    assert!(same_set(want, got), "GetParams returned another set")
                }
                (Want::Exact(want), got) => assert_eq!(got, want, "reply to a {kind}"),
                (want, got) => panic!("wanted {want:?}, got {got:?} to a {kind}"),
            }
        }
        let missing: Vec<_> = wanted.collect();
        assert!(missing.is_empty(), "no reply to a {kind}: {missing:?}");

        for event in &received.events {
            if let Event::CalibratedBatch(batch) = event {
                for (sample, _) in batch.iter() {
                    let values = sample.accel.iter().chain(&sample.gyro).chain(&sample.mag);
                    assert!(values.clone().all(|v| v.is_finite()), "{sample:?}");
                    figures.calibrated_samples_checked += 1;
                }
            }
        }

        // The active set is the model's: it changed only through a valid commit or reset.
        let active = *bench.device.active_params();
        assert!(
            same_set(&active, &model.active),
            "the active set changed outside a valid commit after a {kind}"
        );
        if model.active_seq != checked_seq {
            checked_seq = model.active_seq;
            assert_eq!(validate(&active, &scales()), Ok(()));
            assert_finite_on_corners(&active);
        }
    }

    // Still alive and answering.
    let reply = bench.request(RequestBody::Ping(0x5EED_CAFE));
    assert_eq!(reply, ResponseBody::Pong(0x5EED_CAFE));
    let counters = bench.device.error_counters();
    let elapsed = started.elapsed().as_secs_f64();
    eprintln!(
        "storm: {FRAMES} frames, {} bytes, {} polls, {} commits/resets accepted, \
         {} calibrated samples checked, {} noise frames that decoded, {elapsed:.1} s",
        figures.bytes,
        figures.polls,
        model.active_seq,
        figures.calibrated_samples_checked,
        figures.noise_that_decoded
    );
    eprintln!("frames by kind: {:?}", figures.frames);
    eprintln!("replies by kind: {:?}", figures.replies);
    eprintln!("device error counters: {counters:?}");
    // Every kind of reply and every parameter rejection must have been exercised.
    assert!(model.active_seq > 1_000, "commits: {}", model.active_seq);
    for name in [
        "NothingStaged",
        "CrcMismatch",
        "UnknownRequest",
        "VersionMismatch",
        "InvalidArgument",
        "Busy",
        "PoseStats",
        "InvalidParams(NonFinite)",
        "InvalidParams(IllConditioned)",
        "InvalidParams(GainOutOfRange)",
        "InvalidParams(OffsetOutOfRange)",
        "InvalidParams(ExtendedTermOutOfRange)",
        "InvalidParams(ReferenceTemperatureOutOfRange)",
        "InvalidParams(UnsupportedFormat)",
    ] {
        assert!(
            figures.replies.get(name).copied().unwrap_or(0) > 0,
            "the storm never provoked {name}"
        );
    }
}
