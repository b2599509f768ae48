//! Settings of the still detector and why it can refuse.

/// Settings of the detector. [`StillOptions::default`] suits hand-placed poses at 50–1000 Hz.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StillOptions {
    /// Window length in seconds over which variance is computed.
    pub window_s: f64,
    /// Shortest hold kept, in seconds.
    pub min_hold_s: f64,
    /// Probability that a window of pure white noise is called moving (the test's size `α`).
    pub false_alarm: f64,
    /// Percentile (0–1) of windowed variances taken as the quietest stretch.
    pub noise_percentile: f64,
    /// Factor on the threshold for noise that is not white; 1 is the pure χ² test. `None`
    /// chooses it from the data (Otsu's method, within [`MIN_MARGIN`, `MAX_MARGIN`]).
    pub margin: Option<f64>,
    /// Runs separated by at most this many seconds are merged when their means agree.
    pub merge_gap_s: f64,
    /// Holds whose gravity directions are within this angle (degrees) count as one direction.
    pub direction_angle_deg: f64,
}

impl Default for StillOptions {
    fn default() -> Self {
        Self {
            window_s: 0.5,
            min_hold_s: 1.0,
            false_alarm: 1e-3,
            noise_percentile: 0.1,
            margin: None,
            merge_gap_s: 0.5,
            direction_angle_deg: 10.0,
        }
    }
}

/// Smallest automatic margin: below it, slow wander of real sensors over a window splits holds
/// (seen on the Xsens data at 2: 40 pieces instead of 38 holds).
pub const MIN_MARGIN: f64 = 4.0;
/// Largest automatic margin: window variance 256/3 ≈ 85 times the noise, i.e. a standard
/// deviation about 9 times the noise, above which slow hand motion would pass as still.
pub const MAX_MARGIN: f64 = 256.0;

/// Why still intervals could not be found.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StillError {
    /// The recording has neither an accelerometer nor a gyroscope (nor a magnetometer on the
    /// same rows) to detect stillness with.
    #[error("`{0}` has no accelerometer or gyroscope columns to detect still intervals with")]
    NoSensor(String),
    /// Times are row numbers, so windows in seconds cannot be formed nor holds timed.
    #[error("`{0}` has no `t_s` column and no sample rate was given; still intervals are found and timed in seconds, so pass the rate (e.g. `--rate 100`) or add a `t_s` column")]
    NoRate(String),
    /// The relative test found still stretches, but in every one the gyroscope varies by more
    /// than a board at rest can ([`super::MAX_STILL_GYRO_STD_DPS`]).
    #[error("the gyroscope of `{path}` never rests: even in its quietest window it varies by {quietest_dps:.1} °/s (reading the data as {unit}), more than the {bound_dps} °/s of sensor noise a board at rest shows; either the board moved throughout (hold it still for 2–3 s in each orientation) or the gyroscope is not in {unit} (pass --gyro-unit {other_units} as the data are){window_note}")]
    NeverAtRest {
        /// The recording.
        path: String,
        /// Largest per-axis standard deviation of the gyroscope in its quietest window, °/s.
        quietest_dps: f64,
        /// The declared gyroscope unit.
        unit: &'static str,
        /// The `--gyro-unit` values other than the declared one, e.g. `rads or counts`.
        other_units: &'static str,
        /// The rest bound, °/s.
        bound_dps: f64,
        /// When the window is longer than the shortest hold kept, that a window longer than the
        /// holds sees every one with a move in it (empty otherwise).
        window_note: String,
    },
    /// An option is out of range.
    #[error("still-detection option {name} = {value} is out of range ({expected})")]
    BadOption {
        /// Option name.
        name: &'static str,
        /// Value given.
        value: f64,
        /// What is allowed.
        expected: &'static str,
    },
}
