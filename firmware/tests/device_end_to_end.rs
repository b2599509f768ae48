//! End-to-end tests of `Device::poll()` through the wire protocol: a scripted IMU, an in-memory
//! link and a RAM flash, driven by encoded request frames and checked on decoded replies.

// Axis-indexed loops read like the per-axis formulas they check.
#![allow(clippy::needless_range_loop)]

use std::cell::{Cell, RefCell};
use std::rc::Rc;

mod bench;
use bench::{MemoryLink, StepClock};

use imucal_firmware::device::{Device, DeviceInfo};
use imucal_firmware::imu::{Imu, RawSample, SensorScales};
use imucal_firmware::ram_flash::RamFlash;
use imucal_firmware::store::ParamStore;
use imucal_protocol::{
    encode_frame, CalibrationSet, DeviceId, DeviceMessage, ErrorCode, Event, FirmwareVersion,
    FrameDecoder, InvalidParamsReason, ParamField, Request, RequestBody, ResponseBody, SensorKind,
    SensorSet, StillThresholds, StreamKind, MAX_FRAME, PROTOCOL_VERSION,
};

const RATE_HZ: f32 = 100.0;
const PERIOD_US: u64 = 10_000;
/// The still pose's true accelerometer counts (board flat, slightly tilted).
const STILL_ACCEL: [i16; 3] = [100, -200, 16_384];
/// Uniform noise half-widths in counts: std = w/√3 = 11.5 counts = 0.0069 m/s² (accel) and
/// 5.8 counts = 0.00088 rad/s (gyro), well inside the default stillness thresholds.
const ACCEL_NOISE: i32 = 20;
const GYRO_NOISE: i32 = 10;

type Flash = RamFlash<8192, 1024, 4>;
type TestDevice = Device<ScriptedImu, MemoryLink, Flash, StepClock, 32>;

fn scales() -> SensorScales {
    // LSM9DS1 at ±2 g, 245 °/s, ±4 gauss.
    SensorScales {
        accel_mps2_per_count: 0.061e-3 * 9.806_65,
        gyro_rads_per_count: 8.75e-3 * core::f32::consts::PI / 180.0,
        mag_ut_per_count: 0.014,
        temp_c_per_count: 1.0 / 16.0,
        temp_offset_c: 25.0,
        accel_range_mps2: 2.0 * 9.806_65,
        gyro_range_rads: 245.0 * core::f32::consts::PI / 180.0,
        mag_range_ut: 400.0,
        sample_rate_hz: RATE_HZ,
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Motion {
    Still,
    Turning,
    /// Still, with the accelerometer's z axis on the positive rail.
    StillSaturated,
    /// Every read fails.
    Broken,
}

struct ScriptedImu {
    motion: Rc<Cell<Motion>>,
    recorded: Rc<RefCell<Vec<RawSample>>>,
    rng: u32,
}

impl ScriptedImu {
    fn uniform(&mut self, half_width: i32) -> i32 {
        self.rng ^= self.rng << 13;
        self.rng ^= self.rng >> 17;
        self.rng ^= self.rng << 5;
        (self.rng % (2 * half_width as u32 + 1)) as i32 - half_width
    }
}

impl Imu for ScriptedImu {
    type Error = &'static str;

    fn scales(&self) -> SensorScales {
        scales()
    }

    fn read(&mut self) -> Result<RawSample, Self::Error> {
        let index = self.recorded.borrow().len() as f32;
        let noisy =
            |imu: &mut Self, value: i32, half_width: i32| (value + imu.uniform(half_width)) as i16;
        let sample = match self.motion.get() {
            Motion::Broken => return Err("bus error"),
            Motion::Still | Motion::StillSaturated => RawSample {
                accel: [
                    noisy(self, STILL_ACCEL[0].into(), ACCEL_NOISE),
                    noisy(self, STILL_ACCEL[1].into(), ACCEL_NOISE),
                    if self.motion.get() == Motion::StillSaturated {
                        i16::MAX
                    } else {
                        noisy(self, STILL_ACCEL[2].into(), ACCEL_NOISE)
                    },
                ],
                gyro: [
                    noisy(self, 30, GYRO_NOISE),
                    noisy(self, -12, GYRO_NOISE),
                    noisy(self, 5, GYRO_NOISE),
                ],
                mag: [
                    noisy(self, 2_000, 30),
                    noisy(self, -1_500, 30),
                    noisy(self, 3_000, 30),
                ],
                temp: noisy(self, 80, 2),
            },
            Motion::Turning => {
                // A turn at about 1 rad/s: gravity sweeps between axes.
                let phase = index * 0.15;
                RawSample {
                    accel: [
                        (16_000.0 * phase.sin()) as i16,
                        0,
                        (16_000.0 * phase.cos()) as i16,
                    ],
                    gyro: [0, (6_500.0 * (phase * 0.5).cos()) as i16, 0],
                    mag: [0; 3],
                    temp: 80,
                }
            }
        };
        self.recorded.borrow_mut().push(sample);
        Ok(sample)
    }
}

/// A device on the bench with the host side of its link.
struct Bench {
    device: TestDevice,
    time: Rc<Cell<u64>>,
    motion: Rc<Cell<Motion>>,
    recorded: Rc<RefCell<Vec<RawSample>>>,
    link: MemoryLink,
    decoder: FrameDecoder<MAX_FRAME>,
    next_seq: u16,
    /// Events received while waiting for responses.
    events: Vec<Event>,
}

fn info() -> DeviceInfo {
    DeviceInfo {
        device_id: DeviceId::from_u64(0x1234_5678_9abc_def0),
        firmware_version: FirmwareVersion {
            major: 0,
            minor: 1,
            patch: 0,
        },
        sensors: SensorSet {
            accel: true,
            gyro: true,
            mag: true,
            temp: true,
        },
    }
}

impl Bench {
    fn new() -> Self {
        Self::with_flash(Flash::new())
    }

    fn with_flash(flash: Flash) -> Self {
        let time = Rc::new(Cell::new(1_000_000));
        let motion = Rc::new(Cell::new(Motion::Still));
        let recorded = Rc::new(RefCell::new(Vec::new()));
        let imu = ScriptedImu {
            motion: motion.clone(),
            recorded: recorded.clone(),
            rng: 0x9E37_79B9,
        };
        let link = MemoryLink::default();
        let store = ParamStore::new(flash, 0, 2048).unwrap();
        let device =
            Device::new(imu, link.clone(), store, StepClock(time.clone()), info()).unwrap();
        Self {
            device,
            time,
            motion,
            recorded,
            link,
            decoder: FrameDecoder::new(),
            next_seq: 100,
            events: Vec::new(),
        }
    }

    /// Power off and on again: same flash, fresh device.
    fn reboot(self) -> Self {
        let (_, _, store, _) = self.device.into_parts();
        let mut flash = store.into_flash();
        flash.restore_power();
        Self::with_flash(flash)
    }

    fn send(&mut self, body: RequestBody) -> u16 {
        self.next_seq = self.next_seq.wrapping_add(7);
        let mut frame = [0u8; MAX_FRAME];
        let len = encode_frame(
            &Request {
                seq: self.next_seq,
                body,
            },
            &mut frame,
        )
        .unwrap();
        self.link.to_device.borrow_mut().extend(&frame[..len]);
        self.next_seq
    }

    /// Advance the clock one sample period and poll.
    fn step(&mut self) {
        self.time.set(self.time.get() + PERIOD_US);
        self.device.poll();
    }

    fn run(&mut self, steps: usize) {
        for _ in 0..steps {
            self.step();
        }
        self.collect();
    }

    /// Decode everything the device sent; responses are returned, events kept.
    fn collect(&mut self) -> Vec<(u16, ResponseBody)> {
        let bytes: Vec<u8> = self.link.from_device.borrow_mut().drain(..).collect();
        let mut responses = Vec::new();
        for message in self.decoder.messages::<DeviceMessage>(&bytes) {
            match message.expect("device frames decode") {
                DeviceMessage::Response(response) => responses.push((response.seq, response.body)),
                DeviceMessage::Event(event) => self.events.push(event),
            }
        }
        responses
    }

    /// Send a request and poll until its response arrives.
    fn request(&mut self, body: RequestBody, max_steps: usize) -> ResponseBody {
        let seq = self.send(body);
        for _ in 0..max_steps {
            self.step();
            let responses = self.collect();
            if let Some((echoed, body)) = responses.into_iter().next() {
                assert_eq!(echoed, seq, "the reply must echo the request's seq");
                return body;
            }
        }
        panic!("no response within {max_steps} steps");
    }
}

fn capture(min_still_ms: u32, timeout_ms: u32) -> RequestBody {
    RequestBody::CapturePose {
        min_still_ms,
        thresholds: StillThresholds {
            accel_std_mps2: 0.05,
            gyro_std_rads: 0.01,
        },
        timeout_ms,
    }
}

/// A plausible fitted set: small scale and cross-axis errors, offsets of a real part.
fn fitted_set() -> CalibrationSet {
    let mut set = CalibrationSet::identity();
    set.created_unix_s = 1_790_000_000;
    set.accel.a = [
        [1.02, 0.01, -0.005],
        [0.003, 0.98, 0.012],
        [-0.004, 0.006, 1.01],
    ];
    set.accel.b = [0.12, -0.3, 0.05];
    set.gyro.a = [[1.01, -0.02, 0.0], [0.015, 0.99, 0.004], [0.0, 0.01, 1.03]];
    set.gyro.b = [0.004, -0.002, 0.001];
    set.mag.a = [
        [1.0 / 48.0, 0.001, 0.0],
        [0.0, 1.0 / 52.0, -0.0005],
        [0.0, 0.0, 1.0 / 45.0],
    ];
    set.mag.b = [30.0, -12.0, 80.0];
    set
}

fn write_and_commit(bench: &mut Bench, set: &CalibrationSet) -> ResponseBody {
    let crc = set.crc32();
    let staged = bench.request(RequestBody::WriteParams { set: *set, crc }, 3);
    let ResponseBody::ParamStatus(status) = staged else {
        return staged;
    };
    assert_eq!(status.staged_crc, Some(crc));
    bench.request(RequestBody::CommitParams { crc }, 3)
}

#[test]
fn hello_is_answered_with_welcome_carrying_identity_and_scales() {
    let mut bench = Bench::new();
    let reply = bench.request(RequestBody::hello(), 3);
    let ResponseBody::Welcome(welcome) = reply else {
        panic!("expected Welcome, got {reply:?}");
    };
    assert_eq!(welcome.protocol_version(), PROTOCOL_VERSION);
    assert_eq!(welcome.device_id, info().device_id);
    assert_eq!(welcome.scales, scales());
    assert_eq!(welcome.sensors, info().sensors);
}

#[test]
fn hello_from_another_major_version_is_a_version_mismatch() {
    let mut bench = Bench::new();
    let reply = bench.request(
        RequestBody::Hello {
            protocol_major: PROTOCOL_VERSION.major + 1,
            protocol_minor: 0,
        },
        3,
    );
    assert_eq!(
        reply,
        ResponseBody::Error(ErrorCode::VersionMismatch {
            device_major: PROTOCOL_VERSION.major,
            device_minor: PROTOCOL_VERSION.minor,
        })
    );
}

#[test]
fn ping_status_and_garbage_are_handled() {
    let mut bench = Bench::new();
    assert_eq!(
        bench.request(RequestBody::Ping(0xDEAD_BEEF), 3),
        ResponseBody::Pong(0xDEAD_BEEF)
    );
    // A corrupt frame is dropped and counted; the next request is still served.
    bench
        .link
        .to_device
        .borrow_mut()
        .extend([0x05, 0x11, 0x22, 0x33, 0x44, 0x00]);
    bench.run(40);
    let ResponseBody::Status(status) = bench.request(RequestBody::Status, 3) else {
        panic!("expected Status");
    };
    assert_eq!(status.errors.rx_frame_errors, 1);
    assert!(
        status.still,
        "a still board is reported still once the window is full"
    );
    assert_eq!(status.active_seq, 0);
    assert_eq!(status.active_crc, CalibrationSet::identity().crc32());
    // Ping, 40 steps, then Status: handled in the 42nd poll, each 10 ms after construction.
    assert_eq!(status.uptime_ms, 420);
}

#[test]
fn still_pose_statistics_equal_those_of_the_averaged_samples() {
    let mut bench = Bench::new();
    bench.run(40); // fill the stillness window
    let first = bench.recorded.borrow().len();
    let reply = bench.request(capture(500, 5_000), 200);
    let ResponseBody::PoseStats(stats) = reply else {
        panic!("expected PoseStats, got {reply:?}");
    };
    // 500 ms at 100 Hz = 50 samples, the first 50 after the request (all still).
    assert_eq!(stats.n, 50);
    assert_eq!(stats.duration_ms, 490);
    let averaged = &bench.recorded.borrow()[first..first + 50];
    let s = scales();
    for axis in 0..3 {
        let values: Vec<f64> = averaged.iter().map(|x| f64::from(x.accel[axis])).collect();
        let mean = values.iter().sum::<f64>() / 50.0;
        let variance = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / 49.0;
        let unit = f64::from(s.accel_mps2_per_count);
        // The device's f64 Welford result rounded once to f32: 1e-6 relative covers it.
        let got_mean = f64::from(stats.accel_mean[axis]);
        assert!((got_mean - mean * unit).abs() <= 1e-6 * (mean * unit).abs());
        let got_var = f64::from(stats.accel_var[axis]);
        assert!((got_var - variance * unit * unit).abs() <= 1e-6 * variance * unit * unit);
        // Against the generating truth: within 4 standard errors (σ = 20/√3 counts, n = 50).
        let standard_error = 20.0 / 3f64.sqrt() / 50f64.sqrt() * unit;
        let truth = f64::from(STILL_ACCEL[axis]) * unit;
        assert!(
            (got_mean - truth).abs() < 4.0 * standard_error,
            "axis {axis}"
        );
        // Sample variance of uniform noise: (2w+1)²−1)/12 counts² = 140 counts², ±40 % at n = 50.
        let true_variance = (41.0f64.powi(2) - 1.0) / 12.0 * unit * unit;
        assert!((got_var / true_variance - 1.0).abs() < 0.4, "axis {axis}");
    }
    // Temperature 80 ± 2 counts → 30 °C ± 0.125 °C.
    assert!((stats.temp_mean_c - 30.0).abs() < 0.1);
    assert!(stats.temp_min_c >= 29.875 && stats.temp_max_c <= 30.125);
}

#[test]
fn a_turning_board_fails_with_not_still_and_emits_stillness_events() {
    let mut bench = Bench::new();
    bench.run(40);
    bench.motion.set(Motion::Turning);
    let reply = bench.request(capture(500, 1_000), 200);
    assert_eq!(reply, ResponseBody::Error(ErrorCode::NotStill));
    let changes: Vec<bool> = bench
        .events
        .iter()
        .filter_map(|e| match e {
            Event::StillnessChanged { still, .. } => Some(*still),
            _ => None,
        })
        .collect();
    assert_eq!(changes, vec![true, false]);
}

#[test]
fn a_board_on_the_rail_fails_with_saturated() {
    let mut bench = Bench::new();
    bench.motion.set(Motion::StillSaturated);
    bench.run(40);
    let reply = bench.request(capture(500, 5_000), 200);
    assert_eq!(reply, ResponseBody::Error(ErrorCode::Saturated));
}

#[test]
fn a_sensor_that_stops_answering_fails_the_capture_with_timeout() {
    let mut bench = Bench::new();
    bench.run(40);
    bench.motion.set(Motion::Broken);
    let reply = bench.request(capture(500, 300), 100);
    assert_eq!(reply, ResponseBody::Error(ErrorCode::Timeout));
    assert!(bench.device.error_counters().sensor_errors >= 30);
}

#[test]
fn a_second_capture_while_one_runs_is_busy() {
    let mut bench = Bench::new();
    let first = bench.send(capture(500, 5_000));
    let second = bench.send(capture(500, 5_000));
    bench.step();
    let responses = bench.collect();
    assert_eq!(
        responses,
        vec![(second, ResponseBody::Error(ErrorCode::Busy))]
    );
    assert_ne!(first, second);
}

#[test]
fn written_parameters_are_committed_read_back_and_survive_a_reboot() {
    let mut bench = Bench::new();
    let set = fitted_set();
    let ResponseBody::ParamStatus(status) = write_and_commit(&mut bench, &set) else {
        panic!("commit failed");
    };
    assert_eq!(status.active_crc, set.crc32());
    assert_eq!(status.active_seq, 1);
    assert_eq!(status.staged_crc, None);
    assert_eq!(
        bench.request(RequestBody::GetParams, 3),
        ResponseBody::Params(set)
    );

    let mut bench = bench.reboot();
    assert_eq!(
        bench.request(RequestBody::GetParams, 3),
        ResponseBody::Params(set)
    );
    // Reset installs the identity, also persistently.
    let ResponseBody::ParamStatus(status) = bench.request(RequestBody::ResetParams, 3) else {
        panic!("reset failed");
    };
    assert_eq!(status.active_seq, 2);
    let mut bench = bench.reboot();
    assert_eq!(
        bench.request(RequestBody::GetParams, 3),
        ResponseBody::Params(CalibrationSet::identity())
    );
}

#[test]
fn rejected_parameters_leave_the_previous_set_active() {
    let mut bench = Bench::new();
    let good = fitted_set();
    write_and_commit(&mut bench, &good);

    let mut nan = good;
    nan.gyro.a[1][1] = f32::NAN;
    let reply = bench.request(
        RequestBody::WriteParams {
            set: nan,
            crc: nan.crc32(),
        },
        3,
    );
    assert_eq!(
        reply,
        ResponseBody::Error(ErrorCode::InvalidParams(InvalidParamsReason::NonFinite(
            ParamField::Matrix(SensorKind::Gyro)
        )))
    );

    let wrong_crc = good.crc32() ^ 1;
    let reply = bench.request(
        RequestBody::WriteParams {
            set: good,
            crc: wrong_crc,
        },
        3,
    );
    assert_eq!(
        reply,
        ResponseBody::Error(ErrorCode::CrcMismatch {
            received: wrong_crc,
            computed: good.crc32()
        })
    );
    assert_eq!(
        bench.request(RequestBody::CommitParams { crc: 7 }, 3),
        ResponseBody::Error(ErrorCode::NothingStaged)
    );
    assert_eq!(
        bench.request(RequestBody::GetParams, 3),
        ResponseBody::Params(good)
    );
    let mut bench = bench.reboot();
    assert_eq!(
        bench.request(RequestBody::GetParams, 3),
        ResponseBody::Params(good)
    );
}

#[test]
fn a_power_cut_during_commit_keeps_the_previous_set() {
    let mut bench = Bench::new();
    let good = fitted_set();
    write_and_commit(&mut bench, &good);
    let mut newer = good;
    newer.accel.b = [0.2, -0.1, 0.0];
    let crc = newer.crc32();
    bench.request(RequestBody::WriteParams { set: newer, crc }, 3);
    // Reboot with a flash that dies during the next write (step 5: after the erase).
    let (_, _, store, _) = bench.device.into_parts();
    let mut flash = store.into_flash();
    flash.restore_power();
    flash.cut_power_at_step(Some(5));
    let mut bench = Bench::with_flash(flash);
    bench.request(RequestBody::WriteParams { set: newer, crc }, 3);
    assert_eq!(
        bench.request(RequestBody::CommitParams { crc }, 3),
        ResponseBody::Error(ErrorCode::FlashError)
    );
    assert_eq!(bench.device.error_counters().flash_errors, 1);
    assert_eq!(
        bench.request(RequestBody::GetParams, 3),
        ResponseBody::Params(good)
    );
    let mut bench = bench.reboot();
    assert_eq!(
        bench.request(RequestBody::GetParams, 3),
        ResponseBody::Params(good)
    );
}

/// Emitted stream samples paired with the raw samples they came from.
fn streamed(
    bench: &mut Bench,
    kind: StreamKind,
    decimation: u16,
    steps: usize,
) -> (usize, Vec<Event>) {
    bench.events.clear();
    let first = bench.recorded.borrow().len();
    assert_eq!(
        bench.request(RequestBody::StartStream { kind, decimation }, 1),
        ResponseBody::Ack
    );
    // The first streamed sample is the one read in the same poll as the request.
    bench.run(steps - 1);
    assert_eq!(bench.request(RequestBody::StopStream, 1), ResponseBody::Ack);
    let batches = bench
        .events
        .drain(..)
        .filter(|e| matches!(e, Event::SampleBatch(_) | Event::CalibratedBatch(_)))
        .collect();
    (first, batches)
}

#[test]
fn raw_stream_carries_every_decimated_sample_in_order() {
    let mut bench = Bench::new();
    let (first, batches) = streamed(&mut bench, StreamKind::Raw, 3, 100);
    let recorded = bench.recorded.borrow();
    let mut count = 0;
    for event in &batches {
        let Event::SampleBatch(batch) = event else {
            unreachable!()
        };
        assert_eq!(
            batch.header().first_index as usize,
            count,
            "no gap between batches"
        );
        for (i, (sample, t_us)) in batch.iter().enumerate() {
            let k = batch.header().first_index as usize + i;
            assert_eq!(sample, recorded[first + 3 * k]);
            // Sample k was read at boot + (first + 3k + 1) periods, quantised down to the tick.
            let read_at = 1_000_000 + (first + 3 * k + 1) as u64 * PERIOD_US;
            assert!(t_us <= read_at && read_at - t_us < u64::from(batch.header().tick_us));
            count += 1;
        }
    }
    // 100 samples streamed (request poll included), every third emitted: 0, 3, …, 99.
    assert_eq!(count, 34);
}

#[test]
fn calibrated_stream_equals_a_times_x_minus_b_in_f64() {
    let mut bench = Bench::new();
    let set = fitted_set();
    write_and_commit(&mut bench, &set);
    bench.motion.set(Motion::Turning); // exercise the full range, not one pose
    let (first, batches) = streamed(&mut bench, StreamKind::Calibrated, 2, 120);
    let recorded = bench.recorded.borrow();
    let s = scales();
    let sensors = [
        (&set.accel, s.accel_mps2_per_count, s.accel_range_mps2),
        (&set.gyro, s.gyro_rads_per_count, s.gyro_range_rads),
        (&set.mag, s.mag_ut_per_count, s.mag_range_ut),
    ];
    let mut count = 0;
    let mut worst = 0.0f64;
    for event in &batches {
        let Event::CalibratedBatch(batch) = event else {
            unreachable!()
        };
        for (i, (sample, _)) in batch.iter().enumerate() {
            let raw = recorded[first + 2 * (batch.header().first_index as usize + i)];
            let raw_axes = [raw.accel, raw.gyro, raw.mag];
            let outputs = [sample.accel, sample.gyro, sample.mag];
            for (((sensor, per_count, range), counts), output) in
                sensors.iter().zip(raw_axes).zip(outputs)
            {
                for row in 0..3 {
                    let expected: f64 = (0..3)
                        .map(|col| {
                            let x = f64::from(counts[col]) * f64::from(*per_count);
                            f64::from(sensor.a[row][col]) * (x - f64::from(sensor.b[col]))
                        })
                        .sum();
                    worst =
                        worst.max((f64::from(output[row]) - expected).abs() / f64::from(*range));
                }
            }
            count += 1;
        }
    }
    assert_eq!(count, 60);
    // f32 rounding of a 3-term dot product of full-scale-sized terms: < 1e-6 of full scale.
    assert!(worst < 1e-6, "worst error {worst:e} of full scale");
}

#[test]
fn zero_decimation_is_an_invalid_argument() {
    let mut bench = Bench::new();
    let reply = bench.request(
        RequestBody::StartStream {
            kind: StreamKind::Raw,
            decimation: 0,
        },
        1,
    );
    assert_eq!(reply, ResponseBody::Error(ErrorCode::InvalidArgument));
}
