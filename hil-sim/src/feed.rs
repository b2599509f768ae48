//! Sensor feed for an emulated board: the simulated world, the sensor physics and a person with
//! timed holds, turned into [`FeedFrame`]s (a `Scales` frame, then one `Sample { t_us, sample }`
//! per output-data-rate tick) written to a unix socket or any [`Write`].
//!
//! The QEMU board reads this feed on its UART1 and takes its clock from the sample times, so the
//! feed's time is the board's time. The person holding the board cannot see what the firmware
//! does (the host tool owns the board's serial port), so instead of reacting to captures as
//! [`crate::board::Person`] does, this person follows a fixed timetable in feed time:
//! 1. wait in the first position, hand off the board, until started ([`FeedControl::start`]) or
//!    until `lead_in_s` has passed;
//! 2. the twelve positions of seed 003 (Chen et al. 2012, §2.2) in their fixed order, each held
//!    for `hold_s`, with the placement errors, headings and optional tremor of
//!    [`crate::poser::build_schedule`] (`twelve`);
//! 3. the slow tumble of the `tumble` schedule (the field direction sweeps the body sphere);
//! 4. rest in the first position without tremor, until the feed stops.
//!
//! The readings are those of [`crate::physics`]: `x = A⁻¹·y + b + …` with the truth drawn from the
//! seed, quantised to LSM9DS1 counts. Frames are paced against wall time at `speed` (feed
//! seconds per wall second); a socket whose reader falls behind pushes back on the writer, which
//! then simply runs late.

use std::io::{ErrorKind, Write};
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use imucal_protocol::feed::{self, FeedFrame, MAX_FEED_FRAME};
use imucal_protocol::{RawSample, SensorScales};
use nalgebra::UnitQuaternion;
use thiserror::Error;

use crate::effects::EffectRequest;
use crate::error::{require_non_negative, require_positive, SimError};
use crate::physics::{lsm9ds1_scales, ImuErrorRanges, ImuPhysics, ImuTruth};
use crate::poser::{build_schedule, PoserOptions, ScheduleKind};
use crate::recording::{write_truth_file, SimConfig, Truth, WorldTruth};
use crate::world::{
    EarthField, Segment, TemperatureProfile, Trajectory, TrajectoryBuilder, World, WorldState,
    STANDARD_GRAVITY_MPS2,
};

/// A `Scales` frame is repeated every this many samples, so that a rebooted firmware finds one.
pub const SCALES_EVERY: u64 = 32;
/// Output data rate of the emulated chip, Hz (the LSM9DS1 driver's default).
pub const FEED_RATE_HZ: f32 = 119.0;
/// Length of the final rest, s: long enough to be "until stopped" (about 30 years).
const OPEN_REST_S: f64 = 1.0e9;

/// Everything that determines a feed.
#[derive(Debug, Clone, PartialEq)]
pub struct FeedOptions {
    /// Seed of every random draw (board errors, effects, noise, the person's positions).
    pub seed: u64,
    /// Effects switched on without telling the host.
    pub effects: Vec<EffectRequest>,
    /// Feed time each of the twelve positions is held, s.
    pub hold_s: f64,
    /// Whether holds carry hand tremor.
    pub tremor: bool,
    /// Feed time after which the person starts without [`FeedControl::start`]; `None` waits.
    pub lead_in_s: Option<f64>,
    /// Turn rates, placement errors and temperature of the person's schedule.
    pub poser: PoserOptions,
    /// Ranges the board's errors are drawn from.
    pub error_ranges: ImuErrorRanges,
    /// Magnitude of gravity, m/s².
    pub gravity_mps2: f64,
    /// The Earth's field.
    pub earth_field: EarthField,
}

impl FeedOptions {
    /// Defaults: 6 s holds with tremor, start on request, consumer MEMS errors, no effects,
    /// standard gravity, 48 µT at 60° dip, 25 °C.
    pub fn new(seed: u64) -> Self {
        Self {
            seed,
            effects: Vec::new(),
            hold_s: 6.0,
            tremor: true,
            lead_in_s: None,
            poser: PoserOptions::default(),
            error_ranges: ImuErrorRanges::default(),
            gravity_mps2: STANDARD_GRAVITY_MPS2,
            earth_field: EarthField::default(),
        }
    }
}

/// Where the person is in the timetable.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FeedPhase {
    /// Waiting in the first position for the start.
    Waiting,
    /// Holding position `index` (0–11) of the twelve, or turning towards it.
    Positions {
        /// Position index.
        index: usize,
    },
    /// Tumbling for the magnetometer.
    Tumble,
    /// Resting in the first position.
    Rest,
}

/// The simulated world, the board's sensor physics and the person with timed holds.
#[derive(Debug, Clone)]
pub struct FeedWorld {
    world: World,
    physics: ImuPhysics,
    truth: Truth,
    scales: SensorScales,
    period_us: u64,
    next_index: u64,
    lead_in_s: Option<f64>,
    /// Feed time at which the timetable began.
    started_s: Option<f64>,
    /// Timetable times at which the positions, the tumble and the rest begin.
    positions_end_s: f64,
    tumble_end_s: f64,
    position_starts_s: Vec<f64>,
}

impl FeedWorld {
    /// Draws the board and builds the person's timetable from `options`.
    pub fn new(options: &FeedOptions) -> Result<Self, SimError> {
        require_positive("hold time (s)", options.hold_s)?;
        if let Some(lead_in) = options.lead_in_s {
            require_non_negative("lead-in (s)", lead_in)?;
        }
        let mut poser = options.poser;
        poser.hold_s = options.hold_s;
        poser.tremor = options.tremor;
        let twelve = build_schedule(
            ScheduleKind::Twelve,
            &poser,
            &options.earth_field,
            options.seed,
        )?;
        let tumble = build_schedule(
            ScheduleKind::Tumble,
            &poser,
            &options.earth_field,
            options.seed,
        )?;
        let timetable = Timetable::build(&twelve.trajectory, &tumble.trajectory, &poser)?;
        let temperature = TemperatureProfile::Constant {
            temp_c: poser.ambient_c,
        };
        let world = World {
            trajectory: timetable.trajectory,
            gravity_mps2: options.gravity_mps2,
            earth_field: options.earth_field,
            disturbance: None,
            temperature,
        };
        world.validate()?;
        let rate = f64::from(FEED_RATE_HZ);
        let imu = ImuTruth::draw(
            options.seed,
            &options.error_ranges,
            &options.effects,
            rate,
            timetable.rest_start_s,
        )?;
        let physics = ImuPhysics::new(imu, options.seed)?;
        let truth = Truth {
            config: SimConfig {
                seed: options.seed,
                schedule: ScheduleKind::Twelve,
                poser,
                sample_rate_hz: rate,
                gravity_mps2: options.gravity_mps2,
                earth_field: options.earth_field,
                disturbance: None,
                temperature: Some(temperature),
                error_ranges: options.error_ranges,
                effects: options.effects.clone(),
            },
            world: WorldTruth {
                gravity_mps2: options.gravity_mps2,
                earth_field: options.earth_field,
                field_world_ut: options.earth_field.world_vector_ut().into(),
                disturbance: None,
                temperature,
            },
            imu,
            duration_s: 0.0,
        };
        Ok(Self {
            world,
            physics,
            truth,
            scales: lsm9ds1_scales(FEED_RATE_HZ),
            // Rounded as the firmware rounds its sample period.
            period_us: (1.0e6 / rate).round() as u64,
            next_index: 0,
            lead_in_s: options.lead_in_s,
            started_s: None,
            positions_end_s: timetable.tumble_start_s,
            tumble_end_s: timetable.rest_start_s,
            position_starts_s: timetable.position_starts_s,
        })
    }

    /// Every true parameter of the board; `duration_s` is the feed time so far.
    pub fn truth(&self) -> Truth {
        let mut truth = self.truth.clone();
        truth.duration_s = self.time_s();
        truth
    }

    /// The chip configuration the feed announces.
    pub fn scales(&self) -> SensorScales {
        self.scales
    }

    /// Sample period, µs.
    pub fn period_us(&self) -> u64 {
        self.period_us
    }

    /// Feed time of the next sample, µs.
    pub fn next_time_us(&self) -> u64 {
        self.next_index.saturating_mul(self.period_us)
    }

    /// Feed time of the next sample, s.
    pub fn time_s(&self) -> f64 {
        self.next_time_us() as f64 * 1e-6
    }

    /// Feed time from the start to the beginning of the final rest, s.
    pub fn timetable_s(&self) -> f64 {
        self.tumble_end_s
    }

    /// Starts the timetable at the next sample (no effect once started).
    pub fn start(&mut self) {
        if self.started_s.is_none() {
            self.started_s = Some(self.time_s());
        }
    }

    /// Feed time at which the timetable began, s, once started.
    pub fn started_s(&self) -> Option<f64> {
        self.started_s
    }

    /// Where the person is at the next sample.
    pub fn phase(&self) -> FeedPhase {
        let Some(started) = self.started_s else {
            return FeedPhase::Waiting;
        };
        let tau = self.time_s() - started;
        if tau >= self.tumble_end_s {
            FeedPhase::Rest
        } else if tau >= self.positions_end_s {
            FeedPhase::Tumble
        } else {
            let index = self
                .position_starts_s
                .iter()
                .rposition(|start| tau >= *start)
                .unwrap_or(0);
            FeedPhase::Positions { index }
        }
    }

    /// The true state of the world at the next sample.
    fn state_now(&self) -> WorldState {
        let t = self.time_s();
        // Before the start the person holds the timetable's first instant: the first position.
        let tau = self.started_s.map_or(0.0, |started| (t - started).max(0.0));
        let mut state = self.world.state(tau);
        state.t = t;
        state.temp_c = self.world.temperature.at(t);
        state
    }

    /// The next sample and its feed time, µs; starts the timetable when the lead-in has passed.
    pub fn next_sample(&mut self) -> (u64, RawSample) {
        if self
            .lead_in_s
            .is_some_and(|lead_in| self.time_s() >= lead_in)
        {
            self.start();
        }
        let t_us = self.next_time_us();
        let state = self.state_now();
        let sample = self.physics.sample(&state);
        self.next_index = self.next_index.saturating_add(1);
        (t_us, sample.raw)
    }

    /// The true specific force and field in the body frame at the next sample (for checks).
    pub fn true_state(&self) -> WorldState {
        self.state_now()
    }
}

/// The person's motion after the start, and where its parts begin.
struct Timetable {
    trajectory: Trajectory,
    position_starts_s: Vec<f64>,
    tumble_start_s: f64,
    rest_start_s: f64,
}

impl Timetable {
    /// Twelve holds and their turns, a turn into the tumble, the tumble, a turn to the first
    /// position and an open rest there.
    fn build(
        twelve: &Trajectory,
        tumble: &Trajectory,
        poser: &PoserOptions,
    ) -> Result<Self, SimError> {
        let first = match twelve.segments().first() {
            Some(Segment::Hold { orientation, .. }) => *orientation,
            Some(Segment::Turn { from, .. }) => *from,
            None => return Err(SimError::EmptyTrajectory),
        };
        let mut builder = TrajectoryBuilder::new(first);
        let mut position_starts_s = Vec::with_capacity(12);
        let mut t = 0.0;
        for segment in twelve.segments() {
            match segment {
                Segment::Hold {
                    duration_s, tremor, ..
                } => builder = builder.hold(*duration_s, tremor.clone())?,
                Segment::Turn { to, duration_s, .. } => {
                    builder = builder.turn_to(*to, *duration_s)?
                }
            }
            // A position's time starts with the turn towards it (or the first hold).
            let starts_position =
                matches!(segment, Segment::Turn { .. }) || position_starts_s.is_empty();
            if starts_position {
                position_starts_s.push(t);
            }
            t += segment_duration_s(segment);
        }
        let tumble_start_s = t;
        for segment in tumble.segments() {
            match segment {
                Segment::Hold {
                    orientation,
                    duration_s,
                    ..
                } => {
                    builder = turn_if_needed(builder, orientation, poser)?;
                    builder = builder.hold(*duration_s, None)?;
                }
                Segment::Turn { to, duration_s, .. } => {
                    builder = builder.turn_to(*to, *duration_s)?;
                }
            }
        }
        builder = turn_if_needed(builder, &first, poser)?;
        let trajectory_so_far = builder.clone().build()?;
        let rest_start_s = trajectory_so_far.duration_s();
        let trajectory = builder.hold(OPEN_REST_S, None)?.build()?;
        Ok(Self {
            trajectory,
            position_starts_s,
            tumble_start_s,
            rest_start_s,
        })
    }
}

fn segment_duration_s(segment: &Segment) -> f64 {
    match segment {
        Segment::Hold { duration_s, .. } | Segment::Turn { duration_s, .. } => *duration_s,
    }
}

/// A minimum-jerk turn to `to` at the person's turn rate, unless already there.
fn turn_if_needed(
    builder: TrajectoryBuilder,
    to: &UnitQuaternion<f64>,
    poser: &PoserOptions,
) -> Result<TrajectoryBuilder, SimError> {
    let angle = builder.current().angle_to(to);
    if angle < 1e-9 {
        return Ok(builder);
    }
    // Peak rate is 1.875 times the mean of a minimum-jerk turn.
    let duration = (1.875 * angle / poser.turn_peak_rate_dps.to_radians()).max(0.6);
    builder.turn_to(*to, duration)
}

/// Shared switches and counters of a running feed.
#[derive(Debug, Default)]
pub struct FeedControl {
    start: AtomicBool,
    stop: AtomicBool,
    time_us: AtomicU64,
    samples: AtomicU64,
}

impl FeedControl {
    /// A control with the person waiting and the feed running.
    pub fn new() -> Self {
        Self::default()
    }

    /// Lets the person begin the timetable at the next sample.
    pub fn start(&self) {
        self.start.store(true, Ordering::Relaxed);
    }

    /// Stops the feed after the frame being written.
    pub fn stop(&self) {
        self.stop.store(true, Ordering::Relaxed);
    }

    /// Whether the feed has been told to stop.
    pub fn is_stopped(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }

    /// Feed time of the newest sample written, µs.
    pub fn time_us(&self) -> u64 {
        self.time_us.load(Ordering::Relaxed)
    }

    /// Samples written so far.
    pub fn samples(&self) -> u64 {
        self.samples.load(Ordering::Relaxed)
    }
}

/// Why the feed stopped early or could not start.
#[derive(Debug, Error)]
pub enum FeedError {
    /// A setting is invalid.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// The speed factor is not usable.
    #[error("speed {0} is not usable; give a finite factor greater than zero (1 = real time)")]
    InvalidSpeed(f64),
    /// The socket could not be reached.
    #[error(
        "could not connect to the feed socket {path} ({source}); start QEMU first with \
         `-chardev socket,id=u1,path={path},server=on,wait=off -serial … -serial chardev:u1`"
    )]
    Connect {
        /// Socket path.
        path: String,
        /// Underlying error.
        source: std::io::Error,
    },
    /// Writing a frame failed for another reason than the reader going away.
    #[error("writing the feed failed ({0}); check that the emulator is still running")]
    Write(std::io::Error),
}

/// Counters of a feed run.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FeedStats {
    /// Samples written.
    pub samples: u64,
    /// Feed time at the end, s.
    pub feed_time_s: f64,
    /// Wall time of the run, s.
    pub wall_time_s: f64,
    /// Largest lag of the feed behind its pace, s of feed time (the reader pushing back).
    pub max_lag_s: f64,
    /// Whether the run ended because the reader closed the connection.
    pub reader_closed: bool,
}

/// Writes `world`'s frames to `out`, paced at `speed`, until `control` says stop or the reader
/// closes the connection (then `reader_closed` is set; it is not an error). `on_sample` sees
/// every sample, with its feed time in µs, just before it is written.
pub fn run_feed<W: Write>(
    world: &mut FeedWorld,
    out: &mut W,
    speed: f64,
    control: &FeedControl,
    on_sample: &mut dyn FnMut(u64, &RawSample),
) -> Result<FeedStats, FeedError> {
    if !(speed.is_finite() && speed > 0.0) {
        return Err(FeedError::InvalidSpeed(speed));
    }
    let wall_start = Instant::now();
    let feed_start_us = world.next_time_us();
    let mut stats = FeedStats::default();
    let mut buf = [0u8; MAX_FEED_FRAME];
    let scales = FeedFrame::Scales(world.scales());
    let mut sent = 0u64;
    while !control.stop.load(Ordering::Relaxed) {
        if control.start.load(Ordering::Relaxed) {
            world.start();
        }
        let mut frames = [None, None];
        if sent.is_multiple_of(SCALES_EVERY) {
            frames[0] = Some(scales);
        }
        let (t_us, sample) = world.next_sample();
        frames[1] = Some(FeedFrame::Sample { t_us, sample });
        // Seen before it is written, so a reader never streams a sample not yet seen here.
        on_sample(t_us, &sample);
        for frame in frames.iter().flatten() {
            // Both frame kinds fit MAX_FEED_FRAME by construction; a failure would be a bug.
            let n = feed::encode(frame, &mut buf).unwrap_or(0);
            match out.write_all(buf.get(..n).unwrap_or_default()) {
                Ok(()) => {}
                Err(e) if is_reader_gone(&e) => {
                    stats.reader_closed = true;
                    return Ok(finish(stats, world, wall_start));
                }
                Err(e) => return Err(FeedError::Write(e)),
            }
        }
        sent += 1;
        stats.samples = sent;
        control.time_us.store(t_us, Ordering::Relaxed);
        control.samples.store(sent, Ordering::Relaxed);
        let fed_s = (world.next_time_us().saturating_sub(feed_start_us)) as f64 * 1e-6;
        let due = Duration::from_secs_f64(fed_s / speed);
        let elapsed = wall_start.elapsed();
        match due.checked_sub(elapsed) {
            Some(wait) => std::thread::sleep(wait),
            None => {
                let lag_s = (elapsed - due).as_secs_f64() * speed;
                stats.max_lag_s = stats.max_lag_s.max(lag_s);
            }
        }
    }
    Ok(finish(stats, world, wall_start))
}

fn finish(mut stats: FeedStats, world: &FeedWorld, wall_start: Instant) -> FeedStats {
    stats.feed_time_s = world.time_s();
    stats.wall_time_s = wall_start.elapsed().as_secs_f64();
    stats
}

fn is_reader_gone(error: &std::io::Error) -> bool {
    matches!(
        error.kind(),
        ErrorKind::BrokenPipe | ErrorKind::ConnectionReset | ErrorKind::ConnectionAborted
    )
}

/// Connects to a unix socket served by the emulator, retrying for `patience` while it starts.
pub fn connect_feed_socket(path: &Path, patience: Duration) -> Result<UnixStream, FeedError> {
    let deadline = Instant::now() + patience;
    loop {
        match UnixStream::connect(path) {
            Ok(stream) => return Ok(stream),
            Err(_) if Instant::now() < deadline => std::thread::sleep(Duration::from_millis(50)),
            Err(source) => {
                return Err(FeedError::Connect {
                    path: path.display().to_string(),
                    source,
                })
            }
        }
    }
}

/// Arguments of the `feed` command.
#[derive(Debug, Clone, PartialEq, clap::Args)]
pub struct FeedArgs {
    /// Unix socket of the emulated board's sensor UART (QEMU serves it).
    #[arg(long)]
    pub socket: PathBuf,
    /// Seed of every random draw (board errors, effects, noise, the person's positions).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Feed seconds per wall-clock second (1 = real time).
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
    /// Switch an effect on (repeatable): `[sensor.]name[=size]`.
    #[arg(long = "effect")]
    pub effects: Vec<EffectRequest>,
    /// Feed seconds each of the twelve positions is held.
    #[arg(long = "hold", default_value_t = 6.0)]
    pub hold_s: f64,
    /// Feed seconds in the first position before the person starts the timetable.
    #[arg(long = "lead-in", default_value_t = 10.0)]
    pub lead_in_s: f64,
    /// Hold perfectly still (no hand tremor).
    #[arg(long)]
    pub no_tremor: bool,
    /// Stop after this many wall-clock seconds.
    #[arg(long)]
    pub seconds: Option<f64>,
    /// Write every true parameter as JSON here at the start.
    #[arg(long)]
    pub truth: Option<PathBuf>,
}

impl FeedArgs {
    /// The feed options these arguments describe.
    pub fn options(&self) -> FeedOptions {
        let mut options = FeedOptions::new(self.seed);
        options.effects = self.effects.clone();
        options.hold_s = self.hold_s;
        options.tremor = !self.no_tremor;
        options.lead_in_s = Some(self.lead_in_s);
        options
    }
}

/// Run the `feed` command: connect to the socket, feed until `--seconds` pass or the emulator
/// closes the socket, then print the counters on stderr.
pub fn run_command(args: &FeedArgs) -> Result<(), FeedError> {
    let wall_limit = args
        .seconds
        .map(|s| require_non_negative("--seconds", s).map(Duration::from_secs_f64))
        .transpose()?;
    let mut world = FeedWorld::new(&args.options())?;
    if let Some(path) = &args.truth {
        write_truth_file(&world.truth(), path)?;
    }
    let mut stream = connect_feed_socket(&args.socket, Duration::from_secs(10))?;
    eprintln!(
        "feeding {} (seed {}, {}× real time): {:.0} s in the first position, then {:.0} s of \
         positions and tumble, then rest",
        args.socket.display(),
        args.seed,
        args.speed,
        args.lead_in_s,
        world.timetable_s()
    );
    let control = FeedControl::new();
    let stats = std::thread::scope(|scope| {
        if let Some(limit) = wall_limit {
            let control = &control;
            scope.spawn(move || {
                let started = Instant::now();
                while started.elapsed() < limit && !control.is_stopped() {
                    std::thread::sleep(Duration::from_millis(20));
                }
                control.stop();
            });
        }
        let stats = run_feed(
            &mut world,
            &mut stream,
            args.speed,
            &control,
            &mut |_, _| {},
        );
        // Ends the timer thread when the run ended first.
        control.stop();
        stats
    })?;
    eprintln!(
        "fed {:.1} s in {:.1} s ({} samples, largest lag {:.2} s){}",
        stats.feed_time_s,
        stats.wall_time_s,
        stats.samples,
        stats.max_lag_s,
        if stats.reader_closed {
            "; the emulator closed the socket"
        } else {
            ""
        }
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::poser::twelve_position_up_directions;
    use imucal_protocol::feed::FeedDecoder;
    use nalgebra::Vector3;

    fn calibrated(truth: &crate::physics::SensorTruth, counts: [i16; 3]) -> Vector3<f64> {
        let x = Vector3::from(counts.map(|c| f64::from(c) * truth.units_per_count));
        truth.calibrate(&x)
    }

    #[test]
    fn frames_start_with_scales_and_carry_consecutive_sample_times() {
        let mut world = FeedWorld::new(&FeedOptions::new(3)).expect("valid options");
        let control = FeedControl::new();
        let mut bytes = Vec::new();
        let mut count = 0;
        // A high speed keeps the paced run short; stop after 100 samples.
        let stats = run_feed(&mut world, &mut bytes, 1.0e6, &control, &mut |_, _| {
            count += 1;
            if count == 100 {
                control.stop();
            }
        })
        .expect("writing to memory works");
        let mut decoder = FeedDecoder::new();
        let frames: Vec<FeedFrame> = bytes
            .iter()
            .filter_map(|b| decoder.push(*b))
            .map(|f| f.expect("every frame decodes"))
            .collect();
        assert_eq!(stats.samples, 100);
        assert!(matches!(frames.first(), Some(FeedFrame::Scales(s)) if s.sample_rate_hz == 119.0));
        let times: Vec<u64> = frames
            .iter()
            .filter_map(|f| match f {
                FeedFrame::Sample { t_us, .. } => Some(*t_us),
                FeedFrame::Scales(_) => None,
            })
            .collect();
        let expected: Vec<u64> = (0..100).map(|k| k * 8403).collect();
        assert_eq!(times, expected);
        // 100 samples carry ⌈100 / 32⌉ = 4 Scales frames.
        assert_eq!(frames.len(), 104);
    }

    #[test]
    fn waiting_board_reads_gravity_and_field_through_the_true_calibration() {
        let mut options = FeedOptions::new(5);
        options.lead_in_s = None;
        let mut world = FeedWorld::new(&options).expect("valid options");
        let truth = world.truth().imu;
        let n = 119;
        let (mut a_sum, mut m_sum) = (0.0, 0.0);
        for _ in 0..n {
            let (_, raw) = world.next_sample();
            a_sum += calibrated(&truth.accel, raw.accel).norm();
            m_sum += calibrated(&truth.mag, raw.mag).norm();
        }
        assert_eq!(world.phase(), FeedPhase::Waiting);
        // Mean of 119 norms: noise σ/√119 (2.1 mg → 0.2 mg; 0.33 µT → 0.03 µT) plus the
        // quantisation (0.12 mg, 0.014 µT, both uniform): 5σ bounds of 1.5 mg and 0.2 µT.
        let g_err_mg = (a_sum / n as f64 - STANDARD_GRAVITY_MPS2).abs() / STANDARD_GRAVITY_MPS2;
        assert!(g_err_mg * 1000.0 < 1.5, "|a| off by {} mg", g_err_mg * 1e3);
        assert!(
            (m_sum / n as f64 - 48.0).abs() < 0.2,
            "|m| = {}",
            m_sum / n as f64
        );
    }

    #[test]
    fn timed_person_holds_the_twelve_positions_then_tumbles_through_all_directions() {
        let mut options = FeedOptions::new(11);
        options.tremor = false;
        options.hold_s = 3.0;
        let mut world = FeedWorld::new(&options).expect("valid options");
        world.start();
        let ups = twelve_position_up_directions();
        let mut seen_hold_ups: Vec<Option<Vector3<f64>>> = vec![None; 12];
        let mut field_octants = [0usize; 8];
        loop {
            let phase = world.phase();
            let state = world.true_state();
            let _ = world.next_sample();
            match phase {
                FeedPhase::Positions { index } => {
                    if let Some(slot) = seen_hold_ups.get_mut(index) {
                        // The last instant before the next turn is inside the hold.
                        *slot = Some(state.specific_force_body.normalize());
                    }
                }
                FeedPhase::Tumble => {
                    let f = state.field_body;
                    let octant = usize::from(f.x > 0.0)
                        | (usize::from(f.y > 0.0) << 1)
                        | (usize::from(f.z > 0.0) << 2);
                    field_octants[octant] += 1;
                }
                FeedPhase::Rest => break,
                FeedPhase::Waiting => panic!("the person was started"),
            }
        }
        for (index, (up, seen)) in ups.iter().zip(&seen_hold_ups).enumerate() {
            let seen = seen.expect("every position is visited");
            // Placement error is at most 3° (PoserOptions default).
            let angle = seen.angle(up).to_degrees();
            assert!(angle <= 3.0 + 1e-6, "position {index} is {angle:.2}° off");
        }
        // The spiral covers the sphere: every octant of field directions gets samples.
        assert!(
            field_octants.iter().all(|&n| n >= 50),
            "field directions per octant {field_octants:?}"
        );
        // At rest the board is back in the first position.
        let rest_up = world.true_state().specific_force_body.normalize();
        assert!(rest_up.angle(&ups[0]).to_degrees() <= 3.0 + 1e-6);
    }

    #[test]
    fn lead_in_starts_the_timetable_by_itself() {
        let mut options = FeedOptions::new(2);
        options.lead_in_s = Some(1.0);
        let mut world = FeedWorld::new(&options).expect("valid options");
        while world.time_s() < 1.0 {
            assert_eq!(world.phase(), FeedPhase::Waiting);
            let _ = world.next_sample();
        }
        let _ = world.next_sample();
        assert_eq!(world.phase(), FeedPhase::Positions { index: 0 });
        let started = world.started_s().expect("started after the lead-in");
        assert!((started - 1.0).abs() <= 0.0085, "started at {started} s");
    }

    #[test]
    fn unusable_speed_and_hold_are_refused_with_a_reason() {
        let mut world = FeedWorld::new(&FeedOptions::new(1)).expect("valid options");
        let error = run_feed(
            &mut world,
            &mut Vec::new(),
            0.0,
            &FeedControl::new(),
            &mut |_, _| {},
        )
        .expect_err("speed 0 is refused");
        assert!(error.to_string().contains("speed 0 is not usable"));
        let mut options = FeedOptions::new(1);
        options.hold_s = f64::NAN;
        let error = FeedWorld::new(&options).expect_err("NaN hold is refused");
        assert!(error.to_string().contains("hold time"));
    }
}
