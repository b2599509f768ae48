//! The algebraic and closed-form fits (gyro bias, min/max, axis-aligned, six-position, Chen, Li)
//! against synthetic truth: exact recovery without noise, error within bounds derived from the
//! noise, refusals of pose sets that cannot determine the parameters, Chen's rank deficiency, and
//! the conditioning gain of Li's mean subtraction.
//!
//! Noise bounds use k = 5 standard deviations: a correct estimator fails such a check with
//! probability below 1e-6 per check, so a failure means a wrong estimator or a wrong σ.

use imucal::fit::axis_aligned::{fit_axis_aligned, fit_axis_aligned_poses};
use imucal::fit::chen::{chen_coarse, fit_chen, norm_jacobian_full, norm_jacobian_gauge};
use imucal::fit::gyro_bias::fit_gyro_bias;
use imucal::fit::li::{fit_li, LiOptions};
use imucal::fit::linalg::{singular_values, upper_triangular_gauge};
use imucal::fit::loo::leave_one_out_rms;
use imucal::fit::minmax::fit_minmax;
use imucal::fit::six_position::fit_six_position;
use imucal::fit::validate::count_distinct;
use imucal::fit::{Calibration, FitError, Mat3, Pose, Vec3};
use imucal::synthetic::{
    accel_poses, cap_directions, directions, mag_samples, perturb_directions, random_calibration,
    raw_from_true, rng, PoseSet, TruthSpec,
};

/// Exact-arithmetic recovery tolerance: parameters of order 1–10 through an SVD/eigen solve of a
/// well-conditioned problem lose a few digits to rounding; 1e-9 leaves ample margin.
const EXACT: f64 = 1e-9;
/// Sigma multiple for noise bounds (see the file comment).
const K: f64 = 5.0;
const G: f64 = 9.80665;

fn max_abs_diff_mat(a: &Mat3, b: &Mat3) -> f64 {
    (a - b).abs().max()
}

fn max_abs_diff_vec(a: &Vec3, b: &Vec3) -> f64 {
    (a - b).abs().max()
}

fn is_underdetermined_with(result: Result<impl std::fmt::Debug, FitError>, needle: &str) -> bool {
    match result {
        Err(FitError::Underdetermined(msg)) if msg.contains(needle) => true,
        other => {
            eprintln!("expected Underdetermined containing {needle:?}, got {other:?}");
            false
        }
    }
}

// ---------------------------------------------------------------- synthetic data

#[test]
fn synthetic_raw_reading_maps_back_onto_the_true_vector() {
    let mut r = rng(1);
    let truth = random_calibration(
        &mut r,
        &TruthSpec {
            offset_ratio: 5.0,
            ..TruthSpec::default()
        },
    );
    let y = Vec3::new(0.3, -0.5, 0.8);
    let x = raw_from_true(&truth, &y).expect("invertible truth");
    assert!(max_abs_diff_vec(&truth.apply(&x), &y) < 1e-12);
    assert!(
        (truth.b.norm() - 5.0).abs() < 1e-12,
        "offset magnitude is offset_ratio × reference"
    );
}

#[test]
fn upper_triangular_gauge_preserves_every_norm() {
    let mut r = rng(2);
    let truth = random_calibration(
        &mut r,
        &TruthSpec {
            cross_axis: 0.2,
            ..TruthSpec::default()
        },
    );
    let upper = upper_triangular_gauge(&truth.a);
    assert_eq!(upper[(1, 0)], 0.0);
    assert_eq!(upper[(2, 0)], 0.0);
    assert_eq!(upper[(2, 1)], 0.0);
    for u in directions(&mut r, PoseSet::Random(20)) {
        assert!(((truth.a * u).norm() - (upper * u).norm()).abs() < 1e-12);
    }
}

// ---------------------------------------------------------------- gyro bias

#[test]
fn gyro_bias_is_within_noise_of_truth_and_reports_its_standard_error() {
    let mut r = rng(10);
    let truth = Calibration {
        a: Mat3::identity(),
        b: Vec3::new(0.8, -1.2, 0.35),
    };
    let (sigma, n, poses_count) = (0.05, 400, 5);
    // Still gyro: the true rate is zero in every pose.
    let dirs = vec![Vec3::zeros(); poses_count];
    let poses = accel_poses(&mut r, &truth, &dirs, 1.0, sigma, n);
    let scale = std::f64::consts::PI / 180.0;
    let fit = fit_gyro_bias(&poses, scale).expect("fit");
    // Standard error of the pooled mean: σ/√(n·poses).
    let se = sigma / ((n * poses_count) as f64).sqrt();
    assert!(max_abs_diff_vec(&fit.cal.b, &truth.b) < K * se);
    let std = fit.std.expect("noise was reported");
    for k in 0..3 {
        // The within-pose standard error, inflated by the Birge ratio √(χ²/ν) of the pose means
        // about the pooled mean when they scatter more than it (ν = poses − 1).
        let chi2: f64 = poses
            .iter()
            .map(|p| (p.mean[k] - fit.cal.b[k]).powi(2) / p.var_of_mean()[k])
            .sum();
        let birge = (chi2 / (poses_count - 1) as f64).max(1.0).sqrt();
        // Variance estimated from 2000 samples: relative error of the std ≈ 1/√(2·2000) ≈ 1.6 %.
        assert!(
            (std.b[k] / (se * birge) - 1.0).abs() < 0.1,
            "std {} vs {se}·{birge}",
            std.b[k]
        );
    }
    assert!(max_abs_diff_mat(&fit.cal.a, &(Mat3::identity() * scale)) < 1e-15);
    // Held-out residual of a still pose: |scale·(mean − b)| ≈ scale·σ/√n·√3.
    let loo = fit.loo_rms.expect("several poses");
    assert!(loo < K * scale * sigma / (n as f64).sqrt() * 3f64.sqrt());
}

#[test]
fn gyro_bias_refuses_no_data_a_bad_scale_and_nan() {
    assert!(is_underdetermined_with(
        fit_gyro_bias(&[], 1.0),
        "no still poses"
    ));
    let pose = Pose {
        mean: Vec3::zeros(),
        var: Vec3::repeat(1.0),
        n: 10,
        label: None,
    };
    assert!(is_underdetermined_with(
        fit_gyro_bias(std::slice::from_ref(&pose), -1.0),
        "positive factor"
    ));
    let bad = Pose {
        mean: Vec3::new(f64::NAN, 0.0, 0.0),
        ..pose
    };
    assert!(matches!(
        fit_gyro_bias(&[bad], 1.0),
        Err(FitError::NonFinite(_))
    ));
}

// ---------------------------------------------------------------- min/max

fn diagonal_truth(seed: u64, offset_ratio: f64, reference: f64) -> Calibration {
    random_calibration(
        &mut rng(seed),
        &TruthSpec {
            scale_error: 0.3,
            cross_axis: 0.0,
            offset_ratio,
            reference,
            upper_triangular: false,
        },
    )
}

#[test]
fn minmax_recovers_diagonal_truth_exactly_without_noise() {
    let truth = diagonal_truth(20, 0.2, G);
    let mut r = rng(21);
    let dirs = directions(&mut r, PoseSet::SixFaces);
    let poses = accel_poses(&mut r, &truth, &dirs, G, 0.0, 1);
    let fit = fit_minmax(&poses, G).expect("fit");
    assert!(max_abs_diff_mat(&fit.cal.a, &truth.a) < EXACT);
    assert!(max_abs_diff_vec(&fit.cal.b, &truth.b) < EXACT);
    assert!(fit.rms < EXACT);
}

#[test]
fn minmax_bias_error_is_within_noise_and_matches_reported_std() {
    let truth = diagonal_truth(22, 0.05, G);
    let mut r = rng(23);
    let (sigma, n) = (0.02, 100);
    let dirs = directions(&mut r, PoseSet::SixFaces);
    let poses = accel_poses(&mut r, &truth, &dirs, G, sigma, n);
    let fit = fit_minmax(&poses, G).expect("fit");
    // b = (max + min)/2 of two means of n samples: σ_b = σ/√(2n).
    let sigma_b = sigma / (2.0 * n as f64).sqrt();
    assert!(max_abs_diff_vec(&fit.cal.b, &truth.b) < K * sigma_b);
    let std = fit.std.expect("noise was reported");
    for k in 0..3 {
        // Variance from 100 samples per pose: std relative error ≈ 1/√(2·99·2) ≈ 5 %.
        assert!((std.b[k] / sigma_b - 1.0).abs() < 0.3);
    }
}

#[test]
fn minmax_refuses_a_set_without_the_minus_z_face() {
    let truth = diagonal_truth(24, 0.05, G);
    let mut r = rng(25);
    let mut dirs = directions(&mut r, PoseSet::SixFaces);
    dirs.retain(|d| d.z > -0.5);
    let poses = accel_poses(&mut r, &truth, &dirs, G, 0.0, 1);
    assert!(is_underdetermined_with(
        fit_minmax(&poses, G),
        "no pose with −Z up"
    ));
}

// ---------------------------------------------------------------- axis-aligned ellipsoid

#[test]
fn axis_aligned_recovers_diagonal_truth_exactly_even_with_a_large_offset() {
    let truth = diagonal_truth(30, 10.0, 50.0);
    let mut r = rng(31);
    let dirs = directions(&mut r, PoseSet::Random(60));
    let points = mag_samples(&mut r, &truth, &dirs, 50.0, 0.0);
    let fit = fit_axis_aligned(&points, 50.0).expect("fit");
    assert!(max_abs_diff_mat(&fit.cal.a, &truth.a) < EXACT);
    assert!(
        max_abs_diff_vec(&fit.cal.b, &truth.b) < EXACT * 500.0,
        "b is of order 500"
    );
}

#[test]
fn axis_aligned_on_poses_predicts_held_out_poses_exactly_without_noise() {
    let truth = diagonal_truth(32, 0.1, G);
    let mut r = rng(33);
    let dirs = directions(&mut r, PoseSet::TwelvePositions);
    let poses = accel_poses(&mut r, &truth, &dirs, G, 0.0, 1);
    let fit = fit_axis_aligned_poses(&poses, G).expect("fit");
    assert!(fit.loo_rms.expect("12 poses leave 11") < EXACT);
}

#[test]
fn axis_aligned_refuses_samples_in_one_plane() {
    let truth = diagonal_truth(34, 0.1, 1.0);
    let mut r = rng(35);
    let dirs: Vec<Vec3> = (0..40)
        .map(|i| {
            let t = i as f64 * 0.157;
            Vec3::new(t.cos(), t.sin(), 0.0)
        })
        .collect();
    let points = mag_samples(&mut r, &truth, &dirs, 1.0, 0.0);
    assert!(matches!(
        fit_axis_aligned(&points, 1.0),
        Err(FitError::Underdetermined(_))
    ));
}

// ---------------------------------------------------------------- six-position

#[test]
fn six_position_recovers_a_full_matrix_exactly_without_noise() {
    let mut r = rng(40);
    let truth = random_calibration(
        &mut r,
        &TruthSpec {
            scale_error: 0.3,
            cross_axis: 0.05,
            offset_ratio: 0.2,
            reference: G,
            upper_triangular: false,
        },
    );
    for set in [PoseSet::SixFaces, PoseSet::TwelvePositions] {
        let dirs = directions(&mut r, set);
        let poses = accel_poses(&mut r, &truth, &dirs, G, 0.0, 1);
        let fit = fit_six_position(&poses, Some(&dirs), G).expect("fit");
        assert!(max_abs_diff_mat(&fit.cal.a, &truth.a) < EXACT, "{set:?}");
        assert!(max_abs_diff_vec(&fit.cal.b, &truth.b) < EXACT, "{set:?}");
    }
    // The six faces alone need no expected directions.
    let dirs = directions(&mut r, PoseSet::SixFaces);
    let poses = accel_poses(&mut r, &truth, &dirs, G, 0.0, 1);
    let fit = fit_six_position(&poses, None, G).expect("fit");
    assert!(max_abs_diff_mat(&fit.cal.a, &truth.a) < EXACT);
}

#[test]
fn six_position_reports_the_same_norm_residual_as_its_held_out_error_and_the_other_fits() {
    // Faces placed 3° off their axes: the six-position model takes each pose for its ±axis, so
    // its vector error holds the placement, while its held-out error (and every other static
    // fit's residual) is the norm residual. Fit and held-out error must be one quantity.
    let truth = upper_truth(42, G);
    let mut r = rng(43);
    let level = directions(&mut r, PoseSet::SixFaces);
    let dirs = perturb_directions(&mut r, &level, 3.0);
    let faces: Vec<Vec3> = dirs.iter().map(face_axis).collect();
    let poses = accel_poses(&mut r, &truth, &dirs, G, 0.0, 1);
    let fit = fit_six_position(&poses, Some(&faces), G).expect("fit");
    for (pose, residual) in poses.iter().zip(&fit.residuals) {
        let norm = (fit.cal.apply(&pose.mean).norm() - G) / G;
        assert_eq!(residual.to_bits(), norm.to_bits());
    }
    let vector_rms = (poses
        .iter()
        .zip(&faces)
        .map(|(p, u)| ((fit.cal.apply(&p.mean) - u * G).norm() / G).powi(2))
        .sum::<f64>()
        / poses.len() as f64)
        .sqrt();
    assert!(
        vector_rms > 1.5 * fit.rms,
        "the placement must show in the vector error for the test to mean anything: \
         vector {vector_rms:.3e}, norm {:.3e}",
        fit.rms
    );
}

/// The ±axis nearest to `d`.
fn face_axis(d: &Vec3) -> Vec3 {
    let k = d.iamax();
    let mut axis = Vec3::zeros();
    axis[k] = d[k].signum();
    axis
}

#[test]
fn six_position_covariance_predicts_the_monte_carlo_spread_of_b() {
    let mut r = rng(41);
    let truth = random_calibration(
        &mut r,
        &TruthSpec {
            reference: G,
            ..TruthSpec::default()
        },
    );
    let dirs = directions(&mut r, PoseSet::TwelvePositions);
    let (sigma, n, trials) = (0.05, 50, 400);
    let mut errors: Vec<Vec3> = Vec::new();
    let mut predicted = Vec3::zeros();
    for _ in 0..trials {
        let poses = accel_poses(&mut r, &truth, &dirs, G, sigma, n);
        let fit = fit_six_position(&poses, Some(&dirs), G).expect("fit");
        errors.push(fit.cal.b - truth.b);
        predicted += fit.std.expect("noise was reported").b / trials as f64;
    }
    for k in 0..3 {
        let mean = errors.iter().map(|e| e[k]).sum::<f64>() / trials as f64;
        let sd = (errors.iter().map(|e| (e[k] - mean).powi(2)).sum::<f64>() / (trials - 1) as f64)
            .sqrt();
        // Unbiased: the mean error is within K standard errors of zero.
        assert!(
            mean.abs() < K * sd / (trials as f64).sqrt(),
            "axis {k}: mean {mean}"
        );
        eprintln!(
            "six-position b{k}: empirical sd {sd:.3e}, predicted {:.3e}",
            predicted[k]
        );
        // A sample std from 400 trials has relative standard error 1/√800 ≈ 3.5 %; 20 % is > 5σ.
        assert!(
            (sd / predicted[k] - 1.0).abs() < 0.2,
            "axis {k}: empirical {sd} vs predicted {}",
            predicted[k]
        );
    }
}

#[test]
fn six_position_refuses_tilted_poses_without_expected_directions() {
    let truth = diagonal_truth(42, 0.05, G);
    let mut r = rng(43);
    let dirs = directions(&mut r, PoseSet::TwelvePositions);
    let poses = accel_poses(&mut r, &truth, &dirs, G, 0.0, 1);
    assert!(is_underdetermined_with(
        fit_six_position(&poses, None, G),
        "every pose must lie on a face"
    ));
}

#[test]
fn six_position_refuses_poses_near_one_plane() {
    let truth = diagonal_truth(44, 0.05, G);
    let mut r = rng(45);
    let dirs: Vec<Vec3> = (0..8)
        .map(|i| {
            let t = i as f64 * std::f64::consts::FRAC_PI_4;
            Vec3::new(t.cos(), t.sin(), 0.05).normalize()
        })
        .collect();
    let poses = accel_poses(&mut r, &truth, &dirs, G, 0.0, 1);
    assert!(is_underdetermined_with(
        fit_six_position(&poses, Some(&dirs), G),
        "all poses lie within 20° of a plane"
    ));
}

#[test]
fn six_position_refuses_nan_input() {
    let truth = diagonal_truth(46, 0.05, G);
    let mut r = rng(47);
    let dirs = directions(&mut r, PoseSet::SixFaces);
    let mut poses = accel_poses(&mut r, &truth, &dirs, G, 0.0, 1);
    poses[3].mean.y = f64::NAN;
    assert!(matches!(
        fit_six_position(&poses, None, G),
        Err(FitError::NonFinite(_))
    ));
    assert!(matches!(fit_minmax(&poses, G), Err(FitError::NonFinite(_))));
    assert!(matches!(fit_chen(&poses, G), Err(FitError::NonFinite(_))));
}

// ---------------------------------------------------------------- Chen

fn upper_truth(seed: u64, reference: f64) -> Calibration {
    random_calibration(
        &mut rng(seed),
        &TruthSpec {
            scale_error: 0.3,
            cross_axis: 0.05,
            offset_ratio: 0.2,
            reference,
            upper_triangular: true,
        },
    )
}

#[test]
fn chen_recovers_the_gauge_fixed_truth_exactly_from_an_unlevel_table() {
    let truth = upper_truth(50, G);
    let mut r = rng(51);
    // A table tilted by ~3°: the coarse six-face model is then wrong, the norm model is not.
    let level = directions(&mut r, PoseSet::TwelvePositions);
    let dirs = perturb_directions(&mut r, &level, 3.0);
    let poses = accel_poses(&mut r, &truth, &dirs, G, 0.0, 1);
    let coarse = chen_coarse(&poses, G).expect("coarse");
    assert!(
        max_abs_diff_vec(&coarse.b, &truth.b) > 1e-3,
        "the tilt must matter for the test to mean anything"
    );
    let fit = fit_chen(&poses, G).expect("fit");
    assert!(fit.iterations > 1);
    assert!(max_abs_diff_mat(&fit.cal.a, &truth.a) < EXACT);
    assert!(max_abs_diff_vec(&fit.cal.b, &truth.b) < EXACT);
    assert!(fit.loo_rms.expect("12 poses") < EXACT);
}

#[test]
fn chen_twelve_unknown_jacobian_has_three_null_directions_and_the_gauge_fixed_one_none() {
    let truth = upper_truth(52, G);
    let mut r = rng(53);
    // A full (non-triangular) A: the rank deficiency holds at every point, not just in the gauge.
    let rotated = Calibration {
        a: nalgebra::Rotation3::new(Vec3::new(0.3, -0.2, 0.5)).matrix() * truth.a,
        b: truth.b,
    };
    let dirs = directions(&mut r, PoseSet::TwelvePositions);
    let poses = accel_poses(&mut r, &rotated, &dirs, G, 0.0, 1);
    let sv = singular_values(&norm_jacobian_full(&poses, &rotated, G));
    assert_eq!(sv.len(), 12);
    // Rounding leaves the null singular values at ~1e-16 of the largest.
    for s in &sv[9..] {
        assert!(s / sv[0] < 1e-12, "null singular value ratio {}", s / sv[0]);
    }
    assert!(sv[8] / sv[0] > 1e-3, "rank 9: ratio {}", sv[8] / sv[0]);
    let sv9 = singular_values(&norm_jacobian_gauge(&poses, &truth, G));
    assert!(
        sv9[8] / sv9[0] > 1e-3,
        "gauge-fixed Jacobian has full rank: ratio {}",
        sv9[8] / sv9[0]
    );
}

#[test]
fn chen_covariance_predicts_the_monte_carlo_spread_of_b() {
    let truth = upper_truth(54, G);
    let mut r = rng(55);
    let dirs = directions(&mut r, PoseSet::TwelvePositions);
    let (sigma, n, trials) = (0.05, 50, 300);
    let mut errors: Vec<Vec3> = Vec::new();
    let mut predicted = Vec3::zeros();
    for _ in 0..trials {
        let poses = accel_poses(&mut r, &truth, &dirs, G, sigma, n);
        let fit = fit_chen(&poses, G).expect("fit");
        errors.push(fit.cal.b - truth.b);
        predicted += fit.std.expect("noise was reported").b / trials as f64;
    }
    for k in 0..3 {
        let mean = errors.iter().map(|e| e[k]).sum::<f64>() / trials as f64;
        let sd = (errors.iter().map(|e| (e[k] - mean).powi(2)).sum::<f64>() / (trials - 1) as f64)
            .sqrt();
        assert!(
            mean.abs() < K * sd / (trials as f64).sqrt(),
            "axis {k}: mean {mean}"
        );
        eprintln!(
            "chen b{k}: empirical sd {sd:.3e}, predicted {:.3e}",
            predicted[k]
        );
        // Relative standard error of a std from 300 trials ≈ 4 %; 25 % allows > 5σ.
        assert!(
            (sd / predicted[k] - 1.0).abs() < 0.25,
            "axis {k}: empirical {sd} vs predicted {}",
            predicted[k]
        );
    }
}

#[test]
fn chen_refuses_fewer_than_nine_distinct_orientations() {
    let truth = upper_truth(56, G);
    let mut r = rng(57);
    let mut dirs = directions(&mut r, PoseSet::SixFaces);
    dirs.extend(directions(&mut r, PoseSet::SixFaces));
    let poses = accel_poses(&mut r, &truth, &dirs, G, 0.0, 1);
    assert!(is_underdetermined_with(
        fit_chen(&poses, G),
        "6 distinct orientations (readings within 5° counted as one) cannot determine the 9 unknowns"
    ));
}

// ---------------------------------------------------------------- Li

#[test]
fn li_fits_noise_free_samples_exactly_despite_the_zero_eigenvalue() {
    let mut r = rng(60);
    let truth = random_calibration(
        &mut r,
        &TruthSpec {
            scale_error: 0.3,
            cross_axis: 0.1,
            offset_ratio: 2.0,
            reference: 1.0,
            upper_triangular: false,
        },
    );
    let dirs = directions(&mut r, PoseSet::Random(200));
    let points = mag_samples(&mut r, &truth, &dirs, 1.0, 0.0);
    for subtract_mean in [false, true] {
        let fit = fit_li(&points, 1.0, LiOptions { subtract_mean }).expect("fit");
        // Li returns the symmetric representative: compare the gauge-invariant AᵀA.
        let gram = fit.cal.a.transpose() * fit.cal.a;
        let gram_true = truth.a.transpose() * truth.a;
        assert!(
            max_abs_diff_mat(&gram, &gram_true) < EXACT,
            "mean {subtract_mean}"
        );
        assert!(
            max_abs_diff_vec(&fit.cal.b, &truth.b) < EXACT,
            "mean {subtract_mean}"
        );
        assert!(
            (fit.cal.a - fit.cal.a.transpose()).abs().max() < 1e-12,
            "M^½ is symmetric"
        );
        assert!(fit.rms < EXACT);
    }
}

#[test]
fn li_centre_error_is_within_noise_bounds() {
    let mut r = rng(61);
    let truth = random_calibration(
        &mut r,
        &TruthSpec {
            offset_ratio: 1.0,
            ..TruthSpec::default()
        },
    );
    let (sigma, count) = (0.01, 2000);
    let dirs = directions(&mut r, PoseSet::Random(count));
    let points = mag_samples(&mut r, &truth, &dirs, 1.0, sigma);
    let fit = fit_li(
        &points,
        1.0,
        LiOptions {
            subtract_mean: true,
        },
    )
    .expect("fit");
    // Centre of a sphere from N samples with radial noise σ: σ_b ≈ σ·√(3/N) per axis (each sample
    // constrains the centre along its own direction, ⟨u_k²⟩ = 1/3).
    let sigma_b = sigma * (3.0 / count as f64).sqrt();
    eprintln!(
        "li noisy: centre error {:.3e} (σ_b {sigma_b:.3e}), rms {:.4}",
        max_abs_diff_vec(&fit.cal.b, &truth.b),
        fit.rms
    );
    assert!(max_abs_diff_vec(&fit.cal.b, &truth.b) < K * sigma_b);
    // The residual RMS estimates the radial noise σ (relative to the unit field).
    assert!((fit.rms / sigma - 1.0).abs() < 0.1, "rms {}", fit.rms);
}

#[test]
fn li_mean_subtraction_improves_conditioning_with_a_large_offset() {
    let mut r = rng(62);
    let truth = random_calibration(
        &mut r,
        &TruthSpec {
            offset_ratio: 10.0,
            ..TruthSpec::default()
        },
    );
    let dirs = directions(&mut r, PoseSet::Random(500));
    let points = mag_samples(&mut r, &truth, &dirs, 1.0, 0.005);
    let plain = fit_li(
        &points,
        1.0,
        LiOptions {
            subtract_mean: false,
        },
    )
    .expect("fit");
    let centred = fit_li(
        &points,
        1.0,
        LiOptions {
            subtract_mean: true,
        },
    )
    .expect("fit");
    assert!(
        centred.condition_number * 100.0 < plain.condition_number,
        "centred {} vs plain {}",
        centred.condition_number,
        plain.condition_number
    );
    let err_plain = max_abs_diff_vec(&plain.cal.b, &truth.b);
    let err_centred = max_abs_diff_vec(&centred.cal.b, &truth.b);
    eprintln!(
        "li offset 10x: condition {:.3e} -> {:.3e}, centre error {err_plain:.3e} -> {err_centred:.3e}",
        plain.condition_number, centred.condition_number
    );
    // Centre from N samples with radial noise σ: σ_b ≈ σ·√(3/N) per axis.
    let sigma_b = 0.005 * (3.0 / 500.0_f64).sqrt();
    assert!(err_centred < K * sigma_b);

    // Without noise, rounding is all that is left: an offset 1000× the field squeezes the plain
    // design (condition ~1e7, squared in DᵀD) so far that it is refused, while the centred fit
    // keeps full precision.
    let far = Calibration {
        a: truth.a,
        b: truth.b * 100.0,
    };
    let exact = mag_samples(&mut r, &far, &dirs, 1.0, 0.0);
    assert!(is_underdetermined_with(
        fit_li(
            &exact,
            1.0,
            LiOptions {
                subtract_mean: false
            }
        ),
        "fit with mean subtraction"
    ));
    let centred = fit_li(
        &exact,
        1.0,
        LiOptions {
            subtract_mean: true,
        },
    )
    .expect("fit");
    let err_centred = max_abs_diff_vec(&centred.cal.b, &far.b) / far.b.norm();
    eprintln!(
        "li offset 1000x exact: condition {:.3e}, relative centre error {err_centred:.3e}",
        centred.condition_number
    );
    assert!(err_centred < 1e-12, "centred relative error {err_centred}");
}

#[test]
fn li_refuses_too_few_coplanar_and_nan_samples() {
    let truth = diagonal_truth(63, 1.0, 1.0);
    let mut r = rng(64);
    let dirs = directions(&mut r, PoseSet::Random(9));
    let few = mag_samples(&mut r, &truth, &dirs, 1.0, 0.0);
    assert!(is_underdetermined_with(
        fit_li(&few, 1.0, LiOptions::default()),
        "at least 10"
    ));
    let ring: Vec<Vec3> = (0..50)
        .map(|i| {
            let t = i as f64 * 0.1;
            Vec3::new(t.cos(), t.sin(), 0.0)
        })
        .collect();
    let ring_points = mag_samples(&mut r, &truth, &ring, 1.0, 0.0);
    assert!(matches!(
        fit_li(&ring_points, 1.0, LiOptions::default()),
        Err(FitError::Underdetermined(_))
    ));
    let sphere = directions(&mut r, PoseSet::Random(30));
    let mut nan = mag_samples(&mut r, &truth, &sphere, 1.0, 0.0);
    nan[7].z = f64::INFINITY;
    assert!(matches!(
        fit_li(&nan, 1.0, LiOptions::default()),
        Err(FitError::NonFinite(_))
    ));
}

#[test]
fn li_on_a_partial_cap_still_fits_exact_data() {
    let mut r = rng(65);
    let truth = random_calibration(&mut r, &TruthSpec::default());
    let dirs = cap_directions(&mut r, 300, Vec3::new(0.0, 0.3, 1.0), 70.0);
    let points = mag_samples(&mut r, &truth, &dirs, 1.0, 0.0);
    let fit = fit_li(
        &points,
        1.0,
        LiOptions {
            subtract_mean: true,
        },
    )
    .expect("fit");
    assert!(
        max_abs_diff_vec(&fit.cal.b, &truth.b) < 1e-7,
        "a cap is worse conditioned than the sphere"
    );
}

// ---------------------------------------------------------------- validation and LOO

#[test]
fn distinct_orientation_count_merges_repeats() {
    let mut r = rng(70);
    let mut dirs = directions(&mut r, PoseSet::TwelvePositions);
    dirs.extend(perturb_directions(&mut r, &dirs.clone(), 0.5));
    assert_eq!(count_distinct(&dirs, 5.0), 12);
}

#[test]
fn leave_one_out_flags_a_single_corrupted_pose() {
    let truth = upper_truth(71, G);
    let mut r = rng(72);
    let dirs = directions(&mut r, PoseSet::Random(15));
    let mut poses = accel_poses(&mut r, &truth, &dirs, G, 0.0, 1);
    let fit = |p: &[Pose]| {
        let start = Calibration {
            a: Mat3::identity(),
            b: Vec3::zeros(),
        };
        imucal::fit::chen::refine_norm_model(p, &start, G).map(|r| r.cal)
    };
    let clean = leave_one_out_rms(&poses, G, fit).expect("all refits succeed");
    assert!(
        clean < EXACT,
        "exact data predicts every held-out pose: {clean}"
    );
    poses[4].mean.x += 0.1 * G;
    let corrupted = leave_one_out_rms(&poses, G, fit).expect("all refits succeed");
    assert!(
        corrupted > 1e-3,
        "a 0.1 g error in one pose shows in held-out prediction: {corrupted}"
    );
}
