//! The one default accelerometer chain, used by `fit`, `calibrate` and `analyze` alike.
//!
//! Candidates, simplest first: the six-face min/max (6 unknowns: per-axis scale and offset from
//! the face readings, seed 004), the axis-aligned ellipsoid (6 unknowns: the same parameters by
//! least squares over every pose), the norm model solved by Levenberg–Marquardt (9:
//! upper-triangular `A` and `b`) and the six-position least squares of seed 000 eq. 11–15 (12:
//! full `A` and `b`, poses labelled by their nearest face). Each is first fitted on every pose
//! with its own refusals (coverage, faces, closed ellipsoid).
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
//! **Two estimators of the same unknowns are averaged unless a paired test tells them apart.**
//! Min/max and the axis-aligned ellipsoid estimate the same 6 unknowns, so choosing between them
//! is not a question of model size, and the one-standard-error rule is the wrong tool for it:
//! its margin is the unpaired standard error of one score, whereas the two scores rest on the
//! same poses and are strongly correlated (a pose far from the others, or one taken after the
//! sensor drifted, costs both). Whether one predicts held-out poses better than the other is a
//! paired question: Student's t on the per-pose differences of their squared held-out
//! residuals, two-sided at α = 0.05 ([`pair`], which states why). When it finds a difference,
//! the worse model leaves the contest. When it does not, picking the lower score anyway bets the
//! whole calibration on noise — selection between near equals has a large variance (Breiman
//! 1996, *Ann. Statist.* 24:2350) — so the mean of their outputs ([`mean`], again an
//! axis-aligned calibration) joins the contest with its own LOPO error on the same poses, and
//! is preferred to its members whenever it is itself within one standard error of the best.
//! Since `|·|²` is convex, its squared vector error on any pose is at most the mean of the two
//! models' (to first order the same holds for the norm residual), so whichever of the two turns
//! out better on poses not yet seen, the mean does no worse than their average.
//!
//! The mean must pass the same one-standard-error bar as every model because a t test on a few
//! poses has little power against a difference carried by one pose: one member far off on a
//! single pose (min/max reading a tilted hold as a face) gives `t ≈ 1` however large the
//! miss, and the average of a good and a bad model is not good. The bar, set by the best
//! model's own standard error, catches that case; the paired test catches consistent
//! differences the bar is too wide to see. Model size is decided by the bar alone.
//!
//! **Models are compared on the same held-out poses.** A refit can be refused when a pose is
//! left out (leaving out the only hold of a face leaves a norm model without that direction;
//! six-position, knowing the directions, still fits). Errors are therefore compared on the poses
//! every model can be refit without — a paired comparison, which scoring each model on its own
//! folds would not be. When fewer than [`MIN_COMMON_FOLDS`] such poses remain, the model with
//! the fewest successful refits is set aside as not validated and the rest compared again. When
//! no model can be validated (e.g. only six poses), the fitted model with the fewest unknowns is
//! used. The output says which case applied.

pub mod mean;
pub mod pair;

use crate::fit::axis_aligned::{self, fit_axis_aligned, fit_axis_aligned_poses};
use crate::fit::loo::{self, rms_of_all, UPDATED_FOLDS_MIN_POSES};
use crate::fit::minmax::{self, fit_minmax, minmax_calibration};
use crate::fit::norm_lm::{fit_accel_lm_detailed, refit_accel_lm_from};
use crate::fit::norm_loo::FoldUpdate;
use crate::fit::six_position::{fit_six_position, nearest_axes, six_position_calibration};
use crate::fit::{Calibration, Fit, FitError, Method, Pose, Vec3};
use mean::{mean_calibration, mean_fit};

/// RMS of the held-out errors that exist; `None` when none does.
fn rms_of_available(errors: Vec<Option<f64>>) -> Option<f64> {
    rms_of_all(errors.into_iter().flatten().map(Some).collect())
}
use pair::{paired_t, PairTest, PAIR_ALPHA};

/// Fewest held-out poses a comparison rests on: with fewer, the standard error of the mean square
/// (from `n − 1` degrees of freedom) is not an estimate.
pub const MIN_COMMON_FOLDS: usize = 3;

/// The candidate models, simplest (fewest unknowns) first.
pub const CANDIDATES: [Method; 4] = [
    Method::MinMax,
    Method::AxisAligned,
    Method::Lm,
    Method::SixPosition,
];

/// The two estimators of the same 6 unknowns: their mean replaces them unless a paired test on
/// their held-out errors finds one better (the only candidates with equally many unknowns).
pub const TIED_PAIR: [Method; 2] = [Method::MinMax, Method::AxisAligned];

/// Number of unknowns of an accelerometer model (or of the mean of [`TIED_PAIR`]): what the
/// norm residual's χ² test subtracts from the poses for its degrees of freedom.
pub fn unknowns(method: Method) -> usize {
    match method {
        Method::MinMax | Method::AxisAligned | Method::MinMaxAxisAlignedMean => 6,
        // A general ellipsoid (A up to a rotation, the norm model's gauge) and its centre.
        Method::Lm | Method::Chen | Method::Li | Method::Frosio | Method::Merayo => 9,
        Method::GyroBias => 3,
        // The whole matrix: the poses' expected directions fix the rotation too.
        Method::SixPosition | Method::GyroScale => 12,
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
    /// Every candidate, in [`CANDIDATES`] order, followed by the mean of [`TIED_PAIR`] when
    /// the paired test formed it.
    pub candidates: Vec<Candidate>,
    /// The paired test between the two [`TIED_PAIR`] models, when both were scored.
    pub pair: Option<PairTest>,
    /// One sentence: why this model, and why not the others.
    pub reason: String,
}

/// Fit `poses` with the default chain (see the module comment) to gravity `reference`.
pub fn default_accel_chain(poses: &[Pose], reference: f64) -> Result<ChainChoice, FitError> {
    accel_chain(poses, reference, UPDATED_FOLDS_MIN_POSES)
}

/// The chain, its held-out folds from the full fits from `updated_from` poses on (see
/// [`candidate_errors`]).
fn accel_chain(
    poses: &[Pose],
    reference: f64,
    updated_from: usize,
) -> Result<ChainChoice, FitError> {
    let faces = face_labels(poses);
    let mut fits: Vec<(Method, Fit)> = Vec::new();
    let mut outcomes: Vec<(Method, Option<CandidateOutcome>)> = Vec::new();
    let mut folds: Vec<(Method, Vec<Option<f64>>)> = Vec::new();
    for method in CANDIDATES {
        match fit_full(method, poses, reference) {
            Err(e) => outcomes.push((method, Some(CandidateOutcome::Refused(e.to_string())))),
            Ok((mut fit, update)) => {
                let errors =
                    candidate_errors(method, poses, &faces, reference, &fit, update, updated_from);
                if method == Method::Lm {
                    // The same held-out residuals `fit_accel_lm` would compute for itself.
                    fit.loo_rms = rms_of_all(errors.clone());
                }
                folds.push((method, errors));
                fits.push((method, fit));
                outcomes.push((method, None));
            }
        }
    }
    let (common, scores) = compare(folds.clone(), poses.len());
    for (method, outcome) in scores {
        if let Some(slot) = outcomes.iter_mut().find(|(m, _)| *m == method) {
            slot.1 = Some(outcome);
        }
    }
    let mut candidates: Vec<Candidate> = outcomes
        .into_iter()
        .filter_map(|(method, outcome)| {
            Some(Candidate {
                method,
                outcome: outcome?,
            })
        })
        .collect();
    // The models in the one-standard-error contest: every scored one, less the member of the
    // pair the paired test finds worse, or else joined by the pair's mean.
    let mut contest: Vec<Method> = candidates
        .iter()
        .filter(|c| matches!(c.outcome, CandidateOutcome::Scored { .. }))
        .map(|c| c.method)
        .collect();
    let pair = compare_pair(&folds, &common, &contest);
    let mut mean_errors = None;
    match pair {
        Some(test) if test.significant() => {
            let worse = pair_worse(&test);
            contest.retain(|&m| m != worse);
        }
        Some(_) => {
            let errors = pair_mean_errors(poses, &faces, reference, updated_from);
            candidates.push(Candidate {
                method: Method::MinMaxAxisAlignedMean,
                outcome: score(&errors, &common),
            });
            contest.push(Method::MinMaxAxisAlignedMean);
            mean_errors = Some(errors);
        }
        None => {}
    }
    let passing = within_one_se(&candidates, &contest);
    let chosen = simplest_passing(&passing, &candidates)
        // None validated: the fitted model with the fewest unknowns.
        .or_else(|| fits.first().map(|(m, _)| *m));
    let fit_of = |m: Method| fits.iter().find(|(f, _)| *f == m).map(|(_, f)| f);
    let fit = match (chosen, mean_errors) {
        (Some(Method::MinMaxAxisAlignedMean), Some(errors)) => {
            let members: Vec<&Fit> = TIED_PAIR.iter().filter_map(|&m| fit_of(m)).collect();
            mean_fit(
                Method::MinMaxAxisAlignedMean,
                &members,
                poses,
                reference,
                // Over the poses it could be refit without, as the contest scored it: the mean
                // of two refits exists wherever both members' refits do.
                rms_of_available(errors),
            )?
        }
        _ => match chosen.and_then(fit_of) {
            Some(fit) => fit.clone(),
            None => {
                let reasons: Vec<String> = candidates
                    .iter()
                    .map(|c| format!("{}: {}", c.method.name(), describe(&c.outcome)))
                    .collect();
                return Err(FitError::Underdetermined(format!(
                    "no accelerometer model fits these poses ({})",
                    reasons.join("; ")
                )));
            }
        },
    };
    let reason = explain(fit.method, &passing, &candidates, pair.as_ref());
    Ok(ChainChoice {
        fit,
        candidates,
        pair,
        reason,
    })
}

/// Among the `passing` models with the fewest unknowns: the mean of [`TIED_PAIR`] when it is one
/// of them, else the one with the lowest held-out mean square.
fn simplest_passing(passing: &[Method], candidates: &[Candidate]) -> Option<Method> {
    let fewest = passing.iter().map(|&m| unknowns(m)).min()?;
    let simplest: Vec<Method> = passing
        .iter()
        .copied()
        .filter(|&m| unknowns(m) == fewest)
        .collect();
    if simplest.contains(&Method::MinMaxAxisAlignedMean) {
        return Some(Method::MinMaxAxisAlignedMean);
    }
    let mse = |m: Method| {
        candidates.iter().find_map(|c| match c.outcome {
            CandidateOutcome::Scored { lopo_mse, .. } if c.method == m => Some(lopo_mse),
            _ => None,
        })
    };
    simplest.into_iter().min_by(|&a, &b| {
        mse(a)
            .unwrap_or(f64::INFINITY)
            .total_cmp(&mse(b).unwrap_or(f64::INFINITY))
    })
}

/// The paired test of the two [`TIED_PAIR`] models on the common held-out poses, when both are
/// in `contest` (scored) and at least two such poses exist.
fn compare_pair(
    folds: &[(Method, Vec<Option<f64>>)],
    common: &[usize],
    contest: &[Method],
) -> Option<PairTest> {
    let squares = |method: Method| -> Option<Vec<f64>> {
        if !contest.contains(&method) {
            return None;
        }
        let (_, errors) = folds.iter().find(|(m, _)| *m == method)?;
        common
            .iter()
            .map(|&i| errors.get(i).copied().flatten().map(|e| e * e))
            .collect()
    };
    paired_t(&squares(TIED_PAIR[0])?, &squares(TIED_PAIR[1])?)
}

/// The full fit of one candidate, with its refusals, and for the norm model the update that
/// gives it without one pose.
fn fit_full(
    method: Method,
    poses: &[Pose],
    reference: f64,
) -> Result<(Fit, Option<FoldUpdate>), FitError> {
    match method {
        Method::MinMax => fit_minmax(poses, reference).map(|f| (f, None)),
        Method::AxisAligned => fit_axis_aligned_poses(poses, reference).map(|f| (f, None)),
        // Its leave-one-out RMS comes from the chain's own held-out errors.
        Method::Lm => fit_accel_lm_detailed(poses, reference).map(|o| (o.fit, o.fold_update)),
        _ => fit_six_position(poses, None, reference).map(|f| (f, None)),
    }
}

/// The held-out error of every pose under `method` (`fit` on every pose, `update` its norm-model
/// update). From `updated_from` poses on ([`UPDATED_FOLDS_MIN_POSES`] in the default chain),
/// each fold comes from the full fit where the method has a closed form (min/max: exact), a
/// rank-one downdate (axis-aligned: exact up to rounding) or a first-order update (the norm
/// model, [`FoldUpdate`]), without the coverage rule of a refit; a pose of high leverage
/// ([`high_leverage`]) is refitted all the same, since the update's error grows with its
/// leverage and its fold is the one the coverage rule may refuse. Otherwise, and for
/// six-position, a refit per pose.
fn candidate_errors(
    method: Method,
    poses: &[Pose],
    faces: &[Vec3],
    reference: f64,
    fit: &Fit,
    update: Option<FoldUpdate>,
    updated_from: usize,
) -> Vec<Option<f64>> {
    let all = fit.cal;
    let refit_fold = |i: usize| {
        refit(
            method,
            &loo::without(poses, i),
            &loo::without(faces, i),
            reference,
            Some(&all),
        )
    };
    let high = high_leverage(method, poses.len());
    let updated = (poses.len() >= updated_from)
        .then(|| match method {
            Method::MinMax => loo::held_out_errors(
                poses,
                reference,
                minmax::calibrations_without(poses, reference),
            ),
            Method::AxisAligned => {
                let means: Vec<Vec3> = poses.iter().map(|p| p.mean).collect();
                let fold = axis_aligned::folds_without(&means, reference)?;
                loo::held_out_errors(poses, reference, |i| match fold(i) {
                    Ok((cal, h)) if h <= high => Ok(cal),
                    _ => refit_fold(i),
                })
            }
            Method::Lm => {
                let update = update?;
                loo::held_out_errors(poses, reference, |i| match update.without(i) {
                    Ok((cal, h)) if h <= high => Ok(cal),
                    _ => refit_fold(i),
                })
            }
            _ => None,
        })
        .flatten();
    updated.unwrap_or_else(|| {
        held_out_errors(poses, faces, reference, |rest, rest_faces| {
            refit(method, rest, rest_faces, reference, Some(&all))
        })
    })
}

/// Leverage above which a fold is refitted rather than updated: `3p/N` for `p` unknowns and
/// `N` poses, the mark of a high-leverage point (Belsley, Kuh & Welsch, *Regression
/// Diagnostics*, 1980; the mean leverage is `p/N`).
fn high_leverage(method: Method, poses: usize) -> f64 {
    3.0 * unknowns(method) as f64 / poses.max(1) as f64
}

/// The held-out error of every pose under the mean of the [`TIED_PAIR`] models, each fold the
/// mean of the two members' folds (from their full fits from `updated_from` poses on, as in
/// [`candidate_errors`]).
fn pair_mean_errors(
    poses: &[Pose],
    faces: &[Vec3],
    reference: f64,
    updated_from: usize,
) -> Vec<Option<f64>> {
    let refit_members = |rest: &[Pose], rest_faces: &[Vec3]| {
        let members = TIED_PAIR
            .iter()
            .map(|&m| refit(m, rest, rest_faces, reference, None))
            .collect::<Result<Vec<Calibration>, FitError>>()?;
        mean_calibration(&members)
    };
    if poses.len() >= updated_from {
        let means: Vec<Vec3> = poses.iter().map(|p| p.mean).collect();
        let mut minmax_fold = minmax::calibrations_without(poses, reference);
        let high = high_leverage(Method::AxisAligned, poses.len());
        if let Some(aligned_fold) = axis_aligned::folds_without(&means, reference) {
            let errors = loo::held_out_errors(poses, reference, |i| match aligned_fold(i) {
                Ok((aligned, h)) if h <= high => mean_calibration(&[minmax_fold(i)?, aligned]),
                _ => refit_members(&loo::without(poses, i), &loo::without(faces, i)),
            });
            if let Some(errors) = errors {
                return errors;
            }
        }
    }
    held_out_errors(poses, faces, reference, refit_members)
}

/// A refit of one candidate on the poses without one (the solver and its refusals, without the
/// fit's own leave-one-out statistics); `all` is its fit on every pose, where the iterative
/// fit starts when given.
fn refit(
    method: Method,
    rest: &[Pose],
    rest_faces: &[Vec3],
    reference: f64,
    all: Option<&Calibration>,
) -> Result<Calibration, FitError> {
    match method {
        Method::MinMax => minmax_calibration(rest, reference),
        Method::AxisAligned => {
            let means: Vec<Vec3> = rest.iter().map(|p| p.mean).collect();
            fit_axis_aligned(&means, reference).map(|f| f.cal)
        }
        Method::Lm => match all {
            Some(all) => refit_accel_lm_from(rest, reference, all),
            None => fit_accel_lm_detailed(rest, reference),
        }
        .map(|o| o.fit.cal),
        _ => six_position_calibration(rest, rest_faces, reference),
    }
}

/// Each pose's face from the full set: six-position keeps it, so a held-out pose is judged
/// against the same label it had when all poses were fitted.
fn face_labels(poses: &[Pose]) -> Vec<Vec3> {
    nearest_axes(poses)
        .into_iter()
        .map(|f| f.unwrap_or_else(Vec3::zeros))
        .collect()
}

/// The held-out error of every pose (`None` where the refit without it was refused), `refit`
/// receiving the other poses and their face labels. Empty when there are fewer than two poses
/// or the reference is not positive. On many poses the folds run on two threads.
fn held_out_errors(
    poses: &[Pose],
    faces: &[Vec3],
    reference: f64,
    refit: impl Fn(&[Pose], &[Vec3]) -> Result<Calibration, FitError> + Sync,
) -> Vec<Option<f64>> {
    loo::held_out_errors_threaded(poses, reference, |i| {
        refit(&loo::without(poses, i), &loo::without(faces, i))
    })
    .unwrap_or_default()
}

/// Score the candidates on the held-out poses they can all be refit without, setting aside the
/// one with the fewest refits while fewer than [`MIN_COMMON_FOLDS`] such poses remain. Returns
/// those poses' indices and every candidate's outcome.
fn compare(
    mut folds: Vec<(Method, Vec<Option<f64>>)>,
    n_poses: usize,
) -> (Vec<usize>, Vec<(Method, CandidateOutcome)>) {
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
                outcomes.push((*method, score(errors, &common)));
            }
            return (common, outcomes);
        }
        // Set aside the candidate with the fewest successful refits (the most complex on a tie).
        let Some(worst) = folds
            .iter()
            .enumerate()
            .min_by_key(|(k, (_, e))| (e.iter().flatten().count(), usize::MAX - k))
            .map(|(k, _)| k)
        else {
            return (Vec::new(), outcomes);
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

/// The held-out error of one model on the poses `common` (those of its refits that exist).
fn score(errors: &[Option<f64>], common: &[usize]) -> CandidateOutcome {
    let squares: Vec<f64> = common
        .iter()
        .filter_map(|&i| errors.get(i).copied().flatten())
        .map(|e| e * e)
        .collect();
    if squares.len() < 2 {
        return CandidateOutcome::NotValidated(format!(
            "it could be refit without only {} of the {} compared poses",
            squares.len(),
            common.len()
        ));
    }
    let n = squares.len() as f64;
    let mse = squares.iter().sum::<f64>() / n;
    let var = squares.iter().map(|s| (s - mse).powi(2)).sum::<f64>() / (n - 1.0);
    CandidateOutcome::Scored {
        folds: squares.len(),
        lopo_rms: mse.sqrt(),
        lopo_mse: mse,
        lopo_mse_se: (var / n).sqrt(),
    }
}

/// The scored candidates in `contest` whose LOPO mean square is within one standard error of
/// the best of them, in candidate order (empty when none is scored).
fn within_one_se(candidates: &[Candidate], contest: &[Method]) -> Vec<Method> {
    let scored: Vec<(Method, f64, f64)> = candidates
        .iter()
        .filter(|c| contest.contains(&c.method))
        .filter_map(|c| match c.outcome {
            CandidateOutcome::Scored {
                lopo_mse,
                lopo_mse_se,
                ..
            } => Some((c.method, lopo_mse, lopo_mse_se)),
            _ => None,
        })
        .collect();
    let Some((_, best_mse, best_se)) = scored.iter().copied().min_by(|a, b| a.1.total_cmp(&b.1))
    else {
        return Vec::new();
    };
    scored
        .iter()
        .filter(|(_, mse, _)| *mse <= best_mse + best_se)
        .map(|(m, _, _)| *m)
        .collect()
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

/// The [`TIED_PAIR`] model with the larger held-out mean square in `test`.
fn pair_worse(test: &PairTest) -> Method {
    if test.mean_difference > 0.0 {
        TIED_PAIR[0]
    } else {
        TIED_PAIR[1]
    }
}

/// Why a [`TIED_PAIR`] model left the one-standard-error contest: the paired test `test` found
/// it worse than the other (`None` for every other case).
fn pair_verdict(method: Method, test: &PairTest) -> Option<String> {
    let [first, second] = TIED_PAIR;
    let other = if method == first { second } else { first };
    (test.significant() && method == pair_worse(test)).then(|| {
        format!(
            "worse than {} on the same poses (paired t, p {})",
            other.name(),
            test.p_text()
        )
    })
}

/// Why `chosen` was chosen and the others were not; `passing` are the models within one
/// standard error of the best, `pair` the paired test between the [`TIED_PAIR`] models.
fn explain(
    chosen: Method,
    passing: &[Method],
    candidates: &[Candidate],
    pair: Option<&PairTest>,
) -> String {
    let scored = |m: Method| {
        candidates.iter().find_map(|c| match c.outcome {
            CandidateOutcome::Scored {
                lopo_rms, folds, ..
            } if c.method == m => Some((lopo_rms, folds)),
            _ => None,
        })
    };
    let members: &[Method] = if chosen == Method::MinMaxAxisAlignedMean {
        &TIED_PAIR
    } else {
        std::slice::from_ref(&chosen)
    };
    let simplest = "the simplest model within one standard error of the best";
    let head = match (chosen, scored(chosen), pair) {
        (Method::MinMaxAxisAlignedMean, Some((lopo_rms, folds)), Some(test)) => {
            let each: Vec<String> = TIED_PAIR
                .iter()
                .filter_map(|&m| scored(m).map(|(e, _)| format!("{} {e:.3e}", m.name())))
                .collect();
            format!(
                "{} ({} unknowns), the mean of the min/max and axis-aligned models, chosen by \
                 leave-one-pose-out error: the two estimate the same unknowns and a paired t \
                 test on the {} poses both were refit without cannot tell them apart ({} of g, \
                 p {}, not below {PAIR_ALPHA}); their mean, {lopo_rms:.3e} of g over the \
                 {folds} poses every compared model could be refit without, is {simplest}",
                chosen.name(),
                unknowns(chosen),
                test.folds,
                each.join(", "),
                test.p_text(),
            )
        }
        (_, Some((lopo_rms, folds)), _) => format!(
            "{} ({} unknowns) chosen by leave-one-pose-out error: {:.3e} of g over the {} poses \
             every compared model could be refit without, {simplest}",
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
        .filter(|c| !members.contains(&c.method) && c.method != chosen)
        .map(|c| {
            let left_pair = pair.and_then(|test| pair_verdict(c.method, test));
            let why = match (&c.outcome, left_pair) {
                (CandidateOutcome::Scored { lopo_rms, .. }, Some(verdict)) => {
                    format!("held-out error {lopo_rms:.3e}, {verdict}")
                }
                (CandidateOutcome::Scored { lopo_rms, .. }, None)
                    if passing.contains(&c.method) && unknowns(c.method) == unknowns(chosen) =>
                {
                    format!(
                        "held-out error {lopo_rms:.3e}, within the standard error of the best \
                         but higher, with as many unknowns"
                    )
                }
                (CandidateOutcome::Scored { lopo_rms, .. }, None)
                    if passing.contains(&c.method) =>
                {
                    format!(
                        "held-out error {lopo_rms:.3e}, no better within the standard error \
                         for {} more unknowns",
                        unknowns(c.method).saturating_sub(unknowns(chosen))
                    )
                }
                (CandidateOutcome::Scored { lopo_rms, .. }, _) => {
                    format!("held-out error {lopo_rms:.3e}, worse by more than its standard error")
                }
                (other, _) => describe(other),
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
mod tests;
