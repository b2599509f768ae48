//! Settings of a guided session, their defaults and why, and their checks.

use std::time::Duration;

use imucal_protocol::StillThresholds;

use super::error::SessionError;
use super::gyro_fit::GyroBudgets;
use super::solve::{self, Budgets, FieldSource};

/// Settings of a guided session. Durations marked "board time" are measured on the board's
/// clock; the others are wall-clock limits of the host.
#[derive(Debug, Clone, PartialEq)]
pub struct SessionOptions {
    /// Local gravity, m/s².
    pub gravity_mps2: f64,
    /// Local field magnitude, µT; `None` keeps the sensor's mean radius (see [`FieldSource`]).
    pub field_ut: Option<f64>,
    /// Where `field_ut` came from, as the session records it (unused without one).
    pub field_source: FieldSource,
    /// What counts as still, for the prompt and for the board's pose capture.
    pub thresholds: StillThresholds,
    /// Longest still time averaged per pose (board time); each hold ends sooner once its mean
    /// is good enough ([`super::hold`]).
    pub hold: Duration,
    /// Stillness seen by the host before a capture is requested, s (board time).
    pub settle_s: f64,
    /// Stillness window, s (board time).
    pub window_s: f64,
    /// Longest a single capture may take on the board.
    pub capture_timeout: Duration,
    /// Stream decimation while watching the board (1 = every sample, which the gyroscope's
    /// scale fit needs to integrate the moves between holds).
    pub decimation: u16,
    /// Longest wait for the next needed orientation.
    pub pose_timeout: Duration,
    /// Times the twelve positions are captured (at least 1). More rounds spread the poses over
    /// time and temperature, which the residual analysis needs to see a temperature effect of
    /// the accelerometer (its norm model leaves only three degrees of freedom in one round).
    pub rounds: usize,
    /// Most extra positions asked for when the covariance says they help (0 = never).
    pub max_extra_poses: usize,
    /// Most corner positions asked for to tilt the board about an axis the gyroscope's fit
    /// needs (0 = none; see `gyro_phase`).
    pub max_gyro_moves: usize,
    /// Longest wait for the extra positions before going on without them.
    pub extra_pose_timeout: Duration,
    /// Error budgets at rest (the verdict and the extra positions use them).
    pub budgets: Budgets,
    /// What the gyroscope's scale and misalignment must reach.
    pub gyro_budgets: GyroBudgets,
    /// Magnetometer samples needed at least.
    pub mag_min_samples: usize,
    /// Samples a direction region needs to count as covered.
    pub mag_min_per_region: usize,
    /// Fraction of regions accepted (with a note) when the magnetometer phase times out.
    pub mag_accept_fraction: f64,
    /// Longest magnetometer phase.
    pub mag_timeout: Duration,
    /// Most magnetometer samples fitted (pauses kept as one sample, then evenly thinned; 0 =
    /// all; [`crate::pipeline::methods::thin_redundant`]).
    pub mag_max_fit_samples: usize,
    /// Stillness (after the window first says still) not kept before the rest measurement, s
    /// (board time).
    pub rest_settle_s: f64,
    /// Length of each rest measurement, s (board time).
    pub rest_measure_s: f64,
    /// Longest wait for the board to come to rest.
    pub rest_timeout: Duration,
    /// Longest wait for the next sample batch of a running stream.
    pub read_timeout: Duration,
    /// Write a set past a refusing bound of every common part's datasheet
    /// ([`crate::history::part_limits`]) anyway (`--accept-outlier`).
    pub accept_outlier: bool,
}

impl Default for SessionOptions {
    /// Standard gravity, no field given; stillness limits 0.1 m/s² and 0.02 rad/s (a hand-held
    /// board sways by a few tenths of a degree at 0.2–0.5 Hz and trembles at ~10 Hz, which gives
    /// up to ≈0.04 m/s² and ≈0.013 rad/s of standard deviation over half a second on top of the
    /// sensor noise; a turn between positions is far above both); holds of at most 1.5 s, ended
    /// sooner by [`super::hold`]; 0.15 s of stillness seen before a capture (on top of the 0.5 s
    /// window that judges it); the full-rate stream while watching (the gyroscope's moves);
    /// 0.5 s of rest (on top of the 0.5 s window that judges it: the end of the turn into the
    /// rest, whose last slow rotation would bias the gyroscope's mean rate) before a 3 s
    /// "before" measurement in the same stream (which also gives the gyroscope's bias without a
    /// hand on the board); budgets 2 mg, 0.5 %, and 0.1 % / 0.05° for the gyroscope.
    fn default() -> Self {
        Self {
            gravity_mps2: solve::STANDARD_GRAVITY,
            field_ut: None,
            field_source: FieldSource::Given,
            thresholds: StillThresholds {
                accel_std_mps2: 0.1,
                gyro_std_rads: 0.02,
            },
            hold: Duration::from_millis(1500),
            settle_s: 0.15,
            window_s: 0.5,
            capture_timeout: Duration::from_secs(15),
            decimation: 1,
            pose_timeout: Duration::from_secs(180),
            rounds: 1,
            max_extra_poses: 4,
            max_gyro_moves: 4,
            extra_pose_timeout: Duration::from_secs(30),
            budgets: Budgets {
                accel_mg: 2.0,
                mag_pct: 0.5,
            },
            gyro_budgets: GyroBudgets::default(),
            mag_min_samples: 1500,
            mag_min_per_region: 10,
            mag_accept_fraction: 0.8,
            mag_timeout: Duration::from_secs(180),
            mag_max_fit_samples: 3000,
            rest_settle_s: 0.5,
            rest_measure_s: 3.0,
            rest_timeout: Duration::from_secs(120),
            read_timeout: Duration::from_secs(3),
            accept_outlier: false,
        }
    }
}

impl SessionOptions {
    pub(super) fn validate(&self) -> Result<(), SessionError> {
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
