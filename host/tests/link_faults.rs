//! The device client against the simulated board behind a fault-injecting link: byte drops and
//! bit flips, duplicated and delayed frames, a port that vanishes, a board of another protocol
//! major, and parameter sets corrupted inside valid frames.

use std::time::Duration;

use imucal::device::{ClientOptions, DeviceClient, DeviceError, PoseRequest};
use imucal_hil_sim::board::PersonSchedule;
use imucal_hil_sim::link_faults::{LinkFaults, ParamTamper};
use imucal_hil_sim::serve::{SimHandle, SimOptions, SimServer};
use imucal_protocol::{CalibrationSet, ErrorCode, StillThresholds};

/// A board lying still, served at `speed` × real time through `faults`.
fn board_with(seed: u64, faults: LinkFaults) -> SimHandle {
    let mut options = SimOptions::new(seed);
    options.schedule = PersonSchedule::Rest;
    options.board.poser.tremor = false;
    options.speed = 5.0;
    options.faults = faults;
    SimServer::start(options).expect("the simulator starts")
}

/// Short timeouts: the pty answers within milliseconds, so 100 ms is ample and keeps the
/// retries of a lossy link fast.
fn quick_options() -> ClientOptions {
    ClientOptions {
        reply_timeout: Duration::from_millis(100),
        flash_timeout: Duration::from_millis(1000),
        ..ClientOptions::default()
    }
}

/// A plausible calibration: the identity with small scale and offset changes set by `k`.
fn calibration(k: u16) -> CalibrationSet {
    let mut set = CalibrationSet::identity();
    let step = f32::from(k) * 1e-3;
    set.accel.a[0][0] = 1.0 + step;
    set.accel.b = [0.01 * step, -0.02, 0.03];
    set.gyro.b = [step * 1e-2, 0.0, -1e-3];
    set.created_unix_s = 1_700_000_000 + u64::from(k);
    set
}

fn still_pose() -> PoseRequest {
    PoseRequest {
        min_still: Duration::from_millis(500),
        thresholds: StillThresholds {
            accel_std_mps2: 0.2,
            gyro_std_rads: 0.05,
        },
        timeout: Duration::from_secs(10),
    }
}

/// Retry `f` until it succeeds (up to 20 times): for reading state back through a lossy link.
fn eventually<T>(mut f: impl FnMut() -> Result<T, DeviceError>) -> T {
    let mut last = None;
    for _ in 0..20 {
        match f() {
            Ok(value) => return value,
            Err(error) => last = Some(error),
        }
    }
    panic!("failed 20 times, last: {last:?}");
}

#[test]
fn drops_and_bit_flips_at_one_per_thousand_bytes_both_ways_are_ridden_out_by_retries() {
    let faults = LinkFaults {
        drop_rate: 1e-3,
        flip_rate: 1e-3,
        ..LinkFaults::default()
    };
    let sim = board_with(21, faults);
    let options = ClientOptions {
        // A 300-byte parameter frame survives 2e-3 faults per byte with p ≈ 0.55; six tries
        // leave (0.45)^6 < 1 % to chance (the default three would leave 9 %).
        tries: 6,
        ..quick_options()
    };
    let mut client =
        DeviceClient::open_with(sim.port_path(), options).expect("Hello succeeds through retries");
    for i in 0..200 {
        client
            .ping()
            .unwrap_or_else(|e| panic!("ping {i} failed: {e}"));
    }
    client.get_params().expect("GetParams succeeds");
    let mut committed = client.status().expect("Status succeeds").active_crc;
    // Every write either succeeds with the board holding exactly the host's set, or fails
    // leaving the previous set or the new one active, never a third.
    let mut written = 0;
    for k in 1..=8 {
        let set = calibration(k);
        let result = client.write_params_verified(&set);
        let active = eventually(|| client.status()).active_crc;
        match result {
            Ok(status) => {
                assert_eq!(status.active_crc, set.crc32());
                assert_eq!(active, set.crc32(), "write {k} reported success");
                written += 1;
            }
            Err(error) => assert!(
                active == committed || active == set.crc32(),
                "write {k} failed ({error}) and left {active:#010x} active"
            ),
        }
        committed = active;
    }
    let pose = client
        .capture_pose(&still_pose(), &mut |_| {})
        .expect("the pose capture succeeds through resends");
    let link = client.stats();
    let injected = sim.fault_stats();
    println!(
        "writes verified {written}/8, pose n = {}; host: {} retries, {} frame errors, {} stale \
         replies; injected to board: {} drops, {} flips in {} frames; to host: {} drops, {} \
         flips in {} frames",
        pose.n,
        link.retries,
        link.frame_errors,
        link.stale_replies,
        injected.to_device.bytes_dropped,
        injected.to_device.bits_flipped,
        injected.to_device.frames,
        injected.to_host.bytes_dropped,
        injected.to_host.bits_flipped,
        injected.to_host.frames,
    );
    // The faults really hit: at 2e-3 per byte over tens of kilobytes, hundreds of faults.
    assert!(injected.to_device.bytes_dropped + injected.to_device.bits_flipped > 0);
    assert!(injected.to_host.bytes_dropped + injected.to_host.bits_flipped > 0);
    assert!(link.retries > 0 && link.frame_errors > 0, "{link:?}");
    // With six tries each write fails with p < 1 %; losing more than two of eight is far out.
    assert!(written >= 6, "only {written} of 8 writes verified");
    // Half a second at 119 Hz, minus the samples of the window edge.
    let rate = f64::from(client.welcome().scales.sample_rate_hz);
    assert!(f64::from(pose.n) >= 0.45 * rate, "n = {}", pose.n);
}

#[test]
fn duplicated_frames_are_matched_by_seq_and_the_extra_replies_counted_stale() {
    let faults = LinkFaults {
        dup_rate: 0.3,
        ..LinkFaults::default()
    };
    let sim = board_with(22, faults);
    let mut client = DeviceClient::open_with(sim.port_path(), quick_options()).expect("connect");
    let requests = 100;
    for _ in 0..requests {
        // `ping` checks the echoed nonce, so a reply taken for the wrong request fails here.
        client.ping().expect("ping");
    }
    let set = calibration(3);
    client.write_params_verified(&set).expect("verified write");
    assert_eq!(client.get_params().expect("GetParams"), set);
    // Let the last duplicates arrive, then count them.
    let _ = client.next_event(Duration::from_millis(100));
    let stale = client.stats().stale_replies;
    let injected = sim.fault_stats();
    println!("stale replies {stale}; {injected:?}");
    // Every duplicated request draws one more reply (but the lone delimiter sent at connect,
    // which may be doubled too, draws none), and every duplicated frame to the host is a reply
    // or an event: the stale count lies between the two, whatever the draws.
    let (requests_doubled, frames_doubled) = (
        injected.to_device.frames_duplicated,
        injected.to_host.frames_duplicated,
    );
    assert!(requests_doubled > 0 && frames_doubled > 0, "{injected:?}");
    assert!(
        stale + 1 >= requests_doubled && stale <= requests_doubled + frames_doubled,
        "stale {stale}, doubled requests {requests_doubled}, doubled frames {frames_doubled}"
    );
    assert_eq!(client.stats().retries, 0, "duplicates alone need no retry");
}

#[test]
fn a_reply_later_than_the_timeout_is_discarded_and_the_retry_succeeds() {
    let faults = LinkFaults {
        delay_rate: 0.2,
        // Three reply timeouts: the late frame arrives after the request has moved on.
        delay: Duration::from_millis(300),
        ..LinkFaults::default()
    };
    let sim = board_with(23, faults);
    let options = ClientOptions {
        // Each try is delayed with p ≈ 0.36 (request or reply); ten tries leave 4e-5.
        tries: 10,
        ..quick_options()
    };
    let mut client = DeviceClient::open_with(sim.port_path(), options).expect("connect");
    for _ in 0..40 {
        client.ping().expect("ping with the right nonce");
    }
    let set = calibration(5);
    client.write_params_verified(&set).expect("verified write");
    std::thread::sleep(Duration::from_millis(400));
    let _ = client.next_event(Duration::from_millis(20));
    let link = client.stats();
    let injected = sim.fault_stats();
    println!("{link:?}; {injected:?}");
    assert!(injected.to_device.frames_delayed + injected.to_host.frames_delayed > 0);
    assert!(link.retries > 0, "a delayed frame forces a retry: {link:?}");
    assert!(
        link.stale_replies > 0,
        "late replies are discarded: {link:?}"
    );
    assert_eq!(eventually(|| client.get_params()), set);
}

fn port_gone_sentence(port: &str) -> String {
    format!("the port {port} went away: the board was unplugged or reset; reconnect and run again")
}

#[test]
fn a_vanished_port_fails_with_a_sentence_naming_it() {
    let sim = board_with(24, LinkFaults::default());
    let port = sim.port_path().to_string();
    let mut client = DeviceClient::open_with(&port, quick_options()).expect("connect");
    client.ping().expect("ping before");
    sim.vanish();
    let error = (0..50)
        .find_map(|_| {
            std::thread::sleep(Duration::from_millis(10));
            client.ping().err()
        })
        .expect("pings fail once the port is gone");
    assert!(matches!(error, DeviceError::PortGone { .. }), "{error:?}");
    assert_eq!(error.to_string(), port_gone_sentence(&port));
    assert!(sim.fault_stats().vanished);
    assert!(sim.take_notes().iter().any(|n| n.contains(&port)));
}

#[test]
fn the_cli_exits_non_zero_naming_the_port_when_it_vanishes_mid_stream() {
    use std::io::BufRead;
    let sim = board_with(25, LinkFaults::default());
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_imucal"))
        .args(["stream", "--port", sim.port_path(), "--seconds", "20"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("imucal runs");
    // Unplug once samples flow, so the port vanishes mid-stream whatever the machine's load.
    let stdout = child.stdout.take().expect("stdout is piped");
    let mut lines = std::io::BufReader::new(stdout).lines();
    assert!(lines.next().is_some_and(|l| l.is_ok()), "no sample printed");
    sim.vanish();
    // Keep reading so a full pipe never blocks the tool.
    let drain = std::thread::spawn(move || lines.count());
    let output = child.wait_with_output().expect("imucal ends");
    drain.join().expect("stdout drained");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success(), "exit status {}", output.status);
    assert!(
        stderr.contains(&port_gone_sentence(sim.port_path())),
        "stderr: {stderr}"
    );
}

#[test]
fn a_board_of_another_protocol_major_is_refused_with_both_versions_named_on_both_ends() {
    let ours = imucal_protocol::PROTOCOL_MAJOR;
    for (major, advice) in [
        (ours + 1, "update imucal (the host tool)"),
        (ours - 1, "update the board's firmware"),
    ] {
        let faults = LinkFaults {
            protocol_major: Some(major),
            ..LinkFaults::default()
        };
        let sim = board_with(26, faults);
        let error = DeviceClient::open_with(sim.port_path(), quick_options())
            .expect_err("a board of another major is refused");
        assert_eq!(
            error.to_string(),
            format!(
                "{} speaks imucal protocol {major}.0, this imucal speaks {ours}.{}; {advice}",
                sim.port_path(),
                imucal_protocol::PROTOCOL_MINOR
            )
        );
        assert_eq!(sim.fault_stats().hellos_refused, 1);
        assert_eq!(
            sim.take_notes(),
            vec![format!(
                "refused Hello: the host speaks imucal protocol {ours}.{}, this board speaks {major}.0",
                imucal_protocol::PROTOCOL_MINOR
            )]
        );
    }
}

#[test]
fn the_cli_reports_a_protocol_mismatch_and_exits_non_zero() {
    let ours = imucal_protocol::PROTOCOL_MAJOR;
    let faults = LinkFaults {
        protocol_major: Some(ours + 1),
        ..LinkFaults::default()
    };
    let sim = board_with(27, faults);
    let output = std::process::Command::new(env!("CARGO_BIN_EXE_imucal"))
        .args(["info", "--port", sim.port_path()])
        .output()
        .expect("imucal runs");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success());
    assert!(
        stderr.contains(&format!(
            "speaks imucal protocol {}.0, this imucal speaks {ours}.{}",
            ours + 1,
            imucal_protocol::PROTOCOL_MINOR
        )),
        "stderr: {stderr}"
    );
}

/// A board with `first` committed and verified, and a client on it.
fn board_holding(seed: u64, first: &CalibrationSet) -> (SimHandle, DeviceClient) {
    let faults = LinkFaults {
        // Active but harmless until a tampering is set.
        param_tamper: None,
        dup_rate: 1e-12,
        ..LinkFaults::default()
    };
    let sim = board_with(seed, faults);
    let mut client = DeviceClient::open_with(sim.port_path(), quick_options()).expect("connect");
    client.write_params_verified(first).expect("first write");
    (sim, client)
}

fn assert_still_active(client: &mut DeviceClient, set: &CalibrationSet) {
    assert_eq!(client.status().expect("status").active_crc, set.crc32());
    assert_eq!(&client.get_params().expect("GetParams"), set);
}

#[test]
fn a_set_changed_before_staging_is_not_committed_because_its_echoed_crc_differs() {
    let (first, second) = (calibration(1), calibration(2));
    let (sim, mut client) = board_holding(31, &first);
    sim.set_param_tamper(Some(ParamTamper::RestageFlipped { bit: 4 }))
        .expect("tamper");
    let error = client
        .write_params_verified(&second)
        .expect_err("the changed set is refused");
    match error {
        DeviceError::StagedCrcMismatch { sent, echoed, .. } => {
            assert_eq!(sent, second.crc32());
            assert!(echoed.is_some_and(|crc| crc != sent), "{echoed:?}");
        }
        other => panic!("expected a staged CRC mismatch, got {other:?}"),
    }
    sim.set_param_tamper(None).expect("untamper");
    assert_still_active(&mut client, &first);
    assert!(sim.fault_stats().params_tampered >= 1);
}

#[test]
fn a_changed_set_behind_a_forged_echo_is_refused_by_the_boards_commit_check() {
    let (first, second) = (calibration(1), calibration(2));
    let (sim, mut client) = board_holding(32, &first);
    sim.set_param_tamper(Some(ParamTamper::RestageFlippedHideEcho { bit: 7 }))
        .expect("tamper");
    let error = client
        .write_params_verified(&second)
        .expect_err("the commit of the host's CRC does not match the staged set");
    assert!(
        matches!(
            error.device_code(),
            Some(ErrorCode::CrcMismatch { received, .. }) if received == second.crc32()
        ),
        "{error:?}"
    );
    sim.set_param_tamper(None).expect("untamper");
    assert_still_active(&mut client, &first);
}

#[test]
fn a_corrupted_read_back_is_reported_as_a_verification_failure() {
    let (first, second) = (calibration(1), calibration(2));
    let (sim, mut client) = board_holding(33, &first);
    sim.set_param_tamper(Some(ParamTamper::FlipReadBack { bit: 2 }))
        .expect("tamper");
    let error = client
        .write_params_verified(&second)
        .expect_err("the read-back differs");
    assert!(
        matches!(error, DeviceError::VerifyFailed { .. }),
        "{error:?}"
    );
    assert!(error.to_string().contains("differing: accel"), "{error}");
    sim.set_param_tamper(None).expect("untamper");
    // The board holds exactly what the host computed; only the read-back was corrupted.
    assert_still_active(&mut client, &second);
}

#[test]
fn pose_captures_survive_lost_requests_and_replies_by_resending() {
    let faults = LinkFaults {
        // A 30-byte request is lost with p ≈ 12 %, a 100-byte PoseStats reply with p ≈ 33 %.
        flip_rate: 4e-3,
        ..LinkFaults::default()
    };
    let sim = board_with(28, faults);
    let options = ClientOptions {
        tries: 6,
        ..quick_options()
    };
    let mut client = DeviceClient::open_with(sim.port_path(), options).expect("connect");
    let rate = f64::from(client.welcome().scales.sample_rate_hz);
    let mut last_pose = None;
    for i in 0..6 {
        let pose = client
            .capture_pose(&still_pose(), &mut |_| {})
            .unwrap_or_else(|e| panic!("capture {i} failed: {e}"));
        // Half a second at the sample rate, less the samples of the window edge.
        assert!(f64::from(pose.n) >= 0.45 * rate, "n = {}", pose.n);
        last_pose = Some(pose);
    }
    let link = client.stats();
    println!(
        "6 captures: {} resends, {} frame errors; {:?}",
        link.retries,
        link.frame_errors,
        sim.fault_stats()
    );
    assert!(last_pose.is_some());
    assert!(link.frame_errors > 0, "the flips hit: {link:?}");
}

#[test]
fn a_capture_that_finds_another_running_waits_for_it_and_then_captures() {
    use std::io::Write;
    let sim = board_with(29, LinkFaults::default());
    // Another capture, started before this client connects (as one a resend started just as the
    // previous capture ended would be): 2 s of stillness.
    let mut foreign = [0u8; imucal_protocol::MAX_FRAME];
    let request = imucal_protocol::Request {
        seq: 999,
        body: imucal_protocol::RequestBody::CapturePose {
            min_still_ms: 2000,
            thresholds: still_pose().thresholds,
            timeout_ms: 10_000,
        },
    };
    let len = imucal_protocol::encode_frame(&request, &mut foreign).expect("encodes");
    let mut port = imucal::device::open_port(sim.port_path()).expect("open");
    port.write_all(&foreign[..len]).expect("write");
    drop(port);
    let mut client = DeviceClient::open_with(sim.port_path(), quick_options()).expect("connect");
    let pose = client
        .capture_pose(&still_pose(), &mut |_| {})
        .expect("the capture waits for the other one and succeeds");
    let rate = f64::from(client.welcome().scales.sample_rate_hz);
    // This capture's 0.5 s, not the other one's 2 s (whose reply, seq 999, is stale).
    assert!(
        f64::from(pose.n) >= 0.45 * rate && f64::from(pose.n) < 1.5 * rate,
        "n = {}",
        pose.n
    );
    assert!(client.stats().retries >= 2, "{:?}", client.stats());
}

/// A board holding `first` whose link garbles the `lose` replies after the first `skip` that
/// follow the next commit.
fn board_losing_replies_after_commit(
    seed: u64,
    first: &CalibrationSet,
    skip: u8,
    lose: u8,
) -> (SimHandle, DeviceClient) {
    let (sim, client) = board_holding(seed, first);
    sim.set_param_tamper(Some(ParamTamper::LoseRepliesAfterCommit { skip, lose }))
        .expect("tamper");
    (sim, client)
}

#[test]
fn a_commit_whose_answers_are_lost_is_settled_by_reading_the_board_again() {
    let (first, second) = (calibration(1), calibration(2));
    // The commit's answer and its two resends' answers are lost, then one more.
    let (sim, mut client) = board_losing_replies_after_commit(34, &first, 0, 4);
    let report = client
        .write_params_settled(&second)
        .expect("the board committed the set, so the write is settled as written");
    assert_eq!(report.status.active_crc, second.crc32());
    let note = report.recovered.expect("the lost answer is told");
    assert!(note.contains("the new set is active"), "{note}");
    assert!(note.contains("link is noisy"), "{note}");
    assert!(note.contains("matched every value"), "{note}");
    sim.set_param_tamper(None).expect("untamper");
    assert_still_active(&mut client, &second);
}

#[test]
fn a_read_back_lost_after_the_commit_is_retried_until_the_new_set_is_verified() {
    let (first, second) = (calibration(1), calibration(2));
    // The commit is answered; every try of the read-back that follows is lost.
    let (sim, mut client) = board_losing_replies_after_commit(35, &first, 1, 3);
    let report = client
        .write_params_settled(&second)
        .expect("the read-back is retried until it arrives");
    assert_eq!(report.status.active_crc, second.crc32());
    assert!(report.status.active_seq > 1, "{:?}", report.status);
    let note = report.recovered.expect("the lost answer is told");
    assert!(note.contains("GetParams"), "{note}");
    sim.set_param_tamper(None).expect("untamper");
    assert_still_active(&mut client, &second);
}

#[test]
fn answers_lost_until_contact_cannot_be_had_say_which_sets_it_could_be_and_blame_the_link() {
    let (first, second) = (calibration(1), calibration(2));
    let (_sim, mut client) = board_losing_replies_after_commit(36, &first, 1, 200);
    let error = client
        .write_params_settled(&second)
        .expect_err("nothing can be read back");
    let text = error.to_string();
    assert!(
        matches!(error, DeviceError::WriteUnsettled { .. }),
        "{error:?}"
    );
    assert!(text.contains("link is noisy"), "{text}");
    assert!(!text.contains("right port"), "{text}");
    assert!(
        text.contains(&format!("{:#010x}", second.crc32()))
            && text.contains(&format!("{:#010x}", first.crc32())),
        "{text}"
    );
}
