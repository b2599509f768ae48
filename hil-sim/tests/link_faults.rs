//! The fault-injecting link on its own: measured fault rates against the configured ones,
//! reproducibility from the seed, duplicated and held-back frames, the version shim, parameter
//! tampering, and the port vanishing under the server.

use std::time::{Duration, Instant};

use imucal_hil_sim::link_faults::{FaultyLink, LinkFaults, ParamTamper};
use imucal_hil_sim::serve::{SimOptions, SimServer};
use imucal_protocol::{
    decode_payload, encode_frame, CalibrationSet, DeviceMessage, ErrorCode, Event, FrameDecoder,
    ParamStatus, Request, RequestBody, Response, ResponseBody, MAX_FRAME,
};

fn frame<T: serde::Serialize>(message: &T) -> Vec<u8> {
    let mut buffer = [0u8; MAX_FRAME];
    let len = encode_frame(message, &mut buffer).expect("encodes");
    buffer[..len].to_vec()
}

fn ping(seq: u16) -> Vec<u8> {
    frame(&Request {
        seq,
        body: RequestBody::Ping(u32::from(seq) * 7919),
    })
}

/// Every payload that decodes from `bytes`.
fn payloads(bytes: &[u8]) -> Vec<Vec<u8>> {
    let mut decoder = FrameDecoder::<MAX_FRAME>::new();
    let mut out = Vec::new();
    for &byte in bytes {
        if let Some(Ok(payload)) = decoder.push(byte) {
            out.push(payload.to_vec());
        }
    }
    out
}

#[test]
fn byte_drops_and_flips_occur_at_the_configured_rate_and_repeat_with_the_seed() {
    let faults = LinkFaults {
        drop_rate: 1e-3,
        flip_rate: 2e-3,
        ..LinkFaults::default()
    };
    let now = Instant::now();
    let stream: Vec<u8> = (0..20_000u16).flat_map(ping).collect();
    let run = |seed| {
        let mut link = FaultyLink::new(faults, seed).expect("valid faults");
        link.push_from_host(&stream, now);
        (link.take_for_device(now), link.stats())
    };
    let (bytes, stats) = run(5);
    let n = stream.len() as f64;
    let drops = stats.to_device.bytes_dropped as f64;
    let flips = stats.to_device.bits_flipped as f64;
    // Binomial counts: 5σ = 5·√(n·p·(1 − p)) around n·p (a flip needs the byte not dropped).
    let within = |count: f64, p: f64| (count - n * p).abs() < 5.0 * (n * p * (1.0 - p)).sqrt();
    assert!(within(drops, 1e-3), "{drops} drops in {n} bytes");
    assert!(
        within(flips, 2e-3 * (1.0 - 1e-3)),
        "{flips} flips in {n} bytes"
    );
    assert_eq!(bytes.len() as f64, n - drops);
    assert_eq!(stats.to_device.frames, 20_000);
    // Frames survive unless hit: about (1 − 3e-3)^len of them decode.
    let survived = payloads(&bytes).len();
    assert!(
        survived > 17_000 && survived < 20_000,
        "{survived} frames decoded"
    );
    assert_eq!(run(5).0, bytes, "the same seed gives the same faults");
    assert_ne!(run(6).0, bytes, "another seed gives other faults");
}

#[test]
fn duplicated_frames_arrive_twice_and_held_frames_after_the_delay_overtaken_by_later_ones() {
    let faults = LinkFaults {
        dup_rate: 0.25,
        delay_rate: 0.25,
        delay: Duration::from_millis(40),
        ..LinkFaults::default()
    };
    let mut link = FaultyLink::new(faults, 9).expect("valid faults");
    let start = Instant::now();
    let count = 400u16;
    for seq in 0..count {
        link.push_from_device(&ping(seq), start);
    }
    let seqs = |bytes: &[u8]| -> Vec<u16> {
        payloads(bytes)
            .iter()
            .map(|p| decode_payload::<Request>(p).expect("decodes").seq)
            .collect()
    };
    let first = seqs(&link.take_for_host(start + Duration::from_millis(39)));
    let held = seqs(&link.take_for_host(start + Duration::from_millis(40)));
    // A held frame is overtaken: a later frame went out before it.
    let last_first = first.iter().copied().max().unwrap_or_default();
    assert!(held.iter().any(|&seq| seq < last_first), "{held:?}");
    let (at_once, later) = (first.len(), held.len());
    let stats = link.stats().to_host;
    assert_eq!(
        at_once + later,
        usize::from(count) + stats.frames_duplicated as usize
    );
    assert_eq!(later as u64, stats.frames_delayed);
    // 400 frames at p = 0.25: 100 ± 5σ (σ = √(400·0.25·0.75) ≈ 8.7) each; the delay draw is per
    // copy, so delayed frames number (400 + duplicates)·0.25.
    assert!(
        (stats.frames_duplicated as f64 - 100.0).abs() < 44.0,
        "{stats:?}"
    );
    let copies = 400.0 + stats.frames_duplicated as f64;
    assert!(
        (stats.frames_delayed as f64 - copies * 0.25).abs() < 5.0 * (copies * 0.1875).sqrt(),
        "{stats:?}"
    );
}

#[test]
fn a_board_of_another_major_answers_hello_itself_with_its_version() {
    let ours = imucal_protocol::PROTOCOL_MAJOR;
    let theirs = ours + 1;
    let faults = LinkFaults {
        protocol_major: Some(theirs),
        ..LinkFaults::default()
    };
    let mut link = FaultyLink::new(faults, 1).expect("valid faults");
    let now = Instant::now();
    link.push_from_host(
        &frame(&Request {
            seq: 77,
            body: RequestBody::hello(),
        }),
        now,
    );
    assert!(
        link.take_for_device(now).is_empty(),
        "the Hello is answered by the shim, not passed on"
    );
    let messages: Vec<DeviceMessage> = payloads(&link.take_for_host(now))
        .iter()
        .map(|p| decode_payload(p).expect("decodes"))
        .collect();
    assert!(
        matches!(&messages[0], DeviceMessage::Event(Event::Log(line))
        if line.text.as_str() == format!("refused Hello: the host speaks imucal protocol {ours}.{}, this board speaks {theirs}.0", imucal_protocol::PROTOCOL_MINOR))
    );
    assert_eq!(
        messages[1],
        DeviceMessage::Response(Response {
            seq: 77,
            body: ResponseBody::Error(ErrorCode::VersionMismatch {
                device_major: theirs,
                device_minor: 0
            })
        })
    );
    assert_eq!(link.stats().hellos_refused, 1);
    assert_eq!(link.take_notes().len(), 1);
    // Other requests still reach the board unchanged.
    link.push_from_host(&ping(78), now);
    assert_eq!(link.take_for_device(now), ping(78));
}

#[test]
fn a_restaged_set_gets_its_own_crc_and_a_hidden_echo_shows_the_hosts() {
    let faults = LinkFaults {
        param_tamper: Some(ParamTamper::RestageFlippedHideEcho { bit: 5 }),
        ..LinkFaults::default()
    };
    let mut link = FaultyLink::new(faults, 1).expect("valid faults");
    let now = Instant::now();
    let set = CalibrationSet::identity();
    let crc = set.crc32();
    link.push_from_host(
        &frame(&Request {
            seq: 9,
            body: RequestBody::WriteParams { set, crc },
        }),
        now,
    );
    let forwarded = payloads(&link.take_for_device(now));
    let Ok(Request {
        body:
            RequestBody::WriteParams {
                set: changed,
                crc: changed_crc,
            },
        ..
    }) = decode_payload::<Request>(&forwarded[0])
    else {
        panic!("a WriteParams is forwarded");
    };
    assert_ne!(changed, set);
    assert_eq!(
        changed_crc,
        changed.crc32(),
        "the frame is valid for the board"
    );
    assert_eq!(
        changed.accel.a[0][0].to_bits() ^ set.accel.a[0][0].to_bits(),
        1 << 5
    );
    let echo = |staged| {
        frame(&DeviceMessage::Response(Response {
            seq: 9,
            body: ResponseBody::ParamStatus(ParamStatus {
                active_crc: 1,
                active_seq: 1,
                staged_crc: Some(staged),
            }),
        }))
    };
    link.push_from_device(&echo(changed_crc), now);
    assert_eq!(
        link.take_for_host(now),
        echo(crc),
        "the echo shows the host's CRC"
    );
}

#[test]
fn invalid_rates_are_refused_with_a_sentence() {
    for rate in [-0.1, 1.5, f64::NAN] {
        let faults = LinkFaults {
            drop_rate: rate,
            ..LinkFaults::default()
        };
        let error = FaultyLink::new(faults, 1).expect_err("refused");
        assert!(
            error.to_string().starts_with("drop rate is")
                && error.to_string().contains("a probability from 0 to 1"),
            "{error}"
        );
    }
}

#[test]
fn the_port_vanishes_after_the_given_time() {
    let mut options = SimOptions::new(4);
    options.faults.vanish_after = Some(Duration::from_millis(200));
    let sim = SimServer::start(options).expect("starts");
    let path = sim.port_path().to_string();
    assert!(std::path::Path::new(&path).exists());
    let start = Instant::now();
    while sim.is_running() && start.elapsed() < Duration::from_secs(5) {
        std::thread::sleep(Duration::from_millis(10));
    }
    assert!(!sim.is_running(), "serving ended");
    assert!(start.elapsed() < Duration::from_secs(2));
    assert!(sim.fault_stats().vanished);
    assert_eq!(
        sim.take_notes(),
        vec![format!(
            "closed the port {path}, as if the board were unplugged"
        )]
    );
}
