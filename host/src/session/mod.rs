//! The guided calibration session: which orientations are still needed, live stillness, the
//! magnetometer's sphere coverage, when enough data is in, fitting, writing, verifying, and the
//! before/after check at rest. The user interface is the caller's: it receives
//! [`SessionEvent`]s through a [`SessionObserver`] and is asked before the parameters are written.
//!
//! Sequence ([`run_session`]):
//! 1. Positions: a raw stream (decimated) gives the up direction and stillness
//!    ([`motion::MotionMonitor`]); when the board is still in one of the twelve positions of
//!    seed 003 ([`targets::twelve_positions`]) that is still needed, the stream stops and the
//!    board averages a pose (`CapturePose`). Poses may come in any order. With
//!    [`SessionOptions::rounds`] above 1 the twelve are captured that many times over. Afterwards, if the
//!    covariance of the accelerometer fit says the expected `|a|` error exceeds a quarter of the
//!    budget, up to four corner positions are asked for as well ([`targets::corner_positions`]).
//! 2. Magnetometer: raw samples while the user turns the board, until every one of 26 direction
//!    regions holds enough samples ([`coverage`]).
//! 3. Rest: once the board lies still, raw samples give the "before" errors.
//! 4. Fit with the library's default methods ([`solve::fit_session`]), show the result with its
//!    uncertainties and verdict, write the set, commit, read it back and compare (CRC and every
//!    value), then stream calibrated samples at rest for the "after" errors.
//!
//!
//! Afterwards [`extend`] can run the residual analysis on the poses and add the effects it
//! accepts (temperature polynomial of the bias, …) to the set as the firmware's extended terms.
//!
//! Every request has the device client's timeouts and retries; each phase has its own wall-clock
//! limit, and every failure is a [`SessionError`] sentence.

pub mod coverage;
mod error;
pub mod extend;
pub mod motion;
pub mod rest;
pub mod save;
pub mod solve;
pub mod targets;

use std::io::{Read, Write};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use imucal_protocol::{ErrorCode, ParamStatus, StillThresholds, StreamKind};

use crate::device::{
    DeviceClient, DeviceError, PoseProgress, PoseRequest, SampleChunk, UnitSample,
};
use crate::fit::norm_lm::fit_accel_lm;
use crate::fit::{Pose, Vec3};

pub use coverage::{Coverage, REGIONS};
pub use error::SessionError;
pub use extend::{analyse_poses, extend_set, ExtendedSet};
pub use motion::{MotionMonitor, MotionState};
pub use rest::{rest_errors, RestErrors};
pub use save::{load_poses, save_session, summary, SessionSummary};
pub use solve::{
    fit_session, Budgets, CapturedPose, FieldSource, SessionFit, Uncertainties, Verdict,
    VerdictLevel,
};
pub use targets::{Target, MATCH_ANGLE_DEG};

/// Settings of a guided session. Durations marked "board time" are measured on the board's
/// clock; the others are wall-clock limits of the host.
#[derive(Debug, Clone, PartialEq)]
pub struct SessionOptions {
    /// Local gravity, m/s².
    pub gravity_mps2: f64,
    /// Local field magnitude, µT; `None` keeps the sensor's mean radius (see [`FieldSource`]).
    pub field_ut: Option<f64>,
    /// What counts as still, for the prompt and for the board's pose capture.
    pub thresholds: StillThresholds,
    /// Still data averaged per pose (board time).
    pub hold: Duration,
    /// Stillness seen by the host before a capture is requested, s (board time).
    pub settle_s: f64,
    /// Stillness window, s (board time).
    pub window_s: f64,
    /// Longest a single capture may take on the board.
    pub capture_timeout: Duration,
    /// Stream decimation while watching the board (1 = every sample).
    pub decimation: u16,
    /// Longest wait for the next needed orientation.
    pub pose_timeout: Duration,
    /// Times the twelve positions are captured (at least 1). More rounds spread the poses over
    /// time and temperature, which the residual analysis needs to see a temperature effect of
    /// the accelerometer (its norm model leaves only three degrees of freedom in one round).
    pub rounds: usize,
    /// Most extra positions asked for when the covariance says they help (0 = never).
    pub max_extra_poses: usize,
    /// Longest wait for the extra positions before going on without them.
    pub extra_pose_timeout: Duration,
    /// Error budgets at rest (the verdict and the extra positions use them).
    pub budgets: Budgets,
    /// Magnetometer samples needed at least.
    pub mag_min_samples: usize,
    /// Samples a direction region needs to count as covered.
    pub mag_min_per_region: usize,
    /// Fraction of regions accepted (with a note) when the magnetometer phase times out.
    pub mag_accept_fraction: f64,
    /// Longest magnetometer phase.
    pub mag_timeout: Duration,
    /// Most magnetometer samples fitted (evenly thinned; 0 = all).
    pub mag_max_fit_samples: usize,
    /// Stillness needed before the rest measurement, s (board time).
    pub rest_settle_s: f64,
    /// Length of each rest measurement, s (board time).
    pub rest_measure_s: f64,
    /// Longest wait for the board to come to rest.
    pub rest_timeout: Duration,
    /// Longest wait for the next sample batch of a running stream.
    pub read_timeout: Duration,
}

impl Default for SessionOptions {
    /// Standard gravity, no field given; stillness limits 0.1 m/s² and 0.02 rad/s (a hand-held
    /// board sways by a few tenths of a degree at 0.2–0.5 Hz and trembles at ~10 Hz, which gives
    /// up to ≈0.04 m/s² and ≈0.013 rad/s of standard deviation over half a second on top of the
    /// sensor noise; a turn between positions is far above both); 1.5 s holds; budgets 2 mg and
    /// 0.5 %.
    fn default() -> Self {
        Self {
            gravity_mps2: solve::STANDARD_GRAVITY,
            field_ut: None,
            thresholds: StillThresholds {
                accel_std_mps2: 0.1,
                gyro_std_rads: 0.02,
            },
            hold: Duration::from_millis(1500),
            settle_s: 0.3,
            window_s: 0.5,
            capture_timeout: Duration::from_secs(15),
            decimation: 2,
            pose_timeout: Duration::from_secs(180),
            rounds: 1,
            max_extra_poses: 4,
            extra_pose_timeout: Duration::from_secs(30),
            budgets: Budgets {
                accel_mg: 2.0,
                mag_pct: 0.5,
            },
            mag_min_samples: 1500,
            mag_min_per_region: 10,
            mag_accept_fraction: 0.8,
            mag_timeout: Duration::from_secs(180),
            mag_max_fit_samples: 3000,
            rest_settle_s: 2.0,
            rest_measure_s: 3.0,
            rest_timeout: Duration::from_secs(120),
            read_timeout: Duration::from_secs(3),
        }
    }
}

impl SessionOptions {
    fn validate(&self) -> Result<(), SessionError> {
        let positive = |name: &'static str, value: f64| {
            if value.is_finite() && value > 0.0 {
                Ok(())
            } else {
                Err(SessionError::InvalidOption {
                    name,
                    value,
                    requirement: "a finite number greater than zero",
                })
            }
        };
        positive("gravity (m/s²)", self.gravity_mps2)?;
        if let Some(field) = self.field_ut {
            positive("field (µT)", field)?;
        }
        positive(
            "accelerometer stillness limit (m/s²)",
            f64::from(self.thresholds.accel_std_mps2),
        )?;
        positive(
            "gyroscope stillness limit (rad/s)",
            f64::from(self.thresholds.gyro_std_rads),
        )?;
        positive("hold (s)", self.hold.as_secs_f64())?;
        positive("stillness window (s)", self.window_s)?;
        positive("rest measurement (s)", self.rest_measure_s)?;
        positive("decimation", f64::from(self.decimation))?;
        if self.rounds == 0 {
            return Err(SessionError::InvalidOption {
                name: "rounds of the twelve positions",
                value: 0.0,
                requirement: "at least 1",
            });
        }
        if !(0.0..=1.0).contains(&self.mag_accept_fraction) {
            return Err(SessionError::InvalidOption {
                name: "accepted magnetometer coverage",
                value: self.mag_accept_fraction,
                requirement: "a fraction between 0 and 1",
            });
        }
        Ok(())
    }
}

/// Which part of the session a magnetometer sample was taken in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Phase {
    /// Moving between and holding the positions.
    Positions,
    /// Turning the board in all directions.
    Tumble,
    /// Waiting for the board to lie still.
    Rest,
}

impl Phase {
    /// Name as written to files.
    pub fn name(self) -> &'static str {
        match self {
            Phase::Positions => "positions",
            Phase::Tumble => "tumble",
            Phase::Rest => "rest",
        }
    }
}

/// One raw magnetometer reading of the stream.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MagSample {
    /// Board time, s.
    pub t_s: f64,
    /// Reading, µT (nominal units).
    pub mag: [f64; 3],
    /// Die temperature, °C.
    pub temp_c: f64,
    /// When it was taken.
    pub phase: Phase,
}

/// What the session reports while it runs.
#[derive(Debug, Clone)]
pub enum SessionEvent<'a> {
    /// The next orientation to hold.
    Prompt {
        /// The orientation.
        target: &'a Target,
        /// Poses captured so far.
        captured: usize,
        /// Poses wanted in this phase.
        total: usize,
    },
    /// The latest stillness window while watching for a position.
    Motion {
        /// Stillness and up direction.
        state: MotionState,
        /// The position the board is in, if any.
        at: Option<&'a Target>,
        /// Whether that position is still needed.
        needed: bool,
        /// Stillness needed before the capture starts, s.
        settle_s: f64,
    },
    /// The board is averaging a pose.
    Capturing {
        /// The position.
        target: &'a Target,
        /// Progress reported by the device client.
        progress: PoseProgress,
    },
    /// A pose was captured.
    Captured {
        /// The position.
        target: &'a Target,
        /// Samples averaged.
        samples: u32,
        /// Poses captured so far.
        captured: usize,
        /// Poses wanted in this phase.
        total: usize,
    },
    /// A capture did not succeed; the session keeps watching.
    CaptureFailed {
        /// The position.
        target: &'a Target,
        /// What happened, as a sentence.
        reason: String,
    },
    /// A sentence worth showing (extra positions decided, phase accepted with less data, …).
    Note(String),
    /// The magnetometer phase begins.
    MagPrompt,
    /// Magnetometer coverage so far.
    MagCoverage {
        /// Regions with enough samples.
        covered: usize,
        /// All regions.
        regions: usize,
        /// Samples so far in this phase.
        samples: usize,
        /// Names of the regions still short of samples.
        empty: Vec<String>,
    },
    /// The board should be put down.
    RestPrompt,
    /// Stillness while waiting for rest.
    Resting {
        /// Still time so far, s.
        still_for_s: f64,
        /// Still time needed, s.
        needed_s: f64,
    },
    /// A rest measurement is being taken.
    Measuring {
        /// Raw ("before") or calibrated ("after").
        kind: StreamKind,
    },
    /// The fit is done (shown before writing).
    Fitted(&'a SessionFit),
    /// The set is written, committed, read back and matches.
    Verified(ParamStatus),
}

/// The caller's user interface of a session.
pub trait SessionObserver {
    /// Something happened.
    fn event(&mut self, event: &SessionEvent<'_>);

    /// Whether to write `fit` to the board (default: yes, for unattended use).
    fn confirm_write(&mut self, fit: &SessionFit) -> bool {
        let _ = fit;
        true
    }
}

/// An observer that ignores every event and always writes.
#[derive(Debug, Clone, Copy, Default)]
pub struct Unattended;

impl SessionObserver for Unattended {
    fn event(&mut self, _event: &SessionEvent<'_>) {}
}

/// Everything a session produced.
#[derive(Debug, Clone)]
pub struct SessionOutcome {
    /// The port.
    pub port: String,
    /// The board's id.
    pub device_id: String,
    /// Every captured pose, in capture order.
    pub poses: Vec<CapturedPose>,
    /// Why extra positions were or were not asked for.
    pub extra_positions_note: String,
    /// Every raw magnetometer sample streamed.
    pub mag_samples: Vec<MagSample>,
    /// Coverage of the magnetometer phase.
    pub coverage: Coverage,
    /// The fit.
    pub fit: SessionFit,
    /// Whether the set was written (false when the write was declined).
    pub written: bool,
    /// Whether the set read back from the board matched (CRC and every value).
    pub verified: bool,
    /// The store's state after the commit.
    pub param_status: Option<ParamStatus>,
    /// Errors at rest before calibration (raw readings).
    pub before: RestErrors,
    /// Errors at rest after calibration (the board's calibrated stream).
    pub after: Option<RestErrors>,
    /// Board time from the first prompt to the verified write, s (simulated time on a
    /// simulated board).
    pub session_seconds: f64,
    /// Wall time of the same span, s.
    pub wall_seconds: f64,
    /// Calibrated samples per second of board time during the "after" measurement.
    pub stream_rate_hz: f64,
    /// Samples lost in transit over the whole session.
    pub lost_samples: u64,
}

struct Runner<'a, L: Read + Write> {
    client: &'a mut DeviceClient<L>,
    options: &'a SessionOptions,
    observer: &'a mut dyn SessionObserver,
    monitor: MotionMonitor,
    mag: Vec<MagSample>,
}

fn unix_now() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs())
}

fn names(targets: &[&Target]) -> String {
    targets
        .iter()
        .map(|t| t.name.as_str())
        .collect::<Vec<_>>()
        .join(", ")
}

impl<L: Read + Write> Runner<'_, L> {
    fn read_chunk(&mut self) -> Result<SampleChunk, SessionError> {
        match self.client.next_samples(self.options.read_timeout)? {
            Some(chunk) => Ok(chunk),
            None => Err(SessionError::NoSamples {
                port: self.client.port_name().to_string(),
                waited_s: self.options.read_timeout.as_secs_f64(),
            }),
        }
    }

    fn record_mag(&mut self, sample: &UnitSample, phase: Phase) {
        self.mag.push(MagSample {
            t_s: sample.t_s,
            mag: sample.mag,
            temp_c: sample.temp_c,
            phase,
        });
    }

    fn start_watching(&mut self) -> Result<(), SessionError> {
        self.monitor.reset();
        self.client
            .start_stream(StreamKind::Raw, self.options.decimation)?;
        Ok(())
    }

    /// Capture every target of `targets` not yet in `captured`. Returns `false` when
    /// `timeout` passed without progress and `give_up_quietly` is set.
    fn capture_targets(
        &mut self,
        targets: &[Target],
        captured: &mut Vec<CapturedPose>,
        timeout: Duration,
        give_up_quietly: bool,
    ) -> Result<bool, SessionError> {
        let total = captured.len()
            + targets
                .iter()
                .filter(|t| !captured.iter().any(|c| c.target.index == t.index))
                .count();
        let request = PoseRequest {
            min_still: self.options.hold,
            thresholds: self.options.thresholds,
            timeout: self.options.capture_timeout,
        };
        self.start_watching()?;
        let mut last_progress = Instant::now();
        let mut prompted = None;
        // The capture starts right after the last watched sample.
        let mut last_sample_s = 0.0;
        loop {
            let needed: Vec<&Target> = targets
                .iter()
                .filter(|t| !captured.iter().any(|c| c.target.index == t.index))
                .collect();
            let Some(next) = needed.first() else {
                return Ok(true);
            };
            if prompted != Some(next.index) {
                self.observer.event(&SessionEvent::Prompt {
                    target: next,
                    captured: captured.len(),
                    total,
                });
                prompted = Some(next.index);
            }
            if last_progress.elapsed() > timeout {
                self.client.stop_stream()?;
                if give_up_quietly {
                    return Ok(false);
                }
                return Err(SessionError::NoProgress {
                    port: self.client.port_name().to_string(),
                    waited_s: timeout.as_secs_f64(),
                    missing: names(&needed),
                });
            }
            let chunk = self.read_chunk()?;
            let mut latest = None;
            for sample in &chunk.samples {
                self.record_mag(sample, Phase::Positions);
                last_sample_s = sample.t_s;
                if let Some(state) = self.monitor.push(sample) {
                    latest = Some(state);
                }
            }
            let Some(state) = latest else {
                continue;
            };
            let at = targets::target_at(targets, &state.up);
            let wanted = at.filter(|t| needed.iter().any(|n| n.index == t.index));
            self.observer.event(&SessionEvent::Motion {
                state,
                at,
                needed: wanted.is_some(),
                settle_s: self.options.settle_s,
            });
            let Some(target) = wanted else {
                continue;
            };
            if !(state.still && state.still_for_s >= self.options.settle_s) {
                continue;
            }
            self.client.stop_stream()?;
            let observer = &mut *self.observer;
            let result = self.client.capture_pose(&request, &mut |progress| {
                observer.event(&SessionEvent::Capturing {
                    target,
                    progress: *progress,
                });
            });
            match result {
                Ok(stats) => {
                    let up = Vec3::from(stats.accel_mean.map(f64::from));
                    let landed = targets::target_at(targets, &up)
                        .filter(|t| !captured.iter().any(|c| c.target.index == t.index));
                    match landed {
                        Some(actual) => {
                            captured.push(CapturedPose {
                                target: actual.clone(),
                                stats,
                                t_s: last_sample_s + 0.5 * f64::from(stats.duration_ms) * 1e-3,
                            });
                            last_progress = Instant::now();
                            self.observer.event(&SessionEvent::Captured {
                                target: actual,
                                samples: stats.n,
                                captured: captured.len(),
                                total,
                            });
                        }
                        None => self.observer.event(&SessionEvent::CaptureFailed {
                            target,
                            reason: "the board ended up in another orientation during the \
                                     capture; the pose was discarded"
                                .into(),
                        }),
                    }
                }
                Err(DeviceError::Device { code, .. })
                    if matches!(
                        code,
                        ErrorCode::NotStill | ErrorCode::Timeout | ErrorCode::Saturated
                    ) =>
                {
                    let reason = match code {
                        ErrorCode::Saturated => {
                            "a reading hit the sensor's range; hold the board without knocking it"
                        }
                        _ => "the board did not stay still long enough; hold it steadier",
                    };
                    self.observer.event(&SessionEvent::CaptureFailed {
                        target,
                        reason: reason.into(),
                    });
                }
                Err(other) => return Err(other.into()),
            }
            self.start_watching()?;
        }
    }

    /// After the twelve: ask for corner positions if the covariance says they help.
    fn extra_positions(
        &mut self,
        captured: &mut Vec<CapturedPose>,
    ) -> Result<String, SessionError> {
        let target_mg = self.options.budgets.accel_mg / 4.0;
        let mg = 1000.0 / solve::STANDARD_GRAVITY;
        let poses: Vec<Pose> = captured
            .iter()
            .map(|p| solve::pose_of(&p.stats, solve::accel_of))
            .collect();
        let fit = fit_accel_lm(&poses, self.options.gravity_mps2)?;
        let Some(predicted) = solve::max_norm_sigma(&fit).map(|s| s * mg) else {
            return Ok(
                "the accelerometer fit gave no covariance, so the benefit of extra positions \
                 could not be judged; none were asked for"
                    .into(),
            );
        };
        if predicted <= target_mg {
            return Ok(format!(
                "{} positions give an expected |a| error of {predicted:.3} mg (1σ), within the \
                 {target_mg:.2} mg target (a quarter of the {:.1} mg budget); no extra positions \
                 needed",
                captured.len(),
                self.options.budgets.accel_mg
            ));
        }
        if self.options.max_extra_poses == 0 {
            return Ok(format!(
                "the expected |a| error is {predicted:.3} mg (1σ), above the {target_mg:.2} mg \
                 target, but extra positions are switched off"
            ));
        }
        let mut corners = targets::corner_positions(captured.len().max(12));
        corners.sort_by(|a, b| {
            let sa = solve::norm_sigma_at(&fit, &a.up).unwrap_or(0.0);
            let sb = solve::norm_sigma_at(&fit, &b.up).unwrap_or(0.0);
            sb.total_cmp(&sa)
        });
        corners.truncate(self.options.max_extra_poses);
        self.observer.event(&SessionEvent::Note(format!(
            "the expected |a| error is {predicted:.3} mg (1σ), above the {target_mg:.2} mg \
             target: {} more positions will help ({})",
            corners.len(),
            names(&corners.iter().collect::<Vec<_>>())
        )));
        let before = captured.len();
        let complete =
            self.capture_targets(&corners, captured, self.options.extra_pose_timeout, true)?;
        if complete {
            self.client.stop_stream()?;
        }
        let added = captured.len() - before;
        Ok(if complete {
            format!(
                "the expected |a| error with 12 positions was {predicted:.3} mg (1σ), above the \
                 {target_mg:.2} mg target; {added} corner positions were added"
            )
        } else {
            format!(
                "the expected |a| error with 12 positions was {predicted:.3} mg (1σ), above the \
                 {target_mg:.2} mg target; {added} of {} corner positions were held before the \
                 {:.0} s limit, so the fit goes on with what there is",
                corners.len(),
                self.options.extra_pose_timeout.as_secs_f64()
            )
        })
    }

    fn magnetometer(&mut self) -> Result<Coverage, SessionError> {
        self.observer.event(&SessionEvent::MagPrompt);
        self.start_watching()?;
        let start = Instant::now();
        let first = self.mag.len();
        let mut last_update = first;
        let regions = REGIONS;
        let needed_at_timeout = (self.options.mag_accept_fraction * regions as f64).ceil() as usize;
        loop {
            let chunk = self.read_chunk()?;
            for sample in &chunk.samples {
                self.record_mag(sample, Phase::Tumble);
            }
            let count = self.mag.len() - first;
            let timed_out = start.elapsed() > self.options.mag_timeout;
            if self.mag.len() - last_update < 100 && !timed_out {
                continue;
            }
            last_update = self.mag.len();
            let all: Vec<Vec3> = self.mag.iter().map(|m| Vec3::from(m.mag)).collect();
            let Some(centre) = coverage::sphere_centre(&all) else {
                if timed_out {
                    return Err(SessionError::MagCoverage {
                        waited_s: start.elapsed().as_secs_f64(),
                        covered: 0,
                        needed: needed_at_timeout,
                        regions,
                        empty: "all".into(),
                    });
                }
                continue;
            };
            let tumble = all.get(first..).unwrap_or_default();
            let cover = Coverage::of(tumble, &centre);
            let covered = cover.covered(self.options.mag_min_per_region);
            let empty = cover.empty_regions(self.options.mag_min_per_region);
            self.observer.event(&SessionEvent::MagCoverage {
                covered,
                regions,
                samples: count,
                empty: empty.clone(),
            });
            if covered == regions && count >= self.options.mag_min_samples {
                self.client.stop_stream()?;
                return Ok(cover);
            }
            if timed_out {
                self.client.stop_stream()?;
                if covered >= needed_at_timeout && count >= self.options.mag_min_samples {
                    self.observer.event(&SessionEvent::Note(format!(
                        "the magnetometer phase ended at its time limit with {covered} of \
                         {regions} directions covered (empty: {}); the fit goes on with them",
                        empty.join(", ")
                    )));
                    return Ok(cover);
                }
                return Err(SessionError::MagCoverage {
                    waited_s: start.elapsed().as_secs_f64(),
                    covered,
                    needed: needed_at_timeout,
                    regions,
                    empty: empty.join(", "),
                });
            }
        }
    }

    fn wait_for_rest(&mut self) -> Result<(), SessionError> {
        self.observer.event(&SessionEvent::RestPrompt);
        self.start_watching()?;
        let start = Instant::now();
        loop {
            if start.elapsed() > self.options.rest_timeout {
                self.client.stop_stream()?;
                return Err(SessionError::NotAtRest {
                    port: self.client.port_name().to_string(),
                    needed_s: self.options.rest_settle_s,
                    waited_s: self.options.rest_timeout.as_secs_f64(),
                });
            }
            let chunk = self.read_chunk()?;
            let mut latest = None;
            for sample in &chunk.samples {
                self.record_mag(sample, Phase::Rest);
                if let Some(state) = self.monitor.push(sample) {
                    latest = Some(state);
                }
            }
            if let Some(state) = latest {
                self.observer.event(&SessionEvent::Resting {
                    still_for_s: state.still_for_s,
                    needed_s: self.options.rest_settle_s,
                });
                if state.still_for_s >= self.options.rest_settle_s {
                    self.client.stop_stream()?;
                    return Ok(());
                }
            }
        }
    }

    /// Stream `kind` at full rate for `rest_measure_s` of board time.
    fn measure(&mut self, kind: StreamKind) -> Result<Vec<UnitSample>, SessionError> {
        self.observer.event(&SessionEvent::Measuring { kind });
        stream_for(
            self.client,
            kind,
            self.options.rest_measure_s,
            self.options.read_timeout,
        )
    }

    fn board_time_s(&mut self) -> Result<f64, SessionError> {
        Ok(self.client.status()?.uptime_ms as f64 * 1e-3)
    }
}

/// Stream `kind` at full rate until `seconds` of board time are covered, then stop the stream;
/// `read_timeout` is the longest wait for each sample batch.
pub fn stream_for<L: Read + Write>(
    client: &mut DeviceClient<L>,
    kind: StreamKind,
    seconds: f64,
    read_timeout: Duration,
) -> Result<Vec<UnitSample>, SessionError> {
    client.start_stream(kind, 1)?;
    let mut samples: Vec<UnitSample> = Vec::new();
    let result = loop {
        match client.next_samples(read_timeout) {
            Ok(Some(chunk)) => samples.extend_from_slice(&chunk.samples),
            Ok(None) => {
                break Err(SessionError::NoSamples {
                    port: client.port_name().to_string(),
                    waited_s: read_timeout.as_secs_f64(),
                })
            }
            Err(e) => break Err(e.into()),
        }
        let span = match (samples.first(), samples.last()) {
            (Some(a), Some(b)) => b.t_s - a.t_s,
            _ => 0.0,
        };
        // NaN (a non-finite request) ends the stream at once instead of never.
        if span >= seconds || seconds.is_nan() {
            break Ok(());
        }
    };
    let stopped = client.stop_stream();
    result?;
    stopped?;
    Ok(samples)
}

/// Run a whole guided session on a connected board (see the module documentation).
pub fn run_session<L: Read + Write>(
    client: &mut DeviceClient<L>,
    options: &SessionOptions,
    observer: &mut dyn SessionObserver,
) -> Result<SessionOutcome, SessionError> {
    options.validate()?;
    let mut runner = Runner {
        monitor: MotionMonitor::new(options.window_s, options.thresholds),
        client,
        options,
        observer,
        mag: Vec::new(),
    };
    // A stream left running by an earlier program would mix into the replies' timing.
    runner.client.stop_stream()?;
    let board_start_s = runner.board_time_s()?;
    let wall_start = Instant::now();

    let mut captured = Vec::new();
    let twelve = targets::twelve_positions();
    for round in 1..=options.rounds {
        if options.rounds > 1 {
            runner.observer.event(&SessionEvent::Note(format!(
                "round {round} of {}: the twelve positions again",
                options.rounds
            )));
        }
        // Each round captures every position once more; poses of earlier rounds do not count.
        let mut this_round = Vec::new();
        runner.capture_targets(&twelve, &mut this_round, options.pose_timeout, false)?;
        runner.client.stop_stream()?;
        captured.append(&mut this_round);
    }
    let extra_positions_note = runner.extra_positions(&mut captured)?;
    runner
        .observer
        .event(&SessionEvent::Note(extra_positions_note.clone()));

    let coverage = runner.magnetometer()?;
    runner.wait_for_rest()?;
    let raw_rest = runner.measure(StreamKind::Raw)?;

    let tumble: Vec<Vec3> = runner
        .mag
        .iter()
        .filter(|m| m.phase == Phase::Tumble)
        .map(|m| Vec3::from(m.mag))
        .collect();
    let fit = fit_session(
        &captured,
        &solve::thin(&tumble, options.mag_max_fit_samples),
        options.gravity_mps2,
        options.field_ut,
        options.budgets,
        unix_now(),
    )?;
    let no_samples = || SessionError::NoSamples {
        port: runner.client.port_name().to_string(),
        waited_s: options.read_timeout.as_secs_f64(),
    };
    let before = rest_errors(&raw_rest, fit.gravity_mps2, fit.field_ut).ok_or_else(no_samples)?;
    runner.observer.event(&SessionEvent::Fitted(&fit));

    let mut outcome = SessionOutcome {
        port: runner.client.port_name().to_string(),
        device_id: runner.client.welcome().device_id.to_string(),
        poses: captured,
        extra_positions_note,
        mag_samples: Vec::new(),
        coverage,
        written: false,
        verified: false,
        param_status: None,
        before,
        after: None,
        session_seconds: 0.0,
        wall_seconds: 0.0,
        stream_rate_hz: 0.0,
        lost_samples: 0,
        fit,
    };
    if runner.observer.confirm_write(&outcome.fit) {
        let status = runner.client.write_params_verified(&outcome.fit.set)?;
        outcome.written = true;
        outcome.verified = true;
        outcome.param_status = Some(status);
        runner.observer.event(&SessionEvent::Verified(status));
        let board_end_s = runner.board_time_s()?;
        outcome.wall_seconds = wall_start.elapsed().as_secs_f64();
        // A board that restarted in between has a younger clock; fall back to wall time.
        outcome.session_seconds = if board_end_s >= board_start_s {
            board_end_s - board_start_s
        } else {
            outcome.wall_seconds
        };
        let calibrated = runner.measure(StreamKind::Calibrated)?;
        let after = rest_errors(&calibrated, outcome.fit.gravity_mps2, outcome.fit.field_ut)
            .ok_or_else(|| SessionError::NoSamples {
                port: outcome.port.clone(),
                waited_s: options.read_timeout.as_secs_f64(),
            })?;
        outcome.stream_rate_hz = if after.duration_s > 0.0 {
            (after.samples.saturating_sub(1)) as f64 / after.duration_s
        } else {
            0.0
        };
        outcome.after = Some(after);
    } else {
        outcome.wall_seconds = wall_start.elapsed().as_secs_f64();
        outcome.session_seconds = runner.board_time_s()? - board_start_s;
    }
    outcome.lost_samples = runner.client.stats().lost_samples;
    outcome.mag_samples = std::mem::take(&mut runner.mag);
    Ok(outcome)
}
