//! The device client against a fake board on a pseudo-terminal: handshake, version mismatch,
//! timeouts and retries, verified parameter writes, events while waiting, and streams.

mod device_fake;

use std::time::{Duration, Instant};

use device_fake::{fake_sample, scales, FakeConfig, FakeDevice};
use imucal::device::{open_port, ClientOptions, DeviceClient, DeviceError, PoseRequest};
use imucal_protocol::{
    CalibrationSet, ErrorCode, InvalidParamsReason, ProtocolVersion, SensorKind, StillThresholds,
    StreamKind,
};

/// Short timeouts: the fake answers within a few ms, so 200 ms only expires on purpose.
fn options() -> ClientOptions {
    ClientOptions {
        reply_timeout: Duration::from_millis(200),
        flash_timeout: Duration::from_millis(400),
        tries: 3,
        connect_tries: 3,
        event_queue_limit: 256,
    }
}

fn connect(fake: &FakeDevice) -> Result<DeviceClient, DeviceError> {
    DeviceClient::connect(open_port(&fake.path)?, fake.path.clone(), options())
}

fn calibrated_set() -> CalibrationSet {
    let mut set = CalibrationSet::identity();
    set.created_unix_s = 1_763_700_000;
    set.accel.a = [[1.002, 0.001, 0.0], [0.0, 0.998, 0.002], [0.0, 0.0, 1.004]];
    set.accel.b = [0.05, -0.02, 0.11];
    set.gyro.b = [0.001, -0.002, 0.0005];
    set.reference.field_ut = 48.5;
    set
}

#[test]
fn handshake_keeps_the_welcome_with_device_id_and_scales() {
    let fake = FakeDevice::start(FakeConfig::default());
    let client = connect(&fake).expect("the fake answers");
    let welcome = client.welcome();
    assert_eq!(
        welcome.device_id.to_string(),
        "eeffc000000000000000000000000000"
    );
    assert_eq!(welcome.scales, scales());
    assert_eq!(client.protocol(), imucal_protocol::PROTOCOL_VERSION);
    assert_eq!(fake.state().requests[..2], ["Ping", "Hello"]);
}

#[test]
fn a_newer_board_protocol_is_refused_naming_both_versions_and_what_to_update() {
    // One major version ahead of this host, whatever the current one is.
    let ours = imucal_protocol::PROTOCOL_VERSION;
    let newer = ProtocolVersion {
        major: ours.major + 1,
        minor: 3,
    };
    let fake = FakeDevice::start(FakeConfig {
        protocol: Some(newer),
        ..FakeConfig::default()
    });
    let message = connect(&fake)
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(message.contains(&fake.path), "{message}");
    assert!(
        message.contains(&format!("protocol {}.3", newer.major)),
        "{message}"
    );
    assert!(
        message.contains(&format!("speaks {}.{}", ours.major, ours.minor)),
        "{message}"
    );
    assert!(message.contains("update imucal"), "{message}");
}

#[test]
fn an_older_board_protocol_asks_for_a_firmware_update() {
    let fake = FakeDevice::start(FakeConfig {
        protocol: Some(ProtocolVersion { major: 0, minor: 9 }),
        ..FakeConfig::default()
    });
    let message = connect(&fake)
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(message.contains("protocol 0.9"), "{message}");
    assert!(message.contains("update the board's firmware"), "{message}");
}

#[test]
fn a_dropped_first_request_is_retried_after_the_reply_timeout() {
    let fake = FakeDevice::start(FakeConfig {
        drop_first_requests: 1,
        ..FakeConfig::default()
    });
    let start = Instant::now();
    let client = connect(&fake).expect("the retry reaches the fake");
    let elapsed = start.elapsed();
    assert_eq!(client.stats().retries, 1);
    assert_eq!(fake.state().requests[..3], ["Ping", "Ping", "Hello"]);
    // One reply timeout (200 ms) was waited; the rest is a few ms of pty round trips.
    assert!(elapsed >= Duration::from_millis(200), "{elapsed:?}");
    assert!(elapsed < Duration::from_millis(1000), "{elapsed:?}");
}

#[test]
fn a_silent_board_gives_a_no_answer_sentence_after_every_try() {
    let fake = FakeDevice::start(FakeConfig {
        silent: true,
        ..FakeConfig::default()
    });
    let error = connect(&fake).expect_err("a silent board cannot connect");
    let message = error.to_string();
    assert!(
        matches!(error, DeviceError::NoAnswer { tries: 3, .. }),
        "{message}"
    );
    assert!(
        message.contains(&format!("no answer from {}", fake.path)),
        "{message}"
    );
    assert!(message.contains("after 3 tries"), "{message}");
    assert!(message.contains("imucal firmware"), "{message}");
    // Three pings and the one fallback Hello.
    assert_eq!(fake.state().requests, ["Ping", "Ping", "Ping", "Hello"]);
}

#[test]
fn verified_write_stages_commits_and_reads_back_the_same_set() {
    let fake = FakeDevice::start(FakeConfig::default());
    let mut client = connect(&fake).expect("connect");
    let set = calibrated_set();
    let status = client.write_params_verified(&set).expect("verified write");
    assert_eq!(status.active_crc, set.crc32());
    assert_eq!(status.active_seq, 1);
    let state = fake.state();
    assert_eq!(state.active, set);
    // The active set is read first, so that a lost answer after the commit can be settled
    // against it.
    assert_eq!(
        state.requests[2..],
        ["Status", "WriteParams", "CommitParams", "GetParams"]
    );
}

#[test]
fn a_wrong_staged_crc_echo_refuses_to_commit() {
    let fake = FakeDevice::start(FakeConfig {
        wrong_staged_crc: true,
        ..FakeConfig::default()
    });
    let mut client = connect(&fake).expect("connect");
    let set = calibrated_set();
    let error = client.write_params_verified(&set).expect_err("must refuse");
    let message = error.to_string();
    assert!(
        matches!(error, DeviceError::StagedCrcMismatch { .. }),
        "{message}"
    );
    assert!(message.contains("not committed"), "{message}");
    assert!(
        message.contains(&format!("{:#010x}", set.crc32())),
        "{message}"
    );
    let state = fake.state();
    assert!(
        !state.requests.contains(&"CommitParams"),
        "{:?}",
        state.requests
    );
    assert_eq!(state.active, CalibrationSet::identity());
}

#[test]
fn a_lost_commit_reply_is_resolved_by_the_active_crc() {
    let fake = FakeDevice::start(FakeConfig {
        drop_first_commit_reply: true,
        ..FakeConfig::default()
    });
    let mut client = connect(&fake).expect("connect");
    let set = calibrated_set();
    let status = client
        .write_params_verified(&set)
        .expect("commit went through");
    assert_eq!(status.active_crc, set.crc32());
    let state = fake.state();
    assert_eq!(state.commits, 1, "committed once, not twice");
    assert_eq!(
        state.requests[2..],
        [
            "Status",
            "WriteParams",
            "CommitParams",
            "CommitParams",
            "Status",
            "GetParams"
        ]
    );
}

#[test]
fn a_refused_parameter_set_is_reported_with_the_boards_reason() {
    let fake = FakeDevice::start(FakeConfig {
        reject_params: Some(ErrorCode::InvalidParams(
            InvalidParamsReason::IllConditioned(SensorKind::Accel),
        )),
        ..FakeConfig::default()
    });
    let mut client = connect(&fake).expect("connect");
    let error = client
        .write_params_verified(&calibrated_set())
        .expect_err("refused");
    assert_eq!(
        error.device_code(),
        Some(ErrorCode::InvalidParams(
            InvalidParamsReason::IllConditioned(SensorKind::Accel)
        ))
    );
    let message = error.to_string();
    assert!(message.contains("refused WriteParams"), "{message}");
    assert!(message.contains("accel.A is singular"), "{message}");
    assert!(!fake.state().requests.contains(&"CommitParams"));
}

#[test]
fn a_set_the_board_would_refuse_is_not_sent_at_all() {
    // A fit in the wrong unit (gain 9.8) and an absurd reference temperature: the host applies
    // the board's own validation first and names the field.
    let fake = FakeDevice::start(FakeConfig::default());
    let mut client = connect(&fake).expect("connect");
    let mut wrong_unit = calibrated_set();
    wrong_unit.gyro.a = [[9.8, 0.0, 0.0], [0.0, 9.8, 0.0], [0.0, 0.0, 9.8]];
    let mut absurd_t_ref = calibrated_set();
    absurd_t_ref.accel.t_ref_c = 1e30;
    for (set, field) in [(wrong_unit, "gyro.A"), (absurd_t_ref, "accel.t_ref_c")] {
        let error = client.write_params_verified(&set).expect_err("refused");
        let message = error.to_string();
        assert!(
            message.contains(field) && message.contains("not writing"),
            "{message}"
        );
    }
    assert!(!fake.state().requests.contains(&"WriteParams"));
}

#[test]
fn corrupt_frames_are_counted_and_skipped() {
    let fake = FakeDevice::start(FakeConfig {
        noise_before_replies: true,
        ..FakeConfig::default()
    });
    let mut client = connect(&fake).expect("connect through noise");
    client.status().expect("status through noise");
    // Each reply (Pong, Welcome, Status) is preceded by one garbage frame and one frame with
    // a broken CRC.
    assert_eq!(client.stats().frame_errors, 6);
    assert_eq!(client.stats().retries, 0);
}

#[test]
fn events_arriving_before_a_reply_are_queued_and_converted_to_units() {
    let fake = FakeDevice::start(FakeConfig {
        events_before_status: true,
        ..FakeConfig::default()
    });
    let mut client = connect(&fake).expect("connect");
    client.status().expect("status");
    assert_eq!(client.is_still(), Some(true));
    let chunk = client
        .next_samples(Duration::from_millis(100))
        .expect("link ok")
        .expect("the queued batch");
    assert_eq!(chunk.samples.len(), 3);
    let s = scales();
    for (i, sample) in chunk.samples.iter().enumerate() {
        let raw = fake_sample(i as u32);
        // f32 scale widened to f64: exact product of two f64s, rounding ≤ 1e-12 relative.
        let expected_az = f64::from(raw.accel[2]) * f64::from(s.accel_mps2_per_count);
        assert!((sample.accel[2] - expected_az).abs() < 1e-12);
        assert!((sample.temp_c - 28.0).abs() < 1e-9, "25 °C + 48/16 °C");
        // Batch time stamps are quantised to the 10 µs tick.
        let expected_t = 1.0 + i as f64 * 0.01;
        assert!((sample.t_s - expected_t).abs() < 10e-6);
    }
}

#[test]
fn streamed_batches_arrive_in_units_and_a_lost_batch_is_counted() {
    let fake = FakeDevice::start(FakeConfig {
        gap_at_batch: Some(20),
        ..FakeConfig::default()
    });
    let mut client = connect(&fake).expect("connect");
    let mut lost = Vec::new();
    let samples = client
        .collect_samples(StreamKind::Raw, Duration::from_millis(900), &mut |chunk| {
            lost.push(chunk.lost_before)
        })
        .expect("stream");
    // 900 ms at one batch per 200 ms: 4 batches received, the second one lost in transit.
    assert!(lost.len() >= 3, "{lost:?}");
    assert_eq!(lost[..3], [0, 20, 0]);
    assert_eq!(client.stats().lost_samples, 20);
    assert_eq!(samples.len(), 20 * lost.len());
    let state = fake.state();
    assert_eq!(state.requests.last(), Some(&"StopStream"));
}

#[test]
fn pose_capture_reports_progress_and_stillness_until_the_stats_arrive() {
    let fake = FakeDevice::start(FakeConfig {
        pose_delay: Duration::from_millis(600),
        ..FakeConfig::default()
    });
    let mut client = connect(&fake).expect("connect");
    let mut calls = Vec::new();
    let stats = client
        .capture_pose(
            &PoseRequest {
                min_still: Duration::from_secs(2),
                thresholds: StillThresholds {
                    accel_std_mps2: 0.05,
                    gyro_std_rads: 0.01,
                },
                timeout: Duration::from_secs(5),
            },
            &mut |p| calls.push(*p),
        )
        .expect("pose stats");
    assert_eq!(stats.n, 200);
    // Progress about every 100 ms over the 600 ms capture.
    assert!(calls.len() >= 4, "{}", calls.len());
    assert_eq!(calls.first().map(|p| p.still), Some(None));
    assert_eq!(calls.last().map(|p| p.still), Some(Some(true)));
    assert!(calls.windows(2).all(|w| w[0].elapsed <= w[1].elapsed));
}

#[test]
fn an_event_handler_receives_events_instead_of_the_queue() {
    let fake = FakeDevice::start(FakeConfig {
        events_before_status: true,
        ..FakeConfig::default()
    });
    let mut client = connect(&fake).expect("connect");
    let seen = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
    let sink = std::sync::Arc::clone(&seen);
    client.set_event_handler(Some(Box::new(move |event| {
        if let Ok(mut names) = sink.lock() {
            names.push(match event {
                imucal_protocol::Event::SampleBatch(b) => format!("batch of {}", b.len()),
                imucal_protocol::Event::StillnessChanged { still, .. } => format!("still {still}"),
                other => format!("{other:?}"),
            });
        }
    })));
    client.status().expect("status");
    assert_eq!(
        *seen.lock().expect("handler lock"),
        ["still true", "batch of 3"]
    );
    assert_eq!(
        client
            .next_event(Duration::from_millis(50))
            .expect("link ok"),
        None
    );
}
