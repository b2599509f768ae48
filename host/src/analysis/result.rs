//! What the residual analysis finds: per sensor the base and final fits' residuals against the
//! noise floor, every candidate effect's verdict and coefficients, and the extended terms in
//! the firmware's form.

use imucal_protocol::{BiasTemperature, Nonlinearity, SensorCalibration};

use super::effects::EffectKind;
use super::extended_fit::{physical_factor, BaseKind, ExtendedFit, Problem};
use crate::fit::{Calibration, FitError};
use crate::pipeline::observations::Observation;
use crate::recording::Sensor;
use crate::stats::chi_square::ChiSquareTest;

/// Why a sensor could not be analysed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AnalysisError {
    /// The recording does not have the sensor.
    #[error("the recording has no {0} data; analyse another sensor")]
    NoSensor(&'static str),
    /// Too few observations for the base model and a held-out test.
    #[error("only {found} usable {what} for the {sensor}; record at least {needed} to analyse its residual")]
    TooFewObservations {
        /// Sensor name.
        sensor: &'static str,
        /// What was counted.
        what: &'static str,
        /// Number found.
        found: usize,
        /// Number needed.
        needed: usize,
    },
    /// The input checks refused the sensor (the sentence names cause and fix).
    #[error("{0}")]
    Refused(String),
    /// The base fit failed.
    #[error("the base {sensor} fit failed: {source}")]
    BaseFit {
        /// Sensor name.
        sensor: &'static str,
        /// Why.
        source: FitError,
    },
    /// The base model cannot be evaluated held out although there are enough observations:
    /// fewer than two of them can be left out with the rest still determining it.
    #[error(
        "the {sensor} base model {model} ({unknowns} unknowns) cannot be tested on poses it was \
         not fitted on: the poses show {distinct} distinct orientation(s) (within 5°), and \
         fewer than two of them can be left out with the others still determining the model; \
         record poses in more directions (e.g. the twelve positions)"
    )]
    Refit {
        /// Sensor name.
        sensor: &'static str,
        /// Base model name.
        model: String,
        /// Unknowns of the base model.
        unknowns: usize,
        /// Distinct orientations among the poses.
        distinct: usize,
    },
}

/// Settings of the analysis (the input options of `imucal fit`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AnalysisOptions {
    /// Local gravity, m/s².
    pub gravity: f64,
    /// Local field magnitude (µT), or `None` to normalise to 1.
    pub field_ut: Option<f64>,
    /// Gyroscope data unit to rad/s.
    pub gyro_scale: f64,
    /// Whether `gyro_scale` is known; without it the gyroscope is analysed in counts.
    pub gyro_scale_known: bool,
    /// Magnetometer window length (samples) when it has too few still poses.
    pub mag_window: usize,
    /// Largest number of magnetometer windows.
    pub max_mag_windows: usize,
    /// Geodetic latitude (degrees), when known: the gyroscope's rest model then includes the
    /// vertical component of the Earth's rotation (see [`super::earth_rate`]).
    pub latitude_deg: Option<f64>,
}

impl Default for AnalysisOptions {
    fn default() -> Self {
        Self {
            gravity: crate::recording::STANDARD_GRAVITY,
            field_ut: None,
            gyro_scale: 1.0,
            gyro_scale_known: true,
            mag_window: crate::pipeline::observations::MAG_WINDOW_SAMPLES,
            max_mag_windows: crate::pipeline::observations::MAX_MAG_WINDOWS,
            latitude_deg: None,
        }
    }
}

/// One coefficient in physical units.
#[derive(Debug, Clone, PartialEq)]
pub struct Coefficient {
    /// Name, e.g. `c1_x`.
    pub name: String,
    /// Value.
    pub value: f64,
    /// One-sigma uncertainty (inflated by `√(χ²/dof)` when the final residual is above the floor).
    pub std: f64,
    /// Unit.
    pub unit: String,
}

/// Verdict on one candidate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EffectStatus {
    /// Improves held-out error by more than chance and enough to matter; in the final model.
    Accepted,
    /// Tested and not supported.
    Rejected,
    /// Would pass, but temperature and time are too correlated to tell it from its rival.
    Confounded,
    /// The data do not carry what it depends on (no temperature, no accelerometer, …).
    NotTestable,
    /// The data carry what it depends on, but the model with it could not be fitted on every
    /// held-out fold (too few observations for its unknowns, or the solver did not converge);
    /// the note says which and, for too few, how many more poses are needed.
    NotFittable,
}

/// The outcome for one candidate effect.
#[derive(Debug, Clone)]
pub struct EffectResult {
    /// Which effect (with the chosen degree for `bias_temperature`).
    pub kind: EffectKind,
    /// Verdict.
    pub status: EffectStatus,
    /// Relative fall of the mean held-out loss (last round it was tested in).
    pub score: f64,
    /// One-sided p-value of the corrected resampled t test (last round).
    pub p_value: f64,
    /// Fall of the held-out loss per component, in variances of the floor inflated by the
    /// Birge ratio (last round).
    pub gain: f64,
    /// Coefficients (of the final model when accepted, of the tested extension otherwise).
    pub coefficients: Vec<Coefficient>,
    /// A sentence explaining the verdict.
    pub note: String,
}

/// Everything found for one sensor.
#[derive(Debug, Clone)]
pub struct SensorAnalysis {
    /// Which sensor.
    pub sensor: Sensor,
    /// Name of the base model (the `fit` default method).
    pub base_model: String,
    /// Unit of the residuals and the noise floor: `relative` (to the reference magnitude) for
    /// the accelerometer and magnetometer, `rad/s` or `counts` for the gyroscope.
    pub residual_unit: &'static str,
    /// Observations used.
    pub observations: Vec<Observation>,
    /// RMS residual expected from noise alone (units of `rms_*`).
    pub noise_floor: f64,
    /// Chi-square test of the base model.
    pub test_before: ChiSquareTest,
    /// Chi-square test of the final model.
    pub test_after: ChiSquareTest,
    /// RMS of the base model on the fit observations (relative for accel/mag, rad/s for gyro).
    pub rms_before: f64,
    /// RMS of the final model on the fit observations.
    pub rms_after: f64,
    /// Held-out RMS of the base model.
    pub heldout_rms_before: f64,
    /// Held-out RMS of the final model.
    pub heldout_rms_after: f64,
    /// Observations never held out: the base model cannot be refit without them (each is the
    /// only pose of its face), so the held-out figures are leave-one-out over the others.
    pub always_trained: usize,
    /// Why the base model is not the one `fit` chose, when it is not.
    pub base_note: Option<String>,
    /// Every candidate tested.
    pub effects: Vec<EffectResult>,
    /// The final residual is above the floor (the χ² test at its level) after the accepted effects.
    pub unexplained: bool,
    /// The recorded variable the final residual correlates with best, and the correlation.
    pub best_correlate: Option<(String, f64)>,
    /// Pearson correlation of pose temperature and time, when temperature is recorded.
    pub temp_time_correlation: Option<f64>,
    /// Base calibration of the final model.
    pub calibration: Calibration,
    /// Reference temperature `T₀` of the temperature terms, °C.
    pub t_ref_c: f64,
    /// Per-observation residual of the base and final models (signed, physical units).
    pub residuals_before: Vec<f64>,
    /// See `residuals_before`.
    pub residuals_after: Vec<f64>,
    /// Final extended terms (scaled problem and parameters), for [`SensorAnalysis::to_calibration_terms`].
    pub(super) final_fit: ExtendedFit,
    pub(super) problem: Problem,
}

/// Extended calibration terms of one sensor in the firmware's form.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibrationTerms {
    /// `A`, `b` and the extended terms the firmware applies.
    pub sensor: SensorCalibration,
    /// Gyro g-sensitivity `K` (rad/s per m/s²), when accepted.
    pub gyro_g_sensitivity: Option<[[f32; 3]; 3]>,
}

/// The sentence saying that an accelerometer analysis's base, the full norm model, is not
/// `chosen`, the model that `by` fitted (`` `fit` `` or "the session").
pub fn full_base_note(chosen: &str, by: &str) -> String {
    format!(
        "the base is the full norm model (9 unknowns), not {chosen}, which {by} fitted: \
         misalignment it leaves out must not be credited to an effect, and an extended set \
         carries the full matrix"
    )
}

impl SensorAnalysis {
    /// Accepted effects.
    pub fn accepted(&self) -> impl Iterator<Item = &EffectResult> {
        self.effects
            .iter()
            .filter(|e| e.status == EffectStatus::Accepted)
    }

    /// Whether the base residual is consistent with the noise.
    pub fn consistent_with_noise(&self) -> bool {
        self.test_before.consistent()
    }

    /// Covariance of the final model's base parameters `A`, `b` in data units, named as
    /// [`crate::fit::Fit::param_names`] (`A11 A12 A13 A22 A23 A33 b1 b2 b3` for the full norm
    /// model, `A11 A22 A33 b1 b2 b3` axis-aligned, `b1 b2 b3` at rest): the marginal block of
    /// the joint fit with its effects (so the terms' correlation with the base is in it), at the
    /// reference temperature, scaled by the final model's Birge ratio `max(1, χ²/ν)` as the
    /// base fits' uncertainties are. `None` when the joint fit's covariance is singular.
    pub fn base_covariance(&self) -> Option<(Vec<String>, nalgebra::DMatrix<f64>)> {
        let joint = self.final_fit.covariance.as_ref()?;
        let s = self.problem.scale;
        let (names, factors): (Vec<&str>, Vec<f64>) = match self.problem.base {
            BaseKind::Norm {
                reference,
                axis_aligned: true,
            } => (
                vec!["A11", "A22", "A33", "b1", "b2", "b3"],
                [[reference / s; 3], [s; 3]].concat(),
            ),
            BaseKind::Norm { reference, .. } => (
                vec!["A11", "A12", "A13", "A22", "A23", "A33", "b1", "b2", "b3"],
                [vec![reference / s; 6], vec![s; 3]].concat(),
            ),
            BaseKind::Rest { .. } => (vec!["b1", "b2", "b3"], vec![s; 3]),
        };
        let n = names.len();
        if joint.nrows() < n {
            return None;
        }
        let birge = (self.test_after.chi2 / self.test_after.dof).max(1.0);
        let cov = nalgebra::DMatrix::from_fn(n, n, |r, c| {
            joint[(r, c)] * factors[r] * factors[c] * birge
        });
        cov.iter()
            .all(|v| v.is_finite())
            .then(|| (names.into_iter().map(String::from).collect(), cov))
    }

    /// The final model in the protocol's `CalibrationSet` form: `A`, `b`, and each accepted
    /// effect that has a firmware term (`bias_drift` has none and is left out).
    pub fn to_calibration_terms(&self) -> CalibrationTerms {
        let mut out = SensorCalibration::identity();
        let a = self.calibration.a;
        out.a = [0, 1, 2].map(|r| [0, 1, 2].map(|c| a[(r, c)] as f32));
        out.b = [0, 1, 2].map(|k| self.calibration.b[k] as f32);
        // Every temperature term was fitted about T₀, the poses' mean temperature.
        out.t_ref_c = self.t_ref_c as f32;
        let mut g_sens = None;
        let p = &self.final_fit.params;
        let mut offset = self.problem.base_params();
        for e in &self.final_fit.effects {
            let value = |j: usize| {
                p[offset + j] * physical_factor(&self.problem, &self.final_fit.effects, offset + j)
            };
            match *e {
                EffectKind::BiasTemperature(d) => {
                    let mut coeffs = [[0f32; 3]; 3];
                    for (k, row) in coeffs
                        .iter_mut()
                        .enumerate()
                        .take(usize::from(d.clamp(1, 3)))
                    {
                        *row = [0, 1, 2].map(|axis| value(3 * k + axis) as f32);
                    }
                    out.bias_temp = Some(BiasTemperature { coeffs });
                }
                EffectKind::ScaleTemperature => {
                    out.scale_temp = Some([0, 1, 2].map(|k| value(k) as f32))
                }
                EffectKind::ScaleNonlinearity => {
                    out.nonlinearity = Some(Nonlinearity {
                        quadratic: [0, 1, 2].map(|k| value(k) as f32),
                        cubic: [0, 1, 2].map(|k| value(3 + k) as f32),
                    })
                }
                EffectKind::GSensitivity => {
                    g_sens = Some([0, 1, 2].map(|r| [0, 1, 2].map(|c| value(3 * r + c) as f32)));
                }
                EffectKind::BiasDrift | EffectKind::BinnedBias(_) => {}
            }
            offset += e.param_count();
        }
        CalibrationTerms {
            sensor: out,
            gyro_g_sensitivity: g_sens,
        }
    }
}

/// The analysis of every sensor of a recording.
#[derive(Debug, Clone)]
pub struct RecordingAnalysis {
    /// Per sensor: the analysis, or why it could not be done.
    pub sensors: Vec<(Sensor, Result<SensorAnalysis, AnalysisError>)>,
}
