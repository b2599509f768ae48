//! The one default accelerometer chain, used by `fit`, `calibrate` and `analyze` alike.
//!
//! Candidates, simplest first: the axis-aligned ellipsoid (6 unknowns: scales and offsets), the
//! norm model solved by Levenberg–Marquardt (9: upper-triangular `A` and `b`) and the
//! six-position least squares of seed 000 eq. 11–15 (12: full `A` and `b`, poses labelled by
//! their nearest face). Each is first fitted on every pose with its own refusals (coverage,
//! faces, closed ellipsoid).
//!
//! **Choice by leave-one-pose-out (LOPO) error of the norm residual** `(|A(xᵢ − b)| − g)/g`,
//! each pose predicted by the model fitted without it. This measures what a calibration is for —
//! predicting |g| in orientations it was not fitted on — in the same unit for every model,
//! including six-position, whose vector residual is not comparable to a norm residual and
//! whose known-direction assumption an information criterion on its own residual would not
//! test. AIC/BIC would also need a noise model that holds across poses; on real recordings the
//! pose-to-pose scatter (placement, temperature) exceeds the within-pose noise several times,
//! which makes their penalties arbitrary, whereas LOPO needs no noise model.
//!
//! **One-standard-error rule** (Hastie, Tibshirani & Friedman, *Elements of Statistical
//! Learning*, §7.10): the LOPO mean square error is itself an estimate, with standard error
//! `sd(eᵢ²)/√n`. Among the models whose LOPO MSE is within one standard error of the best, the
//! one with the fewest unknowns is chosen: the data cannot tell them apart, and the simpler one
//! has the smaller variance on poses not seen. The rule has no tuned threshold: its margin is
//! the sampling error of the data at hand.
//!
//! **Models are compared on the same held-out poses.** A refit can be refused when a pose is
//! left out (leaving out the only hold of a face leaves a norm model without that direction;
//! six-position, knowing the directions, still fits). Errors are therefore compared on the poses
//! every model can be refit without — a paired comparison, which scoring each model on its own
//! folds would not be. When fewer than [`MIN_COMMON_FOLDS`] such poses remain, the model with
//! the fewest successful refits is set aside as not validated and the rest compared again. When
//! no model can be validated (e.g. only six poses), the fitted model with the fewest unknowns is
//! used. The output says which case applied.

use crate::fit::axis_aligned::{fit_axis_aligned, fit_axis_aligned_poses};
use crate::fit::loo::leave_one_out_errors;
use crate::fit::norm_lm::{fit_accel_lm, fit_accel_lm_detailed};
use crate::fit::six_position::{fit_six_position, nearest_axes, six_position_calibration};
use crate::fit::{Calibration, Fit, FitError, Method, Pose, Vec3};

/// Fewest held-out poses a comparison rests on: with fewer, the standard error of the mean square
/// (from `n − 1` degrees of freedom) is not an estimate.
pub const MIN_COMMON_FOLDS: usize = 3;

/// The candidate models, simplest (fewest unknowns) first.
pub const CANDIDATES: [Method; 3] = [Method::AxisAligned, Method::Lm, Method::SixPosition];

/// Number of unknowns of a candidate model.
pub fn unknowns(method: Method) -> usize {
    match method {
        Method::AxisAligned => 6,
        Method::Lm => 9,
        _ => 12,
    }
}

/// How one candidate fared.
#[derive(Debug, Clone)]
pub enum CandidateOutcome {
    /// The model refused the poses (the sentence says why).
    Refused(String),
    /// It fitted every pose, but some held-out refit failed.
    NotValidated(String),
    /// Leave-one-pose-out error of the relative norm residual over the poses every compared
    /// model could be refit without.
    Scored {
        /// Held-out poses the score rests on.
        folds: usize,
        /// RMS of the held-out residuals (relative to g).
        lopo_rms: f64,
        /// Mean of the squared held-out residuals.
        lopo_mse: f64,
        /// Standard error of `lopo_mse`.
        lopo_mse_se: f64,
    },
}

/// One candidate model and its outcome.
#[derive(Debug, Clone)]
pub struct Candidate {
    /// The model.
    pub method: Method,
    /// What happened to it.
    pub outcome: CandidateOutcome,
}

/// The chain's result: the fit of the chosen model and why it was chosen.
#[derive(Debug, Clone)]
pub struct ChainChoice {
    /// The chosen model fitted on every pose.
    pub fit: Fit,
    /// Every candidate, in [`CANDIDATES`] order.
    pub candidates: Vec<Candidate>,
    /// One sentence: why this model, and why not the others.
    pub reason: String,
}

/// Fit `poses` with the default chain (see the module comment) to gravity `reference`.
pub fn default_accel_chain(poses: &[Pose], reference: f64) -> Result<ChainChoice, FitError> {
    let mut fits: Vec<(Method, Fit)> = Vec::new();
    let mut outcomes: Vec<(Method, Option<CandidateOutcome>)> = Vec::new();
    let mut folds: Vec<(Method, Vec<Option<f64>>)> = Vec::new();
    for method in CANDIDATES {
        match fit_full(method, poses, reference) {
            Err(e) => outcomes.push((method, Some(CandidateOutcome::Refused(e.to_string())))),
            Ok(fit) => {
                folds.push((method, held_out_errors(method, poses, reference)));
                fits.push((method, fit));
                outcomes.push((method, None));
            }
        }
    }
    for (method, outcome) in compare(folds, poses.len()) {
        if let Some(slot) = outcomes.iter_mut().find(|(m, _)| *m == method) {
            slot.1 = Some(outcome);
        }
    }
    let candidates: Vec<Candidate> = outcomes
        .into_iter()
        .filter_map(|(method, outcome)| {
            Some(Candidate {
                method,
                outcome: outcome?,
            })
        })
        .collect();
    let Some(chosen) = choose(&candidates).or_else(|| fits.first().map(|(m, _)| *m)) else {
        let reasons: Vec<String> = candidates
            .iter()
            .map(|c| format!("{}: {}", c.method.name(), describe(&c.outcome)))
            .collect();
        return Err(FitError::Underdetermined(format!(
            "no accelerometer model fits these poses ({})",
            reasons.join("; ")
        )));
    };
    let reason = explain(chosen, &candidates);
    let fit = fits
        .into_iter()
        .find(|(m, _)| *m == chosen)
        .map(|(_, f)| f)
        .ok_or_else(|| FitError::Underdetermined("the chosen model has no fit".into()))?;
    Ok(ChainChoice {
        fit,
        candidates,
        reason,
    })
}

/// The full fit of one candidate, with its refusals.
fn fit_full(method: Method, poses: &[Pose], reference: f64) -> Result<Fit, FitError> {
    match method {
        Method::AxisAligned => fit_axis_aligned_poses(poses, reference),
        Method::Lm => fit_accel_lm(poses, reference),
        _ => fit_six_position(poses, None, reference),
    }
}

/// A refit of one candidate on the poses without one (the solver and its refusals, without the
/// fit's own leave-one-out statistics).
fn refit(
    method: Method,
    rest: &[Pose],
    rest_faces: &[Vec3],
    reference: f64,
) -> Result<Calibration, FitError> {
    match method {
        Method::AxisAligned => {
            let means: Vec<Vec3> = rest.iter().map(|p| p.mean).collect();
            fit_axis_aligned(&means, reference).map(|f| f.cal)
        }
        Method::Lm => fit_accel_lm_detailed(rest, reference).map(|o| o.fit.cal),
        _ => six_position_calibration(rest, rest_faces, reference),
    }
}

/// The held-out error of every pose for a candidate that fitted every pose (`None` where the
/// refit without that pose was refused).
fn held_out_errors(method: Method, poses: &[Pose], reference: f64) -> Vec<Option<f64>> {
    // Six-position keeps each pose's face from the full set, so a held-out pose is judged
    // against the same label it had when all poses were fitted.
    let faces: Vec<Vec3> = nearest_axes(poses)
        .into_iter()
        .map(|f| f.unwrap_or_else(Vec3::zeros))
        .collect();
    leave_one_out_errors(poses, reference, |i, rest| {
        let rest_faces: Vec<Vec3> = faces
            .iter()
            .enumerate()
            .filter(|&(j, _)| j != i)
            .map(|(_, f)| *f)
            .collect();
        refit(method, rest, &rest_faces, reference)
    })
    .unwrap_or_default()
}

/// Score the candidates on the held-out poses they can all be refit without, setting aside the
/// one with the fewest refits while fewer than [`MIN_COMMON_FOLDS`] such poses remain.
fn compare(
    mut folds: Vec<(Method, Vec<Option<f64>>)>,
    n_poses: usize,
) -> Vec<(Method, CandidateOutcome)> {
    let mut outcomes = Vec::new();
    loop {
        let common: Vec<usize> = (0..n_poses)
            .filter(|&i| {
                folds
                    .iter()
                    .all(|(_, e)| e.get(i).copied().flatten().is_some())
            })
            .collect();
        if common.len() >= MIN_COMMON_FOLDS || folds.is_empty() {
            for (method, errors) in &folds {
                let squares: Vec<f64> = common
                    .iter()
                    .filter_map(|&i| errors.get(i).copied().flatten())
                    .map(|e| e * e)
                    .collect();
                let n = squares.len() as f64;
                let mse = squares.iter().sum::<f64>() / n;
                let var = squares.iter().map(|s| (s - mse).powi(2)).sum::<f64>() / (n - 1.0);
                outcomes.push((
                    *method,
                    CandidateOutcome::Scored {
                        folds: common.len(),
                        lopo_rms: mse.sqrt(),
                        lopo_mse: mse,
                        lopo_mse_se: (var / n).sqrt(),
                    },
                ));
            }
            return outcomes;
        }
        // Set aside the candidate with the fewest successful refits (the most complex on a tie).
        let Some(worst) = folds
            .iter()
            .enumerate()
            .min_by_key(|(k, (_, e))| (e.iter().flatten().count(), usize::MAX - k))
            .map(|(k, _)| k)
        else {
            return outcomes;
        };
        let (method, errors) = folds.remove(worst);
        let refits = errors.iter().flatten().count();
        outcomes.push((
            method,
            CandidateOutcome::NotValidated(format!(
                "it could be refit without only {refits} of the {n_poses} poses, too few to \
                 compare its error on poses it was not fitted on"
            )),
        ));
    }
}

/// The one-standard-error choice among the scored candidates, or `None` when none is scored.
fn choose(candidates: &[Candidate]) -> Option<Method> {
    let scored: Vec<(Method, f64, f64)> = candidates
        .iter()
        .filter_map(|c| match c.outcome {
            CandidateOutcome::Scored {
                lopo_mse,
                lopo_mse_se,
                ..
            } => Some((c.method, lopo_mse, lopo_mse_se)),
            _ => None,
        })
        .collect();
    let (_, best_mse, best_se) = scored.iter().copied().min_by(|a, b| a.1.total_cmp(&b.1))?;
    // CANDIDATES is ordered simplest first, and so is `scored`.
    scored
        .iter()
        .find(|(_, mse, _)| *mse <= best_mse + best_se)
        .map(|(m, _, _)| *m)
}

fn describe(outcome: &CandidateOutcome) -> String {
    match outcome {
        CandidateOutcome::Refused(e) => format!("refused ({e})"),
        CandidateOutcome::NotValidated(e) => format!("not validated ({e})"),
        CandidateOutcome::Scored {
            lopo_rms, folds, ..
        } => format!("held-out error {lopo_rms:.3e} of g over {folds} poses"),
    }
}

/// Why `chosen` was chosen and the others were not.
fn explain(chosen: Method, candidates: &[Candidate]) -> String {
    let outcome_of = |m: Method| {
        candidates
            .iter()
            .find(|c| c.method == m)
            .map(|c| &c.outcome)
    };
    let head = match outcome_of(chosen) {
        Some(CandidateOutcome::Scored {
            lopo_rms, folds, ..
        }) => format!(
            "{} ({} unknowns) chosen by leave-one-pose-out error: {:.3e} of g over the {} poses \
             every compared model could be refit without, the simplest model within one \
             standard error of the best",
            chosen.name(),
            unknowns(chosen),
            lopo_rms,
            folds
        ),
        _ => format!(
            "{} ({} unknowns) chosen as the simplest model that fits, since no model could be \
             validated on held-out poses",
            chosen.name(),
            unknowns(chosen)
        ),
    };
    let others: Vec<String> = candidates
        .iter()
        .filter(|c| c.method != chosen)
        .map(|c| {
            let why = match &c.outcome {
                CandidateOutcome::Scored { lopo_rms, .. } => {
                    if unknowns(c.method) > unknowns(chosen) {
                        format!(
                            "held-out error {lopo_rms:.3e}, no better within the standard error \
                             for {} more unknowns",
                            unknowns(c.method) - unknowns(chosen)
                        )
                    } else {
                        format!(
                            "held-out error {lopo_rms:.3e}, worse by more than its standard error"
                        )
                    }
                }
                other => describe(other),
            };
            format!("{}: {why}", c.method.name())
        })
        .collect();
    if others.is_empty() {
        head
    } else {
        format!("{head}; not chosen: {}", others.join("; "))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::Mat3;

    /// Pose means of a sensor with `a_inv` (raw = a_inv·g·u + b) in directions `dirs`,
    /// with a small deterministic perturbation of size `jitter` per pose.
    fn poses(a_inv: &Mat3, b: &Vec3, dirs: &[Vec3], jitter: f64) -> Vec<Pose> {
        dirs.iter()
            .enumerate()
            .map(|(i, d)| {
                let wobble = Vec3::new(
                    (i as f64 * 1.7).sin(),
                    (i as f64 * 2.3).cos(),
                    (i as f64 * 0.9).sin(),
                ) * jitter;
                Pose {
                    mean: a_inv * (d.normalize() * 9.81) + b + wobble,
                    var: Vec3::repeat(1e-6),
                    n: 100,
                    label: None,
                }
            })
            .collect()
    }

    fn faces() -> Vec<Vec3> {
        vec![
            Vec3::x(),
            -Vec3::x(),
            Vec3::y(),
            -Vec3::y(),
            Vec3::z(),
            -Vec3::z(),
        ]
    }

    fn tilted_directions() -> Vec<Vec3> {
        let mut dirs = Vec::new();
        for x in [-1.0, 0.0, 1.0] {
            for y in [-1.0, 0.0, 1.0] {
                for z in [-1.0, 0.0, 1.0] {
                    let d = Vec3::new(x, y, z);
                    if d.norm() > 0.0 {
                        dirs.push(d);
                    }
                }
            }
        }
        dirs
    }

    #[test]
    fn cross_axis_coupling_that_the_data_determine_selects_the_norm_model() {
        // 26 well-spread directions and 2 % cross-axis terms: the axis-aligned model cannot
        // predict held-out poses, lm can; six-position refuses poses far from the faces.
        let a_inv = Mat3::new(1.02, 0.02, -0.015, 0.0, 0.98, 0.02, 0.0, 0.0, 1.01);
        let set = poses(
            &a_inv,
            &Vec3::new(0.1, -0.2, 0.05),
            &tilted_directions(),
            1e-4,
        );
        let choice = default_accel_chain(&set, 9.81).expect("fits");
        assert_eq!(choice.fit.method, Method::Lm, "{}", choice.reason);
        assert!(
            choice.reason.contains("six-position: refused"),
            "{}",
            choice.reason
        );
    }

    #[test]
    fn a_sensor_without_cross_coupling_gets_the_simpler_axis_aligned_model() {
        // Diagonal truth: lm's three extra unknowns cannot lower the held-out error by more than
        // its standard error, so parsimony picks the 6-unknown model.
        let a_inv = Mat3::from_diagonal(&Vec3::new(1.02, 0.98, 1.01));
        let set = poses(
            &a_inv,
            &Vec3::new(0.1, -0.2, 0.05),
            &tilted_directions(),
            1e-3,
        );
        let choice = default_accel_chain(&set, 9.81).expect("fits");
        assert_eq!(choice.fit.method, Method::AxisAligned, "{}", choice.reason);
        assert!(
            choice.reason.contains("lm: held-out error"),
            "{}",
            choice.reason
        );
    }

    #[test]
    fn six_faces_are_validated_only_by_six_position_which_is_chosen() {
        // Without one face the norm models lose a direction; six-position, knowing the faces,
        // can still be refit and so is the only model whose held-out error can be measured.
        let a_inv = Mat3::from_diagonal(&Vec3::new(1.02, 0.98, 1.01));
        let set = poses(&a_inv, &Vec3::new(0.1, -0.2, 0.05), &faces(), 1e-4);
        let choice = default_accel_chain(&set, 9.81).expect("fits");
        assert_eq!(choice.fit.method, Method::SixPosition, "{}", choice.reason);
        assert!(
            choice.reason.contains("axis-aligned: not validated"),
            "{}",
            choice.reason
        );
    }

    #[test]
    fn when_no_model_can_be_validated_the_fewest_unknowns_fit_is_used() {
        // Five faces and one tilted pose: six-position refuses the tilted pose, lm has too few
        // directions, and the axis-aligned model is exactly determined (no refit without a pose).
        let mut dirs = faces()[..5].to_vec();
        dirs.push(Vec3::new(1.0, 1.0, -1.0));
        let a_inv = Mat3::from_diagonal(&Vec3::new(1.02, 0.98, 1.01));
        let set = poses(&a_inv, &Vec3::new(0.1, -0.2, 0.05), &dirs, 1e-4);
        let choice = default_accel_chain(&set, 9.81).expect("fits");
        assert_eq!(choice.fit.method, Method::AxisAligned, "{}", choice.reason);
        assert!(
            choice.reason.contains("no model could be validated"),
            "{}",
            choice.reason
        );
        // Exactly determined: the scale comes back to the jitter's order (1e-4 of g).
        assert!((choice.fit.cal.a[(0, 0)] - 1.0 / 1.02).abs() < 1e-3);
    }

    #[test]
    fn poses_that_no_model_fits_give_an_error_naming_every_model() {
        let a_inv = Mat3::identity();
        let set = poses(
            &a_inv,
            &Vec3::zeros(),
            &[Vec3::z(), Vec3::z(), Vec3::z()],
            1e-4,
        );
        let message = default_accel_chain(&set, 9.81)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        for name in ["axis-aligned", "lm", "six-position"] {
            assert!(message.contains(name), "{message}");
        }
    }
}
