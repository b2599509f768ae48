//! Iterative fits against synthetic truth: LM on the norm model (accelerometer poses and
//! magnetometer samples, including the hard cases), the Frosio Gauss–Newton and Merayo
//! comparisons of seed 000, magnetometer-to-accelerometer alignment, and the Tedaldi gyroscope
//! scale fit. Tolerances are multiples of the reported or Monte Carlo standard deviation.

use imucal::fit::alignment::fit_alignment;
use imucal::fit::frosio::{fit_frosio, FrosioOptions};
use imucal::fit::gyro_scale::{fit_gyro_scale, GyroMotion};
use imucal::fit::linalg::upper_triangular_gauge;
use imucal::fit::merayo::fit_merayo;
use imucal::fit::norm_lm::{
    cramer_rao_bound, fit_accel_lm, fit_accel_lm_detailed, fit_mag_lm, refine_lm, NormLmOptions,
    NormObservations,
};
use imucal::fit::{Calibration, FitError, Mat3, Method, Pose, Vec3};
use imucal::synthetic::{
    accel_poses, cap_directions, directions, mag_samples, random_calibration, rng,
    sphere_directions, PoseSet, TruthSpec,
};
use nalgebra::{DMatrix, Rotation3};
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};

const G: f64 = 9.81;
const FIELD: f64 = 50.0;

/// `A11 A12 A13 A22 A23 A33 b1 b2 b3` of a calibration in the upper-triangular gauge.
fn upper_params(cal: &Calibration) -> [f64; 9] {
    let r = upper_triangular_gauge(&cal.a);
    [
        r[(0, 0)],
        r[(0, 1)],
        r[(0, 2)],
        r[(1, 1)],
        r[(1, 2)],
        r[(2, 2)],
        cal.b.x,
        cal.b.y,
        cal.b.z,
    ]
}

fn std_of(cov: &DMatrix<f64>) -> [f64; 9] {
    std::array::from_fn(|k| cov[(k, k)].sqrt())
}

fn assert_within_sigmas(name: &str, est: &[f64; 9], truth: &[f64; 9], std: &[f64; 9], k: f64) {
    for i in 0..9 {
        let err = (est[i] - truth[i]).abs();
        assert!(
            err < k * std[i],
            "{name}: parameter {i}: |error| {err:.3e} ≥ {k}σ = {:.3e}",
            k * std[i]
        );
    }
}

fn accel_truth(seed: u64) -> Calibration {
    let spec = TruthSpec {
        scale_error: 0.05,
        cross_axis: 0.02,
        offset_ratio: 0.05,
        reference: G,
        upper_triangular: true,
    };
    random_calibration(&mut rng(seed), &spec)
}

fn mag_truth(seed: u64, scale_error: f64, offset_ratio: f64) -> Calibration {
    let spec = TruthSpec {
        scale_error,
        cross_axis: 0.05,
        offset_ratio,
        reference: FIELD,
        upper_triangular: true,
    };
    random_calibration(&mut rng(seed), &spec)
}

#[test]
fn accel_lm_recovers_truth_from_twelve_poses_within_four_reported_sigmas() {
    let truth = accel_truth(1);
    let mut r = rng(2);
    let dirs = directions(&mut r, PoseSet::TwelvePositions);
    // 0.02 m/s² per sample, 200 samples per pose: σ of a pose mean ≈ 1.4 mm/s².
    let poses = accel_poses(&mut r, &truth, &dirs, G, 0.02, 200);
    let fit = fit_accel_lm(&poses, G).unwrap();
    let std = std_of(fit.covariance.as_ref().unwrap());
    // 4σ: a Gaussian error passes with probability 0.99994 per parameter.
    assert_within_sigmas(
        "accel",
        &upper_params(&fit.cal),
        &upper_params(&truth),
        &std,
        4.0,
    );
    assert!(
        fit.rms < 1e-3,
        "relative RMS {} should be at the 1e-4 noise level",
        fit.rms
    );
    assert!(fit.loo_rms.is_some_and(|l| l.is_finite() && l >= 0.0));
}

#[test]
fn accel_lm_reported_std_matches_the_monte_carlo_spread() {
    let truth = accel_truth(3);
    let mut r = rng(4);
    let dirs = directions(&mut r, PoseSet::TwelvePositions);
    let trials = 300;
    let mut sum_sq = [0.0; 9];
    let mut reported = [0.0; 9];
    for _ in 0..trials {
        let poses = accel_poses(&mut r, &truth, &dirs, G, 0.02, 100);
        let out = fit_accel_lm_detailed(&poses, G).unwrap();
        let est = upper_params(&out.fit.cal);
        let t = upper_params(&truth);
        let std = std_of(out.fit.covariance.as_ref().unwrap());
        for k in 0..9 {
            sum_sq[k] += (est[k] - t[k]).powi(2);
            reported[k] += std[k] / trials as f64;
        }
    }
    // With the noise right, the Birge rule max(1, χ²/ν) still inflates σ by chance whenever
    // χ²/ν > 1: with 12 poses and 9 parameters (ν = 3) by E[√max(1, χ²₃/3)] = 1.122 on average
    // (numerical integration over the χ²₃ density).
    let birge_mean = 1.122;
    for k in 0..9 {
        let spread = (sum_sq[k] / trials as f64).sqrt();
        // 300 trials estimate a std to ±4 % (1σ); 0.8–1.25 leaves ≥ 5σ of sampling margin.
        let ratio = reported[k] / (spread * birge_mean);
        assert!(
            (0.8..1.25).contains(&ratio),
            "parameter {k}: reported/MC std = {ratio:.3}"
        );
    }
}

#[test]
fn mag_lm_recovers_truth_from_300_samples_and_estimates_the_noise() {
    let truth = mag_truth(5, 0.2, 2.0);
    let mut r = rng(6);
    let dirs = sphere_directions(&mut r, 300);
    let sigma = 0.5;
    let points = mag_samples(&mut r, &truth, &dirs, FIELD, sigma);
    let fit = fit_mag_lm(&points, FIELD).unwrap();
    let std = std_of(fit.covariance.as_ref().unwrap());
    assert_within_sigmas(
        "mag",
        &upper_params(&fit.cal),
        &upper_params(&truth),
        &std,
        4.0,
    );
    // The reported std must agree with the Cramér–Rao bound for the true noise: the noise is
    // estimated from 291 degrees of freedom (±4 %), so within 15 %.
    let clean: Vec<Vec3> = dirs
        .iter()
        .map(|u| truth.a.try_inverse().unwrap() * (u * FIELD) + truth.b)
        .collect();
    let crb = cramer_rao_bound(&clean, &vec![sigma; clean.len()], &truth).unwrap();
    for (k, s) in std.iter().enumerate() {
        let ratio = s / crb[(k, k)].sqrt();
        assert!(
            (0.85..1.15).contains(&ratio),
            "parameter {k}: reported/CRB std = {ratio:.3}"
        );
    }
}

#[test]
fn mag_lm_reported_std_matches_the_monte_carlo_spread() {
    let truth = mag_truth(7, 0.2, 2.0);
    let mut r = rng(8);
    let dirs = sphere_directions(&mut r, 300);
    let trials = 150;
    let t = upper_params(&truth);
    let mut sum_sq = [0.0; 9];
    let mut reported = [0.0; 9];
    for _ in 0..trials {
        let points = mag_samples(&mut r, &truth, &dirs, FIELD, 0.5);
        let fit = fit_mag_lm(&points, FIELD).unwrap();
        let est = upper_params(&fit.cal);
        let std = std_of(fit.covariance.as_ref().unwrap());
        for k in 0..9 {
            sum_sq[k] += (est[k] - t[k]).powi(2);
            reported[k] += std[k] / trials as f64;
        }
    }
    for k in 0..9 {
        let ratio = reported[k] / (sum_sq[k] / trials as f64).sqrt();
        // 150 trials: ±6 % (1σ) on the spread; 0.75–1.33 is a ≥ 4σ margin.
        assert!(
            (0.75..1.33).contains(&ratio),
            "parameter {k}: reported/MC std = {ratio:.3}"
        );
    }
}

/// Run the magnetometer LM on 25 random instances of a hard case; every one must converge to
/// within 5 reported σ of the truth (5σ: 225 comparisons, a Gaussian false alarm ≈ 1e-4).
fn hard_case(name: &str, seed: u64, scale_error: f64, offset_ratio: f64, cap_deg: f64) {
    for trial in 0..25 {
        let truth = mag_truth(seed + trial, scale_error, offset_ratio);
        let mut r = rng(1000 + seed + trial);
        let axis = Vec3::new(r.gen(), r.gen(), r.gen()) - Vec3::repeat(0.5);
        let dirs = cap_directions(&mut r, 300, axis, cap_deg);
        let points = mag_samples(&mut r, &truth, &dirs, FIELD, 0.5);
        let fit =
            fit_mag_lm(&points, FIELD).unwrap_or_else(|e| panic!("{name} trial {trial}: {e}"));
        let std = std_of(fit.covariance.as_ref().unwrap());
        assert_within_sigmas(
            &format!("{name} trial {trial}"),
            &upper_params(&fit.cal),
            &upper_params(&truth),
            &std,
            5.0,
        );
    }
}

#[test]
fn mag_lm_converges_with_an_offset_ten_times_the_field() {
    hard_case("10x offset", 100, 0.2, 10.0, 180.0);
}

#[test]
fn mag_lm_converges_on_half_sphere_coverage() {
    hard_case("half sphere", 200, 0.2, 2.0, 90.0);
}

#[test]
fn mag_lm_converges_with_thirty_percent_scale_errors_and_large_offset() {
    hard_case("±30 % scale", 300, 0.3, 10.0, 180.0);
}

#[test]
fn frosio_gauss_newton_fails_with_a_large_offset_and_succeeds_after_mean_subtraction() {
    // Seed 000 section 3.2: with an offset far larger than the radius the undamped iteration
    // from A = I, b = 0 never converges; subtracting the mean first fixes it.
    let truth = mag_truth(11, 0.1, 10.0);
    let mut r = rng(12);
    let dirs = sphere_directions(&mut r, 300);
    // Normalised units (field = 1), as in seed 000 Table 2.
    let truth_unit = Calibration {
        a: truth.a * (1.0 / FIELD),
        b: truth.b,
    };
    let points = mag_samples(&mut r, &truth, &dirs, FIELD, 0.5);
    let plain = fit_frosio(&points, 1.0, &FrosioOptions::default());
    assert!(
        matches!(plain, Err(FitError::NotConverged { .. })),
        "expected no convergence, got {plain:?}"
    );
    let centred = fit_frosio(
        &points,
        1.0,
        &FrosioOptions {
            subtract_mean: true,
            ..FrosioOptions::default()
        },
    )
    .unwrap();
    let lm = fit_mag_lm(&points, 1.0).unwrap();
    let std = std_of(lm.covariance.as_ref().unwrap());
    // Frosio's squared-norm residual is a different (slightly less efficient) estimator than the
    // LM's; it must still land within 5 σ of the LM uncertainty.
    assert_within_sigmas(
        "frosio",
        &upper_params(&centred.cal),
        &upper_params(&truth_unit),
        &std,
        5.0,
    );
}

#[test]
fn merayo_recovers_truth_on_a_full_sphere() {
    let truth = mag_truth(13, 0.2, 3.0);
    let mut r = rng(14);
    let dirs = sphere_directions(&mut r, 300);
    let points = mag_samples(&mut r, &truth, &dirs, FIELD, 0.5);
    let fit = fit_merayo(&points, FIELD, true).unwrap();
    let lm = fit_mag_lm(&points, FIELD).unwrap();
    // Merayo's algebraic residual is not the ML one; on full coverage it is nearly as good:
    // within 5 σ of the LM uncertainty, and its own reported std within a factor 2 of the LM's.
    let lm_std = std_of(lm.covariance.as_ref().unwrap());
    assert_within_sigmas(
        "merayo",
        &upper_params(&fit.cal),
        &upper_params(&truth),
        &lm_std,
        5.0,
    );
    let own = std_of(fit.covariance.as_ref().unwrap());
    for k in 0..9 {
        let ratio = own[k] / lm_std[k];
        assert!(
            (0.5..2.0).contains(&ratio),
            "parameter {k}: Merayo/LM std = {ratio:.3}"
        );
    }
}

#[test]
fn refine_lm_refuses_non_finite_and_too_few_readings() {
    let mut points: Vec<Vec3> = sphere_directions(&mut rng(15), 20);
    let err = refine_lm(
        &NormObservations::uniform(points[..5].to_vec(), 0.01),
        &Calibration::identity(),
        1.0,
        &NormLmOptions::default(),
    );
    assert!(matches!(err, Err(FitError::Underdetermined(_))));
    points[3].y = f64::NAN;
    let err = refine_lm(
        &NormObservations::uniform(points, 0.01),
        &Calibration::identity(),
        1.0,
        &NormLmOptions::default(),
    );
    assert!(matches!(err, Err(FitError::NonFinite(_))));
}

fn gauss<R: Rng>(r: &mut R) -> f64 {
    StandardNormal.sample(r)
}

/// Accelerometer and magnetometer pose readings for a world with the given dip, the magnetometer
/// frame rotated by `mag_to_accel` relative to the accelerometer frame.
fn dip_poses(
    seed: u64,
    mag_to_accel: &Mat3,
    dip: f64,
    noise: f64,
    n: usize,
) -> (Vec<Vec3>, Vec<Vec3>) {
    let mut r = rng(seed);
    let up = Vec3::z();
    let field = Vec3::new(dip.cos(), 0.0, -dip.sin());
    let mut accel = Vec::new();
    let mut mag = Vec::new();
    for _ in 0..n {
        let w = Vec3::new(gauss(&mut r), gauss(&mut r), gauss(&mut r)) * 2.0;
        let body = Rotation3::new(w); // body → world
        let a =
            body.inverse() * up + Vec3::new(gauss(&mut r), gauss(&mut r), gauss(&mut r)) * noise;
        let m_accel = body.inverse() * field;
        let m = mag_to_accel.transpose() * m_accel
            + Vec3::new(gauss(&mut r), gauss(&mut r), gauss(&mut r)) * noise;
        accel.push(a);
        mag.push(m);
    }
    (accel, mag)
}

#[test]
fn iterations_steered_by_a_sample_of_the_data_reach_the_full_solution() {
    // 300 000 samples: above twice the default 2¹⁶ iteration samples, so by default the first
    // (weighting) pass is fitted on every 4th block of samples and the second pass solves the
    // corrected score straight from that solution, steered by the first pass's `JᵀJ` (no
    // least-squares iterations over every sample); without iteration samples both passes
    // iterate over every sample. The first pass's solution is then about √(N/m) ≈ 2 standard
    // errors off the full one, which moves the second pass's weights by ~10⁻⁴ relative, and
    // either iteration stops within a hundredth of σ of its root: a fiftieth of σ is the
    // bound. The covariance (a full sum at the solution in both) agrees to 10⁻³ relative.
    let points = imucal::synthetic::hard_and_soft_iron_cloud(300_000, 31);
    let start = fit_mag_lm(&points[..2000], FIELD).unwrap().cal;
    let obs = NormObservations::uniform(points, 1.0);
    let sampled = NormLmOptions {
        noise_known: false,
        ..NormLmOptions::default()
    };
    let full = NormLmOptions {
        iteration_samples: None,
        ..sampled
    };
    let a = refine_lm(&obs, &start, FIELD, &sampled).unwrap();
    let b = refine_lm(&obs, &start, FIELD, &full).unwrap();
    let (std_a, std_b) = (a.std.unwrap(), b.std.unwrap());
    for (k, (pa, pb)) in upper_params(&a.cal)
        .iter()
        .zip(upper_params(&b.cal))
        .enumerate()
    {
        let se = b.covariance.as_ref().unwrap()[(k, k)].sqrt();
        assert!(
            (pa - pb).abs() <= 0.02 * se,
            "parameter {k}: {pa} against {pb} ({:.2e} σ)",
            (pa - pb) / se
        );
    }
    for (sa, sb) in std_a
        .a
        .iter()
        .chain(std_a.b.iter())
        .zip(std_b.a.iter().chain(std_b.b.iter()))
    {
        assert!((sa - sb).abs() <= 1e-3 * sb, "σ {sa:.6e} against {sb:.6e}");
    }
    assert!((a.condition_number / b.condition_number - 1.0).abs() < 1e-3);
}

#[test]
fn alignment_recovers_a_small_rotation_and_the_dip() {
    let truth = Rotation3::new(Vec3::new(0.03, -0.02, 0.05)).into_inner();
    let dip = 64f64.to_radians();
    let (accel, mag) = dip_poses(21, &truth, dip, 0.002, 20);
    let fit = fit_alignment(&accel, &mag).unwrap();
    let err = Rotation3::from_matrix(&(fit.rotation * truth.transpose())).scaled_axis();
    for k in 0..3 {
        // 4σ per axis, plus the unobservable-free check that std is at the noise scale.
        assert!(
            err[k].abs() < 4.0 * fit.rotation_std[k],
            "axis {k}: {:.2e} vs σ {:.2e}",
            err[k],
            fit.rotation_std[k]
        );
        assert!(
            fit.rotation_std[k] < 0.01,
            "axis {k}: σ {:.2e} rad is far above the 2 mrad noise",
            fit.rotation_std[k]
        );
    }
    assert!(
        (fit.dip - dip).abs() < 4.0 * fit.dip_std,
        "dip error {:.2e}",
        fit.dip - dip
    );
}

#[test]
fn alignment_recovers_a_swapped_and_inverted_magnetometer_mounting() {
    // Magnetometer x = accelerometer y, y = x, z = −z (a common two-die mounting), plus 2°.
    let swap = Mat3::new(0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, -1.0);
    let truth = Rotation3::new(Vec3::new(0.0, 0.035, 0.0)).into_inner() * swap;
    let (accel, mag) = dip_poses(22, &truth, 50f64.to_radians(), 0.002, 16);
    let fit = fit_alignment(&accel, &mag).unwrap();
    let angle = Rotation3::from_matrix(&(fit.rotation * truth.transpose())).angle();
    // σ per axis ≈ 1 mrad (2 mrad noise, 16 poses); 4σ·√3 ≈ 7 mrad.
    assert!(angle < 0.007, "rotation error {angle:.2e} rad");
}

#[test]
fn alignment_uncertainty_is_the_same_whichever_mounting_the_fit_starts_from() {
    // The same poses, the magnetometer's axes once as they are and once permuted and flipped:
    // the rotation differs by that permutation, its uncertainty about the accelerometer's axes
    // (the same geometry in the accelerometer frame) must not. With a rotation of 100° the
    // winning start is far from the solution, where the rotation vector's own covariance and
    // the rotation's differ by the SO(3) left Jacobian (≈ 30 % at 100°).
    let truth = Rotation3::new(Vec3::new(1.2, -0.8, 0.9)).into_inner();
    let (accel, mag) = dip_poses(23, &truth, 60f64.to_radians(), 0.003, 40);
    let swap = Mat3::new(0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0);
    let swapped: Vec<Vec3> = mag.iter().map(|m| swap * m).collect();
    let plain = fit_alignment(&accel, &mag).unwrap();
    let permuted = fit_alignment(&accel, &swapped).unwrap();
    let rotation_gap =
        Rotation3::from_matrix(&(permuted.rotation * swap * plain.rotation.transpose())).angle();
    assert!(
        rotation_gap < 1e-9,
        "rotations differ by {rotation_gap:.2e} rad"
    );
    for k in 0..3 {
        // Same data, same minimum: equal up to the solver's tolerance, not statistically.
        let (a, b) = (plain.rotation_std[k], permuted.rotation_std[k]);
        assert!(
            (a - b).abs() <= 1e-6 * a,
            "axis {k}: σ {a:.6e} against {b:.6e}"
        );
    }
    // Both are the σ of the left perturbation `exp([δ]×)·R` at the solution: rows
    // `((Rm̂ᵢ × ĝᵢ)ᵀ, cos δ)`, covariance `(JᵀJ)⁻¹·cost/(N − 4)`.
    let unit = |v: &Vec3| v.normalize();
    let rows: Vec<[f64; 4]> = accel
        .iter()
        .zip(&mag)
        .map(|(g, m)| {
            let d = (plain.rotation * unit(m)).cross(&unit(g));
            [d.x, d.y, d.z, plain.dip.cos()]
        })
        .collect();
    let jtj = nalgebra::Matrix4::from_fn(|i, j| rows.iter().map(|r| r[i] * r[j]).sum::<f64>());
    let cost: f64 = accel
        .iter()
        .zip(&mag)
        .map(|(g, m)| (unit(g).dot(&(plain.rotation * unit(m))) + plain.dip.sin()).powi(2))
        .sum();
    let covariance = jtj.try_inverse().unwrap() * (cost / (accel.len() - 4) as f64);
    for k in 0..3 {
        let expected = covariance[(k, k)].sqrt();
        let s = plain.rotation_std[k];
        assert!(
            (s - expected).abs() <= 1e-6 * expected,
            "axis {k}: σ {s:.6e} against {expected:.6e}"
        );
    }
}

#[test]
fn alignment_refuses_poses_turned_only_about_the_vertical() {
    let up = Vec3::z();
    let field = Vec3::new(0.5, 0.0, -0.85);
    let (accel, mag): (Vec<Vec3>, Vec<Vec3>) = (0..10)
        .map(|k| {
            let body = Rotation3::from_axis_angle(&Vec3::z_axis(), f64::from(k) * 0.6);
            (body.inverse() * up, body.inverse() * field)
        })
        .unzip();
    assert!(matches!(
        fit_alignment(&accel, &mag),
        Err(FitError::Underdetermined(_))
    ));
}

/// Motions about fixed body axes with a smooth angle profile: the end rotation is known exactly.
fn gyro_motions(truth: &Mat3, seed: u64, count: usize, rate_noise: f64) -> Vec<GyroMotion> {
    gyro_motions_about(truth, seed, count, rate_noise, &Vec3::repeat(1.0))
}

/// As [`gyro_motions`], the random turn axes weighted per body axis by `axis_weight`.
fn gyro_motions_about(
    truth: &Mat3,
    seed: u64,
    count: usize,
    rate_noise: f64,
    axis_weight: &Vec3,
) -> Vec<GyroMotion> {
    let mut r = rng(seed);
    let dt = 0.005;
    let steps = 300; // 1.5 s per motion
    let duration = dt * steps as f64;
    let to_raw = truth.try_inverse().unwrap();
    let mut gravity = Vec3::new(0.3, -0.2, 0.93).normalize();
    let mut motions = Vec::new();
    for _ in 0..count {
        let axis = Vec3::new(gauss(&mut r), gauss(&mut r), gauss(&mut r))
            .component_mul(axis_weight)
            .normalize();
        let total = r.gen_range(1.0..2.5) * if r.gen::<bool>() { 1.0 } else { -1.0 };
        let rates: Vec<Vec3> = (0..=steps)
            .map(|k| {
                // θ(t) = total·(1 − cos(πt/T))/2, so ω = θ'(t)·axis in the body frame.
                let t = k as f64 * dt;
                let omega = axis
                    * (total * std::f64::consts::PI / (2.0 * duration)
                        * (std::f64::consts::PI * t / duration).sin());
                to_raw * omega + Vec3::new(gauss(&mut r), gauss(&mut r), gauss(&mut r)) * rate_noise
            })
            .collect();
        let after = Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), total)
            .inverse()
            * gravity;
        motions.push(GyroMotion {
            gravity_before: gravity * G,
            gravity_after: after * G,
            rates,
            dt,
            angle_sigma: None,
        });
        gravity = after;
    }
    motions
}

#[test]
fn tedaldi_gyro_fit_recovers_a_known_scale_and_misalignment_matrix() {
    let truth = Mat3::new(1.04, 0.012, -0.008, -0.015, 0.97, 0.02, 0.01, -0.006, 1.02);
    let motions = gyro_motions(&truth, 31, 16, 0.003);
    let fit = fit_gyro_scale(&motions, None).unwrap();
    let std = fit.std.unwrap().a;
    for i in 0..3 {
        for j in 0..3 {
            let err = (fit.cal.a[(i, j)] - truth[(i, j)]).abs();
            // 4σ from the fit's own covariance; the noise (3 mrad/s at 200 Hz) gives σ ≈ 1e-3.
            assert!(
                err < 4.0 * std[(i, j)],
                "A[{i}][{j}]: |error| {err:.2e} vs σ {:.2e}",
                std[(i, j)]
            );
            assert!(err < 0.005, "A[{i}][{j}]: |error| {err:.2e}");
        }
    }
}

#[test]
fn tedaldi_gyro_fit_refuses_motions_that_barely_turn_about_one_axis_and_names_it() {
    let truth = Mat3::new(1.04, 0.012, -0.008, -0.015, 0.97, 0.02, 0.01, -0.006, 1.02);
    // Turns about y are 0.01 % of the others: the y row of A (the output y rate) is not
    // determined by 16 motions (its σ would exceed 10 % of the unit gain).
    let motions = gyro_motions_about(&truth, 33, 16, 0.003, &Vec3::new(1.0, 1e-4, 1.0));
    match fit_gyro_scale(&motions, None) {
        Err(FitError::Underdetermined(msg)) => {
            assert!(msg.contains("y axis"), "{msg}")
        }
        other => panic!("expected a refusal naming the y axis, got {other:?}"),
    }
}

#[test]
fn tedaldi_gyro_fit_reports_its_convergence_reason() {
    let motions = gyro_motions(&Mat3::identity(), 34, 12, 0.003);
    let fit = fit_gyro_scale(&motions, None).unwrap();
    assert!(fit.termination.is_some_and(|t| t.is_converged()));
}

#[test]
fn tedaldi_gyro_fit_refuses_too_few_motions() {
    let truth = Mat3::identity();
    let motions = gyro_motions(&truth, 32, 3, 0.0);
    assert!(matches!(
        fit_gyro_scale(&motions, None),
        Err(FitError::Underdetermined(_))
    ));
}

#[test]
fn twelve_positions_fitted_to_their_noise_converge_where_round_off_exceeds_the_tolerances() {
    // The twelve positions a simulated session (seed 1, 5x speed) captured: accelerometer means
    // (m/s^2), per-axis variances and sample counts. Weighted by the noise of their means the
    // fit leaves a cost of 0.29 for 3 degrees of freedom, and the cost's round-off (weights of
    // thousands) is above ftol = 1e-12 relative to it: every step was rejected and the fit
    // failed with damping_overflow, which sent the chain to min/max at 30x the held-out error.
    // The Gauss-Newton step left there is 1e-6 of a standard error: a minimum.
    let raw = [
        (
            [-0.39119231700897217, 0.6926025152206421, 10.259757041931152],
            [
                0.0006619694759137928,
                0.00044141680700704455,
                0.0005251634865999222,
            ],
            70,
        ),
        (
            [-0.05973241105675697, 0.6924702525138855, -9.76911449432373],
            [
                0.0003966270014643669,
                0.0004323100729379803,
                0.0004163780831731856,
            ],
            95,
        ),
        (
            [9.608709335327148, 0.39674100279808044, 0.3161138594150543],
            [
                0.00042881048284471035,
                0.0006197748007252812,
                0.0004856915329582989,
            ],
            87,
        ),
        (
            [-9.87153148651123, 0.6970700621604919, 0.5559227466583252],
            [
                0.00045125867472961545,
                0.000674048496875912,
                0.0004574196063913405,
            ],
            82,
        ),
        (
            [-0.29927563667297363, 9.976980209350586, 0.2656298875808716],
            [
                0.0005401544622145593,
                0.0004884658847004175,
                0.0005024367710575461,
            ],
            90,
        ),
        (
            [
                -0.08381815254688263,
                -9.385205268859863,
                0.22345149517059326,
            ],
            [
                0.00033283772063441575,
                0.0004769753140863031,
                0.00045523341395892203,
            ],
            69,
        ),
        (
            [6.6667704582214355, 7.131306171417236, -0.008046831004321575],
            [
                0.00045389877050183713,
                0.0005617915885522962,
                0.0005190664669498801,
            ],
            62,
        ),
        (
            [-7.056742191314697, 7.205440521240234, 0.25013288855552673],
            [
                0.0004166992730461061,
                0.0005129429046064615,
                0.0005134791717864573,
            ],
            101,
        ),
        (
            [-0.15723605453968048, 7.296360492706299, 7.152285099029541],
            [
                0.00071235146606341,
                0.0003543395141605288,
                0.0004560639208648354,
            ],
            52,
        ),
        (
            [-0.24970553815364838, -6.531118869781494, 7.370600700378418],
            [
                0.00032220882712863386,
                0.00038296825368888676,
                0.0003508461522869766,
            ],
            66,
        ),
        (
            [6.725956439971924, 0.42553049325942993, 7.373648166656494],
            [
                0.0005520203267224133,
                0.0005013610934838653,
                0.0005122628062963486,
            ],
            58,
        ),
        (
            [-7.083353042602539, 0.21387048065662384, 7.261618614196777],
            [
                0.0005098820547573268,
                0.0005574398091994226,
                0.0005264226929284632,
            ],
            100,
        ),
    ];
    let poses: Vec<Pose> = raw
        .iter()
        .map(|(m, v, n)| Pose {
            mean: Vec3::from(*m),
            var: Vec3::from(*v),
            n: *n,
            label: None,
        })
        .collect();
    let fit = fit_accel_lm(&poses, 9.80665).expect("the norm model fits twelve positions");
    assert!(fit.termination.is_some_and(|t| t.is_converged()));
    // At the noise floor: the relative norm residual is a few 1e-5 (pose noise ≈ 3e-4 m/s²).
    assert!(fit.rms < 1e-4, "rms {}", fit.rms);
    let chain = imucal::pipeline::chain::default_accel_chain(&poses, 9.80665).expect("fits");
    assert_eq!(chain.fit.method, Method::Lm, "{}", chain.reason);
}
