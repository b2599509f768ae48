//! Serve a [`SimBoard`] on a pseudo-terminal, so that the host opens it with `serialport` like any
//! board: start → [`SimHandle::port_path`] → [`SimHandle::stop`].
//!
//! A background thread owns the board and the pty's master side; the host opens the slave's path.
//! Simulated time is paced against wall time: `t_sim = speed · t_wall` (speed 1 = real time). Each
//! turn of the loop moves the host's bytes into the board, runs the board up to the simulated time
//! now due (at most [`MAX_STEP_US`] at once, so I/O keeps flowing when the machine falls behind),
//! writes the board's bytes to the pty without blocking (bytes the pty cannot take yet wait in the
//! board's transmit buffer), then sleeps until the next sample is due (at most 1 ms).
//!
//! The thread keeps the slave side open itself, so the master never sees a hang-up while no host
//! is connected and a host may close and reopen the port. Bytes the board sends while nobody reads
//! wait in the pty, as they would on a real serial line.
//!
//! With [`SimOptions::faults`] active, both directions pass a [`FaultyLink`] (see
//! [`crate::link_faults`]) between the pty and the board, and the pty can be closed on purpose
//! ([`SimHandle::vanish`] or `vanish_after`), as when a board is unplugged.

use std::io::{ErrorKind, Read, Write};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, Sender};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use serialport::{SerialPort, TTYPort};
use thiserror::Error;

use crate::board::{BoardConfig, BoardError, PersonSchedule, Screen, SensorChip, SimBoard};
use crate::effects::EffectRequest;
use crate::error::SimError;
use crate::link_faults::{FaultStats, FaultyLink, LinkFaults, ParamTamper};
use crate::recording::{write_truth_file, Truth};

/// Largest simulated time run in one turn of the serving loop, µs (50 ms).
pub const MAX_STEP_US: u64 = 50_000;
/// Longest sleep of the serving loop, so host bytes are picked up within about a millisecond.
const MAX_SLEEP: Duration = Duration::from_millis(1);
/// Bytes moved per read or write on the pty.
const CHUNK: usize = 4096;

/// Why serving failed.
#[derive(Debug, Error)]
pub enum ServeError {
    /// The board could not be built or run.
    #[error(transparent)]
    Board(#[from] BoardError),
    /// No pseudo-terminal could be created.
    #[error(
        "could not create a pseudo-terminal ({0}); check that /dev/ptmx exists and is usable \
         (in a container, mount devpts)"
    )]
    Pty(serialport::Error),
    /// Reading or writing the pseudo-terminal failed.
    #[error("the pseudo-terminal failed ({0}); restart the simulator")]
    Io(std::io::Error),
    /// The speed factor is not usable.
    #[error("speed {0} is not usable; give a finite factor greater than zero (1 = real time)")]
    InvalidSpeed(f64),
    /// The serving thread is gone (it failed or was stopped).
    #[error("the simulated board has stopped; start a new one")]
    Stopped,
    /// A setting is invalid or the truth file could not be written.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// The serving thread panicked.
    #[error("the simulated board's thread panicked; this is a bug in the simulator")]
    Panicked,
}

/// How to run a simulated board behind a pseudo-terminal.
#[derive(Debug, Clone, PartialEq)]
pub struct SimOptions {
    /// Seed of every random draw.
    pub seed: u64,
    /// Effects switched on without telling the host.
    pub effects: Vec<EffectRequest>,
    /// Simulated seconds per wall-clock second (1 = real time).
    pub speed: f64,
    /// What the person holding the board does.
    pub schedule: PersonSchedule,
    /// Every other setting of the board; its seed, effects and schedule are replaced by the
    /// fields above.
    pub board: BoardConfig,
    /// Faults injected on the serial link (none by default).
    pub faults: LinkFaults,
}

impl SimOptions {
    /// Real time, guided person, no effects, defaults of [`BoardConfig::new`].
    pub fn new(seed: u64) -> Self {
        Self {
            seed,
            effects: Vec::new(),
            speed: 1.0,
            schedule: PersonSchedule::Guided,
            board: BoardConfig::new(seed),
            faults: LinkFaults::default(),
        }
    }

    /// The board configuration these options describe.
    pub fn board_config(&self) -> BoardConfig {
        let mut config = self.board.clone();
        config.seed = self.seed;
        config.effects = self.effects.clone();
        config.schedule = self.schedule;
        config
    }
}

impl Default for SimOptions {
    fn default() -> Self {
        Self::new(1)
    }
}

/// Counters of a serving run.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ServeStats {
    /// Simulated time, s.
    pub sim_time_s: f64,
    /// Wall time since the start, s.
    pub wall_time_s: f64,
    /// Samples the board took.
    pub samples: u64,
    /// Bytes written to the pty (board to host).
    pub bytes_to_host: u64,
    /// Bytes read from the pty (host to board).
    pub bytes_from_host: u64,
    /// Messages the board dropped because its transmit buffer was full.
    pub messages_refused: u64,
    /// Largest lag of simulated time behind the paced target, s.
    pub max_lag_s: f64,
}

enum Command {
    Reboot(Sender<Result<(), BoardError>>),
    CutPower(Option<u32>, Sender<()>),
    Tamper(Option<ParamTamper>, Sender<()>),
}

struct Shared {
    stop: AtomicBool,
    vanish: AtomicBool,
    sim_time_us: AtomicU64,
    stats: Mutex<ServeStats>,
    faults: Mutex<FaultStats>,
    notes: Mutex<Vec<String>>,
    screen: Mutex<Screen>,
    /// Up directions of the positions a resumed session holds, until the board has them.
    held: Mutex<Option<Vec<[f64; 3]>>>,
}

/// Starts simulated boards.
#[derive(Debug, Clone, Copy)]
pub struct SimServer;

impl SimServer {
    /// Build the board, create the pty and start serving in a background thread.
    pub fn start(options: SimOptions) -> Result<SimHandle, ServeError> {
        let speed = options.speed;
        if !(speed.is_finite() && speed > 0.0) {
            return Err(ServeError::InvalidSpeed(speed));
        }
        let faulty = if options.faults.is_active() {
            Some(FaultyLink::new(options.faults, options.seed)?)
        } else {
            None
        };
        let board = SimBoard::new(options.board_config())?;
        let truth = board.truth();
        let (master, slave, port_path) = open_pty()?;
        let shared = Arc::new(Shared {
            stop: AtomicBool::new(false),
            vanish: AtomicBool::new(false),
            sim_time_us: AtomicU64::new(0),
            stats: Mutex::new(ServeStats::default()),
            faults: Mutex::new(FaultStats::default()),
            notes: Mutex::new(Vec::new()),
            screen: Mutex::new(Screen::Unknown),
            held: Mutex::new(None),
        });
        let (commands, receiver) = mpsc::channel();
        let thread_shared = Arc::clone(&shared);
        let thread = std::thread::Builder::new()
            .name("imucal-hil-sim".into())
            .spawn(move || {
                let pty = Pty {
                    master,
                    // The slave stays open while serving (see the module documentation).
                    slave,
                };
                serve(board, pty, faulty, speed, &thread_shared, &receiver)
            })
            .map_err(ServeError::Io)?;
        Ok(SimHandle {
            port_path,
            shared,
            commands,
            thread: Some(thread),
            truth,
        })
    }
}

/// A running simulated board.
pub struct SimHandle {
    port_path: String,
    shared: Arc<Shared>,
    commands: Sender<Command>,
    thread: Option<JoinHandle<Result<(), ServeError>>>,
    truth: Truth,
}

impl std::fmt::Debug for SimHandle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SimHandle")
            .field("port_path", &self.port_path)
            .field("sim_time_s", &self.sim_time_s())
            .finish_non_exhaustive()
    }
}

impl SimHandle {
    /// Path of the serial port to open (the pty's slave, e.g. `/dev/pts/7`).
    pub fn port_path(&self) -> &str {
        &self.port_path
    }

    /// Every true parameter of the board; `duration_s` is the simulated time so far.
    pub fn truth(&self) -> Truth {
        let mut truth = self.truth.clone();
        truth.duration_s = self.sim_time_s();
        truth
    }

    /// Simulated time, s.
    pub fn sim_time_s(&self) -> f64 {
        self.shared.sim_time_us.load(Ordering::Relaxed) as f64 * 1e-6
    }

    /// Counters so far.
    pub fn stats(&self) -> ServeStats {
        *self
            .shared
            .stats
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
    }

    /// Power-cycle the board (the flash keeps its content); returns once it has rebooted.
    pub fn reboot(&self) -> Result<(), ServeError> {
        let (reply, answer) = mpsc::channel();
        self.commands
            .send(Command::Reboot(reply))
            .map_err(|_| ServeError::Stopped)?;
        answer.recv().map_err(|_| ServeError::Stopped)??;
        Ok(())
    }

    /// Cut the power at flash step `step` from now (see [`SimBoard::cut_power_at_flash_step`]).
    pub fn cut_power_at_flash_step(&self, step: Option<u32>) -> Result<(), ServeError> {
        let (reply, answer) = mpsc::channel();
        self.commands
            .send(Command::CutPower(step, reply))
            .map_err(|_| ServeError::Stopped)?;
        answer.recv().map_err(|_| ServeError::Stopped)
    }

    /// Faults injected on the link so far (all zero without [`SimOptions::faults`]).
    pub fn fault_stats(&self) -> FaultStats {
        *self
            .shared
            .faults
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
    }

    /// What the board side noticed since the last call (a refused `Hello`, the port closed), as
    /// sentences, oldest first.
    pub fn take_notes(&self) -> Vec<String> {
        std::mem::take(
            &mut *self
                .shared
                .notes
                .lock()
                .unwrap_or_else(PoisonError::into_inner),
        )
    }

    /// Show the simulated person what the host's screen asks for: a person who reads it takes
    /// the corner named and turns the board when asked to (see [`Screen`]).
    pub fn show(&self, screen: Screen) {
        *self
            .shared
            .screen
            .lock()
            .unwrap_or_else(PoisonError::into_inner) = screen;
    }

    /// Tell the simulated person which positions a resumed session already holds (body-frame
    /// up directions), as the host lists them when it resumes: the person skips them.
    pub fn tell_held(&self, ups: Vec<[f64; 3]>) {
        *self
            .shared
            .held
            .lock()
            .unwrap_or_else(PoisonError::into_inner) = Some(ups);
    }

    /// Close the pseudo-terminal now, as when the board is unplugged: the host's reads and
    /// writes fail and serving ends.
    pub fn vanish(&self) {
        self.shared.vanish.store(true, Ordering::Relaxed);
    }

    /// Change the parameter tampering from now on (`None` stops it). Has an effect only when
    /// the board was started with active [`SimOptions::faults`].
    pub fn set_param_tamper(&self, tamper: Option<ParamTamper>) -> Result<(), ServeError> {
        let (reply, answer) = mpsc::channel();
        self.commands
            .send(Command::Tamper(tamper, reply))
            .map_err(|_| ServeError::Stopped)?;
        answer.recv().map_err(|_| ServeError::Stopped)
    }

    /// Whether the serving thread is still running.
    pub fn is_running(&self) -> bool {
        self.thread.as_ref().is_some_and(|t| !t.is_finished())
    }

    /// Stop serving and return the final counters, or the error that ended serving early.
    pub fn stop(mut self) -> Result<ServeStats, ServeError> {
        self.shutdown()?;
        Ok(self.stats())
    }

    fn shutdown(&mut self) -> Result<(), ServeError> {
        self.shared.stop.store(true, Ordering::Relaxed);
        match self.thread.take() {
            Some(thread) => thread.join().map_err(|_| ServeError::Panicked)?,
            None => Ok(()),
        }
    }
}

impl Drop for SimHandle {
    fn drop(&mut self) {
        // Errors were the caller's to collect through `stop`.
        let _ = self.shutdown();
    }
}

/// A pseudo-terminal for a simulated board: the master (non-blocking, kept out of child
/// processes), the slave, and the slave's path for the host to open.
pub(crate) fn open_pty() -> Result<(TTYPort, TTYPort, String), ServeError> {
    let (mut master, slave) = TTYPort::pair().map_err(ServeError::Pty)?;
    close_on_exec(&master)?;
    close_on_exec(&slave)?;
    never_block(&master)?;
    master
        .set_timeout(Duration::ZERO)
        .map_err(ServeError::Pty)?;
    let port_path = slave.name().ok_or_else(|| {
        ServeError::Pty(serialport::Error::new(
            serialport::ErrorKind::Unknown,
            "the pseudo-terminal has no slave path",
        ))
    })?;
    Ok((master, slave, port_path))
}

pub(crate) fn is_not_ready(error: &std::io::Error) -> bool {
    matches!(
        error.kind(),
        ErrorKind::TimedOut | ErrorKind::WouldBlock | ErrorKind::Interrupted
    )
}

/// Keep `port`'s descriptor out of child processes: a child holding a copy of the master would
/// keep the pty alive after the board vanishes, so its host would never see the hang-up.
fn close_on_exec(port: &TTYPort) -> Result<(), ServeError> {
    use std::os::fd::AsRawFd;
    nix::fcntl::fcntl(
        port.as_raw_fd(),
        nix::fcntl::FcntlArg::F_SETFD(nix::fcntl::FdFlag::FD_CLOEXEC),
    )
    .map(|_| ())
    .map_err(|errno| ServeError::Io(std::io::Error::from(errno)))
}

/// Make writes to `port` return `WouldBlock` instead of waiting when the pty can take only part
/// of a chunk (a ready poll does not promise room for all of it), so the loop never stalls.
fn never_block(port: &TTYPort) -> Result<(), ServeError> {
    use nix::fcntl::{fcntl, FcntlArg, OFlag};
    use std::os::fd::AsRawFd;
    let fd = port.as_raw_fd();
    let to_io = |errno: nix::errno::Errno| ServeError::Io(std::io::Error::from(errno));
    let flags = OFlag::from_bits_truncate(fcntl(fd, FcntlArg::F_GETFL).map_err(to_io)?);
    fcntl(fd, FcntlArg::F_SETFL(flags | OFlag::O_NONBLOCK)).map_err(to_io)?;
    Ok(())
}

/// Both sides of the pseudo-terminal, closed together when dropped.
struct Pty {
    master: TTYPort,
    slave: TTYPort,
}

/// Bytes on their way to the host through a [`FaultyLink`], and those the pty has not taken yet.
struct FaultPath {
    link: FaultyLink,
    unsent: Vec<u8>,
}

/// The serving loop (see the module documentation).
fn serve(
    mut board: SimBoard,
    pty: Pty,
    faulty: Option<FaultyLink>,
    speed: f64,
    shared: &Shared,
    commands: &Receiver<Command>,
) -> Result<(), ServeError> {
    let start = Instant::now();
    let vanish_at = faulty
        .as_ref()
        .and_then(|f| f.faults().vanish_after)
        .and_then(|after| start.checked_add(after));
    let mut faults = faulty.map(|link| FaultPath {
        link,
        unsent: Vec::new(),
    });
    let Pty { mut master, slave } = pty;
    let sim_start_us = board.time_us();
    let mut buffer = [0u8; CHUNK];
    let mut stats = ServeStats::default();
    while !shared.stop.load(Ordering::Relaxed) {
        while let Ok(command) = commands.try_recv() {
            match command {
                Command::Reboot(reply) => {
                    // The caller may have given up waiting; nothing to do then.
                    let _ = reply.send(board.reboot());
                }
                Command::CutPower(step, reply) => {
                    board.cut_power_at_flash_step(step);
                    let _ = reply.send(());
                }
                Command::Tamper(tamper, reply) => {
                    if let Some(path) = faults.as_mut() {
                        path.link.set_param_tamper(tamper);
                    }
                    let _ = reply.send(());
                }
            }
        }
        let now = Instant::now();
        if shared.vanish.load(Ordering::Relaxed) || vanish_at.is_some_and(|at| now >= at) {
            let port = slave.name().unwrap_or_default();
            drop(master);
            drop(slave);
            let mut fault_stats = faults.as_ref().map(|p| p.link.stats()).unwrap_or_default();
            fault_stats.vanished = true;
            *shared.faults.lock().unwrap_or_else(PoisonError::into_inner) = fault_stats;
            shared
                .notes
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .push(format!(
                    "closed the port {port}, as if the board were unplugged"
                ));
            return Ok(());
        }

        loop {
            match master.read(&mut buffer) {
                Ok(0) => break,
                Ok(count) => {
                    let bytes = buffer.get(..count).unwrap_or_default();
                    match faults.as_mut() {
                        Some(path) => path.link.push_from_host(bytes, now),
                        None => board.link().send_to_device(bytes),
                    }
                    stats.bytes_from_host += count as u64;
                }
                Err(error) if is_not_ready(&error) => break,
                Err(error) => return Err(ServeError::Io(error)),
            }
        }
        if let Some(path) = faults.as_mut() {
            board.link().send_to_device(&path.link.take_for_device(now));
        }

        let wall_s = start.elapsed().as_secs_f64();
        let target_us = sim_start_us.saturating_add((wall_s * speed * 1e6) as u64);
        let step_to = target_us.min(board.time_us().saturating_add(MAX_STEP_US));
        board.show(*shared.screen.lock().unwrap_or_else(PoisonError::into_inner));
        if let Some(ups) = shared
            .held
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .take()
        {
            board.tell_held(&ups);
        }
        board.advance_to(step_to)?;
        let lag_s = target_us.saturating_sub(step_to) as f64 * 1e-6;

        match faults.as_mut() {
            Some(path) => {
                pull_through_faults(&mut board, path);
                // Counters and notes first, so they are current once the host has the bytes.
                *shared.faults.lock().unwrap_or_else(PoisonError::into_inner) = path.link.stats();
                let notes = path.link.take_notes();
                if !notes.is_empty() {
                    shared
                        .notes
                        .lock()
                        .unwrap_or_else(PoisonError::into_inner)
                        .extend(notes);
                }
                stats.bytes_to_host += write_through_faults(&mut master, path)?;
            }
            None => stats.bytes_to_host += send_direct(&mut board, &mut master, &mut buffer)?,
        }

        shared.sim_time_us.store(board.time_us(), Ordering::Relaxed);
        stats.sim_time_s = board.time_s();
        stats.wall_time_s = wall_s;
        stats.samples = board.samples_taken();
        stats.messages_refused = board.link().observations().messages_refused;
        stats.max_lag_s = stats.max_lag_s.max(lag_s);
        *shared.stats.lock().unwrap_or_else(PoisonError::into_inner) = stats;

        if lag_s == 0.0 {
            let until_sample_us = board.next_sample_us().saturating_sub(board.time_us());
            let wait = Duration::from_secs_f64(until_sample_us as f64 * 1e-6 / speed);
            std::thread::sleep(wait.min(MAX_SLEEP));
        }
    }
    Ok(())
}

/// Write what the board sent to the pty without blocking; returns the bytes written. Bytes the
/// pty cannot take stay in the board's transmit buffer.
fn send_direct(
    board: &mut SimBoard,
    master: &mut TTYPort,
    buffer: &mut [u8; CHUNK],
) -> Result<u64, ServeError> {
    let mut total = 0;
    loop {
        let count = board.link().peek_from_device(buffer);
        if count == 0 {
            break;
        }
        match master.write(buffer.get(..count).unwrap_or_default()) {
            Ok(0) => break,
            Ok(written) => {
                board.link().consume_from_device(written);
                total += written as u64;
            }
            Err(error) if is_not_ready(&error) => break,
            Err(error) => return Err(ServeError::Io(error)),
        }
    }
    Ok(total)
}

/// Pass what the board sent into the faults. The board's bytes are taken only while little
/// waits on the way, so a host that does not read still fills the board's transmit buffer.
fn pull_through_faults(board: &mut SimBoard, path: &mut FaultPath) {
    let now = Instant::now();
    if path.unsent.len() + path.link.pending_for_host() < CHUNK {
        let bytes = board.link().take_from_device();
        path.link.push_from_device(&bytes, now);
    }
    path.unsent.extend(path.link.take_for_host(now));
}

/// Write the bytes due for the host to the pty without blocking; returns the bytes written.
fn write_through_faults(master: &mut TTYPort, path: &mut FaultPath) -> Result<u64, ServeError> {
    let mut total = 0;
    while !path.unsent.is_empty() {
        match master.write(&path.unsent) {
            Ok(0) => break,
            Ok(written) => {
                path.unsent.drain(..written.min(path.unsent.len()));
                total += written as u64;
            }
            Err(error) if is_not_ready(&error) => break,
            Err(error) => return Err(ServeError::Io(error)),
        }
    }
    Ok(total)
}

/// Arguments of the `serve` command.
#[derive(Debug, Clone, PartialEq, clap::Args)]
pub struct ServeArgs {
    /// Seed of every random draw (board errors, effects, noise, the person's positions).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Switch an effect on (repeatable): `[sensor.]name[=size]`.
    #[arg(long = "effect")]
    pub effects: Vec<EffectRequest>,
    /// Simulated seconds per wall-clock second (1 = real time).
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
    /// What the person holding the board does: guided or rest.
    #[arg(long, default_value = "guided")]
    pub schedule: PersonSchedule,
    /// Longest hold of a position once the host prompts, simulated s.
    #[arg(long = "max-hold", default_value_t = 20.0)]
    pub max_hold_s: f64,
    /// Hold perfectly still (no hand tremor).
    #[arg(long)]
    pub no_tremor: bool,
    /// Stop after this many wall-clock seconds.
    #[arg(long)]
    pub seconds: Option<f64>,
    /// Keep running when stdin closes (for running in the background).
    #[arg(long)]
    pub ignore_stdin: bool,
    /// Write every true parameter as JSON here at the start.
    #[arg(long)]
    pub truth: Option<PathBuf>,
    /// Probability that a byte is lost, per byte, in both directions (e.g. 1e-3).
    #[arg(long = "drop-rate", default_value_t = 0.0)]
    pub drop_rate: f64,
    /// Probability that a byte has one bit flipped, per byte, in both directions.
    #[arg(long = "flip-rate", default_value_t = 0.0)]
    pub flip_rate: f64,
    /// Probability that a frame is sent twice, per frame, in both directions.
    #[arg(long = "dup-rate", default_value_t = 0.0)]
    pub dup_rate: f64,
    /// Hold frames back by this many milliseconds of wall time (see --delay-rate).
    #[arg(long = "delay-ms", default_value_t = 0)]
    pub delay_ms: u64,
    /// Probability that a frame is held back by --delay-ms, per frame, in both directions.
    #[arg(long = "delay-rate", default_value_t = 0.05)]
    pub delay_rate: f64,
    /// Close the port after this many wall-clock seconds, as if the board were unplugged.
    #[arg(long = "vanish-after-s")]
    pub vanish_after_s: Option<f64>,
    /// Speak this protocol major version at Hello (to try a host against another version).
    #[arg(long = "protocol-major")]
    pub protocol_major: Option<u16>,
    /// What the board runs: imucal's firmware, or Adafruit's MotionCal calibration sketch
    /// (prints `Raw:`/`Uni:` lines, stores the 68-byte packet; the link-fault options and the
    /// guided person do not apply to it).
    #[arg(long, value_enum, default_value = "imucal")]
    pub protocol: BoardProtocol,
    /// Sensor chip of a board running imucal's firmware: lsm9ds1 (Nano 33 BLE Sense) or bmi270
    /// (BMI270 + BMM150, Nano 33 BLE Sense Rev2).
    #[arg(long, value_enum, default_value = "lsm9ds1")]
    pub chip: SensorChip,
}

/// The firmware a served board runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum BoardProtocol {
    /// imucal's firmware and framed protocol.
    #[default]
    Imucal,
    /// Adafruit's MotionCal calibration sketch.
    Motioncal,
}

impl Default for ServeArgs {
    /// The same values as the command line's defaults.
    fn default() -> Self {
        Self {
            seed: 1,
            effects: Vec::new(),
            speed: 1.0,
            schedule: PersonSchedule::Guided,
            max_hold_s: 20.0,
            no_tremor: false,
            seconds: None,
            ignore_stdin: false,
            truth: None,
            drop_rate: 0.0,
            flip_rate: 0.0,
            dup_rate: 0.0,
            delay_ms: 0,
            delay_rate: 0.05,
            vanish_after_s: None,
            protocol_major: None,
            protocol: BoardProtocol::Imucal,
            chip: SensorChip::Lsm9ds1,
        }
    }
}

impl ServeArgs {
    /// The server options these arguments describe.
    pub fn options(&self) -> SimOptions {
        let mut options = SimOptions::new(self.seed);
        options.effects = self.effects.clone();
        options.speed = self.speed;
        options.schedule = self.schedule;
        options.board.max_hold_s = self.max_hold_s;
        options.board.poser.tremor = !self.no_tremor;
        options.board.sensor = self.chip;
        options.faults = LinkFaults {
            drop_rate: self.drop_rate,
            flip_rate: self.flip_rate,
            dup_rate: self.dup_rate,
            delay_rate: self.delay_rate,
            delay: Duration::from_millis(self.delay_ms),
            // `run_command` refuses a negative or non-finite time before this is used.
            vanish_after: self
                .vanish_after_s
                .map(|s| Duration::try_from_secs_f64(s).unwrap_or(Duration::MAX)),
            protocol_major: self.protocol_major,
            param_tamper: None,
        };
        options
    }
}

/// Run the `serve` command: print the port path on stdout (one line, flushed), then serve until
/// stdin reaches end of file, `--seconds` pass, or the process is interrupted.
pub fn run_command(args: &ServeArgs) -> Result<(), ServeError> {
    let wall_limit = wall_limit(args)?;
    if let Some(seconds) = args.vanish_after_s {
        crate::error::require_non_negative("--vanish-after-s", seconds)?;
    }
    let handle = SimServer::start(args.options())?;
    if let Some(path) = &args.truth {
        write_truth_file(&handle.truth(), path)?;
    }
    announce_port(handle.port_path())?;
    serve_until_done(args, wall_limit, || {
        for note in handle.take_notes() {
            eprintln!("board: {note}");
        }
        handle.is_running()
    });
    for note in handle.take_notes() {
        eprintln!("board: {note}");
    }
    let stats = handle.stop()?;
    eprintln!(
        "simulated {:.1} s in {:.1} s; {} samples, {} bytes to the host, {} from it",
        stats.sim_time_s,
        stats.wall_time_s,
        stats.samples,
        stats.bytes_to_host,
        stats.bytes_from_host
    );
    Ok(())
}

/// Prints the port path (one line, flushed).
pub(crate) fn announce_port(path: &str) -> Result<(), ServeError> {
    let mut stdout = std::io::stdout().lock();
    writeln!(stdout, "{path}")
        .and_then(|()| stdout.flush())
        .map_err(ServeError::Io)
}

/// Waits until `still_running` says no, stdin ends (unless ignored) or `wall_limit` passes.
pub(crate) fn serve_until_done(
    args: &ServeArgs,
    wall_limit: Option<Duration>,
    mut still_running: impl FnMut() -> bool,
) {
    let (closed, stdin_closed) = mpsc::channel::<()>();
    if !args.ignore_stdin {
        std::thread::spawn(move || {
            // Whatever is typed is ignored; only the end of input matters.
            let _ = std::io::copy(&mut std::io::stdin().lock(), &mut std::io::sink());
            let _ = closed.send(());
        });
    }
    let started = Instant::now();
    while still_running()
        && stdin_closed.try_recv().is_err()
        && wall_limit.is_none_or(|limit| started.elapsed() < limit)
    {
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// `--seconds` as a duration, refused when negative or not finite.
pub(crate) fn wall_limit(args: &ServeArgs) -> Result<Option<Duration>, ServeError> {
    Ok(args
        .seconds
        .map(|s| crate::error::require_non_negative("--seconds", s).map(Duration::from_secs_f64))
        .transpose()?)
}
