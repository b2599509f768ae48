//! `imucal stream` and `imucal record`: a board's readings as they arrive, printed or written
//! as a recording CSV. The board runs imucal's firmware (binary sample batches, board clock,
//! temperature) or a MotionCal sketch (`imucal::compat::MotionCalClient`: `Uni:` lines when it
//! prints them, else `Raw:` with MotionCal's scales; time from the sketch's nominal rate, as its
//! lines carry none, and no temperature).

use std::io::Write;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Args;
use imucal::compat::motioncal::RawAccelScaling;
use imucal::compat::MotionCalClient;
use imucal::device::{DeviceClient, RecordingWriter, UnitSample};
use imucal_protocol::{SensorSet, StreamKind};

use super::board::BoardProtocol;
use super::board::{connect, BoardPort, PortArgs};
use super::write_policy::{check_outputs, Output};

/// What the board runs (imucal's firmware unless told).
#[derive(Debug, Args)]
pub struct SketchArgs {
    /// What the board at --port runs: imucal's firmware, or a sketch that prints MotionCal's
    /// `Raw:`/`Uni:` lines (Adafruit's calibration sketch, PJRC's MotionCal sketches).
    #[arg(long, value_enum, default_value = "imucal", conflicts_with = "sim")]
    pub protocol: BoardProtocol,
    /// Simulator: what the simulated board runs, imucal's firmware or Adafruit's MotionCal
    /// calibration sketch.
    #[arg(long, value_enum, default_value = "imucal", requires = "sim")]
    pub sim_protocol: BoardProtocol,
    /// MotionCal sketch: readings per second it prints (Adafruit's sketch: 100); its lines
    /// carry no time, so sample times are counted at this rate.
    #[arg(long, default_value_t = 100.0)]
    pub sketch_rate: f64,
}

/// Arguments of `imucal stream`.
#[derive(Debug, Args)]
pub struct StreamArgs {
    /// Which port to use.
    #[command(flatten)]
    pub port: PortArgs,
    /// What the board runs.
    #[command(flatten)]
    pub sketch: SketchArgs,
    /// Stream samples calibrated by the board instead of raw counts × scale (imucal's
    /// firmware only).
    #[arg(long)]
    pub calibrated: bool,
    /// Print the recording CSV format instead of readable lines.
    #[arg(long)]
    pub csv: bool,
    /// Stop after this many seconds (default: until interrupted).
    #[arg(long)]
    pub seconds: Option<f64>,
    /// Keep only every N-th sample (imucal's firmware sends fewer; a sketch's are skipped here).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u16).range(1..))]
    pub decimation: u16,
}

/// Arguments of `imucal record`.
#[derive(Debug, Args)]
pub struct RecordArgs {
    /// Which port to use.
    #[command(flatten)]
    pub port: PortArgs,
    /// What the board runs.
    #[command(flatten)]
    pub sketch: SketchArgs,
    /// Output CSV file.
    #[arg(long, short = 'o')]
    pub output: PathBuf,
    /// Replace the output file when it exists.
    #[arg(long)]
    pub force: bool,
    /// Stop after this many seconds (default: until interrupted; the file is flushed as it
    /// grows).
    #[arg(long)]
    pub seconds: Option<f64>,
}

/// A board's readings in units, batch by batch.
trait SampleSource {
    /// The sensors its samples carry.
    fn sensors(&self) -> SensorSet;
    /// The next samples, waiting up to `wait`; `None` when none came.
    fn next(&mut self, wait: Duration) -> anyhow::Result<Option<Vec<UnitSample>>>;
    /// Ends the stream and says what was lost on the way.
    fn stop(&mut self) -> anyhow::Result<()>;
    /// What to check when the board falls silent.
    fn silence_hint(&self) -> &'static str;
}

/// A board running imucal's firmware, streaming.
struct FirmwareSource {
    client: DeviceClient,
}

impl FirmwareSource {
    fn start(mut client: DeviceClient, kind: StreamKind, decimation: u16) -> anyhow::Result<Self> {
        client.start_stream(kind, decimation)?;
        Ok(Self { client })
    }
}

impl SampleSource for FirmwareSource {
    fn sensors(&self) -> SensorSet {
        self.client.welcome().sensors
    }

    fn next(&mut self, wait: Duration) -> anyhow::Result<Option<Vec<UnitSample>>> {
        let chunk = self.client.next_samples(wait)?;
        for line in self.client.drain_logs() {
            say!("board {:?}: {}", line.level, line.text);
        }
        Ok(chunk.map(|c| c.samples))
    }

    fn stop(&mut self) -> anyhow::Result<()> {
        self.client.stop_stream()?;
        let lost = self.client.stats().lost_samples;
        if lost > 0 {
            say!(
                "{lost} samples were lost in transit (the link could not keep up; try --decimation)"
            );
        }
        Ok(())
    }

    fn silence_hint(&self) -> &'static str {
        "check the board with `imucal info`"
    }
}

/// A board running a MotionCal sketch, which prints readings from power-up on.
struct SketchSource {
    client: MotionCalClient,
    rate_hz: f64,
    decimation: u64,
    /// Readings received, kept or skipped.
    index: u64,
}

impl SampleSource for SketchSource {
    fn sensors(&self) -> SensorSet {
        SensorSet {
            accel: true,
            gyro: true,
            mag: true,
            temp: false,
        }
    }

    fn next(&mut self, wait: Duration) -> anyhow::Result<Option<Vec<UnitSample>>> {
        // About a tenth of a second of readings per batch, as the firmware's batches.
        let batch = (self.rate_hz / 10.0).ceil().max(1.0) as usize;
        let mut samples = Vec::with_capacity(batch);
        let mut received = 0;
        while received < batch {
            let Some(reading) = self.client.next_reading(wait)? else {
                break;
            };
            received += 1;
            let index = self.index;
            self.index += 1;
            if index.is_multiple_of(self.decimation) {
                samples.push(UnitSample {
                    t_s: index as f64 / self.rate_hz,
                    accel: reading.accel,
                    gyro: reading.gyro,
                    mag: reading.mag,
                    temp_c: f64::NAN,
                });
            }
        }
        // Readings skipped by the decimation still show the board is alive.
        Ok((received > 0).then_some(samples))
    }

    fn stop(&mut self) -> anyhow::Result<()> {
        let malformed = self.client.malformed_lines();
        if malformed > 0 {
            say!("{malformed} lines could not be read (noise on the line, or another baud rate)");
        }
        say!(
            "readings from the sketch's {} lines",
            if self.client.has_unified_lines() {
                "`Uni:` (SI units as the sketch computed them)"
            } else {
                "`Raw:` (MotionCal's scales: 1/8192 g as Adafruit's sketch scales it, 1/16 °/s, 0.1 µT)"
            }
        );
        Ok(())
    }

    fn silence_hint(&self) -> &'static str {
        "check that it runs a MotionCal-compatible sketch at 115200 baud"
    }
}

/// The board of `port`, streaming: imucal's firmware or a MotionCal sketch.
fn open_source(
    port: &PortArgs,
    sketch: &SketchArgs,
    kind: StreamKind,
    decimation: u16,
) -> anyhow::Result<(Box<dyn SampleSource>, BoardPort)> {
    let protocol = if port.sim {
        sketch.sim_protocol
    } else {
        sketch.protocol
    };
    if protocol == BoardProtocol::Imucal {
        let (client, board) = connect(port)?;
        let source = FirmwareSource::start(client, kind, decimation)?;
        return Ok((Box::new(source), board));
    }
    anyhow::ensure!(
        kind == StreamKind::Raw,
        "a MotionCal sketch prints uncalibrated readings only; leave out --calibrated"
    );
    let rate_hz = sketch.sketch_rate;
    anyhow::ensure!(
        rate_hz.is_finite() && rate_hz > 0.0,
        "--sketch-rate {rate_hz} is not a positive number of readings per second"
    );
    let board = port.open_board(BoardProtocol::Motioncal)?;
    let client = MotionCalClient::open(&board.path, RawAccelScaling::AdafruitSketch)?;
    let source = SketchSource {
        client,
        rate_hz,
        decimation: u64::from(decimation),
        index: 0,
    };
    Ok((Box::new(source), board))
}

fn seconds_arg(seconds: Option<f64>) -> anyhow::Result<Option<Duration>> {
    match seconds {
        None => Ok(None),
        Some(s) if s.is_finite() && s > 0.0 && s < 1e9 => Ok(Some(Duration::from_secs_f64(s))),
        Some(s) => anyhow::bail!("--seconds {s} is not a positive number of seconds"),
    }
}

/// Whether to go on streaming after a batch.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Flow {
    Continue,
    Stop,
}

/// `Flow::Stop` when the reader of stdout has gone (e.g. `| head`), which ends a stream normally.
fn output_flow(written: std::io::Result<()>) -> anyhow::Result<Flow> {
    match written {
        Ok(()) => Ok(Flow::Continue),
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(Flow::Stop),
        Err(e) => Err(e.into()),
    }
}

/// Streams until `limit` (or forever), handing each batch to `on_batch`; stops the stream at
/// the end.
fn run_stream(
    source: &mut dyn SampleSource,
    port: &str,
    limit: Option<Duration>,
    on_batch: &mut dyn FnMut(&[UnitSample]) -> anyhow::Result<Flow>,
) -> anyhow::Result<()> {
    let start = Instant::now();
    // A stream silent this long has stopped: batches come several times a second.
    let silence = Duration::from_secs(3);
    let result = (|| loop {
        let wait = match limit {
            Some(limit) => limit.saturating_sub(start.elapsed()).min(silence),
            None => silence,
        };
        if wait.is_zero() {
            return Ok(());
        }
        match source.next(wait)? {
            Some(samples) => {
                if on_batch(&samples)? == Flow::Stop {
                    return Ok(());
                }
            }
            None if limit.is_some_and(|l| start.elapsed() >= l) => return Ok(()),
            None => anyhow::bail!(
                "{port} sent no samples for {} s; {}",
                silence.as_secs(),
                source.silence_hint()
            ),
        }
    })();
    let stopped = source.stop();
    result?;
    stopped
}

/// Run `imucal stream`.
pub fn stream(args: &StreamArgs) -> anyhow::Result<()> {
    let limit = seconds_arg(args.seconds)?;
    let kind = if args.calibrated {
        StreamKind::Calibrated
    } else {
        StreamKind::Raw
    };
    let (mut source, board) = open_source(&args.port, &args.sketch, kind, args.decimation)?;
    let sensors = source.sensors();
    let stdout = std::io::stdout();
    if args.csv {
        let mut writer = RecordingWriter::new(stdout.lock(), sensors)?;
        run_stream(source.as_mut(), &board.path, limit, &mut |samples| {
            output_flow(samples.iter().try_for_each(|s| writer.write(s)))
        })?;
        // The reader may be gone; nothing is lost by not flushing to it.
        let _ = writer.finish();
    } else {
        let mut out = stdout.lock();
        run_stream(source.as_mut(), &board.path, limit, &mut |samples| {
            output_flow(
                samples
                    .iter()
                    .try_for_each(|s| writeln!(out, "{}", readable(s, sensors.temp))),
            )
        })?;
    }
    Ok(())
}

fn readable(s: &UnitSample, temp: bool) -> String {
    let v = |x: &[f64; 3]| format!("{:>9.4} {:>9.4} {:>9.4}", x[0], x[1], x[2]);
    let t = if temp {
        format!("  T {:>6.2} °C", s.temp_c)
    } else {
        String::new()
    };
    format!(
        "t {:>10.4} s  a {} m/s²  g {} rad/s  m {} µT{t}",
        s.t_s,
        v(&s.accel),
        v(&s.gyro),
        v(&s.mag),
    )
}

/// Run `imucal record`.
pub fn record(args: &RecordArgs) -> anyhow::Result<()> {
    check_outputs(&[Output::File(&args.output)], &[], args.force)?;
    let limit = seconds_arg(args.seconds)?;
    let (mut source, board) = open_source(&args.port, &args.sketch, StreamKind::Raw, 1)?;
    let shown = args.output.display().to_string();
    let file = std::fs::File::create(&args.output).with_context(|| {
        format!("cannot create `{shown}`; check the directory exists and is writable")
    })?;
    let mut writer = RecordingWriter::new(std::io::BufWriter::new(file), source.sensors())
        .with_context(|| format!("cannot write `{shown}`"))?;
    let start = Instant::now();
    let mut last_report = start;
    run_stream(source.as_mut(), &board.path, limit, &mut |samples| {
        // Flushed per batch so an interrupted recording is still a valid file.
        samples
            .iter()
            .try_for_each(|s| writer.write(s))
            .and_then(|()| writer.flush())
            .with_context(|| format!("cannot write `{shown}`; check the disk space"))?;
        if last_report.elapsed() >= Duration::from_secs(1) {
            last_report = Instant::now();
            say_part!(
                "\rrecording {shown}: {:.0} s, {} samples",
                start.elapsed().as_secs_f64(),
                writer.rows()
            );
        }
        Ok(Flow::Continue)
    })?;
    let rows = writer.rows();
    writer
        .finish()
        .with_context(|| format!("cannot write `{shown}`"))?;
    say!();
    println!("recorded {rows} samples to {shown}");
    Ok(())
}
