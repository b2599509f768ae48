//! A fake imucal board for the device tests: a thread that speaks the protocol over the master
//! side of a pseudo-terminal pair, using only the protocol crate, with switchable faults.
#![allow(dead_code, reason = "each test file uses a different part of the fake")]

use std::io::{Read, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use imucal_protocol::{
    check_hello, encode_frame, BatchHeader, CalibrationSet, DeviceId, DeviceMessage, DeviceStatus,
    ErrorCode, ErrorCounters, Event, FirmwareVersion, FrameDecoder, ParamStatus, PoseStats,
    ProtocolVersion, RawSample, Request, RequestBody, Response, ResponseBody, SampleBatch,
    SensorScales, SensorSet, StreamKind, Welcome, MAX_FRAME, PROTOCOL_VERSION,
};
use serialport::{SerialPort, TTYPort};

/// Faults and behaviours of the fake.
#[derive(Debug, Clone, Default)]
pub struct FakeConfig {
    /// Protocol version the fake speaks (default: the crate's).
    pub protocol: Option<ProtocolVersion>,
    /// Never answer anything.
    pub silent: bool,
    /// Ignore this many request frames at the start (as a QEMU pty dropping first bytes).
    pub drop_first_requests: usize,
    /// Apply the first commit but do not answer it.
    pub drop_first_commit_reply: bool,
    /// Report a staged CRC different from the one received.
    pub wrong_staged_crc: bool,
    /// Answer `WriteParams` with this error instead of staging.
    pub reject_params: Option<ErrorCode>,
    /// Send garbage and a frame with a broken CRC before every reply.
    pub noise_before_replies: bool,
    /// Send a stillness event and a sample batch before answering `Status`.
    pub events_before_status: bool,
    /// Skip this stream index range once (first batch index at which 20 samples go missing).
    pub gap_at_batch: Option<u32>,
    /// Delay before answering `CapturePose`, with a stillness event halfway.
    pub pose_delay: Duration,
}

/// What the fake received and holds, for assertions.
#[derive(Debug, Clone, Default)]
pub struct FakeState {
    /// Names of every request received (dropped ones included), in order.
    pub requests: Vec<&'static str>,
    /// The active parameter set.
    pub active: CalibrationSet,
    /// Commits applied.
    pub commits: u32,
}

/// The running fake; stops its thread when dropped.
pub struct FakeDevice {
    /// Path of the pty slave that the host opens.
    pub path: String,
    /// Shared state.
    pub state: Arc<Mutex<FakeState>>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    // Holds the slave open until the host has opened it, so the path stays valid.
    _slave: TTYPort,
}

impl Drop for FakeDevice {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

/// Scale factors like an LSM9DS1 at ±2 g, ±245 °/s, ±4 gauss, 119 Hz.
pub fn scales() -> SensorScales {
    SensorScales {
        accel_mps2_per_count: 0.061e-3 * 9.806_65,
        gyro_rads_per_count: 8.75e-3 * std::f32::consts::PI / 180.0,
        mag_ut_per_count: 0.014,
        temp_c_per_count: 1.0 / 16.0,
        temp_offset_c: 25.0,
        accel_range_mps2: 2.0 * 9.806_65,
        gyro_range_rads: 245.0 * std::f32::consts::PI / 180.0,
        mag_range_ut: 400.0,
        sample_rate_hz: 100.0,
    }
}

/// The raw sample the fake streams at stream index `i`.
pub fn fake_sample(i: u32) -> RawSample {
    let wiggle = (i % 7) as i16;
    RawSample {
        accel: [wiggle, -wiggle, 16_393],
        gyro: [10, -20, 30 + wiggle],
        mag: [1500, -300, 2800],
        temp: 16 * 3,
    }
}

/// Sample period of the fake, µs.
pub const PERIOD_US: u64 = 10_000;

impl FakeDevice {
    /// Starts a fake with `config`.
    pub fn start(config: FakeConfig) -> Self {
        let (master, slave) = TTYPort::pair().expect("the test machine provides pseudo-terminals");
        let path = slave.name().expect("a pty slave has a path");
        let state = Arc::new(Mutex::new(FakeState {
            active: CalibrationSet::identity(),
            ..FakeState::default()
        }));
        let stop = Arc::new(AtomicBool::new(false));
        let thread = {
            let state = Arc::clone(&state);
            let stop = Arc::clone(&stop);
            std::thread::spawn(move || serve(master, config, state, stop))
        };
        Self {
            path,
            state,
            stop,
            thread: Some(thread),
            _slave: slave,
        }
    }

    /// A copy of the fake's state.
    pub fn state(&self) -> FakeState {
        self.state.lock().expect("fake state lock").clone()
    }
}

struct Link {
    port: TTYPort,
    config: FakeConfig,
}

impl Link {
    fn send(&mut self, message: &DeviceMessage) {
        let mut frame = [0u8; MAX_FRAME];
        let len = encode_frame(message, &mut frame).expect("fake messages fit a frame");
        // The host may have closed the port; the fake then just stops being heard.
        let _ = self.port.write_all(&frame[..len]);
        let _ = self.port.flush();
    }

    fn reply(&mut self, seq: u16, body: ResponseBody) {
        if self.config.noise_before_replies {
            let mut frame = [0u8; MAX_FRAME];
            let len = encode_frame(
                &DeviceMessage::Response(Response {
                    seq,
                    body: ResponseBody::Pong(7),
                }),
                &mut frame,
            )
            .expect("fits");
            // Flip a payload bit: the CRC no longer matches.
            frame[2] ^= 0x10;
            let _ = self.port.write_all(&[0x55, 0x13, 0x00]);
            let _ = self.port.write_all(&frame[..len]);
        }
        self.send(&DeviceMessage::Response(Response { seq, body }));
    }
}

struct Stream {
    next_index: u32,
    t_us: u64,
    last_sent: Instant,
    gap_done: bool,
}

fn name(body: &RequestBody) -> &'static str {
    match body {
        RequestBody::Hello { .. } => "Hello",
        RequestBody::Ping(_) => "Ping",
        RequestBody::Status => "Status",
        RequestBody::StartStream { .. } => "StartStream",
        RequestBody::StopStream => "StopStream",
        RequestBody::CapturePose { .. } => "CapturePose",
        RequestBody::GetParams => "GetParams",
        RequestBody::WriteParams { .. } => "WriteParams",
        RequestBody::CommitParams { .. } => "CommitParams",
        RequestBody::ResetParams => "ResetParams",
    }
}

fn batch(stream: &mut Stream, count: u32) -> SampleBatch {
    let mut batch = SampleBatch::new(BatchHeader {
        first_index: stream.next_index,
        t0_us: stream.t_us,
        tick_us: 10,
    });
    for k in 0..count {
        let t = stream.t_us + u64::from(k) * PERIOD_US;
        batch
            .push(&fake_sample(stream.next_index + k), t)
            .expect("a 20-sample batch at 10 ms spans 190 ms < 655 ms");
    }
    stream.next_index += count;
    stream.t_us += u64::from(count) * PERIOD_US;
    batch
}

fn serve(
    mut master: TTYPort,
    config: FakeConfig,
    state: Arc<Mutex<FakeState>>,
    stop: Arc<AtomicBool>,
) {
    master
        .set_timeout(Duration::from_millis(5))
        .expect("pty timeout");
    let protocol = config.protocol.unwrap_or(PROTOCOL_VERSION);
    let mut link = Link {
        port: master,
        config: config.clone(),
    };
    let mut decoder = FrameDecoder::<MAX_FRAME>::new();
    let mut dropped = 0usize;
    let mut commit_replies_dropped = false;
    let mut staged: Option<(CalibrationSet, u32)> = None;
    let mut active_seq = 0u32;
    let mut stream: Option<Stream> = None;
    let mut buf = [0u8; 256];
    while !stop.load(Ordering::SeqCst) {
        let n = match link.port.read(&mut buf) {
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => 0,
            // EIO while no one holds the slave open: wait for the host.
            Err(_) => {
                std::thread::sleep(Duration::from_millis(5));
                0
            }
        };
        let mut requests = Vec::new();
        decoder.feed::<Request>(&buf[..n], |r| {
            if let Ok(request) = r {
                requests.push(request);
            }
        });
        for Request { seq, body } in requests {
            state
                .lock()
                .expect("fake state lock")
                .requests
                .push(name(&body));
            if config.silent {
                continue;
            }
            if dropped < config.drop_first_requests {
                dropped += 1;
                continue;
            }
            let reply = match body {
                RequestBody::Hello {
                    protocol_major,
                    protocol_minor,
                } => match check_hello(
                    protocol,
                    ProtocolVersion {
                        major: protocol_major,
                        minor: protocol_minor,
                    },
                ) {
                    Ok(_) => ResponseBody::Welcome(Welcome {
                        protocol_major: protocol.major,
                        protocol_minor: protocol.minor,
                        firmware_version: FirmwareVersion {
                            major: 0,
                            minor: 3,
                            patch: 1,
                        },
                        device_id: DeviceId::from_u64(0x00C0_FFEE),
                        sensors: SensorSet {
                            accel: true,
                            gyro: true,
                            mag: true,
                            temp: true,
                        },
                        scales: scales(),
                    }),
                    Err(code) => ResponseBody::Error(code),
                },
                RequestBody::Ping(v) => ResponseBody::Pong(v),
                RequestBody::Status => {
                    if config.events_before_status {
                        link.send(&DeviceMessage::Event(Event::StillnessChanged {
                            still: true,
                            t_ms: 1234,
                        }));
                        let mut s = Stream {
                            next_index: 0,
                            t_us: 1_000_000,
                            last_sent: Instant::now(),
                            gap_done: true,
                        };
                        let b = batch(&mut s, 3);
                        link.send(&DeviceMessage::Event(Event::SampleBatch(b)));
                    }
                    let active = state.lock().expect("fake state lock").active;
                    ResponseBody::Status(DeviceStatus {
                        uptime_ms: 5000,
                        streaming: stream.as_ref().map(|_| StreamKind::Raw),
                        still: true,
                        active_crc: active.crc32(),
                        active_seq,
                        errors: ErrorCounters::default(),
                    })
                }
                RequestBody::StartStream { .. } => {
                    stream = Some(Stream {
                        next_index: 0,
                        t_us: 2_000_000,
                        last_sent: Instant::now(),
                        gap_done: false,
                    });
                    ResponseBody::Ack
                }
                RequestBody::StopStream => {
                    stream = None;
                    ResponseBody::Ack
                }
                RequestBody::CapturePose { .. } => {
                    std::thread::sleep(config.pose_delay / 2);
                    link.send(&DeviceMessage::Event(Event::StillnessChanged {
                        still: true,
                        t_ms: 99,
                    }));
                    std::thread::sleep(config.pose_delay / 2);
                    ResponseBody::PoseStats(PoseStats {
                        n: 200,
                        accel_mean: [0.0, 0.0, 9.81],
                        accel_var: [1e-4; 3],
                        gyro_mean: [0.001, -0.002, 0.003],
                        gyro_var: [1e-6; 3],
                        mag_mean: [20.0, -4.0, 40.0],
                        mag_var: [0.1; 3],
                        temp_mean_c: 28.0,
                        temp_min_c: 27.9,
                        temp_max_c: 28.1,
                        duration_ms: 2000,
                    })
                }
                RequestBody::GetParams => {
                    ResponseBody::Params(state.lock().expect("fake state lock").active)
                }
                RequestBody::WriteParams { set, crc } => {
                    if let Some(code) = config.reject_params {
                        ResponseBody::Error(code)
                    } else if set.crc32() != crc {
                        ResponseBody::Error(ErrorCode::CrcMismatch {
                            received: crc,
                            computed: set.crc32(),
                        })
                    } else {
                        staged = Some((set, crc));
                        let active = state.lock().expect("fake state lock").active;
                        let echoed = if config.wrong_staged_crc {
                            crc ^ 0x0100
                        } else {
                            crc
                        };
                        ResponseBody::ParamStatus(ParamStatus {
                            active_crc: active.crc32(),
                            active_seq,
                            staged_crc: Some(echoed),
                        })
                    }
                }
                RequestBody::CommitParams { crc } => match staged.take() {
                    Some((set, staged_crc)) if staged_crc == crc => {
                        active_seq += 1;
                        let mut s = state.lock().expect("fake state lock");
                        s.active = set;
                        s.commits += 1;
                        drop(s);
                        if config.drop_first_commit_reply && !commit_replies_dropped {
                            commit_replies_dropped = true;
                            continue;
                        }
                        ResponseBody::ParamStatus(ParamStatus {
                            active_crc: crc,
                            active_seq,
                            staged_crc: None,
                        })
                    }
                    Some((set, staged_crc)) => {
                        staged = Some((set, staged_crc));
                        ResponseBody::Error(ErrorCode::CrcMismatch {
                            received: crc,
                            computed: staged_crc,
                        })
                    }
                    None => ResponseBody::Error(ErrorCode::NothingStaged),
                },
                RequestBody::ResetParams => {
                    active_seq += 1;
                    let mut s = state.lock().expect("fake state lock");
                    s.active = CalibrationSet::identity();
                    ResponseBody::ParamStatus(ParamStatus {
                        active_crc: s.active.crc32(),
                        active_seq,
                        staged_crc: None,
                    })
                }
            };
            link.reply(seq, reply);
        }
        if let Some(s) = stream.as_mut() {
            // 20 samples at 100 Hz every 200 ms, as a real board at this rate.
            if s.last_sent.elapsed() >= Duration::from_millis(200) {
                s.last_sent = Instant::now();
                if config.gap_at_batch == Some(s.next_index) && !s.gap_done {
                    s.gap_done = true;
                    // Lose one batch in transit.
                    let _ = batch(s, 20);
                }
                let b = batch(s, 20);
                link.send(&DeviceMessage::Event(Event::SampleBatch(b)));
            }
        }
    }
}
