//! Fitting the data of a guided session with the library's default methods, and how good the
//! result is expected to be.
//!
//! - Accelerometer: the default chain of [`crate::pipeline::chain`] (the model chosen by
//!   held-out error, usually Levenberg–Marquardt on the norm model `|A(vᵢ − b)| = g` weighted by
//!   each pose's noise, as `imucal fit` does).
//! - Gyroscope: bias = noise-weighted mean of the pose means (seed 000 eq. 9;
//!   [`crate::fit::gyro_bias::fit_gyro_bias`]); its σ is inflated by the Birge ratio of the pose
//!   means, since slow hand sway leaves a correlated rate in each hold that `var/n` misses. Scale
//!   and misalignment are not fitted here (they need the full-rate stream between holds).
//! - Magnetometer: LM on `|A(mₖ − b)| = H` over the tumble samples, started from Li's ellipsoid
//!   (seed 000 eq. 17–29; [`crate::fit::norm_lm::fit_mag_lm`]), then rotated into the
//!   accelerometer frame by the dip-invariance alignment from the poses (`A ← R·A`,
//!   [`crate::fit::alignment`]), because the norm fit's gauge leaves its output frame arbitrary;
//!   positions whose field disagrees with the calibration are screened out first
//!   ([`super::mag_alignment`]). A failed alignment makes the verdict poor.
//!
//! The expected error of `|a|` (or `|m|`) along an output direction `û` follows from the
//! parameter covariance `Σ` by first-order propagation: `σ² = ∇θᵀ Σ ∇θ` with
//! `∇θ|A(x − b)| = (ûᵢ·(x − b)ⱼ for the upper-triangular Aᵢⱼ, −Aᵀû)`; the largest over the 26
//! cube directions is reported.

use imucal_protocol::{
    CalibrationSet, FitResiduals, PoseStats, ReferenceMagnitudes, SensorCalibration,
    PARAMS_FORMAT_VERSION,
};
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use super::coverage::region_directions;
use super::mag_alignment::{align_session_mag, SessionAlignment};
use super::targets::Target;
use crate::fit::alignment::Alignment;
use crate::fit::gyro_bias::fit_gyro_bias;
use crate::fit::norm_lm::fit_mag_lm;
use crate::fit::{Calibration, Fit, FitError, Mat3, Pose, Vec3};
use crate::pipeline::chain::{default_accel_chain, ChainChoice};
use crate::pipeline::methods::thin_redundant;
use crate::stats::robust::screen_stream;

/// Standard gravity, m/s² (the unit of "mg").
pub const STANDARD_GRAVITY: f64 = 9.806_65;

/// One captured pose and the target it was captured for.
#[derive(Debug, Clone, PartialEq)]
pub struct CapturedPose {
    /// The orientation asked for.
    pub target: Target,
    /// What the board averaged, nominal units.
    pub stats: PoseStats,
    /// Board time at the middle of the averaged samples, s (for telling temperature from time).
    pub t_s: f64,
}

/// Where the magnetometer's reference magnitude came from (`field_source` in `summary.json`;
/// readers of older summaries meet `given` for a simulated site's field too).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FieldSource {
    /// A reference magnitude was given to the session: `--field-ut`, or the field model at
    /// `--location`.
    #[default]
    Given,
    /// A simulated board's site field, standing in for the one a user would look up for the
    /// location (`calibrate --sim` without `--field-ut` or `--location`).
    SimulatedSite,
    /// The geometric mean radius of the raw readings: keeps the sensor's mean sensitivity, since
    /// without a reference the field's magnitude is not observable.
    MeanRadius,
}

/// One-sigma uncertainties of the fitted set, in the units people read.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Uncertainties {
    /// Accelerometer offset per axis, mg.
    pub accel_bias_mg: [f64; 3],
    /// Accelerometer scale (diagonal of `A`) per axis, ppm.
    pub accel_scale_ppm: [f64; 3],
    /// Largest expected error of `|a|` over all directions, mg.
    pub accel_norm_mg: f64,
    /// Gyroscope bias per axis, °/s.
    pub gyro_bias_dps: [f64; 3],
    /// Magnetometer offset per axis, µT.
    pub mag_bias_ut: [f64; 3],
    /// Largest expected error of `|m|` over all directions, % of the field.
    pub mag_norm_pct: f64,
    /// Magnetometer-to-accelerometer alignment (RMS over the three axes), degrees.
    pub alignment_deg: f64,
}

/// How good the fit looks before it is written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum VerdictLevel {
    /// Every check within its budget.
    Good,
    /// Usable, with the reasons listed.
    Marginal,
    /// Not worth writing; the reasons say what to redo.
    Poor,
}

impl VerdictLevel {
    /// The level as the summary's JSON and the screens write it: `good`, `marginal`, `poor`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Good => "good",
            Self::Marginal => "marginal",
            Self::Poor => "poor",
        }
    }
}

/// The verdict and its reasons.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Verdict {
    /// Overall level.
    pub level: VerdictLevel,
    /// One sentence per check that missed its budget (empty when good).
    pub reasons: Vec<String>,
}

/// Budgets the verdict compares against.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Budgets {
    /// Allowed error of `|a|` at rest, mg.
    pub accel_mg: f64,
    /// Allowed error of `|m|` at rest, % of the field.
    pub mag_pct: f64,
}

/// The fitted calibration of a session.
#[derive(Debug, Clone)]
pub struct SessionFit {
    /// The parameter set to write.
    pub set: CalibrationSet,
    /// Accelerometer fit (m/s²), by the default chain.
    pub accel: Fit,
    /// Which accelerometer model the default chain chose, and why.
    pub accel_choice: ChainChoice,
    /// Gyroscope bias fit (rad/s).
    pub gyro: Fit,
    /// Magnetometer fit in its own gauge, before the alignment (µT).
    pub mag: Fit,
    /// Rotation of the magnetometer frame into the accelerometer frame, or why there is none
    /// (the verdict then says so, and the magnetometer is left in its own frame).
    pub alignment: Result<Alignment, String>,
    /// Findings worth a line that do not change the verdict (positions left out of the
    /// magnetometer's alignment, and why).
    pub notes: Vec<String>,
    /// Reference field magnitude, µT.
    pub field_ut: f64,
    /// Where `field_ut` came from.
    pub field_source: FieldSource,
    /// Local gravity used, m/s².
    pub gravity_mps2: f64,
    /// One-sigma uncertainties.
    pub uncertainties: Uncertainties,
    /// The verdict.
    pub verdict: Verdict,
    /// The budgets the verdict and the check at rest are held to.
    pub budgets: Budgets,
}

impl SessionFit {
    /// Names who gave the field the fit was given (`source`, from the session's options): the
    /// fit itself knows only that one was given. A fit that kept the sensor's mean radius
    /// keeps saying so.
    pub fn name_field_source(&mut self, source: FieldSource) {
        if self.field_source == FieldSource::Given {
            self.field_source = source;
        }
    }
}

/// A pose of one sensor from the board's statistics.
pub fn pose_of(stats: &PoseStats, sensor: fn(&PoseStats) -> ([f32; 3], [f32; 3])) -> Pose {
    let (mean, var) = sensor(stats);
    Pose {
        mean: Vec3::from(mean.map(f64::from)),
        var: Vec3::from(var.map(f64::from)),
        n: stats.n as usize,
        label: None,
    }
}

/// Accelerometer mean and variance of a pose.
pub fn accel_of(stats: &PoseStats) -> ([f32; 3], [f32; 3]) {
    (stats.accel_mean, stats.accel_var)
}

/// Gyroscope mean and variance of a pose.
pub fn gyro_of(stats: &PoseStats) -> ([f32; 3], [f32; 3]) {
    (stats.gyro_mean, stats.gyro_var)
}

/// Magnetometer mean and variance of a pose.
pub fn mag_of(stats: &PoseStats) -> ([f32; 3], [f32; 3]) {
    (stats.mag_mean, stats.mag_var)
}

/// Gradient of `|A(x − b)|` with respect to the parameters `names` (`Aij`, `bj`; entries not
/// named are fixed), at the raw reading that maps to `reference·û`: `∂/∂Aᵢⱼ = ûᵢ·uⱼ` and
/// `∂/∂b = −Aᵀû` with `u = x − b`.
fn norm_gradient(
    cal: &Calibration,
    reference: f64,
    names: &[String],
    direction: &Vec3,
) -> Option<DVector<f64>> {
    let u = cal.a.try_inverse()? * (direction * reference);
    let back = cal.a.transpose() * direction;
    let entry = |name: &str| -> Option<f64> {
        let digits: Vec<usize> = name
            .chars()
            .skip(1)
            .map(|c| c.to_digit(10).map(|d| d as usize))
            .collect::<Option<Vec<_>>>()?;
        match (name.chars().next()?, digits.as_slice()) {
            ('A', [r, c]) => Some(direction[r.checked_sub(1)?] * u[c.checked_sub(1)?]),
            ('b', [j]) => Some(-back[j.checked_sub(1)?]),
            _ => None,
        }
    };
    let values = names
        .iter()
        .map(|n| entry(n))
        .collect::<Option<Vec<f64>>>()?;
    Some(DVector::from_vec(values))
}

/// One-sigma error of `|A(x − b)|` along the output direction `direction` (unit), in output
/// units, for the covariance `cov` of the parameters `names` of `cal`; `None` when a name is
/// not an `A`/`b` entry or the sizes differ.
pub fn norm_sigma_of(
    cal: &Calibration,
    reference: f64,
    names: &[String],
    cov: &DMatrix<f64>,
    direction: &Vec3,
) -> Option<f64> {
    let g = norm_gradient(cal, reference, names, direction)?;
    if cov.shape() != (g.len(), g.len()) {
        return None;
    }
    Some((g.transpose() * cov * &g)[(0, 0)].max(0.0).sqrt())
}

/// One-sigma error of `|A(x − b)|` along the output direction `direction` (unit), in output
/// units; `None` without a covariance over named `A`/`b` entries.
pub fn norm_sigma_at(fit: &Fit, direction: &Vec3) -> Option<f64> {
    let cov: &DMatrix<f64> = fit.covariance.as_ref()?;
    norm_sigma_of(&fit.cal, fit.reference, &fit.param_names, cov, direction)
}

/// Largest one-sigma error of `|A(x − b)|` over the 26 cube directions, in output units;
/// `None` without a covariance.
pub fn max_norm_sigma(fit: &Fit) -> Option<f64> {
    let cov: &DMatrix<f64> = fit.covariance.as_ref()?;
    max_norm_sigma_of(&fit.cal, fit.reference, &fit.param_names, cov)
}

/// [`max_norm_sigma`] for a calibration and the covariance of its parameters `names`.
pub fn max_norm_sigma_of(
    cal: &Calibration,
    reference: f64,
    names: &[String],
    cov: &DMatrix<f64>,
) -> Option<f64> {
    region_directions()
        .iter()
        .filter_map(|d| norm_sigma_of(cal, reference, names, cov, d))
        .reduce(f64::max)
}

/// Gyroscope bias σ per axis (rad/s), inflated by the Birge ratio `√(χ²/(N−1))` of the pose
/// means when they scatter more than their `var/n` says.
fn gyro_bias_sigma(fit: &Fit, poses: &[Pose]) -> Vec3 {
    let base = fit.std.map(|s| s.b).unwrap_or_else(Vec3::zeros);
    if poses.len() < 2 {
        return base;
    }
    let mut out = base;
    for axis in 0..3 {
        let chi2: f64 = poses
            .iter()
            .map(|p| {
                let v = p.var_of_mean()[axis];
                if v > 0.0 {
                    (p.mean[axis] - fit.cal.b[axis]).powi(2) / v
                } else {
                    0.0
                }
            })
            .sum();
        let birge = (chi2 / (poses.len() - 1) as f64).sqrt();
        out[axis] = base[axis] * birge.max(1.0);
    }
    out
}

fn to_f32_rows(m: &Mat3) -> [[f32; 3]; 3] {
    [0, 1, 2].map(|r| [0, 1, 2].map(|c| m[(r, c)] as f32))
}

fn to_f32_vec(v: &Vec3) -> [f32; 3] {
    [v.x as f32, v.y as f32, v.z as f32]
}

fn sensor_calibration(cal: &Calibration) -> SensorCalibration {
    SensorCalibration {
        a: to_f32_rows(&cal.a),
        b: to_f32_vec(&cal.b),
        ..SensorCalibration::identity()
    }
}

/// The magnetometer fit with the reference chosen as described by [`FieldSource`].
fn fit_mag(points: &[Vec3], field_ut: Option<f64>) -> Result<(Fit, f64, FieldSource), FitError> {
    match field_ut {
        Some(field) => Ok((fit_mag_lm(points, field)?, field, FieldSource::Given)),
        None => {
            // |A₁u| = 1 maps the ellipsoid to the unit sphere; its geometric mean radius in µT
            // is det(A₁)^(−1/3).
            let unit = fit_mag_lm(points, 1.0)?;
            let det = unit.cal.a.determinant();
            if !(det.is_finite() && det > 0.0) {
                return Err(FitError::Underdetermined(
                    "the magnetometer ellipsoid is degenerate; turn the board through more \
                     directions"
                        .into(),
                ));
            }
            let field = det.powf(-1.0 / 3.0);
            Ok((fit_mag_lm(points, field)?, field, FieldSource::MeanRadius))
        }
    }
}

/// The magnetometer fit's expected `|m|` error in its worst direction, % (1σ), for the raw
/// readings `points` (µT) fitted as [`fit_session`] fits them (at most `max_points`, thinned
/// as the session does, then screened for spikes); infinite when the fit fails or gives no
/// covariance.
pub fn expected_mag_error_pct(points: &[Vec3], field_ut: Option<f64>, max_points: usize) -> f64 {
    let thinned = thin_redundant(points, max_points);
    fit_mag(&screen_stream(&thinned).kept(&thinned), field_ut)
        .ok()
        .and_then(|(fit, field, _)| max_norm_sigma(&fit).map(|s| s / field * 100.0))
        .unwrap_or(f64::INFINITY)
}

/// A sensor of a session that could not be fitted, and why.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("the {sensor}: {source}")]
pub struct SensorFitError {
    /// `accelerometer`, `gyroscope` or `magnetometer`.
    pub sensor: &'static str,
    /// Why.
    pub source: FitError,
}

/// `result` with the sensor it is of named in its error.
fn of_sensor<T>(sensor: &'static str, result: Result<T, FitError>) -> Result<T, SensorFitError> {
    result.map_err(|source| SensorFitError { sensor, source })
}

/// Fit every sensor and build the parameter set; `mag_points` are raw magnetometer readings
/// (µT) from the tumble, `created_unix_s` stamps the set.
pub fn fit_session(
    poses: &[CapturedPose],
    mag_points: &[Vec3],
    gravity_mps2: f64,
    field_ut: Option<f64>,
    budgets: Budgets,
    created_unix_s: u64,
) -> Result<SessionFit, SensorFitError> {
    let accel_poses: Vec<Pose> = poses.iter().map(|p| pose_of(&p.stats, accel_of)).collect();
    let gyro_poses: Vec<Pose> = poses.iter().map(|p| pose_of(&p.stats, gyro_of)).collect();
    let accel_choice = of_sensor(
        "accelerometer",
        default_accel_chain(&accel_poses, gravity_mps2),
    )?;
    let accel = accel_choice.fit.clone();
    let gyro = of_sensor("gyroscope", fit_gyro_bias(&gyro_poses, 1.0))?;
    // A spike in the stream would dominate the ellipsoid: screened like a recording's.
    let screening = screen_stream(mag_points);
    let (mag, field, field_source) = of_sensor(
        "magnetometer",
        fit_mag(&screening.kept(mag_points), field_ut),
    )?;

    let accel_up: Vec<Vec3> = accel_poses
        .iter()
        .map(|p| accel.cal.apply(&p.mean))
        .collect();
    let raw_field: Vec<Vec3> = poses
        .iter()
        .map(|p| pose_of(&p.stats, mag_of).mean)
        .collect();
    let names: Vec<&str> = poses.iter().map(|p| p.target.name.as_str()).collect();
    let SessionAlignment {
        outcome: alignment,
        mut notes,
    } = align_session_mag(&accel_up, &raw_field, &names, &mag, field);
    if screening.dropped > 0 {
        notes.push(format!(
            "{} of {} magnetometer samples of the turns were left out of the field fit as \
             spikes (up to {:.3e} robust standard deviations from their neighbours)",
            screening.dropped,
            mag_points.len(),
            screening.worst_sigmas
        ));
    }
    let mag_final = alignment
        .as_ref()
        .map_or(mag.cal, |align| align.apply_to(&mag.cal));

    let set = CalibrationSet {
        format_version: PARAMS_FORMAT_VERSION,
        created_unix_s,
        accel: sensor_calibration(&accel.cal),
        gyro: sensor_calibration(&gyro.cal),
        mag: sensor_calibration(&mag_final),
        gyro_g_sensitivity: None,
        reference: ReferenceMagnitudes {
            gravity_mps2: gravity_mps2 as f32,
            field_ut: field as f32,
        },
        residuals: FitResiduals {
            accel_rms: (accel.rms * gravity_mps2) as f32,
            gyro_rms: gyro.rms as f32,
            mag_rms: (mag.rms * field) as f32,
        },
    };

    let accel_std = accel.std.map(|s| (s.a, s.b));
    let gyro_sigma = gyro_bias_sigma(&gyro, &gyro_poses);
    let mg = 1000.0 / STANDARD_GRAVITY;
    let uncertainties = Uncertainties {
        accel_bias_mg: accel_std.map_or([f64::NAN; 3], |(_, b)| [b.x, b.y, b.z].map(|v| v * mg)),
        accel_scale_ppm: accel_std.map_or([f64::NAN; 3], |(a, _)| {
            [0, 1, 2].map(|i| a[(i, i)] / accel.cal.a[(i, i)].abs().max(f64::MIN_POSITIVE) * 1e6)
        }),
        accel_norm_mg: max_norm_sigma(&accel).map_or(f64::NAN, |s| s * mg),
        gyro_bias_dps: [gyro_sigma.x, gyro_sigma.y, gyro_sigma.z].map(f64::to_degrees),
        mag_bias_ut: mag.std.map_or([f64::NAN; 3], |s| [s.b.x, s.b.y, s.b.z]),
        mag_norm_pct: max_norm_sigma(&mag).map_or(f64::NAN, |s| s / field * 100.0),
        alignment_deg: alignment.as_ref().map_or(f64::NAN, |a| {
            (a.rotation_std.norm_squared() / 3.0).sqrt().to_degrees()
        }),
    };
    let verdict = judge(
        &accel,
        &uncertainties,
        alignment.as_ref().err(),
        budgets,
        gravity_mps2,
    );
    Ok(SessionFit {
        set,
        accel,
        accel_choice,
        gyro,
        mag,
        alignment,
        notes,
        field_ut: field,
        field_source,
        gravity_mps2,
        uncertainties,
        verdict,
        budgets,
    })
}

/// The reason for a held-out accelerometer error of `loo_mg` (mg RMS) of `model` above its
/// budget, and whether it is poor: marginal up to five budgets, poor beyond. `None` within the
/// budget. The session's verdict says it of the "accelerometer fit".
pub fn heldout_reason(model: &str, loo_mg: f64, budgets: Budgets) -> Option<(String, bool)> {
    (loo_mg > budgets.accel_mg).then(|| {
        let far = loo_mg > 5.0 * budgets.accel_mg;
        (
            format!(
                "a position left out of the {model} is predicted with {loo_mg:.2} mg RMS error, \
                 above the {:.1} mg budget{}: the model does not explain every pose (a pose \
                 taken while moving, or an effect such as temperature drift)",
                budgets.accel_mg,
                if far {
                    " by more than five times (poor)"
                } else {
                    " (marginal up to five times it)"
                }
            ),
            far,
        )
    })
}

/// The verdict of `fit`'s set with terms added by the residual analysis, whose model leaves
/// a position out with `heldout_relative` RMS error (relative to g): the base fit's held-out
/// reason is replaced by the extended model's (or dropped when it is within the budget), every
/// other reason kept, and the level taken again (poor when the new held-out error or one of
/// the checks that can be poor on their own, the magnetometer's and the alignment's, is).
pub fn verdict_with_terms(fit: &SessionFit, heldout_relative: f64) -> Verdict {
    let mg = 1000.0 / STANDARD_GRAVITY;
    let to_mg = |relative: f64| relative * fit.gravity_mps2 * mg;
    let old = fit
        .accel
        .loo_rms
        .and_then(|loo| heldout_reason("accelerometer fit", to_mg(loo), fit.budgets));
    let new = heldout_reason(
        "model with the added terms",
        to_mg(heldout_relative),
        fit.budgets,
    );
    let mut reasons = fit.verdict.reasons.clone();
    let at = old
        .as_ref()
        .and_then(|(text, _)| reasons.iter().position(|r| r == text));
    match (at, &new) {
        (Some(i), Some((text, _))) => reasons[i] = text.clone(),
        (Some(i), None) => {
            reasons.remove(i);
        }
        (None, Some((text, _))) => reasons.push(text.clone()),
        (None, None) => {}
    }
    // The checks besides the held-out error, judged again alone.
    let mut without_heldout = fit.accel.clone();
    without_heldout.loo_rms = None;
    let others = judge(
        &without_heldout,
        &fit.uncertainties,
        fit.alignment.as_ref().err(),
        fit.budgets,
        fit.gravity_mps2,
    );
    let poor = others.level == VerdictLevel::Poor || new.as_ref().is_some_and(|(_, far)| *far);
    Verdict::of(reasons, poor)
}

impl Verdict {
    /// The verdict of `reasons`: good without any, poor when one of them is, else marginal.
    fn of(reasons: Vec<String>, poor: bool) -> Self {
        let level = if reasons.is_empty() {
            VerdictLevel::Good
        } else if poor {
            VerdictLevel::Poor
        } else {
            VerdictLevel::Marginal
        };
        Self { level, reasons }
    }
}

/// The verdict: the expected errors (covariance) must stay within a quarter of the budgets, so
/// that a 4σ error still meets them, and the held-out accelerometer residual within the budget.
fn judge(
    accel: &Fit,
    u: &Uncertainties,
    alignment_error: Option<&String>,
    budgets: Budgets,
    gravity_mps2: f64,
) -> Verdict {
    let mut reasons = Vec::new();
    let mut poor = false;
    let mg = 1000.0 / STANDARD_GRAVITY;
    // A NaN σ (no covariance) counts as over budget.
    let within = |value: f64, limit: f64| value.partial_cmp(&limit).is_some_and(|o| o.is_le());
    if !u.accel_norm_mg.is_finite() {
        reasons.push(format!(
            "the accelerometer's expected |a| error is unknown / not estimated (the fit gave no \
             covariance), so not shown within a quarter of the {:.1} mg budget; hold each \
             position longer or more still",
            budgets.accel_mg
        ));
    } else if !within(u.accel_norm_mg, budgets.accel_mg / 4.0) {
        reasons.push(format!(
            "the accelerometer's expected |a| error is {:.2} mg (1σ), above a quarter of the \
             {:.1} mg budget; hold each position longer or more still",
            u.accel_norm_mg, budgets.accel_mg
        ));
    }
    if let Some((reason, far)) = accel
        .loo_rms
        .and_then(|loo| heldout_reason("accelerometer fit", loo * gravity_mps2 * mg, budgets))
    {
        poor |= far;
        reasons.push(reason);
    }
    if !within(u.mag_norm_pct, budgets.mag_pct / 4.0) {
        poor |= !within(u.mag_norm_pct, budgets.mag_pct);
        let expected = if u.mag_norm_pct.is_finite() {
            format!("{:.3} % (1σ), above", u.mag_norm_pct)
        } else {
            "unknown / not estimated (the fit gave no covariance), so not shown within".to_string()
        };
        reasons.push(format!(
            "the magnetometer's expected |m| error is {expected} a quarter of the {:.1} % \
             budget; turn the board through more directions",
            budgets.mag_pct
        ));
    }
    if let Some(error) = alignment_error {
        // The magnetometer would be written in its own frame: a heading off by the sensors'
        // mounting angle, which for separate dies can be any multiple of 90°.
        poor = true;
        reasons.push(format!(
            "the magnetometer could not be aligned to the accelerometer frame ({error}), so \
             the heading from this calibration would be off by the sensors' mounting angle; \
             hold the positions again, with no magnet or steel near the board"
        ));
    }
    Verdict::of(reasons, poor)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::covariance::UPPER_TRIANGULAR_LAYOUT;

    #[test]
    fn the_norm_sigma_of_an_offset_only_covariance_is_the_offset_sigma() {
        // With Σ = σ²·I on b only (A exact, A = I), |a| along a cube face direction moves by the
        // offset component along it: σ exactly, and the same along every unit direction.
        let sigma = 0.003;
        let mut cov = DMatrix::zeros(9, 9);
        for i in 6..9 {
            cov[(i, i)] = sigma * sigma;
        }
        let got = max_norm_sigma(&identity_fit(cov)).expect("a covariance");
        assert!((got - sigma).abs() < 1e-15, "{got}");
    }

    /// An identity fit of the accelerometer with covariance `cov` over the upper-triangular
    /// `A` and `b`.
    fn identity_fit(cov: DMatrix<f64>) -> Fit {
        Fit {
            method: crate::fit::Method::Lm,
            cal: Calibration::identity(),
            residuals: vec![],
            rms: 0.0,
            loo_rms: None,
            covariance: Some(cov),
            param_names: crate::fit::covariance::param_names(&UPPER_TRIANGULAR_LAYOUT),
            std: None,
            condition_number: 1.0,
            iterations: 0,
            termination: None,
            coverage_factor: crate::fit::uncertainty::Z_95,
            reference: 9.8,
        }
    }

    #[test]
    fn a_failed_alignment_makes_the_verdict_poor_and_names_the_cause() {
        let within = Uncertainties {
            accel_bias_mg: [0.01; 3],
            accel_scale_ppm: [10.0; 3],
            accel_norm_mg: 0.1,
            gyro_bias_dps: [0.001; 3],
            mag_bias_ut: [0.01; 3],
            mag_norm_pct: 0.01,
            alignment_deg: f64::NAN,
        };
        let budgets = Budgets {
            accel_mg: 2.0,
            mag_pct: 0.5,
        };
        let fit = identity_fit(DMatrix::zeros(9, 9));
        let aligned = judge(&fit, &within, None, budgets, 9.8);
        assert_eq!(aligned.level, VerdictLevel::Good, "{:?}", aligned.reasons);
        let error = "only 4 poses for the rotation and the dip".to_string();
        let failed = judge(&fit, &within, Some(&error), budgets, 9.8);
        assert_eq!(failed.level, VerdictLevel::Poor);
        assert!(
            failed.reasons.iter().any(|r| r.contains(&error)),
            "{:?}",
            failed.reasons
        );
    }

    /// `count` readings of a 48 µT field around a hard-iron offset along a Fibonacci spiral over
    /// the part of the sphere with `z ≥ z_min`, with ±0.2 µT of deterministic noise per axis.
    fn field_readings(count: usize, z_min: f64) -> Vec<Vec3> {
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        (0..count)
            .map(|i| {
                let z = 1.0 - (1.0 - z_min) * (i as f64 + 0.5) / count as f64;
                let r = (1.0 - z * z).sqrt();
                let phi = golden * i as f64;
                let noise = |k: f64| 0.2 * (i as f64 * 12.9898 + k * 78.233).sin();
                Vec3::new(30.0, -45.0, 12.0)
                    + 48.0 * Vec3::new(r * phi.cos(), r * phi.sin(), z)
                    + Vec3::new(noise(1.0), noise(2.0), noise(3.0))
            })
            .collect()
    }

    #[test]
    fn the_expected_field_error_grows_as_the_readings_cover_less_of_the_sphere() {
        let whole = expected_mag_error_pct(&field_readings(2000, -1.0), Some(48.0), 3000);
        let upper = expected_mag_error_pct(&field_readings(2000, 0.0), Some(48.0), 3000);
        // ±0.2 µT of noise on 2000 readings: the whole sphere pins |m| to a few thousandths of
        // a percent of 48 µT; half of it leaves the other half to extrapolation.
        assert!(whole.is_finite() && whole > 0.0 && whole < 0.05, "{whole}");
        assert!(
            upper > 2.0 * whole,
            "half sphere {upper} %, whole {whole} %"
        );
        assert!(expected_mag_error_pct(&[], Some(48.0), 3000).is_infinite());
    }
}
