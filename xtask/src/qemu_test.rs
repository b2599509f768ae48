//! `firmware qemu-test`: the release firmware in QEMU, checked end to end over its UARTs.
//!
//! UART0 is a pseudo-terminal owned by this program (`TTYPort::pair`, QEMU opens the slave), the
//! same kind of serial port the host tool uses. UART1 is a unix socket served by QEMU, to which a
//! feeder thread writes the simulator's sensor feed (`imucal_hil_sim::feed`): the simulated
//! world, the board's true sensor errors and noise, and a person with timed holds. Every fed
//! sample is logged with its feed time, so every streamed sample can be matched to the one fed.
//! A second unix socket carries QEMU's monitor, used for `system_reset` (a soft reset that keeps
//! RAM).
//!
//! Protocol checks (the person waits at rest): Hello/Welcome (version, announced scales), Ping,
//! raw stream equal to the feed, write/commit/read-back of a parameter set, calibrated stream
//! equal to `A·(σ·c − b)` computed here, soft reset with the set still active, and a power cycle
//! (new QEMU) that starts on identity. Then the end-to-end calibration (see
//! [`crate::calibrate_e2e`]): `imucal calibrate` against a fresh QEMU while the person goes
//! through the twelve positions, the tumble and the rest; its parameters against the simulated
//! truth, its verification, its errors at rest against the targets, and a soft reset that keeps
//! the calibrated set.

use std::io::{Read, Write};
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use imucal_hil_sim::feed::{
    connect_feed_socket, run_feed, FeedControl, FeedOptions, FeedStats, FeedWorld,
};
use imucal_hil_sim::Truth;
use imucal_protocol::{
    encode_frame, CalibrationSet, DeviceMessage, Event, FrameDecoder, RawSample, Request,
    RequestBody, ResponseBody, SensorCalibration, SensorScales, StreamKind, MAX_FRAME,
    PROTOCOL_MAJOR,
};
use serialport::{SerialPort, TTYPort};

use crate::calibrate_e2e::{self, Relay, ACCEL_TARGET_MG, MAG_TARGET_PCT};
use crate::qemu;

/// Seed of the simulated board and person.
const SEED: u64 = 7;
/// Feed seconds per wall second during the end-to-end calibration (QEMU keeps up with this on
/// two shared cores; see the lag figure printed with the results).
const E2E_SPEED: f64 = 2.0;
/// Feed seconds each of the twelve positions is held: the host needs about 0.8 s of stillness,
/// a request round trip and a 1.5 s capture, so 6 s leaves room for a slow host.
const E2E_HOLD_S: f64 = 6.0;
/// Longest wall time of `imucal calibrate`.
const E2E_LIMIT: Duration = Duration::from_secs(240);

/// Every sample fed, indexed by feed time / period.
type FedLog = Arc<Mutex<Vec<RawSample>>>;

/// Writes the simulator's feed to QEMU's UART1 socket until told to stop.
struct Feeder {
    control: Arc<FeedControl>,
    thread: Option<JoinHandle<Result<FeedStats, String>>>,
    log: FedLog,
    period_us: u64,
    scales: SensorScales,
    truth: Truth,
    timetable_s: f64,
}

impl Feeder {
    fn start(socket: PathBuf, options: &FeedOptions, speed: f64) -> Result<Self, String> {
        let mut world = FeedWorld::new(options).map_err(|e| format!("the simulated world: {e}"))?;
        let control = Arc::new(FeedControl::new());
        let log: FedLog = Arc::new(Mutex::new(Vec::new()));
        let (period_us, scales, truth) = (world.period_us(), world.scales(), world.truth());
        let timetable_s = world.timetable_s();
        let thread_control = Arc::clone(&control);
        let thread_log = Arc::clone(&log);
        let thread = std::thread::spawn(move || {
            let mut stream =
                connect_feed_socket(&socket, Duration::from_secs(10)).map_err(|e| e.to_string())?;
            run_feed(
                &mut world,
                &mut stream,
                speed,
                &thread_control,
                &mut |_, sample| {
                    thread_log
                        .lock()
                        .unwrap_or_else(PoisonError::into_inner)
                        .push(*sample)
                },
            )
            .map_err(|e| e.to_string())
        });
        Ok(Self {
            control,
            thread: Some(thread),
            log,
            period_us,
            scales,
            truth,
            timetable_s,
        })
    }

    /// The sample fed with index `i`, if it was fed.
    fn fed(&self, i: u64) -> Option<RawSample> {
        let log = self.log.lock().unwrap_or_else(PoisonError::into_inner);
        usize::try_from(i).ok().and_then(|i| log.get(i).copied())
    }

    fn finish(mut self) -> Result<FeedStats, String> {
        self.control.stop();
        self.thread.take().map_or(Ok(FeedStats::default()), |t| {
            t.join()
                .unwrap_or_else(|_| Err("the feeder thread panicked".into()))
        })
    }
}

impl Drop for Feeder {
    fn drop(&mut self) {
        self.control.stop();
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

/// One QEMU process with its pty, feeder and monitor.
struct Board {
    qemu: Child,
    port: TTYPort,
    /// `None` only once stopped.
    feeder: Option<Feeder>,
    monitor_socket: PathBuf,
    decoder: FrameDecoder<MAX_FRAME>,
    seq: u16,
    /// Samples seen in stream events, in arrival order.
    raw_seen: Vec<(RawSample, u64)>,
    calibrated_seen: Vec<(imucal_protocol::CalibratedSample, u64)>,
}

impl Board {
    fn start(
        elf: &Path,
        dir: &Path,
        run: u32,
        feed: &FeedOptions,
        speed: f64,
    ) -> Result<Self, String> {
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
        // The guest's semihosting output: defmt frames, decoded by `defmt_logs_decode`.
        .stdout(
            std::fs::File::create(dir.join(format!("qemu-{run}.defmt"))).map_err(|e| {
                format!("cannot create the defmt log file in {}: {e}", dir.display())
            })?,
        )
        .stderr(Stdio::null());
        let qemu = cmd.spawn().map_err(|e| {
            format!(
                "could not start qemu-system-arm ({e}); run scripts/setup-firmware-toolchain.sh"
            )
        })?;
        drop(slave);
        let feeder = Feeder::start(feed_socket, feed, speed)?;
        let mut port = master;
        port.set_timeout(Duration::from_millis(50))
            .map_err(|e| format!("setting the pty timeout failed: {e}"))?;
        Ok(Self {
            qemu,
            port,
            feeder: Some(feeder),
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

    /// The running feeder.
    fn feeder(&self) -> Result<&Feeder, String> {
        self.feeder
            .as_ref()
            .ok_or_else(|| "the feeder has stopped".into())
    }

    /// Stops QEMU and the feeder; returns the feeder's counters.
    fn stop(mut self) -> Result<FeedStats, String> {
        qemu::kill(&mut self.qemu);
        self.feeder
            .take()
            .map_or(Ok(FeedStats::default()), Feeder::finish)
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

/// `A·(σ·c − b)` in f64, and per output the sum of the terms' sizes `Σⱼ |Aᵢⱼ|·(|σcⱼ| + |bⱼ|)`.
fn expected(cal: &SensorCalibration, counts: [i16; 3], per_count: f32) -> ([f64; 3], [f64; 3]) {
    let reading = counts.map(|c| f64::from(per_count) * f64::from(c));
    let offset = cal.b.map(f64::from);
    let mut y = [0.0; 3];
    let mut size = [0.0; 3];
    for ((row, out), size) in cal.a.iter().zip(y.iter_mut()).zip(size.iter_mut()) {
        for ((a, x), b) in row.iter().zip(reading).zip(offset) {
            *out += f64::from(*a) * (x - b);
            *size += f64::from(*a).abs() * (x.abs() + b.abs());
        }
    }
    (y, size)
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

/// Runs every check; fails when any check fails. The end-to-end calibration runs only when the
/// host tool builds; otherwise the output says plainly that it did not run, and the test fails.
pub fn run(elf: &Path) -> Result<(), String> {
    let dir = std::env::temp_dir().join(format!("imucal-qemu-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    println!("qemu-test: firmware {}", elf.display());
    let mut report = Report { lines: Vec::new() };
    let started = Instant::now();
    let result = checks(elf, &dir, &mut report)
        .map(|()| defmt_logs_decode(elf, &dir.join("qemu-1.defmt"), &mut report))
        .and_then(|()| {
            println!("qemu-test: end-to-end calibration");
            end_to_end(elf, &dir, &mut report)
        });
    let _ = std::fs::remove_dir_all(&dir);
    let failed = report.lines.iter().filter(|(_, r)| r.is_err()).count();
    println!(
        "qemu-test: {} checks ran in {:.0} s, {} passed, {failed} failed",
        report.lines.len(),
        started.elapsed().as_secs_f64(),
        report.lines.len() - failed
    );
    result?;
    if failed > 0 {
        return Err(format!("{failed} of {} checks failed", report.lines.len()));
    }
    println!("qemu-test: all {} checks passed", report.lines.len());
    Ok(())
}

/// Decodes the first board's defmt log with `defmt-print` and looks for its start-up lines.
/// Without `defmt-print` the check is reported as not run (it is never counted as passed).
fn defmt_logs_decode(elf: &Path, log: &Path, report: &mut Report) {
    let Ok(input) = std::fs::File::open(log) else {
        report.check(
            "defmt logs decode",
            Err(format!("no log at {}", log.display())),
        );
        return;
    };
    let output = std::process::Command::new("defmt-print")
        .arg("-e")
        .arg(elf)
        .stdin(input)
        .stderr(Stdio::null())
        .output();
    let output = match output {
        Ok(output) => output,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            println!(
                "  SKIP  defmt logs decode: defmt-print is not installed \
                 (scripts/setup-firmware-toolchain.sh --with-defmt-print)"
            );
            return;
        }
        Err(e) => {
            report.check(
                "defmt logs decode",
                Err(format!("defmt-print failed to start: {e}")),
            );
            return;
        }
    };
    let text = String::from_utf8_lossy(&output.stdout);
    let lines = text.lines().filter(|l| !l.trim().is_empty()).count();
    let result = if text.contains("sensor feed up at") {
        Ok(format!(
            "{lines} log lines decoded, including the sensor feed start-up"
        ))
    } else {
        Err(format!(
            "decoded {lines} lines but not the sensor feed start-up: {}",
            text.lines().take(3).collect::<Vec<_>>().join(" | ")
        ))
    };
    report.check("defmt logs decode", result);
}

/// Feed options of the protocol checks: the person never starts, so the board lies still.
fn resting_feed() -> FeedOptions {
    FeedOptions::new(SEED)
}

fn checks(elf: &Path, dir: &Path, report: &mut Report) -> Result<(), String> {
    let mut board = Board::start(elf, dir, 1, &resting_feed(), 1.0)?;
    let scales = board.feeder()?.scales;

    let welcome = board.hello();
    let hello_ok = report.check(
        "Hello/Welcome",
        welcome.as_ref().map_err(Clone::clone).and_then(|w| {
            if w.protocol_major != PROTOCOL_MAJOR {
                Err(format!(
                    "protocol {} vs host {PROTOCOL_MAJOR}",
                    w.protocol_major
                ))
            } else if w.scales != scales {
                Err(format!(
                    "scales {:?} differ from those fed on UART1 {scales:?}",
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
        return board.stop().map(|_| ());
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
        check_raw(board.feeder()?, &ack, &stop_ack, &raw),
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
        check_calibrated(board.feeder()?, &ack, &calibrated, &set),
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
    let mut board = Board::start(elf, dir, 2, &resting_feed(), 1.0)?;
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
    board.stop().map(|_| ())
}

/// `imucal calibrate` against the firmware while the simulated person goes through the session.
fn end_to_end(elf: &Path, dir: &Path, report: &mut Report) -> Result<(), String> {
    let tool = match calibrate_e2e::build_host_tool(&crate::build::repo_root()) {
        Ok(tool) => tool,
        Err(why) => {
            report.check(
                "imucal calibrate end to end",
                Err(format!("NOT RUN: the host tool could not be built: {why}")),
            );
            return Ok(());
        }
    };
    let mut options = FeedOptions::new(SEED);
    options.hold_s = E2E_HOLD_S;
    // Without tremor the only errors are white noise and quantisation, from which the
    // tolerances below are derived.
    options.tremor = false;
    let mut board = Board::start(elf, dir, 3, &options, E2E_SPEED)?;
    if let Err(why) = board.hello() {
        report.check("imucal calibrate end to end", Err(why));
        return board.stop().map(|_| ());
    }
    let (truth, control, timetable_s) = {
        let feeder = board.feeder()?;
        (
            feeder.truth.clone(),
            Arc::clone(&feeder.control),
            feeder.timetable_s,
        )
    };
    let board_side = board
        .port
        .try_clone_native()
        .map_err(|e| format!("could not share the board's pty with the relay: {e}"))?;
    let relay = Relay::start(board_side, Arc::clone(&control))?;
    let session_dir = dir.join("session");
    let args: Vec<String> = [
        "calibrate",
        "--port",
        &relay.host_path,
        "--yes",
        "--json",
        "--out",
        &session_dir.display().to_string(),
        "--field-ut",
        &truth.world.earth_field.magnitude_ut.to_string(),
        "--gravity",
        &truth.world.gravity_mps2.to_string(),
        "--pose-timeout",
        "60",
        "--mag-timeout",
        "60",
        "--rest-timeout",
        "60",
    ]
    .map(String::from)
    .to_vec();
    println!(
        "  running imucal calibrate (seed {SEED}, {E2E_SPEED}x real time, {E2E_HOLD_S} s holds, \
         {timetable_s:.0} s of positions and tumble, then rest)"
    );
    let run = calibrate_e2e::run_tool(&tool, &args, E2E_LIMIT);
    let relayed = relay.finish();
    let run = match run {
        Ok(run) => run,
        Err(why) => {
            report.check("imucal calibrate completes and verifies", Err(why));
            return board.stop().map(|_| ());
        }
    };
    let summary: Result<serde_json::Value, String> = if run.success {
        serde_json::from_str(&run.stdout)
            .map_err(|e| format!("its JSON summary does not parse: {e}"))
    } else {
        Err(format!(
            "imucal calibrate exited with {} after {:.0} s; its last lines: {}",
            run.status,
            run.wall_s,
            run.stderr_tail.join(" / ")
        ))
    };
    let completed = report.check(
        "imucal calibrate completes and verifies",
        summary.as_ref().map_err(Clone::clone).and_then(|summary| {
            let verified = summary["verified"].as_bool() == Some(true);
            let session_s = calibrate_e2e::number(summary, &["session_seconds"])?;
            let relayed = relayed.as_ref().map_err(Clone::clone)?;
            let text = format!(
                "{} positions, {} magnetometer regions, {session_s:.0} s of board time in \
                 {:.0} s wall; {} bytes to the board, {} from it",
                summary["poses"],
                summary["mag_regions_covered"],
                run.wall_s,
                relayed.to_board,
                relayed.to_host
            );
            if verified {
                Ok(format!("verified; {text}"))
            } else {
                Err(format!("the written set was not verified; {text}"))
            }
        }),
    );
    let Ok(summary) = summary else {
        return board.stop().map(|_| ());
    };
    for (name, result) in calibrate_e2e::compare_with_truth(&summary, &truth) {
        report.check(&name, result);
    }
    let accel_mg = calibrate_e2e::number(&summary, &["accel_rest_error_mg"]);
    let mag_pct = calibrate_e2e::number(&summary, &["mag_rest_error_pct"]);
    let gyro_dps = calibrate_e2e::number(&summary, &["gyro_rest_error_dps"]);
    report.check(
        "calibrated stream at rest meets the accuracy targets",
        accel_mg
            .and_then(|a| mag_pct.map(|m| (a, m)))
            .and_then(|(a, m)| {
                let text = format!(
                "|a| error {a:.3} mg (target < {ACCEL_TARGET_MG}), |m| error {m:.3} % (target < \
                 {MAG_TARGET_PCT}), gyro rate {} °/s",
                gyro_dps.map_or_else(|e| e, |g| format!("{g:.4}"))
            );
                if a.abs() < ACCEL_TARGET_MG && m.abs() < MAG_TARGET_PCT {
                    Ok(text)
                } else {
                    Err(text)
                }
            }),
    );

    // Soft reset: the calibrated set stays active.
    let crc = summary["params_crc"]
        .as_str()
        .and_then(|t| u32::from_str_radix(t.trim_start_matches("0x"), 16).ok());
    let uptime_before = status_uptime(&mut board);
    board.monitor("system_reset")?;
    let after = board.hello().and_then(|_| {
        let status = board.request(RequestBody::Status, Duration::from_secs(2))?;
        let params = board.request(RequestBody::GetParams, Duration::from_secs(2))?;
        Ok((status, params))
    });
    report.check(
        "soft reset keeps the calibrated set active",
        match (completed, crc, after, uptime_before) {
            (false, _, _, _) => Err("not meaningful: the calibration did not complete".into()),
            (true, None, _, _) => Err("the summary has no readable params_crc".into()),
            (
                true,
                Some(crc),
                Ok((ResponseBody::Status(status), ResponseBody::Params(back))),
                Ok(before),
            ) if status.uptime_ms < before && status.active_crc == crc && back.crc32() == crc => {
                Ok(format!(
                    "uptime {before} ms -> {} ms (rebooted), GetParams CRC {crc:08x} as written",
                    status.uptime_ms
                ))
            }
            (true, Some(crc), other, before) => Err(format!(
                "expected CRC {crc:08x}; after reset {other:?}, uptime before {before:?}"
            )),
        },
    );
    let last_sample_s = board
        .feeder()
        .map(|f| f.control.time_us() as f64 * 1e-6)
        .unwrap_or_default();
    let stats = board.stop()?;
    println!(
        "  feed: {:.1} s of board time in {:.1} s wall ({:.2}x), largest lag behind the pace \
         {:.2} s, last sample at {last_sample_s:.1} s",
        stats.feed_time_s,
        stats.wall_time_s,
        stats.feed_time_s / stats.wall_time_s.max(1e-9),
        stats.max_lag_s
    );
    Ok(())
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
fn feed_index(feeder: &Feeder, t_us: u64) -> Result<u64, String> {
    let period = feeder.period_us;
    let index = (t_us + period / 2) / period;
    let fed_at = index * period;
    if t_us > fed_at || fed_at - t_us > MAX_TIME_QUANTISATION_US {
        return Err(format!(
            "streamed time {t_us} us is not a feed time (nearest {fed_at} us)"
        ));
    }
    Ok(index)
}

/// The fed sample a sample streamed at `t_us` must be.
fn fed_at(feeder: &Feeder, t_us: u64) -> Result<(u64, RawSample), String> {
    let index = feed_index(feeder, t_us)?;
    feeder
        .fed(index)
        .map(|sample| (index, sample))
        .ok_or_else(|| format!("the firmware streamed a sample at {t_us} us that was never fed"))
}

fn check_raw(
    feeder: &Feeder,
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
    let mut previous = None;
    for (k, (sample, t_us)) in raw.iter().enumerate() {
        let (index, fed) = fed_at(feeder, *t_us)?;
        if *sample != fed {
            return Err(format!(
                "streamed sample {k} at {t_us} us is {sample:?}, the feed sent {fed:?} at {} us",
                index * feeder.period_us
            ));
        }
        if previous.is_some_and(|p: u64| index != p + 1) {
            return Err(format!(
                "sample {k} (feed index {index}) does not follow the previous one"
            ));
        }
        previous = Some(index);
    }
    Ok(format!("{} consecutive samples identical to the simulator's, with their feed timestamps (within the 4 us batch tick)", raw.len()))
}

fn check_calibrated(
    feeder: &Feeder,
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
    let scales = feeder.scales;
    let mut worst = 0.0f64;
    for (sample, t_us) in calibrated {
        let (_, raw) = fed_at(feeder, *t_us)?;
        let sensors = [
            (
                &set.accel,
                raw.accel,
                scales.accel_mps2_per_count,
                sample.accel,
            ),
            (&set.gyro, raw.gyro, scales.gyro_rads_per_count, sample.gyro),
            (&set.mag, raw.mag, scales.mag_ut_per_count, sample.mag),
        ];
        for (cal, counts, per_count, got) in sensors {
            let (want, size) = expected(cal, counts, per_count);
            for ((g, w), size) in got.iter().zip(want).zip(size) {
                // f32 evaluation of `σc − b` and a 3-term dot product: a few ulps (6e-8) of the
                // largest term, so 1e-5 of the sum of |terms| plus a floor for zeros.
                let tolerance = 1e-5 * size.max(1e-3);
                let error = (f64::from(*g) - w).abs();
                worst = worst.max(error / size.max(1e-3));
                if error > tolerance {
                    return Err(format!(
                        "at {t_us} us: firmware {g}, expected {w} (error {error:e})"
                    ));
                }
            }
        }
    }
    Ok(format!(
        "{} samples, worst error {worst:.1e} of the terms' size (f32 rounding)",
        calibrated.len()
    ))
}
