//! Residual analysis ("Closing the loop" in `ARCHITECTURE.md`): fit the base model, compare its
//! residual with the noise floor, test candidate effects by held-out error, refit with those the
//! data support, and report what is left.
//!
//! - [`dataset`]: observations (pose means with standard errors, temperature, time, force);
//! - [`noise`]: the floor and the chi-square test;
//! - [`effects`]: the candidate families and their parameters;
//! - [`extended_fit`]: the base model plus effects, fitted jointly;
//! - [`crossval`]: held-out losses by pose and the acceptance rule;
//! - [`report`]: JSON, text and SVG plots.
//!
//! Selection is forward: every remaining candidate is tested against the current model; the
//! one with the smallest p-value among those that pass is accepted, and the round repeats.
//! Temperature and time are told apart only when the observations decorrelate them: when the
//! Pearson correlation of pose temperature and pose time exceeds [`CONFOUNDING_LIMIT`] in
//! magnitude, a time or temperature effect that would pass is reported as `confounded`
//! (neither is accepted). A time or temperature effect must also pass a form check: a bias free
//! in shape over the same variable (constant within each of 8 quantile bins) must not predict the
//! held-out poses better by the same rule; otherwise the dependence has another form (a step,
//! hysteresis) and the effect is rejected rather than accepted as an approximation.

pub mod crossval;
pub mod dataset;
pub mod effects;
pub mod extended_fit;
pub mod noise;
pub mod report;

use imucal_protocol::{BiasTemperature, Nonlinearity, SensorCalibration};

use crate::fit::gyro_bias::fit_gyro_bias;
use crate::fit::li::{fit_li, LiOptions};
use crate::fit::norm_lm::{fit_mag_lm, sphere_start};
use crate::fit::{Calibration, FitError, Pose, Vec3};
use crate::pipeline::chain::default_accel_chain;
use crate::recording::{Recording, Sensor};
use crate::still::StillReport;
use crossval::{extend_start, held_out, Comparison, HeldOut};
use dataset::Observation;
use effects::{EffectKind, GYRO_FAMILIES, NORM_FAMILIES};
use extended_fit::{
    base_calibration, fit_rows, physical_factor, physical_residual, start_params, BaseKind,
    ExtendedFit, Problem,
};
use noise::ChiSquareTest;

/// Above this |ρ| between pose temperature and pose time, temperature and time effects are
/// reported as confounded instead of choosing one.
pub const CONFOUNDING_LIMIT: f64 = 0.95;

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
    /// The solver failed on all observations.
    #[error(
        "the {0} model could not be refitted on its observations; check the recording for outliers"
    )]
    Refit(&'static str),
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
}

impl Default for AnalysisOptions {
    fn default() -> Self {
        Self {
            gravity: crate::recording::STANDARD_GRAVITY,
            field_ut: None,
            gyro_scale: 1.0,
            gyro_scale_known: true,
            mag_window: 20,
            max_mag_windows: 300,
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
    /// Signed-rank p-value (last round).
    pub p_value: f64,
    /// Fall of the held-out loss per component, noise variances (last round).
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
    /// Every candidate tested.
    pub effects: Vec<EffectResult>,
    /// The final residual is above the floor and no candidate explains it.
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
    final_fit: ExtendedFit,
    problem: Problem,
}

/// Extended calibration terms of one sensor in the firmware's form.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibrationTerms {
    /// `A`, `b` and the extended terms the firmware applies.
    pub sensor: SensorCalibration,
    /// Gyro g-sensitivity `K` (rad/s per m/s²), when accepted.
    pub gyro_g_sensitivity: Option<[[f32; 3]; 3]>,
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

    /// The final model in the protocol's `CalibrationSet` form: `A`, `b`, and each accepted
    /// effect that has a firmware term (`bias_drift` has none and is left out).
    pub fn to_calibration_terms(&self) -> CalibrationTerms {
        let mut out = SensorCalibration::identity();
        let a = self.calibration.a;
        out.a = [0, 1, 2].map(|r| [0, 1, 2].map(|c| a[(r, c)] as f32));
        out.b = [0, 1, 2].map(|k| self.calibration.b[k] as f32);
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
                    out.bias_temp = Some(BiasTemperature {
                        t_ref_c: self.t_ref_c as f32,
                        coeffs,
                    });
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

fn pearson(a: &[f64], b: &[f64]) -> Option<f64> {
    let n = a.len().min(b.len());
    if n < 3 {
        return None;
    }
    let ma = a[..n].iter().sum::<f64>() / n as f64;
    let mb = b[..n].iter().sum::<f64>() / n as f64;
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for i in 0..n {
        sab += (a[i] - ma) * (b[i] - mb);
        saa += (a[i] - ma).powi(2);
        sbb += (b[i] - mb).powi(2);
    }
    let r = sab / (saa * sbb).sqrt();
    r.is_finite().then_some(r)
}

fn to_poses(obs: &[Observation]) -> Vec<Pose> {
    obs.iter()
        .map(|o| Pose {
            mean: o.mean,
            var: o.sigma_mean.component_mul(&o.sigma_mean) * o.n as f64,
            n: o.n,
            label: o.label,
        })
        .collect()
}

fn coefficients(
    problem: &Problem,
    fit: &ExtendedFit,
    effect_index: usize,
    unit: &str,
    inflation: f64,
) -> Vec<Coefficient> {
    let mut offset = problem.base_params();
    for e in &fit.effects[..effect_index] {
        offset += e.param_count();
    }
    let e = fit.effects[effect_index];
    e.param_labels(unit)
        .into_iter()
        .enumerate()
        .map(|(j, (name, unit))| {
            let idx = offset + j;
            let f = physical_factor(problem, &fit.effects, idx);
            let std = fit
                .covariance
                .as_ref()
                .map_or(f64::NAN, |c| c[(idx, idx)].max(0.0).sqrt())
                * f.abs()
                * inflation;
            Coefficient {
                name,
                value: fit.params[idx] * f,
                std,
                unit,
            }
        })
        .collect()
}

/// Fit `effects` on every observation and evaluate held out.
fn evaluate(
    problem: &Problem,
    effects: &[EffectKind],
    start: &nalgebra::DVector<f64>,
) -> Option<(ExtendedFit, HeldOut)> {
    let rows: Vec<usize> = (0..problem.points.len()).collect();
    let fit = fit_rows(problem, effects, &rows, start)?;
    let ho = held_out(problem, effects, &fit)?;
    Some((fit, ho))
}

/// What [`analyse_observations`] needs besides the observations.
#[derive(Debug, Clone)]
pub struct SensorSetup<'a> {
    /// Which sensor.
    pub sensor: Sensor,
    /// Name of the base model.
    pub base_model: &'a str,
    /// Base model kind.
    pub base: BaseKind,
    /// The base fit (start and noise propagation).
    pub start: Calibration,
    /// Calibrated specific force per observation, m/s² (gyroscope).
    pub force: Option<Vec<Vec3>>,
    /// Gravity, m/s².
    pub gravity: f64,
    /// Data unit, for coefficient labels.
    pub unit: &'a str,
}

/// Analyse one sensor's observations (see the module comment).
pub fn analyse_observations(
    setup: SensorSetup<'_>,
    observations: Vec<Observation>,
) -> Result<SensorAnalysis, AnalysisError> {
    let SensorSetup {
        sensor,
        base_model,
        base,
        start,
        force,
        gravity,
        unit,
    } = setup;
    let start = &start;
    let problem = Problem::new(&observations, base, start, force, gravity);
    let components = problem.components();
    let n = observations.len();
    let base_start = start_params(&problem, start, &[]);
    let (base_fit, base_ho) =
        evaluate(&problem, &[], &base_start).ok_or(AnalysisError::Refit(sensor.name()))?;
    let temps: Option<Vec<f64>> = observations.iter().map(|o| o.temp_c).collect();
    let times: Vec<f64> = observations.iter().map(|o| o.time_s).collect();
    let temp_time_correlation = temps.as_ref().and_then(|t| pearson(t, &times));
    let confounded = temp_time_correlation.is_some_and(|r| r.abs() > CONFOUNDING_LIMIT);

    let families: &[EffectKind] = match base {
        BaseKind::Norm { .. } => &NORM_FAMILIES,
        BaseKind::Rest { .. } => &GYRO_FAMILIES,
    };
    let mut results: Vec<EffectResult> = Vec::new();
    let mut remaining: Vec<EffectKind> = Vec::new();
    for &f in families {
        if problem.supports(f) {
            remaining.push(f);
        } else {
            let why = match f {
                EffectKind::BiasTemperature(_) | EffectKind::ScaleTemperature => {
                    "no temperature, or a constant one, was recorded"
                }
                EffectKind::GSensitivity => "no accelerometer was recorded with the gyroscope",
                _ => "the data do not vary in the variable it depends on",
            };
            results.push(EffectResult {
                kind: f,
                status: EffectStatus::NotTestable,
                score: 0.0,
                p_value: 1.0,
                gain: 0.0,
                coefficients: Vec::new(),
                note: format!("not testable: {why}"),
            });
        }
    }
    let mut current: (ExtendedFit, HeldOut) = (base_fit.clone(), base_ho.clone());
    let mut last: Vec<(EffectKind, Comparison, ExtendedFit)> = Vec::new();
    let mut confounded_found = false;
    let mut wrong_form: Vec<(&'static str, String)> = Vec::new();
    while !remaining.is_empty() {
        let m = remaining.len();
        let mut round: Vec<(EffectKind, Comparison, ExtendedFit, HeldOut)> = Vec::new();
        for &cand in &remaining {
            let mut best: Option<(EffectKind, Comparison, ExtendedFit, HeldOut)> = None;
            let degrees: Vec<EffectKind> = match cand {
                EffectKind::BiasTemperature(_) => {
                    (1..=3).map(EffectKind::BiasTemperature).collect()
                }
                other => vec![other],
            };
            for kind in degrees {
                let mut effects = current.0.effects.clone();
                effects.push(kind);
                let start = extend_start(&current.0.params, kind.param_count());
                let Some((fit, ho)) = evaluate(&problem, &effects, &start) else {
                    break;
                };
                let cmp = Comparison::new(&current.1, &ho, components);
                // A higher degree replaces a lower one only if it beats it by the same rule.
                let keep = match &best {
                    None => true,
                    Some((_, _, _, prev_ho)) => Comparison::new(prev_ho, &ho, components).passes(m),
                };
                if keep {
                    best = Some((kind, cmp, fit, ho));
                } else {
                    break;
                }
            }
            if let Some(b) = best {
                round.push(b);
            }
        }
        let winner = round
            .iter()
            .enumerate()
            .filter(|(_, (_, c, _, _))| c.passes(m))
            .min_by(|a, b| {
                a.1 .1
                    .p_value
                    .total_cmp(&b.1 .1.p_value)
                    .then(b.1 .1.score.total_cmp(&a.1 .1.score))
            })
            .map(|(i, _)| i);
        last.retain(|(k, _, _)| !round.iter().any(|(rk, _, _, _)| rk.name() == k.name()));
        for (k, c, f, _) in &round {
            last.push((*k, c.clone(), f.clone()));
        }
        let Some(w) = winner else { break };
        let (kind, _, fit, ho) = round.swap_remove(w);
        let time_or_temp = matches!(
            kind,
            EffectKind::BiasDrift | EffectKind::BiasTemperature(_) | EffectKind::ScaleTemperature
        );
        if confounded && time_or_temp {
            confounded_found = true;
            remaining.retain(|r| {
                !matches!(
                    r,
                    EffectKind::BiasDrift
                        | EffectKind::BiasTemperature(_)
                        | EffectKind::ScaleTemperature
                )
            });
            continue;
        }
        remaining.retain(|r| r.name() != kind.name());
        if time_or_temp {
            // Form check: a bias free in shape over the same variable must not predict better.
            let binned = EffectKind::BinnedBias(kind.needs_temperature());
            let mut effects = current.0.effects.clone();
            effects.push(binned);
            let start = extend_start(&current.0.params, binned.param_count());
            if let Some((_, binned_ho)) = evaluate(&problem, &effects, &start) {
                let cmp = Comparison::new(&ho, &binned_ho, components);
                if cmp.passes(1) {
                    wrong_form.push((
                        kind.name(),
                        format!(
                            "explains part of the residual, but a bias free in shape over {} predicts held-out poses better \
                             (signed-rank p = {:.1e}): the dependence has another form (a step, hysteresis), so it is not accepted",
                            kind.variable(),
                            cmp.p_value
                        ),
                    ));
                    continue;
                }
            }
        }
        current = (fit, ho);
    }

    let final_fit = current.0.clone();
    let final_ho = current.1.clone();
    let p_count = final_fit.params.len();
    let test_before = ChiSquareTest::new(base_fit.cost, n * components, base_start.len());
    let test_after = ChiSquareTest::new(final_fit.cost, n * components, p_count);
    let inflation = test_after.reduced().max(1.0).sqrt();
    let residual_of =
        |fit: &ExtendedFit, i: usize| physical_residual(&problem, i, &fit.effects, &fit.params);
    let residuals_before: Vec<f64> = (0..n).map(|i| residual_of(&base_fit, i).0).collect();
    let residuals_after: Vec<f64> = (0..n).map(|i| residual_of(&final_fit, i).0).collect();
    let rms = |v: &[f64]| (v.iter().map(|r| r * r).sum::<f64>() / v.len().max(1) as f64).sqrt();
    let noise_floor = match base {
        BaseKind::Norm { .. } => (problem
            .weights
            .iter()
            .map(|w| if w[0] > 0.0 { 1.0 / (w[0] * w[0]) } else { 0.0 })
            .sum::<f64>()
            / n as f64)
            .sqrt(),
        BaseKind::Rest { scale } => {
            (observations
                .iter()
                .map(|o| o.sigma_mean.norm_squared())
                .sum::<f64>()
                / n as f64)
                .sqrt()
                * scale
        }
    };

    // Verdicts.
    for (idx, kind) in final_fit.effects.iter().enumerate() {
        let (score, p_value, gain) = last
            .iter()
            .find(|(k, _, _)| k.name() == kind.name())
            .map_or((0.0, 0.0, 0.0), |(_, c, _)| {
                (c.score, c.p_value, c.gain_per_component)
            });
        results.push(EffectResult {
            kind: *kind,
            status: EffectStatus::Accepted,
            score,
            p_value,
            gain,
            coefficients: coefficients(&problem, &final_fit, idx, unit, inflation),
            note: format!(
                "improves held-out error by {:.0} % (signed-rank p = {p_value:.1e})",
                100.0 * score
            ),
        });
    }
    for (kind, cmp, fit) in &last {
        if final_fit.effects.iter().any(|k| k.name() == kind.name()) {
            continue;
        }
        let time_or_temp = matches!(
            kind,
            EffectKind::BiasDrift | EffectKind::BiasTemperature(_) | EffectKind::ScaleTemperature
        );
        let status = if confounded_found && time_or_temp && cmp.passes(1) {
            EffectStatus::Confounded
        } else {
            EffectStatus::Rejected
        };
        let note = match status {
            EffectStatus::Confounded => format!(
                "would improve held-out error, but temperature and time are correlated (ρ = {:.3}, limit {CONFOUNDING_LIMIT}); \
                 record with temperature varying independently of time to tell them apart",
                temp_time_correlation.unwrap_or(f64::NAN)
            ),
            _ => match wrong_form.iter().find(|(name, _)| *name == kind.name()) {
                Some((_, why)) => why.clone(),
                None => format!(
                    "held-out gain {:.2} noise variances per component, signed-rank p = {:.2e}: not enough",
                    cmp.gain_per_component, cmp.p_value
                ),
            },
        };
        let index = fit.effects.len() - 1;
        results.push(EffectResult {
            kind: *kind,
            status,
            score: cmp.score,
            p_value: cmp.p_value,
            gain: cmp.gain_per_component,
            coefficients: coefficients(&problem, fit, index, unit, 1.0),
            note,
        });
    }

    // The recorded variable the final residual follows best.
    let mut variables: Vec<(String, Vec<f64>)> = vec![("time".into(), times.clone())];
    if let Some(t) = &temps {
        variables.push(("temperature".into(), t.clone()));
    }
    let cal = base_calibration(&problem, &final_fit.params);
    // At rest the gyroscope's reading is its residual, so its magnitude is no explanatory variable.
    if matches!(base, BaseKind::Norm { .. }) {
        variables.push((
            "reading magnitude".into(),
            observations
                .iter()
                .map(|o| (o.mean - cal.b).norm())
                .collect(),
        ));
    }
    if let Some(f) = &problem.force {
        for (k, axis) in ["x", "y", "z"].iter().enumerate() {
            variables.push((
                format!("specific force {axis}"),
                f.iter().map(|v| v[k]).collect(),
            ));
        }
    }
    let signed: Vec<Vec3> = (0..n).map(|i| residual_of(&final_fit, i).1).collect();
    let mut best_correlate: Option<(String, f64)> = None;
    for (name, values) in &variables {
        for k in 0..components {
            let comp: Vec<f64> = signed.iter().map(|v| v[k]).collect();
            if let Some(r) = pearson(&comp, values) {
                if best_correlate
                    .as_ref()
                    .is_none_or(|(_, b)| r.abs() > b.abs())
                {
                    let label = if components == 3 {
                        format!("{name} (axis {})", ["x", "y", "z"][k])
                    } else {
                        name.clone()
                    };
                    best_correlate = Some((label, r));
                }
            }
        }
    }
    let unexplained = !test_after.consistent();
    Ok(SensorAnalysis {
        sensor,
        base_model: base_model.to_string(),
        residual_unit: match base {
            BaseKind::Norm { .. } => "relative",
            BaseKind::Rest { .. } => "rad/s",
        },
        noise_floor,
        test_before,
        test_after,
        rms_before: rms(&residuals_before),
        rms_after: rms(&residuals_after),
        heldout_rms_before: base_ho.rms(),
        heldout_rms_after: final_ho.rms(),
        effects: results,
        unexplained,
        best_correlate,
        temp_time_correlation,
        calibration: cal,
        t_ref_c: problem.temp_ref.0,
        residuals_before,
        residuals_after,
        observations,
        final_fit,
        problem,
    })
}

/// Analyse every sensor of a recording. The accelerometer is analysed first: its final
/// calibration gives the specific force for the gyroscope's g-sensitivity.
pub fn analyse_recording(
    recording: &Recording,
    still: &StillReport,
    options: &AnalysisOptions,
) -> RecordingAnalysis {
    let mut sensors = Vec::new();
    let mut accel_cal: Option<Calibration> = None;
    for sensor in recording.sensors() {
        let result = analyse_sensor(recording, still, options, sensor, accel_cal.as_ref());
        if let (Sensor::Accel, Ok(a)) = (sensor, &result) {
            accel_cal = Some(a.calibration);
        }
        sensors.push((sensor, result));
    }
    RecordingAnalysis { sensors }
}

/// Analyse one sensor; `accel_cal` (the accelerometer's calibration) enables g-sensitivity.
pub fn analyse_sensor(
    recording: &Recording,
    still: &StillReport,
    options: &AnalysisOptions,
    sensor: Sensor,
    accel_cal: Option<&Calibration>,
) -> Result<SensorAnalysis, AnalysisError> {
    if !recording.has(sensor) {
        return Err(AnalysisError::NoSensor(sensor.name()));
    }
    let unit = recording.units.symbol(sensor);
    let too_few = |what, found, needed| AnalysisError::TooFewObservations {
        sensor: sensor.name(),
        what,
        found,
        needed,
    };
    match sensor {
        Sensor::Accel => {
            let obs = dataset::pose_observations(recording, still, Sensor::Accel);
            if obs.len() < 10 {
                return Err(too_few("still poses", obs.len(), 10));
            }
            // The default chain's model starts the extended fit; when every model of the chain
            // refuses, the generic solver here restarts from the sphere.
            let start = match default_accel_chain(&to_poses(&obs), options.gravity) {
                Ok(choice) => choice.fit.cal,
                Err(source) => {
                    let means: Vec<Vec3> = obs.iter().map(|o| o.mean).collect();
                    let sphere = sphere_start(&means, options.gravity);
                    let setup = SensorSetup {
                        sensor,
                        base_model: "lm",
                        base: BaseKind::Norm {
                            reference: options.gravity,
                        },
                        start: sphere,
                        force: None,
                        gravity: options.gravity,
                        unit,
                    };
                    return analyse_observations(setup, obs).map_err(|_| AnalysisError::BaseFit {
                        sensor: "accel",
                        source,
                    });
                }
            };
            let setup = SensorSetup {
                sensor,
                base_model: "lm",
                base: BaseKind::Norm {
                    reference: options.gravity,
                },
                start,
                force: None,
                gravity: options.gravity,
                unit,
            };
            analyse_observations(setup, obs)
        }
        Sensor::Gyro => {
            let obs = dataset::pose_observations(recording, still, Sensor::Gyro);
            if obs.len() < 3 {
                return Err(too_few("still poses", obs.len(), 3));
            }
            let start = fit_gyro_bias(&to_poses(&obs), options.gyro_scale).map_err(|source| {
                AnalysisError::BaseFit {
                    sensor: "gyro",
                    source,
                }
            })?;
            // Specific force from the accelerometer's calibration, else from its nominal unit.
            let accel_si = recording.units.to_si(Sensor::Accel);
            let force = obs
                .iter()
                .map(|o| match (accel_cal, accel_si) {
                    (Some(cal), _) => o.accel_mean.map(|a| cal.apply(&a)),
                    (None, Some(k)) => o.accel_mean.map(|a| a * k),
                    (None, None) => None,
                })
                .collect::<Option<Vec<Vec3>>>();
            let setup = SensorSetup {
                sensor,
                base_model: "gyro-bias",
                base: BaseKind::Rest {
                    scale: options.gyro_scale,
                },
                start: start.cal,
                force,
                gravity: options.gravity,
                unit,
            };
            analyse_observations(setup, obs).map(|mut a| {
                if !options.gyro_scale_known {
                    a.residual_unit = "counts";
                }
                a
            })
        }
        Sensor::Mag => {
            // Still poses only when they cover enough orientations for the ellipsoid (nine
            // distinct gravity directions); otherwise short windows of the whole stream.
            let mut obs = dataset::pose_observations(recording, still, Sensor::Mag);
            let covered = still.from_pose_column || still.directions.len() >= 9;
            if obs.len() < 12 || !covered {
                obs = dataset::window_observations(
                    recording,
                    options.mag_window,
                    options.max_mag_windows,
                );
            }
            if obs.len() < 12 {
                return Err(too_few("magnetometer windows", obs.len(), 12));
            }
            let reference = options.field_ut.unwrap_or(1.0);
            let means: Vec<Vec3> = obs.iter().map(|o| o.mean).collect();
            // The `fit` default, else Li's ellipsoid, else the sphere, refined by the solver here.
            let start = match fit_mag_lm(&means, reference) {
                Ok(fit) => fit.cal,
                Err(_) => fit_li(
                    &means,
                    reference,
                    LiOptions {
                        subtract_mean: true,
                    },
                )
                .map(|f| f.cal)
                .unwrap_or_else(|_| sphere_start(&means, reference)),
            };
            let setup = SensorSetup {
                sensor,
                base_model: "lm",
                base: BaseKind::Norm { reference },
                start,
                force: None,
                gravity: options.gravity,
                unit,
            };
            analyse_observations(setup, obs)
        }
    }
}
