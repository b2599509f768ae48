//! Serve a [`MotionCalBoard`] on a pseudo-terminal, paced against wall time like
//! [`crate::serve`] does for imucal's own firmware: each turn moves the host's bytes into the
//! board, runs the sketch loops now due, and writes what the board printed without blocking.

use std::io::{Read, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use serialport::TTYPort;

use crate::motioncal_board::{MotionCalBoard, StoredCalibration};
use crate::physics::ImuTruth;
use crate::serve::{
    announce_port, is_not_ready, open_pty, serve_until_done, wall_limit, ServeArgs, ServeError,
};

/// Longest sleep of the loop.
const MAX_SLEEP: Duration = Duration::from_millis(1);
/// Printed bytes kept while nobody reads; older ones are lost, as on a serial line.
const UNSENT_LIMIT: usize = 64 * 1024;

/// What the serving thread shares with the handle.
#[derive(Debug, Default)]
struct Observed {
    eeprom: Option<StoredCalibration>,
    stored_count: u32,
    sim_time_us: u64,
}

/// A running simulated MotionCal sketch board.
#[derive(Debug)]
pub struct MotionCalHandle {
    port_path: String,
    stop: Arc<AtomicBool>,
    observed: Arc<Mutex<Observed>>,
    thread: Option<JoinHandle<Result<(), ServeError>>>,
    truth: ImuTruth,
    site_field_ut: f64,
    schedule_s: f64,
}

impl MotionCalHandle {
    /// Starts the board with sensor errors from `seed`, `speed` simulated s per wall s.
    pub fn start(seed: u64, speed: f64) -> Result<Self, ServeError> {
        if !(speed.is_finite() && speed > 0.0) {
            return Err(ServeError::InvalidSpeed(speed));
        }
        let board = MotionCalBoard::new(seed)?;
        let truth = *board.truth();
        let site_field_ut = board.site_field_ut();
        let schedule_s = board.schedule_duration_s();
        let (master, slave, port_path) = open_pty()?;
        let stop = Arc::new(AtomicBool::new(false));
        let observed = Arc::new(Mutex::new(Observed::default()));
        let (thread_stop, thread_observed) = (Arc::clone(&stop), Arc::clone(&observed));
        let thread = std::thread::Builder::new()
            .name("imucal-hil-sim-motioncal".into())
            .spawn(move || {
                // The slave stays open so the master never sees a hang-up between hosts.
                let _slave = slave;
                serve(board, master, speed, &thread_stop, &thread_observed)
            })
            .map_err(ServeError::Io)?;
        Ok(Self {
            port_path,
            stop,
            observed,
            thread: Some(thread),
            truth,
            site_field_ut,
            schedule_s,
        })
    }

    /// Path of the serial port to open.
    pub fn port_path(&self) -> &str {
        &self.port_path
    }

    /// The board's true sensor parameters.
    pub fn truth(&self) -> &ImuTruth {
        &self.truth
    }

    /// The Earth's field magnitude at the simulated site, µT.
    pub fn site_field_ut(&self) -> f64 {
        self.site_field_ut
    }

    /// Simulated seconds of the person's schedule (twelve holds and the tumble).
    pub fn schedule_duration_s(&self) -> f64 {
        self.schedule_s
    }

    fn observed<R>(&self, f: impl FnOnce(&Observed) -> R) -> R {
        f(&self.observed.lock().unwrap_or_else(PoisonError::into_inner))
    }

    /// What the board's EEPROM holds.
    pub fn eeprom(&self) -> Option<StoredCalibration> {
        self.observed(|o| o.eeprom)
    }

    /// Packets stored so far.
    pub fn stored_count(&self) -> u32 {
        self.observed(|o| o.stored_count)
    }

    /// Simulated time, s.
    pub fn sim_time_s(&self) -> f64 {
        self.observed(|o| o.sim_time_us as f64 * 1e-6)
    }

    /// Whether the serving thread still runs.
    pub fn is_running(&self) -> bool {
        self.thread.as_ref().is_some_and(|t| !t.is_finished())
    }

    /// Stops serving; returns the error that ended it early, if any.
    pub fn stop(mut self) -> Result<(), ServeError> {
        self.shutdown()
    }

    fn shutdown(&mut self) -> Result<(), ServeError> {
        self.stop.store(true, Ordering::Relaxed);
        match self.thread.take() {
            Some(thread) => thread.join().map_err(|_| ServeError::Panicked)?,
            None => Ok(()),
        }
    }
}

impl Drop for MotionCalHandle {
    fn drop(&mut self) {
        // Errors were the caller's to collect through `stop`.
        let _ = self.shutdown();
    }
}

fn serve(
    mut board: MotionCalBoard,
    mut master: TTYPort,
    speed: f64,
    stop: &AtomicBool,
    observed: &Mutex<Observed>,
) -> Result<(), ServeError> {
    let start = Instant::now();
    let mut buffer = [0u8; 4096];
    let mut unsent: Vec<u8> = Vec::new();
    while !stop.load(Ordering::Relaxed) {
        match master.read(&mut buffer) {
            Ok(n) => board.receive(&buffer[..n]),
            Err(e) if is_not_ready(&e) => {}
            Err(e) => return Err(ServeError::Io(e)),
        }
        let due_us = (start.elapsed().as_secs_f64() * speed * 1e6) as u64;
        board.advance_to(due_us);
        unsent.extend(board.take_output());
        if unsent.len() > UNSENT_LIMIT {
            unsent.drain(..unsent.len() - UNSENT_LIMIT);
        }
        if !unsent.is_empty() {
            match master.write(&unsent) {
                Ok(n) => {
                    unsent.drain(..n);
                }
                Err(e) if is_not_ready(&e) => {}
                Err(e) => return Err(ServeError::Io(e)),
            }
        }
        {
            let mut o = observed.lock().unwrap_or_else(PoisonError::into_inner);
            o.eeprom = board.eeprom();
            o.stored_count = board.stored_count();
            o.sim_time_us = board.time_us();
        }
        std::thread::sleep(MAX_SLEEP);
    }
    Ok(())
}

/// `serve --protocol motioncal`: print the port path, then serve the MotionCal sketch board until
/// stdin ends (unless ignored), `--seconds` pass, or the process is interrupted.
pub fn run_command(args: &ServeArgs) -> Result<(), ServeError> {
    let wall_limit = wall_limit(args)?;
    let handle = MotionCalHandle::start(args.seed, args.speed)?;
    if let Some(path) = &args.truth {
        let text = serde_json::to_string_pretty(handle.truth())
            .map_err(|e| ServeError::Io(std::io::Error::other(e)))?;
        std::fs::write(path, text).map_err(ServeError::Io)?;
    }
    announce_port(handle.port_path())?;
    serve_until_done(args, wall_limit, || handle.is_running());
    let (stored, sim_s) = (handle.stored_count(), handle.sim_time_s());
    handle.stop()?;
    eprintln!("simulated {sim_s:.1} s; {stored} calibration packet(s) stored");
    Ok(())
}
