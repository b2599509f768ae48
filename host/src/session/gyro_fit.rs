//! The whole gyroscope of a session: bias from the holds, then scale and misalignment from the
//! moves between them by Tedaldi, Pretto & Menegatti (2014, §IV-B;
//! [`crate::fit::gyro_scale::fit_gyro_scale`]), written into the session's set as `A` and `b`.
//!
//! Bias: the inverse-variance mean of the hand-held poses' bias (seed 000 eq. 9, its σ inflated
//! by the scatter of the holds, [`super::solve`]) and the mean rate while the board lay on the
//! table for the "before" measurement, the one hold without a hand on the board. The moves'
//! integration error grows with the bias error times the move's length, so the better of the two
//! dominates as it should.
//!
//! Scale and misalignment: the moves' gravity directions depend on the gyroscope matrix through
//! the sway correction of their still ends ([`super::gyro_moves`]), so the fit is run twice,
//! the second time with the ends turned by the first result.
//!
//! Each move counts by the inverse of its own angle noise ([`super::gyro_moves::motion_of`]),
//! the gyroscope's white noise taken from the rest's scatter when the board lay still.
//!
//! The σ of `A` adds to the moves' scatter what the fit inherits from the accelerometer's
//! calibration and the bias ([`super::gyro_nuisance`]): errors common to every move.
//!
//! With a magnetometer aligned to the accelerometer, the field direction at the moves' ends is a
//! second reference ([`super::gyro_field`], [`crate::fit::gyro_joint`]): gravity cannot see a
//! turn about the vertical, the field can, so the axis the positions tilt least (on the twelve
//! positions, body Z) is no longer the weak one. Without a usable field (no magnetometer, no
//! alignment, fewer than [`crate::fit::gyro_joint::MIN_FIELD_MOTIONS`] moves with a steady
//! field, or a failed joint fit) the gravity-only fit is used and a note says why.

use nalgebra::UnitQuaternion;
use serde::Serialize;

use super::gyro_field::{field_seconds, fit_with_field, FieldReference};
use super::gyro_moves::{motions_of, tilt_per_axis_deg};
use super::gyro_nuisance::{inherited_covariance, Nuisance};
use super::solve::{SessionFit, VerdictLevel};
use crate::device::UnitSample;
use crate::fit::covariance::{calibration_std, FULL_MATRIX_LAYOUT};
use crate::fit::gyro_scale::{fit_gyro_scale, integrate_rotation};
use crate::fit::{Calibration, CalibrationStd, Fit, FitError, Mat3, Vec3};

/// What the gyroscope's scale fit must reach, 3σ (the verdict says so when it does not).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct GyroBudgets {
    /// Scale error per axis, %.
    pub scale_pct: f64,
    /// Misalignment (each off-diagonal angle), degrees.
    pub misalignment_deg: f64,
}

impl Default for GyroBudgets {
    /// 0.1 % and 0.05°: a 360° turn then integrates to within ≈0.4°.
    fn default() -> Self {
        Self {
            scale_pct: 0.1,
            misalignment_deg: 0.05,
        }
    }
}

/// The gyroscope's scale and misalignment as people read them, with one-sigma uncertainties.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GyroScale {
    /// Scale factor per axis (diagonal of `A`, output per nominal unit).
    pub scale: [f64; 3],
    /// One-sigma of each scale factor, % of it.
    pub scale_sigma_pct: [f64; 3],
    /// Largest off-diagonal angle `Aᵢⱼ/Aⱼⱼ`, degrees (cross-axis and mounting together).
    pub misalignment_deg: f64,
    /// Largest one-sigma of those angles, degrees.
    pub misalignment_sigma_deg: f64,
    /// Moves recorded between holds.
    pub moves_recorded: usize,
    /// Moves whose still ends and gap-free stream made them usable.
    pub moves_used: usize,
    /// RMS angle mismatch of the moves after the fit, degrees.
    pub rms_deg: f64,
    /// Tilting rotation about each body axis over all moves, degrees.
    pub tilt_deg: [f64; 3],
    /// Whether the field direction was a second reference (false: gravity only).
    pub field_reference: bool,
    /// Moves whose field direction was used.
    pub field_moves: usize,
    /// Seconds of stream in those moves.
    pub field_seconds: f64,
    /// `χ²/ν` of the noise-weighted residuals of the joint fit (`None` for gravity only, whose
    /// noise is estimated from the residuals).
    pub reduced_chi_square: Option<f64>,
    /// Why the field was not used, when it was not.
    pub gravity_only_reason: Option<String>,
}

/// Mean gyroscope rate and its standard error per axis of samples taken lying still; `None`
/// when there are fewer than two samples or they turn by more than `still_rate` (rad/s, per-axis
/// standard deviation): a hand on the board.
pub fn rest_bias(samples: &[UnitSample], still_rate: f64) -> Option<(Vec3, Vec3)> {
    if samples.len() < 2 {
        return None;
    }
    let n = samples.len() as f64;
    let mean = samples.iter().map(|s| Vec3::from(s.gyro)).sum::<Vec3>() / n;
    let var = samples
        .iter()
        .map(|s| (Vec3::from(s.gyro) - mean).map(|v| v * v))
        .sum::<Vec3>()
        / (n - 1.0);
    let std = var.map(f64::sqrt);
    (std.max() < still_rate).then(|| (mean, std / n.sqrt()))
}

/// Inverse-variance mean of two estimates per axis, with its σ.
fn combine(a: (Vec3, Vec3), b: (Vec3, Vec3)) -> (Vec3, Vec3) {
    let mut mean = Vec3::zeros();
    let mut sigma = Vec3::zeros();
    for i in 0..3 {
        let (wa, wb) = (a.1[i].powi(-2), b.1[i].powi(-2));
        if !(wa.is_finite() && wb.is_finite()) {
            // A zero σ (exact data) wins outright.
            let (m, s) = if a.1[i] <= b.1[i] { a } else { b };
            mean[i] = m[i];
            sigma[i] = s[i];
            continue;
        }
        mean[i] = (a.0[i] * wa + b.0[i] * wb) / (wa + wb);
        sigma[i] = (wa + wb).powf(-0.5);
    }
    (mean, sigma)
}

/// Fit the gyroscope's scale and misalignment from `moves` and write the whole gyroscope into
/// `fit` (its `gyro` fit, the set's `A`, `b` and residual, the bias σ, and the verdict). `rest`
/// is the raw stream of the board lying still (used for the bias when still). On failure `fit`
/// keeps the bias-only gyroscope, the verdict says why, and the error is returned.
pub fn complete_gyro(
    fit: &mut SessionFit,
    moves: &[Vec<UnitSample>],
    rest: &[UnitSample],
    still_rate: f64,
    budgets: GyroBudgets,
    mag_budget_pct: f64,
) -> Result<GyroScale, FitError> {
    let holds = (
        fit.gyro.cal.b,
        Vec3::from(fit.uncertainties.gyro_bias_dps.map(f64::to_radians)),
    );
    let table = rest_bias(rest, still_rate);
    let (bias, bias_sigma) = match table {
        Some(table) => combine(holds, table),
        None => holds,
    };
    // The rest's per-sample scatter is the gyroscope's white noise (no hand on the board).
    let rate_noise = table.map(|(_, se)| se.norm() / 3f64.sqrt() * (rest.len() as f64).sqrt());
    let nuisance = Nuisance {
        accel: &fit.accel,
        bias,
        bias_sigma,
        rate_noise,
    };
    let (mag, alignment) = (fit.mag.clone(), fit.alignment.clone());
    let reference = alignment.as_ref().ok().map(|alignment| FieldReference {
        mag: &mag,
        alignment,
        field_ut: fit.field_ut,
        mag_budget_pct,
    });
    let result = match &reference {
        Some(reference) => {
            fit_joint_scale(moves, &nuisance, reference, still_rate).or_else(|error| {
                let reason = format!("the joint fit with the field failed ({error})");
                fit_scale(moves, &nuisance, still_rate, reason)
            })
        }
        None => fit_scale(
            moves,
            &nuisance,
            still_rate,
            "the magnetometer is not aligned to the accelerometer".into(),
        ),
    };
    if let Ok((_, summary)) = &result {
        fit.notes.push(match &summary.gravity_only_reason {
            Some(reason) => format!(
                "the gyroscope's scale and misalignment were fitted against gravity alone: \
                 {reason}; the rotation about the vertical is then seen only through the tilts"
            ),
            None => format!(
                "the gyroscope's scale and misalignment were fitted against gravity and the \
                 field direction ({} of {} moves with a steady field, χ²/ν {:.2})",
                summary.field_moves,
                summary.moves_used,
                summary.reduced_chi_square.unwrap_or(f64::NAN)
            ),
        });
    }
    let (scale_fit, summary) = match result {
        Ok(found) => found,
        Err(error) => {
            fit.verdict.reasons.push(format!(
                "the gyroscope's scale and misalignment were not calibrated ({error}); only its \
                 bias was"
            ));
            if fit.verdict.level == VerdictLevel::Good {
                fit.verdict.level = VerdictLevel::Marginal;
            }
            return Err(error);
        }
    };
    let std = scale_fit.std.map(|s| CalibrationStd {
        a: s.a,
        b: bias_sigma,
    });
    fit.gyro = Fit {
        cal: Calibration {
            a: scale_fit.cal.a,
            b: bias,
        },
        std,
        ..scale_fit
    };
    fit.uncertainties.gyro_bias_dps = [0, 1, 2].map(|i| bias_sigma[i].to_degrees());
    fit.set.gyro.a = [0, 1, 2].map(|r| [0, 1, 2].map(|c| fit.gyro.cal.a[(r, c)] as f32));
    fit.set.gyro.b = [bias.x as f32, bias.y as f32, bias.z as f32];
    fit.set.residuals.gyro_rms = fit.gyro.rms as f32;
    judge(fit, &summary, budgets);
    Ok(summary)
}

/// Tedaldi's fit of the usable moves against gravity alone, twice (see the module
/// documentation), with the calibrated accelerometer `accel`, the gyroscope's `bias` and its
/// per-sample `rate_noise`; its covariance is the fit's own. Also returns the motions used.
pub(super) fn fit_against_gravity(
    moves: &[Vec<UnitSample>],
    accel: &Calibration,
    bias: &Vec3,
    still_rate: f64,
    rate_noise: Option<f64>,
) -> Result<(Fit, usize), FitError> {
    let first = motions_of(
        moves,
        accel,
        &Mat3::identity(),
        bias,
        still_rate,
        rate_noise,
    );
    let rough = fit_gyro_scale(&first, None)?;
    let motions = motions_of(moves, accel, &rough.cal.a, bias, still_rate, rate_noise);
    let fit = fit_gyro_scale(&motions, Some(&rough.cal.a))?;
    Ok((fit, motions.len()))
}

/// [`fit_against_gravity`] with the covariance including what it inherits from `nuisance`;
/// `reason` says why the field is not used.
fn fit_scale(
    moves: &[Vec<UnitSample>],
    nuisance: &Nuisance<'_>,
    still_rate: f64,
    reason: String,
) -> Result<(Fit, GyroScale), FitError> {
    let (mut fit, used) = fit_against_gravity(
        moves,
        &nuisance.accel.cal,
        &nuisance.bias,
        still_rate,
        nuisance.rate_noise,
    )?;
    let inherited = inherited_covariance(moves, &fit.cal.a, nuisance, still_rate);
    if let (Some(own), Some(inherited)) = (fit.covariance.as_mut(), inherited) {
        *own += inherited;
        fit.std = Some(calibration_std(own, &FULL_MATRIX_LAYOUT));
    }
    let mut summary = summarise(&fit, moves, used);
    summary.gravity_only_reason = Some(reason);
    Ok((fit, summary))
}

/// The joint fit with the field ([`fit_with_field`]) and its summary.
fn fit_joint_scale(
    moves: &[Vec<UnitSample>],
    nuisance: &Nuisance<'_>,
    reference: &FieldReference<'_>,
    still_rate: f64,
) -> Result<(Fit, GyroScale), FitError> {
    let (joint, motions) = fit_with_field(moves, nuisance, reference, still_rate)?;
    let mut summary = summarise(&joint.fit, moves, motions.len());
    summary.field_reference = true;
    summary.field_moves = joint.field_motions;
    summary.field_seconds = field_seconds(&motions);
    summary.reduced_chi_square = joint.reduced_chi_square;
    Ok((joint.fit, summary))
}

/// The people's reading of a fitted `A` (gravity only until the caller says otherwise).
fn summarise(fit: &Fit, moves: &[Vec<UnitSample>], used: usize) -> GyroScale {
    let a = fit.cal.a;
    let sigma = fit.std.map_or(Mat3::zeros(), |s| s.a);
    let mut misalignment: f64 = 0.0;
    let mut misalignment_sigma: f64 = 0.0;
    for r in 0..3 {
        for c in (0..3).filter(|&c| c != r) {
            misalignment = misalignment.max((a[(r, c)] / a[(c, c)]).abs().atan().to_degrees());
            misalignment_sigma =
                misalignment_sigma.max((sigma[(r, c)] / a[(c, c)].abs()).to_degrees());
        }
    }
    GyroScale {
        scale: [a[(0, 0)], a[(1, 1)], a[(2, 2)]],
        scale_sigma_pct: [0, 1, 2].map(|i| sigma[(i, i)] / a[(i, i)].abs() * 100.0),
        misalignment_deg: misalignment,
        misalignment_sigma_deg: misalignment_sigma,
        moves_recorded: moves.len(),
        moves_used: used,
        rms_deg: fit.rms.to_degrees(),
        tilt_deg: tilt_per_axis_deg(moves),
        field_reference: false,
        field_moves: 0,
        field_seconds: 0.0,
        reduced_chi_square: None,
        gravity_only_reason: None,
    }
}

/// Add a reason to the verdict when the scale fit's 3σ exceeds its budgets, naming the part(s)
/// over.
fn judge(fit: &mut SessionFit, scale: &GyroScale, budgets: GyroBudgets) {
    if let Some(reason) = over_budget(scale, budgets) {
        fit.verdict.reasons.push(reason);
        if fit.verdict.level == VerdictLevel::Good {
            fit.verdict.level = VerdictLevel::Marginal;
        }
    }
}

/// The sentence for the part(s) of the scale fit whose 3σ exceeds its budget; `None` when both
/// are within.
fn over_budget(scale: &GyroScale, budgets: GyroBudgets) -> Option<String> {
    let worst_scale = scale.scale_sigma_pct.iter().copied().fold(0.0, f64::max);
    let mut over = Vec::new();
    if 3.0 * worst_scale > budgets.scale_pct {
        over.push(format!(
            "the gyroscope's scale is known to {worst_scale:.3} % (1σ), above a third of its {} % \
             budget",
            budgets.scale_pct
        ));
    }
    if 3.0 * scale.misalignment_sigma_deg > budgets.misalignment_deg {
        over.push(format!(
            "{} misalignment is known to {:.3}° (1σ), above a third of its {}° budget",
            if over.is_empty() {
                "the gyroscope's"
            } else {
                "its"
            },
            scale.misalignment_sigma_deg,
            budgets.misalignment_deg
        ));
    }
    (!over.is_empty()).then(|| {
        format!(
            "{}; turn the board between the positions about each of its axes (tilting it, not \
             about the vertical)",
            over.join(" and ")
        )
    })
}

/// Angle, degrees, of the rotation left after integrating a 360° turn about body `axis`
/// (minimum-jerk, `duration_s`, sampled at `rate_hz`) read by a gyroscope whose raw reading of
/// a true rate `ω` is `raw(ω)`, and corrected by `correction`: how far a heading would drift over
/// one full turn.
pub fn full_turn_error_deg(
    correction: &Calibration,
    raw: impl Fn(&Vec3) -> Vec3,
    axis: usize,
    duration_s: f64,
    rate_hz: f64,
) -> f64 {
    let steps = (duration_s * rate_hz).round().max(2.0) as usize;
    let dt = duration_s / steps as f64;
    let unit = Vec3::ith(axis.min(2), 1.0);
    let rates: Vec<Vec3> = (0..=steps)
        .map(|k| {
            // Minimum-jerk profile: ṡ = 30 s² (1 − s)² over the normalised time s.
            let s = k as f64 / steps as f64;
            let rate = std::f64::consts::TAU / duration_s * 30.0 * s * s * (1.0 - s) * (1.0 - s);
            correction.apply(&raw(&(unit * rate)))
        })
        .collect();
    let turned: UnitQuaternion<f64> = integrate_rotation(&Mat3::identity(), &rates, dt);
    turned.angle().to_degrees()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scale_with(scale_sigma_pct: f64, misalignment_sigma_deg: f64) -> GyroScale {
        GyroScale {
            scale: [1.0; 3],
            scale_sigma_pct: [scale_sigma_pct; 3],
            misalignment_deg: 0.0,
            misalignment_sigma_deg,
            moves_recorded: 12,
            moves_used: 12,
            rms_deg: 0.03,
            tilt_deg: [500.0; 3],
            field_reference: true,
            field_moves: 12,
            field_seconds: 20.0,
            reduced_chi_square: Some(1.0),
            gravity_only_reason: None,
        }
    }

    #[test]
    fn the_verdict_names_only_the_part_of_the_gyroscope_fit_over_its_budget() {
        let budgets = GyroBudgets::default();
        // 0.026 % is within a third of 0.1 %; 0.030° is not within a third of 0.05°.
        let reason = over_budget(&scale_with(0.026, 0.030), budgets).expect("misalignment over");
        assert!(
            reason.starts_with("the gyroscope's misalignment is known to 0.030°"),
            "{reason}"
        );
        assert!(!reason.contains("scale is known"), "{reason}");
        let both = over_budget(&scale_with(0.05, 0.030), budgets).expect("both over");
        assert!(
            both.contains("scale is known to 0.050 %") && both.contains("and its misalignment"),
            "{both}"
        );
        assert_eq!(over_budget(&scale_with(0.02, 0.01), budgets), None);
    }

    #[test]
    fn a_perfect_gyroscope_turns_a_full_turn_back_to_where_it_started() {
        let exact = full_turn_error_deg(&Calibration::identity(), |w| *w, 2, 4.0, 119.0);
        // RK4 on a smooth profile at 119 Hz: the error is far below a thousandth of a degree.
        assert!(exact < 1e-3, "{exact}");
    }

    #[test]
    fn a_two_percent_scale_error_leaves_two_percent_of_a_turn() {
        let slow = full_turn_error_deg(&Calibration::identity(), |w| w * 0.98, 0, 4.0, 119.0);
        assert!((slow - 7.2).abs() < 0.01, "{slow}");
        let corrected = Calibration {
            a: Mat3::identity() / 0.98,
            b: Vec3::zeros(),
        };
        let fixed = full_turn_error_deg(&corrected, |w| w * 0.98, 0, 4.0, 119.0);
        assert!(fixed < 1e-3, "{fixed}");
    }

    #[test]
    fn the_rest_bias_is_refused_when_a_hand_turns_the_board() {
        let sample = |t_s: f64, w: f64| UnitSample {
            t_s,
            accel: [0.0, 0.0, 9.8],
            gyro: [w, 0.01, 0.0],
            mag: [0.0; 3],
            temp_c: 25.0,
        };
        let still: Vec<UnitSample> = (0..100).map(|k| sample(k as f64 * 0.01, 0.002)).collect();
        let (mean, sigma) = rest_bias(&still, 0.02).expect("still");
        assert!((mean.x - 0.002).abs() < 1e-12 && (mean.y - 0.01).abs() < 1e-12);
        assert!(sigma.max() < 1e-12);
        let turning: Vec<UnitSample> = (0..100)
            .map(|k| sample(k as f64 * 0.01, if k % 2 == 0 { 0.1 } else { -0.1 }))
            .collect();
        assert!(rest_bias(&turning, 0.02).is_none());
    }
}
