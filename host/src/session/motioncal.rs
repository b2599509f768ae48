//! The guided session on a board that runs a MotionCal-compatible sketch (Adafruit's
//! `calibration.ino` or PJRC's): such a board only prints readings and stores the 68-byte packet,
//! so the host does what imucal's firmware would. It watches the streamed readings for stillness
//! ([`MotionMonitor`], as the main session does), averages a hold in one of the twelve positions
//! itself ([`pose_stats`]), collects the tumble until the magnetometer's sphere is covered, fits
//! with the library's default methods ([`fit_session`]), puts the result in the symmetric gauge
//! the packet carries ([`AdafruitCalibration::from_set`]), says what the Adafruit library cannot
//! apply and what that costs on the captured poses ([`limitations`]), and sends the packet,
//! checking the board's `Cal1:`/`Cal2:` echo against what was sent.
//!
//! The sketch's readings carry no time stamp, so time is the reading index over the sketch's
//! nominal rate ([`MotionCalOptions::sample_rate_hz`]); no temperature either, so poses carry
//! [`UNKNOWN_TEMPERATURE_C`] and the set has no temperature terms.
//!
//! Every reading is handed to the caller as it is read, also when the session stops early (a
//! Ctrl-C, a position not held in time, a lost board), so that nothing measured is lost: the
//! command line saves them as a recording that `imucal fit` reads.

use std::io::{Read, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use imucal_protocol::PoseStats;
use thiserror::Error;

use super::coverage::{sphere_centre, Coverage, REGIONS};
use super::events::{SessionEvent, SessionObserver};
use super::mag_guidance::Attitude;
use super::motion::MotionMonitor;
use super::options::SessionOptions;
use super::runner::unix_now;
use super::solve::{fit_session, Budgets, CapturedPose, SessionFit, VerdictLevel};
use super::targets::{target_at, twelve_positions, Target};
use crate::compat::adafruit::{limitations, AdafruitLimitations, Conversion};
use crate::compat::{AdafruitCalibration, CompatError, EchoCheck, MotionCalClient, MotionCalError};
use crate::device::UnitSample;
use crate::fit::{FitError, Vec3};
use crate::pipeline::methods::thin_redundant;
use crate::stats::descriptive::mean_variance;
use crate::stats::robust::screen_vectors;

/// Temperature given to poses: the sketch prints none, and the set carries no temperature terms,
/// so it only labels the poses.
pub const UNKNOWN_TEMPERATURE_C: f64 = 25.0;
/// Readings between two magnetometer coverage reports.
const COVERAGE_EVERY: usize = 50;

/// How to run the session on a sketch board.
#[derive(Debug, Clone)]
pub struct MotionCalOptions {
    /// The options shared with the main session (stillness, hold, budgets, timeouts).
    pub session: SessionOptions,
    /// Readings per second the sketch prints (Adafruit's `calibration.ino`: one per 10 ms loop).
    pub sample_rate_hz: f64,
    /// Write even when the verdict is poor.
    pub accept_poor: bool,
    /// Longest wait for the board's `Cal1:`/`Cal2:` echo after the packet.
    pub echo_timeout: Duration,
    /// Set (by a Ctrl-C handler) to stop the session at the next reading; nothing is sent.
    pub interrupt: Option<Arc<AtomicBool>>,
}

impl Default for MotionCalOptions {
    fn default() -> Self {
        Self {
            session: SessionOptions::default(),
            sample_rate_hz: 100.0,
            accept_poor: false,
            echo_timeout: Duration::from_secs(10),
            interrupt: None,
        }
    }
}

/// Why the session on a sketch board stopped.
#[derive(Debug, Error)]
pub enum MotionCalSessionError {
    /// Talking to the board failed.
    #[error(transparent)]
    Board(#[from] MotionCalError),
    /// The data could not be fitted.
    #[error("the calibration could not be fitted: {0}")]
    Fit(#[from] FitError),
    /// A sensor's data could not be fitted.
    #[error("the calibration could not be fitted: {0}")]
    SensorFit(#[from] super::solve::SensorFitError),
    /// The fit has no form the packet can carry.
    #[error(transparent)]
    Compat(#[from] CompatError),
    /// An option is out of range.
    #[error("{0}")]
    Options(String),
    /// The user stopped the session (Ctrl-C) before anything was sent.
    #[error("the session was stopped by the user (Ctrl-C); nothing was sent to the board")]
    Interrupted,
    /// The positions were not all held before the time ran out.
    #[error(
        "only {captured} of {total} positions were held still within {seconds:.0} s (missing: \
         {missing}); hold each one still for a moment, or give a longer --pose-timeout"
    )]
    PositionsMissing {
        /// Positions held.
        captured: usize,
        /// Positions wanted.
        total: usize,
        /// Names of those not held.
        missing: String,
        /// Time allowed, s.
        seconds: f64,
    },
}

/// Everything the session on a sketch board produced.
#[derive(Debug, Clone)]
pub struct MotionCalOutcome {
    /// Every captured pose, in capture order.
    pub poses: Vec<CapturedPose>,
    /// Raw magnetometer readings while the board moved, µT.
    pub mag_points: Vec<Vec3>,
    /// Coverage of the magnetometer's sphere when the session stopped collecting.
    pub coverage: Coverage,
    /// The fit (imucal's full model).
    pub fit: SessionFit,
    /// What the Adafruit library stores of it.
    pub conversion: Conversion,
    /// What the library cannot apply and its cost on the poses.
    pub limitations: AdafruitLimitations,
    /// The board's echo of the packet, when it was sent.
    pub echo: Option<EchoCheck>,
    /// Readings streamed.
    pub readings: usize,
    /// Whether the readings came from `Uni:` lines (else `Raw:`).
    pub unified_lines: bool,
    /// Lines that started with a known tag but could not be read.
    pub malformed_lines: u64,
    /// Sketch time from the first reading to the end of collection, s.
    pub session_seconds: f64,
    /// Wall time of the whole session, s.
    pub wall_seconds: f64,
}

/// Mean and variance of a hold, as imucal's firmware reports a pose, each sensor's gross
/// outliers screened out first ([`crate::stats::robust`], as for the holds of a recording).
pub fn pose_stats(samples: &[UnitSample]) -> PoseStats {
    let n = samples.len().max(1) as f64;
    let moments = |pick: fn(&UnitSample) -> [f64; 3]| {
        let values: Vec<Vec3> = samples.iter().map(|s| Vec3::from(pick(s))).collect();
        let kept = screen_vectors(&values).kept(&values);
        let (mean, var, _) =
            mean_variance(kept.iter()).unwrap_or((Vec3::zeros(), Vec3::zeros(), 0));
        (
            [mean.x, mean.y, mean.z].map(|v| v as f32),
            [var.x, var.y, var.z].map(|v| v as f32),
        )
    };
    let (accel_mean, accel_var) = moments(|s| s.accel);
    let (gyro_mean, gyro_var) = moments(|s| s.gyro);
    let (mag_mean, mag_var) = moments(|s| s.mag);
    let temps = samples.iter().map(|s| s.temp_c as f32);
    PoseStats {
        n: u32::try_from(samples.len()).unwrap_or(u32::MAX),
        accel_mean,
        accel_var,
        gyro_mean,
        gyro_var,
        mag_mean,
        mag_var,
        temp_mean_c: (samples.iter().map(|s| s.temp_c).sum::<f64>() / n) as f32,
        temp_min_c: temps.clone().fold(f32::INFINITY, f32::min),
        temp_max_c: temps.fold(f32::NEG_INFINITY, f32::max),
        duration_ms: match (samples.first(), samples.last()) {
            (Some(first), Some(last)) => ((last.t_s - first.t_s) * 1e3).round() as u32,
            _ => 0,
        },
    }
}

/// The positions and the tumble, watched from the stream.
struct Collector<'a> {
    options: &'a MotionCalOptions,
    twelve: Vec<Target>,
    monitor: MotionMonitor,
    poses: Vec<CapturedPose>,
    hold: Vec<UnitSample>,
    hold_target: Option<usize>,
    mag_points: Vec<Vec3>,
    /// The latest attitude, for the magnetometer guidance.
    attitude: Attitude,
    prompted: Option<usize>,
}

impl<'a> Collector<'a> {
    fn new(options: &'a MotionCalOptions) -> Self {
        let session = &options.session;
        Self {
            options,
            twelve: twelve_positions(),
            monitor: MotionMonitor::new(session.window_s, session.thresholds),
            poses: Vec::new(),
            hold: Vec::new(),
            hold_target: None,
            mag_points: Vec::new(),
            attitude: Attitude::default(),
            prompted: None,
        }
    }

    fn needed(&self) -> Vec<&Target> {
        self.twelve
            .iter()
            .filter(|t| !self.poses.iter().any(|p| p.target.index == t.index))
            .collect()
    }

    fn positions_done(&self) -> bool {
        self.needed().is_empty()
    }

    /// Coverage of every moving magnetometer reading so far.
    fn coverage(&self) -> Coverage {
        let centre = sphere_centre(&self.mag_points).unwrap_or_else(Vec3::zeros);
        Coverage::of(&self.mag_points, &centre)
    }

    fn mag_done(&self, coverage: &Coverage) -> bool {
        let session = &self.options.session;
        let wanted = (session.mag_accept_fraction * REGIONS as f64).ceil() as usize;
        self.mag_points.len() >= session.mag_min_samples
            && coverage.covered(session.mag_min_per_region) >= wanted
    }

    /// Take one reading; a finished hold becomes a pose.
    fn push(&mut self, sample: UnitSample, observer: &mut dyn SessionObserver) {
        let state = self.monitor.push(&sample);
        self.attitude.push(&sample);
        let still = state.as_ref().is_some_and(|s| s.still);
        if !still {
            self.mag_points.push(Vec3::from(sample.mag));
        }
        if self.positions_done() {
            self.hold.clear();
            return;
        }
        if self.prompted.is_none() {
            self.prompt(observer);
        }
        let Some(state) = state else { return };
        let at = target_at(&self.twelve, &state.up).map(|t| t.index);
        let needed = at.is_some_and(|i| self.needed().iter().any(|t| t.index == i));
        if !(state.still && needed && state.still_for_s >= self.options.session.settle_s) {
            self.hold.clear();
            self.hold_target = None;
            return;
        }
        if self.hold_target != at {
            self.hold.clear();
            self.hold_target = at;
        }
        self.hold.push(sample);
        let span = self.hold.last().map_or(0.0, |l| l.t_s) - self.hold[0].t_s;
        if span >= self.options.session.hold.as_secs_f64() {
            self.finish_hold(observer);
        }
    }

    fn finish_hold(&mut self, observer: &mut dyn SessionObserver) {
        let samples = std::mem::take(&mut self.hold);
        let Some(target) = self
            .hold_target
            .take()
            .and_then(|i| self.twelve.iter().find(|t| t.index == i))
        else {
            return;
        };
        let t_s = (samples[0].t_s + samples[samples.len() - 1].t_s) / 2.0;
        self.poses.push(CapturedPose {
            target: target.clone(),
            stats: pose_stats(&samples),
            t_s,
        });
        observer.event(&SessionEvent::Captured {
            target,
            samples: u32::try_from(samples.len()).unwrap_or(u32::MAX),
            captured: self.poses.len(),
            total: self.twelve.len(),
        });
        self.prompt(observer);
    }

    /// Name the next position, or start the tumble once all are held.
    fn prompt(&mut self, observer: &mut dyn SessionObserver) {
        let next = self.needed().first().map(|t| (*t).clone());
        match next {
            Some(target) => {
                self.prompted = Some(target.index);
                observer.event(&SessionEvent::Prompt {
                    target: &target,
                    captured: self.poses.len(),
                    total: self.twelve.len(),
                });
            }
            None => observer.event(&SessionEvent::MagPrompt),
        }
    }
}

impl MotionCalOptions {
    fn interrupted(&self) -> Result<(), MotionCalSessionError> {
        match &self.interrupt {
            Some(flag) if flag.load(Ordering::SeqCst) => Err(MotionCalSessionError::Interrupted),
            _ => Ok(()),
        }
    }
}

/// Read the board until the twelve positions are held and the sphere is covered; every
/// reading is also appended to `readings`.
fn collect<'a, L: Read + Write>(
    client: &mut MotionCalClient<L>,
    options: &'a MotionCalOptions,
    observer: &mut dyn SessionObserver,
    readings: &mut Vec<UnitSample>,
) -> Result<(Collector<'a>, usize), MotionCalSessionError> {
    let session = &options.session;
    let mut collector = Collector::new(options);
    let pose_limit_s = session.pose_timeout.as_secs_f64();
    let mut mag_started_s = None;
    let mut index = 0usize;
    loop {
        options.interrupted()?;
        let reading =
            client
                .next_reading(session.read_timeout)?
                .ok_or(MotionCalError::Timeout {
                    what: "sensor readings",
                    seconds: session.read_timeout.as_secs_f64(),
                })?;
        let t_s = index as f64 / options.sample_rate_hz;
        index += 1;
        let sample = UnitSample {
            t_s,
            accel: reading.accel,
            gyro: reading.gyro,
            mag: reading.mag,
            temp_c: UNKNOWN_TEMPERATURE_C,
        };
        readings.push(sample);
        collector.push(sample, observer);
        if !collector.positions_done() {
            if t_s > pose_limit_s {
                let missing: Vec<String> =
                    collector.needed().iter().map(|t| t.name.clone()).collect();
                return Err(MotionCalSessionError::PositionsMissing {
                    captured: collector.poses.len(),
                    total: collector.twelve.len(),
                    missing: missing.join(", "),
                    seconds: pose_limit_s,
                });
            }
            continue;
        }
        let started = *mag_started_s.get_or_insert(t_s);
        if index.is_multiple_of(COVERAGE_EVERY) {
            let coverage = collector.coverage();
            observer.event(&SessionEvent::MagCoverage {
                covered: coverage.covered(session.mag_min_per_region),
                regions: REGIONS,
                samples: collector.mag_points.len(),
                empty: coverage.empty_regions(session.mag_min_per_region),
                guidance: collector
                    .attitude
                    .guidance(&coverage, session.mag_min_per_region),
            });
            if collector.mag_done(&coverage) {
                return Ok((collector, index));
            }
        }
        if t_s - started > session.mag_timeout.as_secs_f64() {
            observer.event(&SessionEvent::Note(format!(
                "the magnetometer phase reached its {:.0} s limit; fitting the readings so far",
                session.mag_timeout.as_secs_f64()
            )));
            return Ok((collector, index));
        }
    }
}

/// What a sketch board does with the packet, said when its session starts: the verdict at the
/// end is of this, not of imucal's full model.
pub const SKETCH_LIMITS_NOTE: &str = "a MotionCal sketch's library applies only the \
     accelerometer's and gyroscope's offsets (not their scale and axis matrices) and a \
     symmetric soft iron, so the verdict is of what this board will apply; if the part's \
     scale errors exceed the budget it will be poor for this firmware whatever the session \
     (--accept-poor still sends the packet, which corrects the offsets); firmware that applies \
     the full model (imucal's, or your own from `imucal export params.json --format c-header`) \
     meets the budget";

/// Adds to `fit`'s verdict what the Adafruit library's model costs on the poses: beyond a
/// budget the board's readings miss it whatever the fit, so the verdict is poor for this
/// firmware. The reason says how far, that measuring again cannot change it, that the packet
/// still corrects the offsets (the part's largest error; `--accept-poor` sends it), and that
/// firmware applying the full model meets the budget.
fn judge_what_the_board_applies(
    fit: &mut SessionFit,
    limits: &AdafruitLimitations,
    budgets: Budgets,
) {
    let mut reasons = Vec::new();
    if limits.accel_error_mg > budgets.accel_mg {
        reasons.push(format!(
            "poor for this firmware: the sketch's library applies only the accelerometer's \
             offsets, not its scale and axis terms: on the {} poses the board's |a| is off by \
             up to {:.2} mg, {:.1}× the {:.1} mg budget; measuring again cannot change that, \
             firmware that applies the full model can (imucal's firmware, or your own from \
             `imucal export params.json --format c-header`); --accept-poor sends the packet \
             anyway, which corrects the offsets",
            limits.poses,
            limits.accel_error_mg,
            limits.accel_error_mg / budgets.accel_mg,
            budgets.accel_mg
        ));
    }
    if limits.mag_error_pct_of_field > budgets.mag_pct {
        reasons.push(format!(
            "poor for this firmware: the sketch's library holds a symmetric soft iron: on the \
             {} poses the board's |m| is off by up to {:.2} % of the field, {:.1}× the {:.1} % \
             budget; measuring again cannot change that, firmware that applies the full model \
             can (imucal's firmware, or your own from `imucal export params.json --format \
             c-header`); --accept-poor sends the packet anyway",
            limits.poses,
            limits.mag_error_pct_of_field,
            limits.mag_error_pct_of_field / budgets.mag_pct,
            budgets.mag_pct
        ));
    }
    if !reasons.is_empty() {
        fit.verdict.level = VerdictLevel::Poor;
    }
    fit.verdict.reasons.extend(reasons);
}

/// Run the guided session on a sketch board: collect, fit, explain, send and check the echo.
/// Every reading taken is appended to `readings`, whether the session succeeds or not.
pub fn run_motioncal_session<L: Read + Write>(
    client: &mut MotionCalClient<L>,
    options: &MotionCalOptions,
    observer: &mut dyn SessionObserver,
    readings: &mut Vec<UnitSample>,
) -> Result<MotionCalOutcome, MotionCalSessionError> {
    options
        .session
        .validate()
        .map_err(|e| MotionCalSessionError::Options(e.to_string()))?;
    if !(options.sample_rate_hz.is_finite() && options.sample_rate_hz > 0.0) {
        return Err(MotionCalSessionError::Options(format!(
            "the sketch's reading rate is {} Hz, but it must be a positive number",
            options.sample_rate_hz
        )));
    }
    let wall_start = Instant::now();
    observer.event(&SessionEvent::Note(SKETCH_LIMITS_NOTE.to_string()));
    let (collector, read) = collect(client, options, observer, readings)?;
    let coverage = collector.coverage();
    let session = &options.session;
    let mut fit = fit_session(
        &collector.poses,
        &thin_redundant(&collector.mag_points, session.mag_max_fit_samples),
        session.gravity_mps2,
        session.field_ut,
        session.budgets,
        unix_now(),
    )?;
    fit.name_field_source(session.field_source);
    let conversion = AdafruitCalibration::from_set(&fit.set)?;
    let pose_means: Vec<UnitSample> = collector
        .poses
        .iter()
        .map(|p| UnitSample {
            t_s: p.t_s,
            accel: p.stats.accel_mean.map(f64::from),
            gyro: p.stats.gyro_mean.map(f64::from),
            mag: p.stats.mag_mean.map(f64::from),
            temp_c: f64::from(p.stats.temp_mean_c),
        })
        .collect();
    let limits = limitations(&fit.set, &pose_means)?;
    // The verdict is of what the board will apply, not of the model it cannot hold.
    judge_what_the_board_applies(&mut fit, &limits, session.budgets);
    observer.event(&SessionEvent::Fitted(&fit));
    let poor = fit.verdict.level == VerdictLevel::Poor;
    let echo = if poor && !options.accept_poor {
        observer.event(&SessionEvent::Note(format!(
            "the verdict is poor ({}); the packet was not sent (--accept-poor sends it anyway)",
            fit.verdict.reasons.join("; ")
        )));
        None
    } else if observer.confirm_write(&fit) {
        // A Ctrl-C at the prompt (or during the fit) means: do not send.
        options.interrupted()?;
        Some(client.send_calibration(&conversion.calibration, options.echo_timeout)?)
    } else {
        None
    };
    Ok(MotionCalOutcome {
        poses: collector.poses,
        mag_points: collector.mag_points,
        coverage,
        fit,
        conversion,
        limitations: limits,
        echo,
        readings: read,
        unified_lines: client.has_unified_lines(),
        malformed_lines: client.malformed_lines(),
        session_seconds: read as f64 / options.sample_rate_hz,
        wall_seconds: wall_start.elapsed().as_secs_f64(),
    })
}

/// Write the session's readings to `dir/readings.csv` (the recording format, for `imucal fit`),
/// creating `dir`; also the only file of a session that stopped before its fit.
pub fn save_motioncal_readings(
    readings: &[UnitSample],
    dir: &std::path::Path,
) -> std::io::Result<std::path::PathBuf> {
    std::fs::create_dir_all(dir)?;
    let path = dir.join(READINGS_FILE);
    std::fs::write(&path, super::save::readings_csv(readings))?;
    Ok(path)
}

/// The session's parameter file: the fitted set, its provenance naming the MotionCal sketch
/// board it was measured on, so that `imucal flash` does not write it to a board running
/// imucal's firmware (whose readings are another's) without being told to.
pub fn sketch_params_file(outcome: &MotionCalOutcome) -> crate::device::ParamsFile {
    use crate::device::params_json::Provenance;
    let mut file = crate::device::ParamsFile::from(&outcome.fit.set);
    file.provenance = Some(Provenance {
        tool: Provenance::tool(),
        source: format!(
            "a session on a MotionCal sketch board ({} `{}` lines)",
            outcome.readings,
            if outcome.unified_lines {
                "Uni:"
            } else {
                "Raw:"
            }
        ),
        device_id: None,
        methods: Default::default(),
        input_units: Default::default(),
        created_unix_s: outcome.fit.set.created_unix_s,
        board_firmware: Some(crate::device::MOTIONCAL_SKETCH.to_string()),
    });
    file
}

/// Name of the readings file in a sketch session's directory.
pub const READINGS_FILE: &str = "readings.csv";

/// Write the session directory: `params.json` (imucal's full model, for `imucal export`),
/// `motioncal.bin` (the packet as sent), `sensor_calib.json` (the library's flash file),
/// `poses.json`, `motioncal.json` (limitations, echo, verdict) and `readings.csv` (every
/// reading, [`save_motioncal_readings`]). Returns the files written.
pub fn save_motioncal_session(
    outcome: &MotionCalOutcome,
    readings: &[UnitSample],
    dir: &std::path::Path,
) -> std::io::Result<Vec<std::path::PathBuf>> {
    let mut written = vec![save_motioncal_readings(readings, dir)?];
    let mut write = |name: &str, bytes: &[u8]| -> std::io::Result<()> {
        let path = dir.join(name);
        std::fs::write(&path, bytes)?;
        written.push(path);
        Ok(())
    };
    write(
        "params.json",
        sketch_params_file(outcome).to_json().as_bytes(),
    )?;
    let cal = &outcome.conversion.calibration;
    let packet = crate::compat::encode_packet(cal).map_err(std::io::Error::other)?;
    write("motioncal.bin", &packet)?;
    write("sensor_calib.json", cal.to_sensor_calib_json().as_bytes())?;
    // The firmware session's format, so that `imucal analyze DIR` reads it too.
    write(
        "poses.json",
        super::save::poses_json(&outcome.poses).as_bytes(),
    )?;
    let text = |v: &serde_json::Value| serde_json::to_string_pretty(v).unwrap_or_default();
    let limits = &outcome.limitations;
    let summary = serde_json::json!({
        "verdict": outcome.fit.verdict,
        "readings": outcome.readings,
        "unified_lines": outcome.unified_lines,
        "malformed_lines": outcome.malformed_lines,
        "session_seconds": outcome.session_seconds,
        "poses": outcome.poses.len(),
        "magnetometer_regions_covered": outcome.coverage.covered(1),
        "adafruit": cal,
        "not_applied": limits.unapplied.iter().map(|t| format!("{}: {}", t.sensor, t.term)).collect::<Vec<_>>(),
        "cost_accel_mg": limits.accel_error_mg,
        "cost_gyro_dps": limits.gyro_error_dps,
        "cost_mag_pct_of_field": limits.mag_error_pct_of_field,
        "mag_rotation_deg": limits.mag_rotation_deg,
        "sent": outcome.echo.is_some(),
        "echo_max_difference": outcome.echo.as_ref().map(|e| e.max_difference),
    });
    write("motioncal.json", text(&summary).as_bytes())?;
    Ok(written)
}
