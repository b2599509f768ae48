//! The simulated board in-process: the real firmware core answering the protocol over the
//! in-memory link, pose captures against the truth, parameters across reboots and power cuts.

use imucal_firmware::lsm9ds1;
use imucal_hil_sim::board::{
    BoardConfig, PersonPhase, PersonSchedule, SimBoard, CORNER_PATIENCE_S,
};
use imucal_hil_sim::physics::{lsm9ds1_scales, SensorKind};
use imucal_hil_sim::poser::{corner_holds, PoserOptions};
use imucal_protocol::{
    encode_frame, CalibrationSet, DeviceMessage, Event, FrameDecoder, PoseStats, Request,
    RequestBody, ResponseBody, StillThresholds, StreamKind, MAX_FRAME,
};
use nalgebra::{UnitQuaternion, Vector3};

/// Host-like thresholds: the hand tremor of the simulated person (sway up to 0.3° near 0.3 Hz)
/// stays below them, motion between positions does not.
const THRESHOLDS: StillThresholds = StillThresholds {
    accel_std_mps2: 0.1,
    gyro_std_rads: 0.02,
};

/// A minimal host speaking the protocol over the board's in-memory link.
struct Host {
    decoder: FrameDecoder<MAX_FRAME>,
    seq: u16,
    events: Vec<Event>,
}

impl Host {
    fn new() -> Self {
        Self {
            decoder: FrameDecoder::new(),
            seq: 0,
            events: Vec::new(),
        }
    }

    fn send(&mut self, board: &SimBoard, body: RequestBody) -> u16 {
        self.seq = self.seq.wrapping_add(1);
        let mut frame = [0u8; MAX_FRAME];
        let len = encode_frame(
            &Request {
                seq: self.seq,
                body,
            },
            &mut frame,
        )
        .unwrap();
        board.link().send_to_device(&frame[..len]);
        self.seq
    }

    /// Run the board in 10 ms steps until the reply to `seq` arrives or `limit_s` passes.
    fn wait(&mut self, board: &mut SimBoard, seq: u16, limit_s: f64) -> Option<ResponseBody> {
        let deadline = board.time_s() + limit_s;
        while board.time_s() < deadline {
            board.run_for(0.01).unwrap();
            let bytes = board.link().take_from_device();
            let mut reply = None;
            for message in self.decoder.messages::<DeviceMessage>(&bytes) {
                match message.unwrap() {
                    DeviceMessage::Response(r) if r.seq == seq => reply = Some(r.body),
                    DeviceMessage::Response(_) => {}
                    DeviceMessage::Event(e) => self.events.push(e),
                }
            }
            if reply.is_some() {
                return reply;
            }
        }
        None
    }

    fn request(&mut self, board: &mut SimBoard, body: RequestBody) -> ResponseBody {
        let seq = self.send(board, body);
        self.wait(board, seq, 1.0)
            .expect("the firmware answers within 1 s")
    }

    /// Show the next prompt as the guided session does: stream while the person reacts and
    /// turns away, then stop the stream.
    fn prompt_next(&mut self, board: &mut SimBoard) {
        let seq = self.send(
            board,
            RequestBody::StartStream {
                kind: StreamKind::Raw,
                decimation: 1,
            },
        );
        assert!(matches!(
            self.wait(board, seq, 1.0),
            Some(ResponseBody::Ack)
        ));
        board.run_for(1.0).unwrap();
        let seq = self.send(board, RequestBody::StopStream);
        assert!(matches!(
            self.wait(board, seq, 1.0),
            Some(ResponseBody::Ack)
        ));
    }

    fn capture(&mut self, board: &mut SimBoard) -> PoseStats {
        let seq = self.send(
            board,
            RequestBody::CapturePose {
                min_still_ms: 1000,
                thresholds: THRESHOLDS,
                timeout_ms: 15_000,
            },
        );
        match self.wait(board, seq, 20.0) {
            Some(ResponseBody::PoseStats(stats)) => stats,
            other => panic!("expected PoseStats, got {other:?}"),
        }
    }
}

fn quiet_board(seed: u64) -> SimBoard {
    let mut config = BoardConfig::new(seed);
    config.poser.tremor = false;
    SimBoard::new(config).unwrap()
}

/// The reading `x = A⁻¹·y + b` the physics produces on average for a still board in orientation
/// `q` (no effects switched on).
fn true_reading(board: &SimBoard, q: &UnitQuaternion<f64>, sensor: SensorKind) -> Vector3<f64> {
    let truth = board.truth();
    let to_body = q.inverse();
    let y = match sensor {
        SensorKind::Accel => to_body * Vector3::new(0.0, 0.0, truth.world.gravity_mps2),
        SensorKind::Gyro => Vector3::zeros(),
        SensorKind::Mag => to_body * Vector3::from(truth.world.field_world_ut),
    };
    let s = truth.imu.sensor(sensor);
    s.a_inverse() * y + s.b()
}

fn mean_and_var(stats: &PoseStats, sensor: SensorKind) -> ([f32; 3], [f32; 3]) {
    match sensor {
        SensorKind::Accel => (stats.accel_mean, stats.accel_var),
        SensorKind::Gyro => (stats.gyro_mean, stats.gyro_var),
        SensorKind::Mag => (stats.mag_mean, stats.mag_var),
    }
}

#[test]
fn hello_is_answered_with_welcome_carrying_the_lsm9ds1_scales() {
    let mut board = quiet_board(1);
    let mut host = Host::new();
    let ResponseBody::Welcome(welcome) = host.request(&mut board, RequestBody::hello()) else {
        panic!("Hello must be answered with Welcome");
    };
    assert_eq!(welcome.scales, lsm9ds1::Config::default().scales());
    let physics = lsm9ds1_scales(119.0);
    // The driver computes in f32 from the datasheet table; the physics in f64 then rounds:
    // they agree to f32 rounding (relative 1e-6).
    for (driver, model) in [
        (
            welcome.scales.accel_mps2_per_count,
            physics.accel_mps2_per_count,
        ),
        (
            welcome.scales.gyro_rads_per_count,
            physics.gyro_rads_per_count,
        ),
        (welcome.scales.mag_ut_per_count, physics.mag_ut_per_count),
        (welcome.scales.sample_rate_hz, physics.sample_rate_hz),
    ] {
        assert!(
            ((driver - model) / model).abs() < 1e-6,
            "{driver} vs {model}"
        );
    }
    assert!(welcome.sensors.accel && welcome.sensors.gyro && welcome.sensors.mag);
}

#[test]
fn samples_follow_the_firmware_period_and_simulated_time() {
    let mut board = quiet_board(2);
    board.run_for(10.0).unwrap();
    // 8403 µs period: 10 s hold 1 + ⌊10e6 / 8403⌋ = 1191 samples (the first at t = 0).
    assert_eq!(board.sample_period_us(), 8403);
    assert_eq!(board.samples_taken(), 1 + 10_000_000 / 8403);
    assert_eq!(board.time_us(), 10_000_000);
}

#[test]
fn pose_capture_at_a_hold_matches_the_true_reading_within_four_standard_errors() {
    let mut board = quiet_board(3);
    let mut host = Host::new();
    board.run_for(0.5).unwrap();
    let stats = host.capture(&mut board);
    let q = board.person().hold_orientations()[0];
    let n = f64::from(stats.n);
    // 1 s at 119 Hz.
    assert!(stats.n >= 119, "averaged only {} samples", stats.n);
    for sensor in SensorKind::ALL {
        let expected = true_reading(&board, &q, sensor);
        let sigma = board.truth().imu.sensor(sensor).noise_sigma;
        let (mean, var) = mean_and_var(&stats, sensor);
        for axis in 0..3 {
            // The standard error from the reported variance (noise plus quantisation).
            let se = (f64::from(var[axis]) / n).sqrt();
            let error = f64::from(mean[axis]) - expected[axis];
            assert!(
                error.abs() < 4.0 * se,
                "{sensor:?}[{axis}]: mean {} vs true {} (error {error:.3e}, SE {se:.3e})",
                mean[axis],
                expected[axis]
            );
            // The variance estimate of n normal samples has relative standard error √(2/(n−1));
            // quantisation adds LSB²/12, below 1 % of σ² for every sensor here.
            let relative = (f64::from(var[axis]) / (sigma * sigma) - 1.0).abs();
            assert!(
                relative < 4.0 * (2.0 / (n - 1.0)).sqrt(),
                "{sensor:?}[{axis}]: variance {} vs σ² {}",
                var[axis],
                sigma * sigma
            );
        }
    }
}

#[test]
fn the_person_holds_each_position_until_captured_then_an_asked_corner_then_tumbles_and_rests() {
    let mut config = BoardConfig::new(4);
    config.schedule = PersonSchedule::Guided;
    let mut board = SimBoard::new(config).unwrap();
    let mut host = Host::new();
    // Without prompts the person keeps the first position.
    board.run_for(30.0).unwrap();
    assert_eq!(board.person().phase(), PersonPhase::Hold { index: 0 });
    let orientations = board.person().hold_orientations();
    let g = board.truth().world.gravity_mps2;
    for (index, q) in orientations.iter().enumerate() {
        let stats = host.capture(&mut board);
        host.prompt_next(&mut board);
        let expected = true_reading(&board, q, SensorKind::Accel);
        let mean = Vector3::from(stats.accel_mean.map(f64::from));
        // Hand sway of up to 0.3° tilts gravity by up to g·sin 0.3° ≈ 0.05 m/s²; bound 0.1.
        assert!(
            (mean - expected).norm() < 0.1,
            "position {index}: accel mean {mean:?}, expected {expected:?}"
        );
        assert!(
            (mean.norm() - g).abs() < 0.05 * g,
            "position {index}: |f| = {}",
            mean.norm()
        );
    }
    // The host asks for a corner: the person holds the first of the corners.
    let stats = host.capture(&mut board);
    let corner = corner_holds(&PoserOptions::default(), 4).unwrap()[0].orientation;
    let expected = true_reading(&board, &corner, SensorKind::Accel);
    let mean = Vector3::from(stats.accel_mean.map(f64::from));
    assert!(
        (mean - expected).norm() < 0.1,
        "corner: accel mean {mean:?}, expected {expected:?}"
    );
    // No capture is asked for at the next corner: after the patience the person tumbles.
    // Moving on (1 s), the ramp (0.3 s), a turn of ≈70° (≈1 s), the patience and the ramp.
    board.run_for(3.0 + CORNER_PATIENCE_S).unwrap();
    assert!(
        matches!(board.person().phase(), PersonPhase::Tumble { .. }),
        "after a corner the host did not ask for the person tumbles, not {:?}",
        board.person().phase()
    );
    board.run_for(600.0).unwrap();
    assert_eq!(board.person().phase(), PersonPhase::Rest);
    let state = board.last_world_state().unwrap();
    assert!(
        state.omega_body.norm() < 1e-9,
        "at rest the board does not turn"
    );
}

#[test]
fn a_hold_ends_after_the_maximum_hold_time_without_a_capture() {
    let mut config = BoardConfig::new(5);
    config.max_hold_s = 3.0;
    let mut board = SimBoard::new(config).unwrap();
    let mut host = Host::new();
    // A capture that can never succeed (thresholds far below the noise) starts the prompts.
    let seq = host.send(
        &board,
        RequestBody::CapturePose {
            min_still_ms: 1000,
            thresholds: StillThresholds {
                accel_std_mps2: 1e-6,
                gyro_std_rads: 1e-9,
            },
            timeout_ms: 2000,
        },
    );
    let reply = host.wait(&mut board, seq, 5.0);
    assert!(matches!(reply, Some(ResponseBody::Error(_))), "{reply:?}");
    board.run_for(2.0).unwrap();
    assert!(
        matches!(
            board.person().phase(),
            PersonPhase::TurnToHold { index: 1 } | PersonPhase::Hold { index: 1 }
        ),
        "after 3 s without a capture the person moves on, not {:?}",
        board.person().phase()
    );
}

fn changed_set() -> CalibrationSet {
    let mut set = CalibrationSet::identity();
    set.created_unix_s = 1_700_000_000;
    set.accel.b = [0.12, -0.07, 0.3];
    set.mag.b = [12.0, -30.0, 5.5];
    set
}

fn commit(host: &mut Host, board: &mut SimBoard, set: &CalibrationSet) -> ResponseBody {
    let crc = set.crc32();
    let staged = host.request(board, RequestBody::WriteParams { set: *set, crc });
    assert!(matches!(staged, ResponseBody::ParamStatus(s) if s.staged_crc == Some(crc)));
    host.request(board, RequestBody::CommitParams { crc })
}

#[test]
fn committed_parameters_survive_a_reboot() {
    let mut board = quiet_board(6);
    let mut host = Host::new();
    let set = changed_set();
    let ResponseBody::ParamStatus(status) = commit(&mut host, &mut board, &set) else {
        panic!("commit must be answered with ParamStatus");
    };
    assert_eq!(status.active_crc, set.crc32());
    board.reboot().unwrap();
    let ResponseBody::Params(active) = host.request(&mut board, RequestBody::GetParams) else {
        panic!("GetParams must be answered with Params");
    };
    assert_eq!(active, set);
    let ResponseBody::Status(status) = host.request(&mut board, RequestBody::Status) else {
        panic!("Status must be answered with Status");
    };
    assert_eq!(status.active_seq, 1);
    assert!(status.uptime_ms < 1000, "uptime counts from the reboot");
}

#[test]
fn a_power_cut_at_any_flash_step_of_a_commit_leaves_the_old_or_the_new_set() {
    let old = {
        let mut set = changed_set();
        set.gyro.b = [0.01, 0.02, -0.03];
        set
    };
    let new = changed_set();
    let prepare = || {
        let mut board = quiet_board(7);
        let mut host = Host::new();
        commit(&mut host, &mut board, &old);
        let crc = new.crc32();
        host.request(&mut board, RequestBody::WriteParams { set: new, crc });
        (board, host)
    };
    let (mut board, mut host) = prepare();
    let before = board.flash_steps();
    host.request(&mut board, RequestBody::CommitParams { crc: new.crc32() });
    let steps = board.flash_steps() - before;
    // One sector erase plus the slot's 4-byte words (header and payload).
    assert!(steps > 10, "a commit takes {steps} flash steps");

    let mut outcomes = Vec::new();
    for cut in 0..=steps {
        let (mut board, mut host) = prepare();
        board.cut_power_at_flash_step(Some(cut));
        let seq = host.send(&board, RequestBody::CommitParams { crc: new.crc32() });
        let reply = host.wait(&mut board, seq, 0.2);
        if cut < steps {
            assert!(!board.is_powered(), "cut at step {cut} must stop the board");
            assert!(reply.is_none(), "a board that lost power does not answer");
        }
        board.reboot().unwrap();
        let ResponseBody::Params(active) = host.request(&mut board, RequestBody::GetParams) else {
            panic!("GetParams must be answered with Params");
        };
        assert!(
            active == old || active == new,
            "cut at step {cut} left neither set"
        );
        outcomes.push(active == new);
    }
    assert!(!outcomes[0], "a cut at the first step keeps the old set");
    assert!(
        outcomes[steps as usize],
        "without a cut the new set is active"
    );
}
