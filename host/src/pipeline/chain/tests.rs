//! The default chain on synthetic poses with known truth.

use super::*;
use crate::fit::validate::face_directions;
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

/// Offset of every synthetic sensor here, m/s².
fn offset() -> Vec3 {
    Vec3::new(0.1, -0.2, 0.05)
}

/// Gain of a sensor without cross-axis terms (raw = gain·true + offset).
fn diagonal_gain() -> Mat3 {
    Mat3::from_diagonal(&Vec3::new(1.02, 0.98, 1.01))
}

/// Pose means of the sensor with [`diagonal_gain`] and [`offset`] (see [`poses`]).
fn diagonal_poses(dirs: &[Vec3], jitter: f64) -> Vec<Pose> {
    poses(&diagonal_gain(), &offset(), dirs, jitter)
}

fn faces() -> Vec<Vec3> {
    face_directions().to_vec()
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
    let set = poses(&a_inv, &offset(), &tilted_directions(), 1e-4);
    let choice = default_accel_chain(&set, 9.81).expect("fits");
    assert_eq!(choice.fit.method, Method::Lm, "{}", choice.reason);
    assert!(
        choice.reason.contains("six-position: refused"),
        "{}",
        choice.reason
    );
    // The two 6-unknown models lose by more than their standard error: no mean is formed.
    for name in ["minmax", "axis-aligned"] {
        let phrase = format!("{name}: held-out error");
        assert!(choice.reason.contains(&phrase), "{}", choice.reason);
    }
    assert!(
        choice
            .reason
            .contains("worse by more than its standard error"),
        "{}",
        choice.reason
    );
}

#[test]
fn a_sensor_without_cross_coupling_gets_the_simpler_axis_aligned_model() {
    // Diagonal truth: lm's three extra unknowns cannot lower the held-out error by more than
    // its standard error, so parsimony picks the 6-unknown model.
    let set = diagonal_poses(&tilted_directions(), 1e-3);
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
    let set = diagonal_poses(&faces(), 1e-4);
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
    let set = diagonal_poses(&dirs, 1e-4);
    let choice = default_accel_chain(&set, 9.81).expect("fits");
    assert_eq!(choice.fit.method, Method::AxisAligned, "{}", choice.reason);
    assert!(
        choice.reason.contains("no model could be validated"),
        "{}",
        choice.reason
    );
    // Exactly determined: the scale comes back to the jitter's order (1e-4 of g).
    assert!((choice.fit.cal.a[(0, 0)] - 1.0 / diagonal_gain()[(0, 0)]).abs() < 1e-3);
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

#[test]
fn equally_simple_models_the_data_cannot_tell_apart_are_averaged() {
    // Each face held twice and one tilted hold (which six-position cannot label and which leaves
    // lm with 7 directions for 9 unknowns), a small wobble and a diagonal truth: min/max and
    // the axis-aligned ellipsoid estimate the same 6 unknowns and predict held-out holds alike.
    let dirs: Vec<Vec3> = faces()
        .into_iter()
        .chain(faces())
        .chain([Vec3::new(1.0, 1.0, 1.0)])
        .collect();
    let set = diagonal_poses(&dirs, 1e-3);
    let choice = default_accel_chain(&set, 9.81).expect("fits");
    assert_eq!(
        choice.fit.method,
        Method::MinMaxAxisAlignedMean,
        "{}",
        choice.reason
    );
    assert!(
        choice.reason.contains("cannot tell them apart"),
        "{}",
        choice.reason
    );
    // The mean of two axis-aligned calibrations is axis-aligned and as close to the truth as
    // the wobble allows (1e-3 m/s² per axis ≈ 1e-4 of g in scale, 1e-3 m/s² in offset).
    let truth = diagonal_gain().try_inverse().expect("invertible");
    assert!((choice.fit.cal.a - truth).norm() < 1e-3);
    assert!((choice.fit.cal.b - offset()).norm() < 3e-3);
    assert!(choice.fit.loo_rms.is_some());
    // The paired test did not separate them, and the mean is a scored candidate of its own.
    assert!(!choice.pair.expect("both scored").significant());
    assert!(choice
        .candidates
        .iter()
        .any(|c| c.method == Method::MinMaxAxisAlignedMean
            && matches!(c.outcome, CandidateOutcome::Scored { .. })));
}

#[test]
fn a_pair_member_the_paired_test_finds_worse_leaves_the_contest() {
    // Each face held twice and the eight corners once, a diagonal truth and a wobble: min/max
    // reads one hold per face and ignores the corners, the axis-aligned ellipsoid fits all 20.
    // On the same held-out poses the ellipsoid is better often enough for the paired test.
    let corners = tilted_directions()
        .into_iter()
        .filter(|d| d.iter().all(|c| c.abs() == 1.0));
    let dirs: Vec<Vec3> = faces().into_iter().chain(faces()).chain(corners).collect();
    let set = diagonal_poses(&dirs, 2e-2);
    let choice = default_accel_chain(&set, 9.81).expect("fits");
    let test = choice.pair.expect("both 6-unknown models scored");
    assert!(test.significant(), "{test:?}: {}", choice.reason);
    assert_eq!(choice.fit.method, Method::AxisAligned, "{}", choice.reason);
    assert!(
        choice.reason.contains("minmax: held-out error")
            && choice
                .reason
                .contains("worse than axis-aligned on the same poses"),
        "{}",
        choice.reason
    );
    // No mean was formed.
    assert!(choice
        .candidates
        .iter()
        .all(|c| c.method != Method::MinMaxAxisAlignedMean));
}

#[test]
fn a_mean_worse_than_the_best_by_more_than_its_standard_error_is_not_used() {
    // Every face held twice except +X, plus a hold tilted 25° from +X. Left without the one +X
    // hold, min/max takes the tilted hold as its +X face and misses that pose badly; on every
    // other pose it does as well as the axis-aligned ellipsoid. One pose carries the whole
    // difference, so the paired t test cannot reject (t ≈ 1), the mean joins the contest, and
    // half of min/max's miss keeps it above the best model's standard error.
    let tilt = 25f64.to_radians();
    let dirs: Vec<Vec3> = faces()
        .into_iter()
        .chain(faces().into_iter().skip(1))
        .chain([Vec3::new(tilt.cos(), tilt.sin(), 0.0)])
        .collect();
    let set = diagonal_poses(&dirs, 1e-3);
    let choice = default_accel_chain(&set, 9.81).expect("fits");
    let test = choice.pair.expect("both 6-unknown models scored");
    assert!(!test.significant(), "{test:?}: {}", choice.reason);
    assert_eq!(choice.fit.method, Method::AxisAligned, "{}", choice.reason);
    assert!(
        choice
            .reason
            .contains("minmax+axis-aligned: held-out error")
            && choice
                .reason
                .contains("worse by more than its standard error"),
        "{}",
        choice.reason
    );
}

#[test]
fn held_out_errors_on_two_threads_equal_refitting_each_pose_in_turn() {
    // 52 poses (twice the 26 tilted directions): above PARALLEL_POSES, so split over threads.
    let mut dirs = tilted_directions();
    dirs.extend(
        tilted_directions()
            .iter()
            .map(|d| d + Vec3::new(0.1, -0.05, 0.02)),
    );
    assert!(dirs.len() >= crate::fit::loo::PARALLEL_POSES);
    let poses = diagonal_poses(&dirs, 0.02);
    let faces = face_labels(&poses);
    let reference = 9.81;
    for method in CANDIDATES {
        let all = fit_full(method, &poses, reference).ok().map(|(f, _)| f.cal);
        let threaded = held_out_errors(&poses, &faces, reference, |rest, rest_faces| {
            refit(method, rest, rest_faces, reference, all.as_ref())
        });
        let in_turn: Vec<Option<f64>> =
            crate::fit::loo::leave_one_out_errors(&poses, reference, |i, rest| {
                refit(
                    method,
                    rest,
                    &crate::fit::loo::without(&faces, i),
                    reference,
                    all.as_ref(),
                )
            })
            .unwrap_or_default();
        assert_eq!(threaded.len(), poses.len(), "{method:?}");
        let bits = |e: &[Option<f64>]| -> Vec<Option<u64>> {
            e.iter().map(|x| x.map(f64::to_bits)).collect()
        };
        assert_eq!(bits(&threaded), bits(&in_turn), "{method:?}");
        if matches!(method, Method::AxisAligned | Method::Lm) {
            // Least-squares models refit without any one of these poses.
            assert_eq!(threaded.iter().flatten().count(), poses.len(), "{method:?}");
        }
    }
}

#[test]
fn norm_model_refits_started_from_the_full_fit_reach_the_refits_from_their_own_start() {
    // Started next to the answer, a held-out LM refit converges to the same optimum as one
    // started from the algebraic fit of its own poses. The solutions differ only where the
    // start enters: the direction each pose's noise is projected on (from the start's centre)
    // and the stopping point: below 10⁻⁶ of the held-out error here, 10⁻⁵ is the bound.
    let poses = diagonal_poses(&tilted_directions(), 0.02);
    let faces = face_labels(&poses);
    let reference = 9.81;
    let all = fit_full(Method::Lm, &poses, reference).unwrap().0.cal;
    let warm = held_out_errors(&poses, &faces, reference, |rest, rest_faces| {
        refit(Method::Lm, rest, rest_faces, reference, Some(&all))
    });
    let cold = held_out_errors(&poses, &faces, reference, |rest, rest_faces| {
        refit(Method::Lm, rest, rest_faces, reference, None)
    });
    assert_eq!(warm.len(), poses.len());
    for (i, (w, c)) in warm.iter().zip(&cold).enumerate() {
        let (w, c) = (w.unwrap(), c.unwrap());
        assert!(
            (w - c).abs() <= 1e-5 * c.abs().max(1e-6),
            "pose {i}: held-out error {w:.6e} started from the full fit, {c:.6e} from its own"
        );
    }
}

/// `copies` copies of the 26 tilted directions, each copy turned a little, on the sensor with
/// 2 % cross-axis terms: many poses, none on a face alone.
fn many_tilted_poses(copies: usize) -> Vec<Pose> {
    let a_inv = Mat3::new(1.02, 0.02, -0.015, 0.0, 0.98, 0.02, 0.0, 0.0, 1.01);
    let dirs: Vec<Vec3> = (0..copies)
        .flat_map(|c| {
            let turn = nalgebra::Rotation3::new(Vec3::new(0.03, -0.02, 0.04) * c as f64);
            tilted_directions().into_iter().map(move |d| turn * d)
        })
        .collect();
    poses(&a_inv, &offset(), &dirs, 2e-3)
}

#[test]
fn from_a_hundred_poses_the_folds_come_from_the_full_fits_and_agree_with_refits() {
    let set = many_tilted_poses(5);
    assert!(set.len() >= UPDATED_FOLDS_MIN_POSES);
    let faces = face_labels(&set);
    let reference = 9.81;
    for method in [Method::MinMax, Method::AxisAligned, Method::Lm] {
        let (fit, update) = fit_full(method, &set, reference).expect("fits");
        assert_eq!(update.is_some(), method == Method::Lm, "{method:?}");
        let all = fit.cal;
        let updated = candidate_errors(
            method,
            &set,
            &faces,
            reference,
            &fit,
            update,
            UPDATED_FOLDS_MIN_POSES,
        );
        let refitted = held_out_errors(&set, &faces, reference, |rest, rest_faces| {
            refit(method, rest, rest_faces, reference, Some(&all))
        });
        assert_eq!(updated.len(), set.len(), "{method:?}");
        for (i, (u, r)) in updated.iter().zip(&refitted).enumerate() {
            let (u, r) = (u.expect("updated fold"), r.expect("refit"));
            let in_sample = (all.apply(&set[i].mean).norm() - reference) / reference;
            // min/max: the same faces, so the same numbers; axis-aligned: the same linear
            // solution up to rounding; the norm model: exact to first order in the leverage
            // (≈ p/N), so it misses at most that fraction of how far the pose's residual moves.
            let bound = match method {
                Method::MinMax => 0.0,
                Method::AxisAligned => 1e-9 * r.abs().max(1e-9),
                _ => 9.0 / set.len() as f64 * (r - in_sample).abs() + 1e-12,
            };
            assert!(
                (u - r).abs() <= bound,
                "{method:?}, pose {i}: from the full fit {u:.9e}, refit {r:.9e}"
            );
        }
    }
    // The mean of the tied pair, fold by fold.
    let updated = pair_mean_errors(&set, &faces, reference, UPDATED_FOLDS_MIN_POSES);
    let refitted = held_out_errors(&set, &faces, reference, |rest, rest_faces| {
        let members = TIED_PAIR
            .iter()
            .map(|&m| refit(m, rest, rest_faces, reference, None))
            .collect::<Result<Vec<Calibration>, FitError>>()?;
        mean_calibration(&members)
    });
    for (u, r) in updated.iter().zip(&refitted) {
        let (u, r) = (u.expect("updated fold"), r.expect("refit"));
        assert!(
            (u - r).abs() <= 1e-9 * r.abs().max(1e-9),
            "{u:.9e} against {r:.9e}"
        );
    }
}

#[test]
fn the_chain_chooses_alike_by_updated_folds_and_by_refits() {
    // The same 130 poses through the chain twice: folds by refits, and from the full fits.
    let set = many_tilted_poses(5);
    assert!(set.len() >= UPDATED_FOLDS_MIN_POSES);
    let refitted = accel_chain(&set, 9.81, usize::MAX).expect("fits");
    let updated = accel_chain(&set, 9.81, UPDATED_FOLDS_MIN_POSES).expect("fits");
    assert_eq!(refitted.fit.method, Method::Lm, "{}", refitted.reason);
    assert_eq!(
        updated.fit.method, refitted.fit.method,
        "{}",
        updated.reason
    );
    let (a, b) = (
        updated.fit.loo_rms.expect("held-out RMS"),
        refitted.fit.loo_rms.expect("held-out RMS"),
    );
    // The first-order update misses at most (p/N)² of the held-out RMS (p = 9 unknowns).
    let h = 9.0 / set.len() as f64;
    assert!(
        (a - b).abs() <= h * h * b,
        "updated {a:.9e}, refitted {b:.9e}"
    );
    for (u, r) in updated.candidates.iter().zip(&refitted.candidates) {
        assert_eq!(u.method, r.method);
        assert_eq!(
            std::mem::discriminant(&u.outcome),
            std::mem::discriminant(&r.outcome),
            "{:?}: {:?} against {:?}",
            u.method,
            u.outcome,
            r.outcome
        );
    }
}

#[test]
fn a_pose_of_high_leverage_is_refitted_and_the_others_updated() {
    // 182 tilted poses, of which those turned towards −Z are dropped, and one added there:
    // that lone pose alone pins the bottom of the ellipsoid, so its leverage is far above the
    // mean p/N.
    let mut set: Vec<Pose> = many_tilted_poses(7)
        .into_iter()
        .filter(|p| p.mean.z > -2.0)
        .collect();
    let bottom = poses(
        &Mat3::new(1.02, 0.02, -0.015, 0.0, 0.98, 0.02, 0.0, 0.0, 1.01),
        &offset(),
        &[Vec3::new(0.1, -0.05, -1.0)],
        0.0,
    );
    set.extend(bottom);
    let lone = set.len() - 1;
    assert!(set.len() >= UPDATED_FOLDS_MIN_POSES, "{} poses", set.len());
    let faces = face_labels(&set);
    let reference = 9.81;
    let (fit, update) = fit_full(Method::Lm, &set, reference).expect("fits");
    let update = update.expect("the norm model's update");
    let high = high_leverage(Method::Lm, set.len());
    let leverage = |i: usize| update.without(i).map(|(_, h)| h).unwrap_or(f64::INFINITY);
    assert!(
        leverage(lone) > high,
        "lone pose leverage {}",
        leverage(lone)
    );
    let updated = candidate_errors(
        Method::Lm,
        &set,
        &faces,
        reference,
        &fit,
        Some(update.clone()),
        UPDATED_FOLDS_MIN_POSES,
    );
    let all = fit.cal;
    let refitted = held_out_errors(&set, &faces, reference, |rest, rest_faces| {
        refit(Method::Lm, rest, rest_faces, reference, Some(&all))
    });
    let mut updated_folds = 0;
    for (i, (u, r)) in updated.iter().zip(&refitted).enumerate() {
        let (u, r) = (u.expect("fold"), r.expect("refit"));
        if leverage(i) > high {
            // Refitted: the very same refit, so the very same number.
            assert_eq!(
                u.to_bits(),
                r.to_bits(),
                "pose {i}: {u:.9e} against {r:.9e}"
            );
        } else {
            // Updated: first order in the leverage, not the refit's bits.
            updated_folds += 1;
            let in_sample = (all.apply(&set[i].mean).norm() - reference) / reference;
            assert!(
                (u - r).abs() <= 3.0 * high * (r - in_sample).abs() + 1e-12,
                "pose {i}: updated {u:.9e}, refit {r:.9e}"
            );
        }
    }
    assert!(
        updated_folds >= set.len() / 2,
        "{updated_folds} folds updated"
    );
}

#[test]
fn each_accelerometer_model_counts_as_many_unknowns_as_it_estimates() {
    // Twenty-six cube directions: every model here fits them.
    let dirs: Vec<Vec3> = crate::session::coverage::region_directions();
    let poses = poses(&diagonal_gain(), &offset(), &dirs, 1e-3);
    for method in [
        Method::MinMax,
        Method::AxisAligned,
        Method::Lm,
        Method::Chen,
        Method::Li,
        Method::Frosio,
        Method::Merayo,
    ] {
        let fit = crate::pipeline::methods::fit_accel(method, &poses, 9.81)
            .unwrap_or_else(|e| panic!("{}: {e}", method.name()));
        // Li's algebraic fit names no parameters (it has no covariance): a symmetric matrix
        // and a centre, nine, as the norm model's gauge.
        if fit.param_names.is_empty() {
            assert_eq!((method, unknowns(method)), (Method::Li, 9));
            continue;
        }
        assert_eq!(
            unknowns(method),
            fit.param_names.len(),
            "{}: {:?}",
            method.name(),
            fit.param_names
        );
    }
}
