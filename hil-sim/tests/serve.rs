//! The simulated board behind a pseudo-terminal, opened with `serialport` as the host does:
//! handshake, ping, streaming rate against the pacing, wire size per sample, reboot.

use std::io::{ErrorKind, Read, Write};
use std::time::{Duration, Instant};

use imucal_hil_sim::board::PersonSchedule;
use imucal_hil_sim::serve::{SimHandle, SimOptions, SimServer};
use imucal_protocol::{
    encode_frame, DeviceMessage, Event, FrameDecoder, Request, RequestBody, ResponseBody,
    StreamKind, MAX_FRAME,
};
use serialport::SerialPort;

/// Sample rate of the board (the driver's default 119 Hz; the firmware's period is 8403 µs).
const RATE_HZ: f64 = 1.0e6 / 8403.0;

struct Port {
    port: Box<dyn SerialPort>,
    decoder: FrameDecoder<MAX_FRAME>,
    seq: u16,
    bytes_read: u64,
}

impl Port {
    fn open(handle: &SimHandle) -> Self {
        let port = serialport::new(handle.port_path(), 921_600)
            .timeout(Duration::from_millis(5))
            .open()
            .expect("the pty opens like a serial port");
        Self {
            port,
            decoder: FrameDecoder::new(),
            seq: 0,
            bytes_read: 0,
        }
    }

    fn send(&mut self, body: RequestBody) -> u16 {
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
        self.port.write_all(&frame[..len]).unwrap();
        self.seq
    }

    /// Every message that arrives within `wait`.
    fn receive(&mut self, wait: Duration, mut on_message: impl FnMut(DeviceMessage) -> bool) {
        let deadline = Instant::now() + wait;
        let mut buffer = [0u8; 4096];
        while Instant::now() < deadline {
            match self.port.read(&mut buffer) {
                Ok(count) => {
                    self.bytes_read += count as u64;
                    // Decode the whole chunk so no frame after the one sought is cut; bytes left
                    // in the pty from before the port was opened may form a broken frame.
                    let mut done = false;
                    for message in self
                        .decoder
                        .messages::<DeviceMessage>(&buffer[..count])
                        .flatten()
                    {
                        done |= on_message(message);
                    }
                    if done {
                        return;
                    }
                }
                Err(e) if e.kind() == ErrorKind::TimedOut => {}
                Err(e) => panic!("reading the pty failed: {e}"),
            }
        }
    }

    fn request(&mut self, body: RequestBody) -> ResponseBody {
        let seq = self.send(body);
        let mut reply = None;
        self.receive(Duration::from_secs(2), |message| match message {
            DeviceMessage::Response(r) if r.seq == seq => {
                reply = Some(r.body);
                true
            }
            _ => false,
        });
        reply.expect("the board answers within 2 s")
    }
}

fn start(speed: f64) -> SimHandle {
    let mut options = SimOptions::new(11);
    options.speed = speed;
    options.schedule = PersonSchedule::Rest;
    SimServer::start(options).unwrap()
}

#[test]
fn the_pty_answers_hello_and_ping_round_trips() {
    let handle = start(20.0);
    let mut port = Port::open(&handle);
    let ResponseBody::Welcome(welcome) = port.request(RequestBody::hello()) else {
        panic!("Hello must be answered with Welcome");
    };
    assert!((f64::from(welcome.scales.sample_rate_hz) - 119.0).abs() < 1e-3);
    let mut round_trips = Vec::new();
    for value in 0..20u32 {
        let sent = Instant::now();
        let reply = port.request(RequestBody::Ping(value * 7919));
        round_trips.push(sent.elapsed().as_secs_f64());
        assert_eq!(reply, ResponseBody::Pong(value * 7919));
    }
    let mean_ms = 1e3 * round_trips.iter().sum::<f64>() / round_trips.len() as f64;
    println!("ping round trip over the pty at speed 20: mean {mean_ms:.2} ms");
    let stats = handle.stop().unwrap();
    assert!(stats.sim_time_s > 0.0);
}

/// Stream raw samples for `wall` and return (samples, simulated span s, bytes read, wall s).
fn stream_for(port: &mut Port, wall: Duration) -> (u64, f64, u64, f64) {
    let ack = port.request(RequestBody::StartStream {
        kind: StreamKind::Raw,
        decimation: 1,
    });
    assert_eq!(ack, ResponseBody::Ack);
    let bytes_before = port.bytes_read;
    let started = Instant::now();
    let mut samples = 0u64;
    let mut next_index = None;
    let mut first_t_us = None;
    let mut last_t_us = 0;
    port.receive(wall, |message| {
        if let DeviceMessage::Event(Event::SampleBatch(batch)) = message {
            let first = batch.header().first_index;
            if let Some(expected) = next_index {
                assert_eq!(first, expected, "no batch may be lost on the pty");
            }
            next_index = Some(first + batch.len() as u32);
            samples += batch.len() as u64;
            for (_, t_us) in batch.iter() {
                first_t_us.get_or_insert(t_us);
                last_t_us = t_us;
            }
        }
        false
    });
    let wall_s = started.elapsed().as_secs_f64();
    let bytes = port.bytes_read - bytes_before;
    port.request(RequestBody::StopStream);
    let span_s = last_t_us.saturating_sub(first_t_us.unwrap_or(0)) as f64 * 1e-6;
    (samples, span_s, bytes, wall_s)
}

#[test]
fn streaming_follows_the_sample_rate_times_the_speed() {
    let speed = 20.0;
    let handle = start(speed);
    let mut port = Port::open(&handle);
    port.request(RequestBody::hello());
    let (samples, span_s, bytes, wall_s) = stream_for(&mut port, Duration::from_secs(2));
    // Simulated time: consecutive samples are one period apart, so the span holds samples − 1
    // periods; timestamps are quantised to the batch tick (≤ 8403·20·1.5/65535 µs ≈ 4 µs).
    assert!(samples > 100);
    let span_rate = (samples - 1) as f64 / span_s;
    assert!(
        (span_rate - RATE_HZ).abs() < 0.01,
        "simulated rate {span_rate} Hz"
    );
    // Wall time: the pacing gives rate × speed; allow 10 % for the batch granularity (20 samples
    // of 2380 per s), the start-up of the stream and a loaded machine.
    let wall_rate = samples as f64 / wall_s;
    let target = RATE_HZ * speed;
    assert!(
        (wall_rate - target).abs() < 0.1 * target,
        "{wall_rate:.0} samples/s over the pty, paced target {target:.0}"
    );
    let per_sample = bytes as f64 / samples as f64;
    println!(
        "speed {speed}: {wall_rate:.0} samples/s over the pty (target {target:.0}), \
         {per_sample:.2} wire bytes per sample"
    );
    // 470-byte frames of 20 samples are 23.5 bytes per sample (protocol crate budget).
    assert!(
        (22.0..=23.6).contains(&per_sample),
        "{per_sample} bytes/sample"
    );
    handle.stop().unwrap();
}

#[test]
fn flat_out_streaming_over_the_pty_loses_no_batch() {
    // Far faster than the board can be simulated: the loop runs flat out, so the pty and the
    // host reader are under the heaviest load they will see. `stream_for` asserts that batch
    // indices are contiguous; the throughput is printed, not asserted (it depends on the machine).
    let speed = 1000.0;
    let handle = start(speed);
    let mut port = Port::open(&handle);
    port.request(RequestBody::hello());
    let (samples, span_s, bytes, wall_s) = stream_for(&mut port, Duration::from_secs(1));
    let stats = handle.stop().unwrap();
    println!(
        "flat out: {:.0} samples/s over the pty ({:.0} kB/s, {:.2} bytes/sample), \
         simulated {:.1} s in {:.1} s wall, {} messages dropped by the board",
        samples as f64 / wall_s,
        bytes as f64 / wall_s / 1e3,
        bytes as f64 / samples as f64,
        stats.sim_time_s,
        stats.wall_time_s,
        stats.messages_refused
    );
    assert!(samples >= 20, "only {samples} samples in 1 s at {speed}x");
    // The stamps keep the board's clock however fast the loop runs: samples − 1 periods span the
    // stream. 1 % allows the batch-tick quantisation of the two end stamps on a short stream.
    let stamped_rate = (samples - 1) as f64 / span_s;
    assert!(
        (stamped_rate - RATE_HZ).abs() < 0.01 * RATE_HZ,
        "stamped rate {stamped_rate:.3} Hz, board runs at {RATE_HZ} Hz"
    );
}

#[test]
fn reboot_over_the_pty_restarts_the_firmware() {
    let handle = start(20.0);
    let mut port = Port::open(&handle);
    port.request(RequestBody::hello());
    std::thread::sleep(Duration::from_millis(300));
    let ResponseBody::Status(before) = port.request(RequestBody::Status) else {
        panic!("Status must be answered with Status");
    };
    handle.reboot().unwrap();
    let ResponseBody::Status(after) = port.request(RequestBody::Status) else {
        panic!("Status must be answered with Status");
    };
    // 300 ms wall at speed 20 is 6 s of uptime; right after a reboot it is well below that.
    assert!(before.uptime_ms >= 5000, "uptime {} ms", before.uptime_ms);
    assert!(after.uptime_ms < before.uptime_ms, "{after:?}");
    handle.stop().unwrap();
}
