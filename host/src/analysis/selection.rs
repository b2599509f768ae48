//! Forward selection of effects for one sensor's observations (see the module comment of
//! [`super`]): the base fit, every candidate tested by held-out error, the accepted ones refitted
//! jointly, temperature and time told apart only when they decorrelate.

use super::crossval::{
    extend_start, held_out, lack_of_fit_p, observations_needed, Comparison, HeldOut, Splits, ALPHA,
    FORM_ALPHA, MIN_GAIN_PER_COMPONENT,
};
use super::effects::{EffectKind, GYRO_FAMILIES, NORM_FAMILIES};
use super::extended_fit::{
    base_calibration, fit_rows, physical_factor, physical_residual, start_params, BaseKind,
    ExtendedFit, Problem,
};
use super::result::{AnalysisError, Coefficient, EffectResult, EffectStatus, SensorAnalysis};
use super::time_structure::{follows_time_p, timed_residuals, without_effect};
use crate::fit::validate::count_distinct;
use crate::fit::{Calibration, Vec3};
use crate::pipeline::observations::Observation;
use crate::recording::Sensor;
use crate::stats::chi_square::ChiSquareTest;

/// Above this |ρ| between pose temperature and pose time, a temperature polynomial is nearly a
/// polynomial in time: a temperature effect that beats the linear drift is still kept only
/// provisionally. Below it, and for a drift, the data decide ([`tell_apart`]).
pub const CONFOUNDING_LIMIT: f64 = 0.95;

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

/// Whether `kind` depends on time or temperature (the pair that warm-up confounds).
fn is_time_or_temperature(kind: EffectKind) -> bool {
    matches!(
        kind,
        EffectKind::BiasDrift | EffectKind::BiasTemperature(_) | EffectKind::ScaleTemperature
    )
}

/// The verdict for a candidate whose model (with `unknowns` parameters) could not be fitted on
/// `n` observations of `components` residuals each.
fn not_fittable(kind: EffectKind, unknowns: usize, n: usize, components: usize) -> EffectResult {
    let needed = observations_needed(unknowns, components);
    let note = if n < needed {
        format!(
            "not fittable: the model with it has {unknowns} unknowns and each held-out fold leaves too few \
             of the {n} poses to determine them; record at least {} more pose(s) ({needed} in all)",
            needed - n
        )
    } else {
        format!(
            "not fittable: the solver did not converge with it on every held-out fold ({n} poses, \
             {unknowns} unknowns); the poses do not vary enough in what it depends on — record poses \
             spread over more orientations, temperatures or time"
        )
    };
    EffectResult {
        kind,
        status: EffectStatus::NotFittable,
        score: 0.0,
        p_value: 1.0,
        gain: 0.0,
        coefficients: Vec::new(),
        note,
    }
}

/// Fit `effects` on every observation and evaluate held out on `splits`.
fn evaluate(
    problem: &Problem,
    effects: &[EffectKind],
    start: &nalgebra::DVector<f64>,
    splits: &Splits,
) -> Option<(ExtendedFit, HeldOut)> {
    let rows: Vec<usize> = (0..problem.points.len()).collect();
    let fit = fit_rows(problem, effects, &rows, start)?;
    let ho = held_out(problem, effects, &fit, splits)?;
    Some((fit, ho))
}

/// The splits of the analysis ([`Splits::for_problem`]) and the base model evaluated on them.
fn evaluate_base(
    problem: &Problem,
    start: &nalgebra::DVector<f64>,
) -> Option<(Splits, ExtendedFit, HeldOut)> {
    let splits = Splits::for_problem(problem)?;
    let (fit, ho) = evaluate(problem, &[], start, &splits)?;
    Some((splits, fit, ho))
}

/// Significance level of the nested F test ([`lack_of_fit_p`]) by which a higher degree of
/// `bias_temperature` replaces a lower one: the same level as a new effect's, Bonferroni aside
/// (two comparisons at most, both within one family already being tested).
pub const DEGREE_ALPHA: f64 = ALPHA;

/// `bias_temperature` added to the model `effects` (fitted parameters `params`), its degree
/// chosen on every observation by the nested F test: degree `d` replaces the degree chosen so
/// far when it lowers χ² significantly (`p ≤ DEGREE_ALPHA`, noise estimated from the higher
/// degree's residual, so an inflated floor cancels). Degree 3 is compared with degree 1 when
/// degree 2 was not chosen (a cubic with a small square term). The chosen model is then
/// evaluated held out, falling back to a lower degree whose folds can be fitted. `Err` with the
/// first degree's kind and unknowns when not even degree 1 can be fitted on every fold.
fn temperature_degree(
    problem: &Problem,
    effects: &[EffectKind],
    params: &nalgebra::DVector<f64>,
    splits: &Splits,
) -> Result<(EffectKind, ExtendedFit, HeldOut), (EffectKind, usize)> {
    let rows: Vec<usize> = (0..problem.points.len()).collect();
    let residuals = rows.len() * problem.components();
    let mut fits: Vec<(EffectKind, ExtendedFit)> = Vec::new();
    for degree in 1..=3u8 {
        let kind = EffectKind::BiasTemperature(degree);
        let mut with = effects.to_vec();
        with.push(kind);
        let start = extend_start(params, kind.param_count());
        let Some(fit) = fit_rows(problem, &with, &rows, &start) else {
            break;
        };
        fits.push((kind, fit));
    }
    let mut chosen = 0;
    for higher in 1..fits.len() {
        let (low, high) = (&fits[chosen].1, &fits[higher].1);
        let extra = high.params.len() - low.params.len();
        let dof = residuals.saturating_sub(high.params.len());
        if lack_of_fit_p(low.cost, high.cost, extra, dof) <= DEGREE_ALPHA {
            chosen = higher;
        }
    }
    for (kind, fit) in fits[..=chosen].iter().rev() {
        if let Some(ho) = held_out(problem, &fit.effects, fit, splits) {
            return Ok((*kind, fit.clone(), ho));
        }
    }
    let first = EffectKind::BiasTemperature(1);
    Err((first, params.len() + first.param_count()))
}

/// The model `fit` with its `bias_temperature` term (if any) refitted at the degree
/// [`temperature_degree`] chooses beside the other effects; `None` when it has no such term or
/// the degree stays.
fn rechoose_degree(
    problem: &Problem,
    fit: &ExtendedFit,
    splits: &Splits,
) -> Option<(ExtendedFit, HeldOut)> {
    let index = fit
        .effects
        .iter()
        .position(|k| matches!(k, EffectKind::BiasTemperature(_)))?;
    let (effects, start) = without_effect(problem, fit, index);
    let rows: Vec<usize> = (0..problem.points.len()).collect();
    let others = fit_rows(problem, &effects, &rows, &start)?;
    let (kind, refit, ho) = temperature_degree(problem, &effects, &others.params, splits).ok()?;
    (kind != fit.effects[index]).then_some((refit, ho))
}

/// The other half of the time–temperature pair: a temperature effect's is `bias_drift`, a
/// drift's is `bias_temperature` (its degree chosen when it is fitted).
fn time_temperature_partner(kind: EffectKind) -> Option<EffectKind> {
    match kind {
        EffectKind::BiasTemperature(_) | EffectKind::ScaleTemperature => {
            Some(EffectKind::BiasDrift)
        }
        EffectKind::BiasDrift => Some(EffectKind::BiasTemperature(1)),
        _ => None,
    }
}

/// Form check of a time or temperature effect `kind`, the last effect of `fit` (held out
/// `ho`): a bias free in shape over the same variable — for a temperature effect also one over
/// time, since in a sequential recording any slow change of the bias is a function of time —
/// added to the model must not both fit significantly better (lack-of-fit F test at
/// [`FORM_ALPHA`]) and predict held-out poses better by the worth-having gain. The model the
/// free shape is compared against holds `partner` too (the other time or temperature
/// candidate, when still untested): otherwise a true drift beside a true temperature effect is
/// a slow change the free shape over time fits and the temperature polynomial cannot, and the
/// right effect would be rejected for the other's absence. `Some(note)` when the form is wrong.
fn other_form(
    problem: &Problem,
    splits: &Splits,
    fit: &ExtendedFit,
    ho: &HeldOut,
    kind: EffectKind,
    partner: Option<EffectKind>,
) -> Option<String> {
    let components = problem.components();
    let n = problem.points.len();
    let with_partner = partner.and_then(|p| match p {
        EffectKind::BiasTemperature(_) => {
            temperature_degree(problem, &fit.effects, &fit.params, splits).ok()
        }
        other => {
            let mut effects = fit.effects.clone();
            effects.push(other);
            let start = extend_start(&fit.params, other.param_count());
            evaluate(problem, &effects, &start, splits).map(|(f, h)| (other, f, h))
        }
    });
    let (partner, base_fit, base_ho) = match &with_partner {
        Some((k, f, h)) => (Some(*k), f, h),
        None => (None, fit, ho),
    };
    let mut checks = vec![EffectKind::BinnedBias(kind.needs_temperature())];
    if kind.needs_temperature() {
        checks.push(EffectKind::BinnedBias(false));
    }
    let (binned, p, gain) = checks.into_iter().find_map(|binned| {
        let mut effects = base_fit.effects.clone();
        effects.push(binned);
        let start = extend_start(&base_fit.params, binned.param_count());
        let (free_fit, free_ho) = evaluate(problem, &effects, &start, splits)?;
        let dof = (n * components).saturating_sub(free_fit.params.len());
        let p = lack_of_fit_p(base_fit.cost, free_fit.cost, binned.param_count(), dof);
        let cmp = Comparison::new(base_ho, &free_ho, components);
        (p <= FORM_ALPHA && cmp.gain_per_component >= MIN_GAIN_PER_COMPONENT).then_some((
            binned,
            p,
            cmp.gain_per_component,
        ))
    })?;
    let beside = partner.map_or(String::new(), |k| format!(", even beside {}", k.name()));
    Some(format!(
        "explains part of the residual, but a bias free in shape over {}{beside} fits it better (lack-of-fit \
         F test p = {p:.1e}) and predicts held-out poses better by {gain:.2} variances of the inflated floor: \
         the dependence has another form than this family, which these tests do not identify (e.g. a step, \
         hysteresis, a random walk, or an effect of another variable), so it is not accepted",
        binned.variable(),
    ))
}

/// Two candidates accepted together: each with its comparison against the model with the
/// other alone, the joint fit and its held-out losses.
struct Pair {
    members: Vec<(EffectKind, Comparison)>,
    fit: ExtendedFit,
    ho: HeldOut,
}

/// The best pair of this round's candidates (`round`: each added alone to `current`), tested
/// jointly against `current` by the acceptance rule with `m` = the number of pairs tested
/// (Bonferroni); each member must also pass the rule against the model with the other member
/// alone, so that no member rides on its partner. The one with the smallest p-value among
/// those that pass. A time and a temperature effect the data cannot tell apart fail the
/// second condition: neither adds to the other.
fn best_pair(
    problem: &Problem,
    splits: &Splits,
    current: &(ExtendedFit, HeldOut),
    round: &[(EffectKind, Comparison, ExtendedFit, HeldOut)],
) -> Option<Pair> {
    let components = problem.components();
    let pairs: Vec<(usize, usize)> = (0..round.len())
        .flat_map(|i| (i + 1..round.len()).map(move |j| (i, j)))
        .collect();
    let m = pairs.len();
    let mut best: Option<(f64, Pair)> = None;
    for (i, j) in pairs {
        let (a, b) = (round[i].0, round[j].0);
        let mut effects = current.0.effects.clone();
        effects.push(a);
        effects.push(b);
        let start = extend_start(&current.0.params, a.param_count() + b.param_count());
        let Some((fit, ho)) = evaluate(problem, &effects, &start, splits) else {
            continue;
        };
        let joint = Comparison::new(&current.1, &ho, components);
        let given_b = Comparison::new(&round[j].3, &ho, components);
        let given_a = Comparison::new(&round[i].3, &ho, components);
        if !(joint.passes(m) && given_b.passes(m) && given_a.passes(m)) {
            continue;
        }
        if best.as_ref().is_none_or(|(p, _)| joint.p_value < *p) {
            best = Some((
                joint.p_value,
                Pair {
                    members: vec![(a, given_b), (b, given_a)],
                    fit,
                    ho,
                },
            ));
        }
    }
    best.map(|(_, pair)| pair)
}

/// Whether the data tell a time or temperature effect from its rival (the other of the pair).
#[derive(Debug, Clone, Copy, PartialEq)]
enum Distinction {
    /// The first adds to the second significantly (it may or may not need the second too).
    First,
    /// Only the second adds to the first: the data prefer the second. The p-values of the first
    /// beside the second and of the second beside the first.
    Second(f64, f64),
    /// Neither adds significantly to the other: the same p-values.
    Neither(f64, f64),
}

/// Tell the models `first` and `second` (each the current model plus one effect, fitted on every
/// observation) apart by encompassing: both effects fitted together, then the nested F test
/// ([`lack_of_fit_p`] at [`ALPHA`]) of each one's contribution beside the other. The F test
/// weighs the fall in χ² against the noise the joint model leaves (its own Birge ratio), so a
/// correlation of temperature and time however high decides nothing by itself: what counts is
/// whether the part of each variable the other does not follow changes the fit by more than
/// the noise. Neither significant: confounded. When the joint model cannot be fitted, the two
/// are taken as confounded.
fn tell_apart(
    problem: &Problem,
    first: &(EffectKind, Comparison, ExtendedFit, HeldOut),
    second: &(EffectKind, Comparison, ExtendedFit, HeldOut),
) -> Distinction {
    let rows: Vec<usize> = (0..problem.points.len()).collect();
    let mut effects = first.2.effects.clone();
    effects.push(second.0);
    let start = extend_start(&first.2.params, second.0.param_count());
    let Some(joint) = fit_rows(problem, &effects, &rows, &start) else {
        return Distinction::Neither(1.0, 1.0);
    };
    let dof = (rows.len() * problem.components()).saturating_sub(joint.params.len());
    let p_first = lack_of_fit_p(second.2.cost, joint.cost, first.0.param_count(), dof);
    let p_second = lack_of_fit_p(first.2.cost, joint.cost, second.0.param_count(), dof);
    match (p_first <= ALPHA, p_second <= ALPHA) {
        (true, _) => Distinction::First,
        (false, true) => Distinction::Second(p_first, p_second),
        (false, false) => Distinction::Neither(p_first, p_second),
    }
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
    let (splits, base_fit, base_ho) = evaluate_base(&problem, &base_start).ok_or_else(|| {
        let needed = observations_needed(base_start.len(), components);
        if n < needed {
            AnalysisError::TooFewObservations {
                sensor: sensor.name(),
                what: "poses",
                found: n,
                needed,
            }
        } else {
            let directions: Vec<Vec3> = problem
                .points
                .iter()
                .filter_map(|p| p.try_normalize(0.0))
                .collect();
            AnalysisError::Refit {
                sensor: sensor.name(),
                model: base_model.to_string(),
                unknowns: base_start.len(),
                distinct: count_distinct(&directions, 5.0),
            }
        }
    })?;
    let temps: Option<Vec<f64>> = observations.iter().map(|o| o.temp_c).collect();
    let times: Vec<f64> = observations.iter().map(|o| o.time_s).collect();
    let temp_time_correlation = temps.as_ref().and_then(|t| pearson(t, &times));

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
                EffectKind::GSensitivity => {
                    "the specific force is not known for every gyroscope hold (no accelerometer \
                     mean for a hold, or an accelerometer in an unknown unit that was not \
                     calibrated)"
                }
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
    // The number of candidates each was tested among in its last round (the `m` of `α/m`).
    let mut tested_among: Vec<(&'static str, usize)> = Vec::new();
    let mut confounded_found = false;
    let mut wrong_form: Vec<(&'static str, String)> = Vec::new();
    let mut unfittable: Vec<(EffectKind, usize)> = Vec::new();
    let mut provisional: Vec<&'static str> = Vec::new();
    // Set aside for a rival the data prefer: (name, why).
    let mut preferred: Vec<(&'static str, String)> = Vec::new();
    // Why the time and temperature effects were not told apart.
    let mut confounding: Option<String> = None;
    while !remaining.is_empty() {
        let m = remaining.len();
        let mut round: Vec<(EffectKind, Comparison, ExtendedFit, HeldOut)> = Vec::new();
        for &cand in &remaining {
            let chosen = match cand {
                EffectKind::BiasTemperature(_) => {
                    temperature_degree(&problem, &current.0.effects, &current.0.params, &splits)
                }
                other => {
                    let mut effects = current.0.effects.clone();
                    effects.push(other);
                    let start = extend_start(&current.0.params, other.param_count());
                    evaluate(&problem, &effects, &start, &splits)
                        .map(|(fit, ho)| (other, fit, ho))
                        .ok_or((other, start.len()))
                }
            };
            match chosen {
                Ok((kind, fit, ho)) => {
                    let cmp = Comparison::new(&current.1, &ho, components);
                    round.push((kind, cmp, fit, ho));
                }
                Err(unknowns) => unfittable.push(unknowns),
            }
        }
        remaining.retain(|r| !unfittable.iter().any(|(k, _)| k.name() == r.name()));
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
            tested_among.retain(|(name, _)| *name != k.name());
            tested_among.push((k.name(), m));
        }
        let Some(w) = winner else {
            // No candidate passes alone, yet the residual is above the floor: two effects can
            // hide each other, each tested against a floor the other inflates (the Birge ratio
            // of a model without it) and, for time and temperature, against a free shape that
            // the other fills. Test the pairs jointly.
            let above = !ChiSquareTest::new(current.0.cost, n * components, current.0.params.len())
                .consistent();
            if !above {
                break;
            }
            let Some(pair) = best_pair(&problem, &splits, &current, &round) else {
                break;
            };
            let Pair { members, fit, ho } = pair;
            let names: Vec<&'static str> = members.iter().map(|(k, _)| k.name()).collect();
            remaining.retain(|r| !names.contains(&r.name()));
            let mut rejected = false;
            for (kind, _) in &members {
                if !is_time_or_temperature(*kind) {
                    continue;
                }
                let partner = time_temperature_partner(*kind)
                    .filter(|p| remaining.iter().any(|r| r.name() == p.name()));
                if let Some(why) = other_form(&problem, &splits, &fit, &ho, *kind, partner) {
                    wrong_form.push((kind.name(), why));
                    last.retain(|(k, _, _)| k.name() != kind.name());
                    last.push((
                        *kind,
                        Comparison::new(&current.1, &ho, components),
                        fit.clone(),
                    ));
                    remaining.extend(
                        members
                            .iter()
                            .map(|(k, _)| *k)
                            .filter(|k| k.name() != kind.name()),
                    );
                    rejected = true;
                    break;
                }
            }
            if rejected {
                continue;
            }
            for (kind, cmp) in members {
                last.retain(|(k, _, _)| k.name() != kind.name());
                last.push((kind, cmp, fit.clone()));
            }
            current = (fit, ho);
            if let Some(r) = rechoose_degree(&problem, &current.0, &splits) {
                current = r;
            }
            continue;
        };
        let mut w = w;
        let time_or_temp = is_time_or_temperature(round[w].0);
        let rival = time_temperature_partner(round[w].0)
            .and_then(|p| round.iter().position(|(k, _, _, _)| k.name() == p.name()));
        let told_apart = rival.map(|r| tell_apart(&problem, &round[w], &round[r]));
        if let (Some(r), Some(Distinction::Second(p_first, p_second))) = (rival, told_apart) {
            // The data prefer the rival: it adds to the winner, the winner does not add to it.
            if round[r].1.passes(m) {
                preferred.push((
                    round[w].0.name(),
                    format!(
                        "lowers held-out error, but {} explains the same residual and more: beside it this effect \
                         adds nothing significant (nested F test p = {p_first:.1e}), while it adds to this one \
                         (p = {p_second:.1e}); it is tested again beside it",
                        round[r].0.name()
                    ),
                ));
                w = r;
            }
        }
        let winner_kind = round[w].0;
        let high_correlation = temp_time_correlation.is_some_and(|r| r.abs() > CONFOUNDING_LIMIT);
        let reason = match told_apart {
            Some(Distinction::Neither(p_first, p_second)) if time_or_temp => Some(format!(
                "{} and {} lower χ² alike: beside each other neither adds significantly (nested F test \
                 p = {p_first:.1e} for {}, {p_second:.1e} for {}), so the data do not tell temperature from time \
                 (ρ = {:.3})",
                winner_kind.name(),
                rival.map_or("", |r| round[r].0.name()),
                winner_kind.name(),
                rival.map_or("", |r| round[r].0.name()),
                temp_time_correlation.unwrap_or(f64::NAN),
            )),
            _ if time_or_temp && winner_kind.needs_temperature() && high_correlation => {
                Some(format!(
                    "temperature follows time (ρ = {:.3}, above {CONFOUNDING_LIMIT}), so a polynomial in \
                     temperature is one in time as well, while the time family holds only a linear drift: a \
                     linear drift not fitting as well does not tell temperature from time",
                    temp_time_correlation.unwrap_or(f64::NAN),
                ))
            }
            _ => None,
        };
        if let Some(reason) = reason {
            confounded_found = true;
            confounding = Some(reason);
            remaining.retain(|r| !is_time_or_temperature(*r));
            // The firmware can only apply a temperature term: keep the best temperature
            // candidate that passes, marked provisional, rather than nothing.
            let temperature_winner = round
                .iter()
                .enumerate()
                .filter(|(_, (k, c, _, _))| k.needs_temperature() && c.passes(m))
                .min_by(|a, b| a.1 .1.p_value.total_cmp(&b.1 .1.p_value))
                .map(|(i, _)| i);
            if let Some(t) = temperature_winner {
                let (kind, _, fit, ho) = round.swap_remove(t);
                provisional.push(kind.name());
                current = (fit, ho);
                if let Some(r) = rechoose_degree(&problem, &current.0, &splits) {
                    current = r;
                }
            }
            continue;
        }
        let (kind, _, fit, ho) = round.swap_remove(w);
        remaining.retain(|r| r.name() != kind.name());
        if time_or_temp {
            let partner = time_temperature_partner(kind)
                .filter(|p| remaining.iter().any(|r| r.name() == p.name()));
            if let Some(why) = other_form(&problem, &splits, &fit, &ho, kind, partner) {
                wrong_form.push((kind.name(), why));
                continue;
            }
        }
        current = (fit, ho);
        if let Some(r) = rechoose_degree(&problem, &current.0, &splits) {
            current = r;
        }
    }

    // A drift whose residual still follows time is the straight-line part of a random walk or
    // of steps, not a drift (see `time_structure`): take it out and refit.
    if let Some(index) = current
        .0
        .effects
        .iter()
        .position(|k| *k == EffectKind::BiasDrift)
    {
        let p = follows_time_p(&timed_residuals(&problem, &current.0, &times));
        let (effects, start) = without_effect(&problem, &current.0, index);
        if p <= ALPHA {
            if let Some(refit) = evaluate(&problem, &effects, &start, &splits) {
                wrong_form.push((
                    EffectKind::BiasDrift.name(),
                    format!(
                        "a linear trend improves held-out error, but the residual after it still follows time \
                         (neighbours-in-time permutation p = {p:.1e}): the bias wanders (a random walk, steps, hysteresis) \
                         rather than drifting linearly, so it is not accepted"
                    ),
                ));
                current = refit;
            }
        }
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
            note: if provisional.contains(&kind.name()) {
                format!(
                    "provisional: confounded with time: lowers the held-out mean square error by {} % \
                     (corrected t p = {p_value:.1e}), but {}. Kept because the firmware applies temperature terms \
                     only; confirm with a recording where temperature does not follow time (a cool-down, or a second \
                     warm-up from cold): the same coefficients confirm it, different ones mean a drift in time",
                    percent(score),
                    confounding.as_deref().unwrap_or("the data do not tell temperature from time"),
                )
            } else {
                format!(
                    "lowers the held-out mean square error by {} % (corrected t p = {p_value:.1e})",
                    percent(score)
                )
            },
        });
    }
    for (kind, cmp, fit) in &last {
        if final_fit.effects.iter().any(|k| k.name() == kind.name()) {
            continue;
        }
        let time_or_temp = is_time_or_temperature(*kind);
        let status = if confounded_found && time_or_temp && cmp.passes(1) {
            EffectStatus::Confounded
        } else {
            EffectStatus::Rejected
        };
        let note = match status {
            EffectStatus::Confounded => format!(
                "would improve held-out error, but {}; record with temperature varying independently of time",
                confounding.as_deref().unwrap_or("the data do not tell temperature from time"),
            ),
            _ => match wrong_form
                .iter()
                .chain(&preferred)
                .find(|(name, _)| *name == kind.name())
            {
                Some((_, why)) => why.clone(),
                None => {
                    let level = match tested_among.iter().find(|(name, _)| *name == kind.name()) {
                        Some(&(_, m)) => format!(
                            "p ≤ {ALPHA}/{m} = {:.1e}, {m} candidate{} tested in its round",
                            ALPHA / m as f64,
                            if m == 1 { "" } else { "s" }
                        ),
                        None => format!("p ≤ {ALPHA}/m, m candidates in the round"),
                    };
                    format!(
                        "held-out gain {:.2} variances of the inflated floor per component (white-noise floor × {:.2}, \
                         the Birge ratio), corrected t p = {:.2e}: not enough (needs ≥ {MIN_GAIN_PER_COMPONENT} and {level})",
                        cmp.gain_per_component, cmp.floor_inflation, cmp.p_value
                    )
                }
            },
        };
        let index = fit
            .effects
            .iter()
            .rposition(|k| k.name() == kind.name())
            .unwrap_or(fit.effects.len() - 1);
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

    for &(kind, unknowns) in &unfittable {
        results.push(not_fittable(kind, unknowns, n, components));
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
        always_trained: splits.always_trained(),
        base_note: None,
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

/// A fraction as a percentage for the notes: whole per cent, but never "100" for a fraction
/// below one (99.95 % is not all of it) nor "0" for one above zero.
fn percent(fraction: f64) -> String {
    let p = 100.0 * fraction;
    let whole = p.round();
    if (whole >= 100.0 && p < 100.0) || (whole <= 0.0 && p > 0.0) {
        let digits = (-(100.0 - p).abs().min(p.abs()).log10())
            .ceil()
            .clamp(1.0, 6.0) as usize;
        format!("{p:.digits$}")
    } else {
        format!("{whole:.0}")
    }
}

#[cfg(test)]
mod tests {
    use super::percent;

    #[test]
    fn a_fraction_just_below_one_is_not_called_all_of_it() {
        assert_eq!(percent(0.36), "36");
        assert_eq!(percent(0.9995), "99.95");
        assert_eq!(percent(1.0), "100");
        assert_eq!(percent(0.004), "0.4");
        assert_eq!(percent(0.0), "0");
    }
}
