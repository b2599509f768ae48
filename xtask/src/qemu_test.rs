//! `firmware qemu-test`: the release firmware in QEMU, checked end to end over its UARTs.
//!
//! UART0 is a pseudo-terminal owned by this program (`TTYPort::pair`, QEMU opens the slave), the
//! same kind of serial port the host tool uses. UART1 is a unix socket served by QEMU, to which a
//! feeder thread writes the board's sensor feed: a `Scales` frame (repeated, so a rebooted
//! firmware finds it), then samples at the announced rate whose magnetometer x count is the
//! sample's index, so every streamed sample can be matched to the one fed. A second unix socket
//! carries QEMU's monitor, used for `system_reset` (a soft reset that keeps RAM).
//!
//! Checks, in order: Hello/Welcome (version, announced scales), Ping, raw stream equal to the
//! feed, write/commit/read-back of a parameter set, calibrated stream equal to `A·(σ·c − b)`
//! computed here, soft reset with the set still active, and a power cycle (new QEMU) that
//! starts on identity. The end-to-end calibration with `imucal calibrate` and the simulator's
//! world model is not run yet; the summary says so.

use std::io::{Read, Write};
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use imucal_protocol::feed::{self, FeedFrame, MAX_FEED_FRAME};
use imucal_protocol::{
    encode_frame, CalibrationSet, DeviceMessage, Event, FrameDecoder, RawSample, Request,
    RequestBody, ResponseBody, SensorCalibration, SensorScales, StreamKind, MAX_FRAME,
    PROTOCOL_MAJOR,
};
use serialport::{SerialPort, TTYPort};

use crate::qemu;

/// The emulated chip: an LSM9DS1 at ±4 g, ±500 °/s, ±8 gauss, 119 Hz (datasheet sensitivities).
const SCALES: SensorScales = SensorScales {
    accel_mps2_per_count: 0.122e-3 * 9.806_65,
    gyro_rads_per_count: 17.5e-3 * std::f32::consts::PI / 180.0,
    mag_ut_per_count: 0.029,
    temp_c_per_count: 1.0 / 16.0,
    temp_offset_c: 25.0,
    accel_range_mps2: 4.0 * 9.806_65,
    gyro_range_rads: 500.0 * std::f32::consts::PI / 180.0,
    mag_range_ut: 800.0,
    sample_rate_hz: 119.0,
};
/// Sample period of the feed, µs (119 Hz rounded as the firmware rounds it).
const PERIOD_US: u64 = 8403;
/// A `Scales` frame is repeated every this many samples.
const SCALES_EVERY: u64 = 32;

/// The fed sample with index `i`: a board lying flat, with the index in the magnetometer x count.
fn fed_sample(i: u64) -> RawSample {
    let wobble = (i % 7) as i16 - 3;
    RawSample {
        accel: [40 + wobble, -25, 8190 - wobble],
        gyro: [3, -2 + wobble, 1],
        mag: [(i % 30_000) as i16, -800 + wobble, 400],
        temp: 64 + wobble,
    }
}

/// Writes the feed to QEMU's UART1 socket until told to stop.
struct Feeder {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<Result<(), String>>>,
}

impl Feeder {
    fn start(socket: PathBuf) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let flag = Arc::clone(&stop);
        let thread = std::thread::spawn(move || feed_loop(&socket, &flag));
        Self {
            stop,
            thread: Some(thread),
        }
    }

    fn finish(mut self) -> Result<(), String> {
        self.stop.store(true, Ordering::Relaxed);
        self.thread.take().map_or(Ok(()), |t| {
            t.join()
                .unwrap_or_else(|_| Err("the feeder thread panicked".into()))
        })
    }
}

impl Drop for Feeder {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

fn connect_retrying(path: &Path, what: &str) -> Result<UnixStream, String> {
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        match UnixStream::connect(path) {
            Ok(stream) => return Ok(stream),
            Err(_) if Instant::now() < deadline => std::thread::sleep(Duration::from_millis(50)),
            Err(e) => {
                return Err(format!(
                    "could not connect to QEMU's {what} socket {}: {e}",
                    path.display()
                ))
            }
        }
    }
}

fn feed_loop(socket: &Path, stop: &AtomicBool) -> Result<(), String> {
    let mut stream = connect_retrying(socket, "UART1")?;
    let started = Instant::now();
    let mut buf = [0u8; MAX_FEED_FRAME];
    let mut send = |stream: &mut UnixStream, frame: &FeedFrame| -> Result<(), String> {
        let n = feed::encode(frame, &mut buf)
            .map_err(|e| format!("feed frame does not encode: {e:?}"))?;
        stream
            .write_all(&buf[..n])
            .map_err(|e| format!("writing the feed to QEMU failed: {e}"))
    };
    let mut i = 0u64;
    while !stop.load(Ordering::Relaxed) {
        if i.is_multiple_of(SCALES_EVERY) {
            send(&mut stream, &FeedFrame::Scales(SCALES))?;
        }
        let t_us = i * PERIOD_US;
        send(
            &mut stream,
            &FeedFrame::Sample {
                t_us,
                sample: fed_sample(i),
            },
        )?;
        i += 1;
        // Real-time pacing keeps the firmware's feed-derived clock close to wall time.
        let due = started + Duration::from_micros(i * PERIOD_US);
        if let Some(wait) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
    }
    Ok(())
}

/// One QEMU process with its pty, feeder and monitor.
struct Board {
    qemu: Child,
    port: TTYPort,
    feeder: Feeder,
    monitor_socket: PathBuf,
    decoder: FrameDecoder<MAX_FRAME>,
    seq: u16,
    /// Samples seen in stream events, in arrival order.
    raw_seen: Vec<(RawSample, u64)>,
    calibrated_seen: Vec<(imucal_protocol::CalibratedSample, u64)>,
}

impl Board {
    fn start(elf: &Path, dir: &Path, run: u32) -> Result<Self, String> {
        let (master, mut slave) =
            TTYPort::pair().map_err(|e| format!("could not create a pseudo-terminal pair: {e}"))?;
        // QEMU opens the slave itself; our handle must not lock it.
        let _ = slave.set_exclusive(false);
        let slave_path = slave.name().ok_or("the pseudo-terminal has no path")?;
        let feed_socket = dir.join(format!("uart1-{run}.sock"));
        let monitor_socket = dir.join(format!("monitor-{run}.sock"));
        let mut cmd = qemu::base_command();
        cmd.args([
            "-chardev",
            &format!("serial,id=u0,path={slave_path}"),
            "-serial",
            "chardev:u0",
        ])
        .args([
            "-chardev",
            &format!(
                "socket,id=u1,path={},server=on,wait=off",
                feed_socket.display()
            ),
            "-serial",
            "chardev:u1",
        ])
        .args([
            "-monitor",
            &format!("unix:{},server=on,wait=off", monitor_socket.display()),
        ])
        .arg("-kernel")
        .arg(elf)
        .stdout(Stdio::null())
        .stderr(Stdio::null());
        let qemu = cmd.spawn().map_err(|e| {
            format!(
                "could not start qemu-system-arm ({e}); run scripts/setup-firmware-toolchain.sh"
            )
        })?;
        drop(slave);
        let feeder = Feeder::start(feed_socket);
        let mut port = master;
        port.set_timeout(Duration::from_millis(50))
            .map_err(|e| format!("setting the pty timeout failed: {e}"))?;
        Ok(Self {
            qemu,
            port,
            feeder,
            monitor_socket,
            decoder: FrameDecoder::new(),
            seq: 0,
            raw_seen: Vec::new(),
            calibrated_seen: Vec::new(),
        })
    }

    /// Sends `body` and waits for the response with the same sequence id, keeping stream events.
    fn request(&mut self, body: RequestBody, timeout: Duration) -> Result<ResponseBody, String> {
        self.seq = self.seq.wrapping_add(1);
        let seq = self.seq;
        let mut frame = [0u8; MAX_FRAME];
        let n = encode_frame(&Request { seq, body }, &mut frame)
            .map_err(|e| format!("request does not encode: {e:?}"))?;
        self.port
            .write_all(&frame[..n])
            .map_err(|e| format!("writing to the pty failed: {e}"))?;
        let deadline = Instant::now() + timeout;
        while Instant::now() < deadline {
            for message in self.receive()? {
                if let DeviceMessage::Response(response) = message {
                    if response.seq == seq {
                        return Ok(response.body);
                    }
                }
            }
        }
        Err(format!(
            "no response to request {seq} within {} ms",
            timeout.as_millis()
        ))
    }

    /// Reads what is available (up to the port timeout) and decodes it; records stream events.
    fn receive(&mut self) -> Result<Vec<DeviceMessage>, String> {
        let mut bytes = [0u8; 1024];
        let n = match self.port.read(&mut bytes) {
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => 0,
            Err(e) => return Err(format!("reading the pty failed: {e}")),
        };
        let mut out = Vec::new();
        for message in self.decoder.messages::<DeviceMessage>(&bytes[..n]) {
            match message {
                Ok(DeviceMessage::Event(Event::SampleBatch(batch))) => {
                    self.raw_seen.extend(batch.iter())
                }
                Ok(DeviceMessage::Event(Event::CalibratedBatch(batch))) => {
                    self.calibrated_seen.extend(batch.iter())
                }
                Ok(message) => out.push(message),
                // A frame cut by QEMU's pty start-up is expected at most once; retries cover it.
                Err(_) => {}
            }
        }
        Ok(out)
    }

    /// Hello with retries: QEMU may take a second to start reading a freshly opened pty.
    fn hello(&mut self) -> Result<imucal_protocol::Welcome, String> {
        for _ in 0..10 {
            match self.request(RequestBody::hello(), Duration::from_millis(700)) {
                Ok(ResponseBody::Welcome(welcome)) => return Ok(welcome),
                Ok(other) => return Err(format!("Hello was answered with {other:?}")),
                Err(_) => continue,
            }
        }
        Err("the firmware did not answer Hello within 7 s (is the feed reaching UART1?)".into())
    }

    /// Collects stream events for `duration`.
    fn listen(&mut self, duration: Duration) -> Result<(), String> {
        let deadline = Instant::now() + duration;
        while Instant::now() < deadline {
            self.receive()?;
        }
        Ok(())
    }

    fn monitor(&self, command: &str) -> Result<(), String> {
        let mut monitor = connect_retrying(&self.monitor_socket, "monitor")?;
        monitor
            .write_all(format!("{command}\n").as_bytes())
            .map_err(|e| format!("writing to the QEMU monitor failed: {e}"))?;
        // Give the monitor time to execute before the connection closes.
        std::thread::sleep(Duration::from_millis(300));
        Ok(())
    }

    fn stop(mut self) -> Result<(), String> {
        qemu::kill(&mut self.qemu);
        let feeder = std::mem::replace(
            &mut self.feeder,
            Feeder {
                stop: Arc::new(AtomicBool::new(true)),
                thread: None,
            },
        );
        // The feeder fails with a broken pipe once QEMU is gone; that is expected here.
        let _ = feeder.finish();
        Ok(())
    }
}

impl Drop for Board {
    fn drop(&mut self) {
        qemu::kill(&mut self.qemu);
    }
}

/// The set written by the test: scale, cross-axis and offset on every sensor.
fn test_set() -> CalibrationSet {
    let sensor = |scale: f32, offset: f32| SensorCalibration {
        a: [
            [scale, 0.01, -0.02],
            [0.003, scale * 0.98, 0.015],
            [-0.01, 0.02, scale * 1.03],
        ],
        b: [offset, -offset * 0.5, offset * 0.25],
        ..SensorCalibration::identity()
    };
    CalibrationSet {
        created_unix_s: 1_700_000_000,
        accel: sensor(1.01, 0.12),
        gyro: sensor(0.99, 0.004),
        mag: sensor(1.05, 12.0),
        ..CalibrationSet::identity()
    }
}

/// `A·(σ·c − b)` in f64.
fn expected(cal: &SensorCalibration, counts: [i16; 3], per_count: f32) -> [f64; 3] {
    let u: Vec<f64> = (0..3)
        .map(|k| f64::from(per_count) * f64::from(counts[k]) - f64::from(cal.b[k]))
        .collect();
    let mut y = [0.0; 3];
    for (row, out) in cal.a.iter().zip(y.iter_mut()) {
        *out = row.iter().zip(&u).map(|(a, u)| f64::from(*a) * u).sum();
    }
    y
}

/// Records the outcome of each check; a check that did not run is listed as such, never as passed.
struct Report {
    lines: Vec<(String, Result<String, String>)>,
}

impl Report {
    fn check(&mut self, name: &str, result: Result<String, String>) -> bool {
        let ok = result.is_ok();
        match &result {
            Ok(detail) => println!("  PASS  {name}: {detail}"),
            Err(why) => println!("  FAIL  {name}: {why}"),
        }
        self.lines.push((name.to_string(), result));
        ok
    }
}

/// Runs every check; fails when any check fails.
pub fn run(elf: &Path) -> Result<(), String> {
    let dir = std::env::temp_dir().join(format!("imucal-qemu-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    println!("qemu-test: firmware {}", elf.display());
    let mut report = Report { lines: Vec::new() };
    let result = checks(elf, &dir, &mut report);
    let _ = std::fs::remove_dir_all(&dir);
    println!("not run: end-to-end `imucal calibrate` against QEMU with the simulator's world model (those pieces are not available to this test yet)");
    let failed = report.lines.iter().filter(|(_, r)| r.is_err()).count();
    result?;
    if failed > 0 {
        return Err(format!("{failed} of {} checks failed", report.lines.len()));
    }
    println!(
        "qemu-test: all {} checks that ran passed",
        report.lines.len()
    );
    Ok(())
}

fn checks(elf: &Path, dir: &Path, report: &mut Report) -> Result<(), String> {
    let mut board = Board::start(elf, dir, 1)?;

    let welcome = board.hello();
    let hello_ok = report.check(
        "Hello/Welcome",
        welcome.as_ref().map_err(Clone::clone).and_then(|w| {
            if w.protocol_major != PROTOCOL_MAJOR {
                Err(format!(
                    "protocol {} vs host {PROTOCOL_MAJOR}",
                    w.protocol_major
                ))
            } else if w.scales != SCALES {
                Err(format!(
                    "scales {:?} differ from those fed on UART1 {SCALES:?}",
                    w.scales
                ))
            } else {
                Ok(format!(
                    "protocol {}.{}, scales as fed on UART1",
                    w.protocol_major, w.protocol_minor
                ))
            }
        }),
    );
    if !hello_ok {
        return board.stop();
    }

    let ping = board.request(RequestBody::Ping(0xC0FF_EE11), Duration::from_secs(2));
    report.check(
        "Ping",
        match ping {
            Ok(ResponseBody::Pong(0xC0FF_EE11)) => Ok("Pong echoed".into()),
            other => Err(format!("{other:?}")),
        },
    );

    // Raw stream: samples must be the fed ones, consecutive, with the fed timestamps.
    let ack = board.request(
        RequestBody::StartStream {
            kind: StreamKind::Raw,
            decimation: 1,
        },
        Duration::from_secs(2),
    );
    board.listen(Duration::from_millis(800))?;
    let stop_ack = board.request(RequestBody::StopStream, Duration::from_secs(2));
    let raw = std::mem::take(&mut board.raw_seen);
    report.check(
        "raw stream equals the UART1 feed",
        check_raw(&ack, &stop_ack, &raw),
    );

    // Parameters: write, commit, read back.
    let set = test_set();
    let crc = set.crc32();
    let write = board.request(
        RequestBody::WriteParams { set, crc },
        Duration::from_secs(2),
    );
    let commit = board.request(RequestBody::CommitParams { crc }, Duration::from_secs(2));
    let read = board.request(RequestBody::GetParams, Duration::from_secs(2));
    let params_ok = report.check(
        "write/commit/read back parameters",
        match (&write, &commit, &read) {
            (
                Ok(ResponseBody::ParamStatus(w)),
                Ok(ResponseBody::ParamStatus(c)),
                Ok(ResponseBody::Params(back)),
            ) if w.staged_crc == Some(crc) && c.active_crc == crc && *back == set => Ok(format!(
                "CRC {crc:08x} staged, committed (sequence {}), read back equal",
                c.active_seq
            )),
            _ => Err(format!("write {write:?}, commit {commit:?}, read {read:?}")),
        },
    );

    // Calibrated stream: the firmware's output against A(σc − b) computed here.
    let ack = board.request(
        RequestBody::StartStream {
            kind: StreamKind::Calibrated,
            decimation: 1,
        },
        Duration::from_secs(2),
    );
    board.listen(Duration::from_millis(600))?;
    let _ = board.request(RequestBody::StopStream, Duration::from_secs(2));
    let calibrated = std::mem::take(&mut board.calibrated_seen);
    report.check(
        "calibrated stream equals A(sigma c - b)",
        check_calibrated(&ack, &calibrated, &set),
    );

    // Soft reset: RAM (and so the parameter storage) survives; the firmware reboots.
    let uptime_before = status_uptime(&mut board);
    board.monitor("system_reset")?;
    let after = board.hello().and_then(|_| {
        let status = board.request(RequestBody::Status, Duration::from_secs(2))?;
        let params = board.request(RequestBody::GetParams, Duration::from_secs(2))?;
        Ok((status, params))
    });
    report.check(
        "soft reset keeps the committed parameters",
        match (params_ok, after, uptime_before) {
            (false, _, _) => Err("not meaningful: the parameters were not committed".into()),
            (true, Ok((ResponseBody::Status(status), ResponseBody::Params(back))), Ok(before))
                if status.uptime_ms < before && status.active_crc == crc && back == set =>
            {
                Ok(format!(
                    "uptime {} ms -> {} ms (rebooted), active CRC {crc:08x}",
                    before, status.uptime_ms
                ))
            }
            (true, other, before) => {
                Err(format!("after reset {other:?}, uptime before {before:?}"))
            }
        },
    );
    board.stop()?;

    // Power cycle: a new QEMU process starts with erased storage, so on identity.
    let mut board = Board::start(elf, dir, 2)?;
    let cold = board
        .hello()
        .and_then(|_| board.request(RequestBody::GetParams, Duration::from_secs(2)));
    report.check(
        "power cycle starts on the identity set",
        match cold {
            Ok(ResponseBody::Params(back)) if back == CalibrationSet::identity() => {
                Ok("identity active".into())
            }
            other => Err(format!("{other:?}")),
        },
    );
    board.stop()
}

fn status_uptime(board: &mut Board) -> Result<u64, String> {
    match board.request(RequestBody::Status, Duration::from_secs(2))? {
        ResponseBody::Status(status) => Ok(status.uptime_ms),
        other => Err(format!("Status answered with {other:?}")),
    }
}

/// Batch times are quantised down to the batch tick (4 µs for a 20-sample batch at 119 Hz, see
/// the firmware's `tick_us`); more than this is a timing error, not quantisation.
const MAX_TIME_QUANTISATION_US: u64 = 8;

/// The feed index of a sample streamed with time `t_us`, checking the time against the feed's.
fn feed_index(t_us: u64) -> Result<u64, String> {
    let index = (t_us + PERIOD_US / 2) / PERIOD_US;
    let fed_at = index * PERIOD_US;
    if t_us > fed_at || fed_at - t_us > MAX_TIME_QUANTISATION_US {
        return Err(format!(
            "streamed time {t_us} us is not a feed time (nearest {fed_at} us)"
        ));
    }
    Ok(index)
}

fn check_raw(
    ack: &Result<ResponseBody, String>,
    stop_ack: &Result<ResponseBody, String>,
    raw: &[(RawSample, u64)],
) -> Result<String, String> {
    if !matches!(ack, Ok(ResponseBody::Ack)) || !matches!(stop_ack, Ok(ResponseBody::Ack)) {
        return Err(format!("StartStream {ack:?}, StopStream {stop_ack:?}"));
    }
    // 0.8 s at 119 Hz is ~95 samples; one full batch (20) is the least that shows streaming.
    if raw.len() < 20 {
        return Err(format!("only {} samples streamed in 0.8 s", raw.len()));
    }
    for (k, (sample, t_us)) in raw.iter().enumerate() {
        let index = feed_index(*t_us)?;
        if *sample != fed_sample(index) {
            return Err(format!(
                "streamed sample {k} at {t_us} us is {sample:?}, the feed sent {:?} at {} us",
                fed_sample(index),
                index * PERIOD_US
            ));
        }
        if k > 0 && index != feed_index(raw[k - 1].1)? + 1 {
            return Err(format!(
                "sample {k} (feed index {index}) does not follow the previous one"
            ));
        }
    }
    Ok(format!("{} consecutive samples identical to the fed ones, with their feed timestamps (within the 4 us batch tick)", raw.len()))
}

fn check_calibrated(
    ack: &Result<ResponseBody, String>,
    calibrated: &[(imucal_protocol::CalibratedSample, u64)],
    set: &CalibrationSet,
) -> Result<String, String> {
    if !matches!(ack, Ok(ResponseBody::Ack)) {
        return Err(format!("StartStream answered {ack:?}"));
    }
    if calibrated.len() < 10 {
        return Err(format!(
            "only {} calibrated samples streamed in 0.6 s",
            calibrated.len()
        ));
    }
    let mut worst = 0.0f64;
    for (sample, t_us) in calibrated {
        let raw = fed_sample(feed_index(*t_us)?);
        let sensors = [
            (
                &set.accel,
                raw.accel,
                SCALES.accel_mps2_per_count,
                sample.accel,
            ),
            (&set.gyro, raw.gyro, SCALES.gyro_rads_per_count, sample.gyro),
            (&set.mag, raw.mag, SCALES.mag_ut_per_count, sample.mag),
        ];
        for (cal, counts, per_count, got) in sensors {
            let want = expected(cal, counts, per_count);
            for (g, w) in got.iter().zip(want) {
                // f32 evaluation of a 3-term dot product: a few ulps of the largest term
                // (|A|·|σc| ≲ 1.1 × the reading), so 1e-5 relative plus a floor for zeros.
                let tolerance = 1e-5 * w.abs().max(1e-3);
                let error = (f64::from(*g) - w).abs();
                worst = worst.max(error / w.abs().max(1e-3));
                if error > tolerance {
                    return Err(format!(
                        "at {t_us} us: firmware {g}, expected {w} (error {error:e})"
                    ));
                }
            }
        }
    }
    Ok(format!(
        "{} samples, worst relative error {worst:.1e} (f32 rounding)",
        calibrated.len()
    ))
}
