//! The coverage rule of the norm-model fits (`fit::coverage::check_coverage`): data that cannot
//! determine the ellipsoid are refused by every method with a sentence naming what is missing,
//! and well-covered data still fit.

use imucal::fit::axis_aligned::fit_axis_aligned;
use imucal::fit::frosio::{fit_frosio, FrosioOptions};
use imucal::fit::li::{fit_li, LiOptions};
use imucal::fit::merayo::fit_merayo;
use imucal::fit::norm_lm::{fit_accel_lm, fit_mag_lm};
use imucal::fit::{Fit, FitError, Vec3};
use imucal::synthetic::{
    accel_poses, directions, mag_samples, random_calibration, rng, sphere_directions, PoseSet,
    TruthSpec,
};

const FIELD: f64 = 50.0;

fn mag_truth() -> imucal::fit::Calibration {
    let spec = TruthSpec {
        scale_error: 0.2,
        cross_axis: 0.05,
        offset_ratio: 2.0,
        reference: FIELD,
        upper_triangular: true,
    };
    random_calibration(&mut rng(7), &spec)
}

fn every_mag_method(points: &[Vec3]) -> Vec<(&'static str, Result<Fit, FitError>)> {
    let centred = FrosioOptions {
        subtract_mean: true,
        ..FrosioOptions::default()
    };
    vec![
        ("lm", fit_mag_lm(points, FIELD)),
        (
            "li",
            fit_li(
                points,
                FIELD,
                LiOptions {
                    subtract_mean: true,
                },
            ),
        ),
        ("merayo", fit_merayo(points, FIELD, true)),
        ("frosio", fit_frosio(points, FIELD, &centred)),
        ("axis-aligned", fit_axis_aligned(points, FIELD)),
    ]
}

fn refusal(name: &str, result: &Result<Fit, FitError>) -> String {
    match result {
        Err(FitError::Underdetermined(text)) => text.clone(),
        Err(other) => panic!("{name}: refused for the wrong reason: {other}"),
        Ok(fit) => panic!(
            "{name}: returned a fit (RMS {:.3e}) on data that cannot determine it",
            fit.rms
        ),
    }
}

#[test]
fn a_planar_circle_of_magnetometer_samples_is_refused_by_every_method() {
    let truth = mag_truth();
    let mut r = rng(8);
    // A horizontal turn: the field's direction sweeps one cone (a circle on the sphere).
    let dirs: Vec<Vec3> = (0..400)
        .map(|k| {
            let a = k as f64 * std::f64::consts::TAU / 400.0;
            Vec3::new(0.8 * a.cos(), 0.8 * a.sin(), 0.6)
        })
        .collect();
    let points = mag_samples(&mut r, &truth, &dirs, FIELD, 0.3);
    for (name, result) in every_mag_method(&points) {
        let text = refusal(name, &result);
        assert!(
            text.contains("turn the board through all orientations"),
            "{name}: {text}"
        );
    }
}

#[test]
fn three_static_poses_of_magnetometer_samples_are_refused_as_three_orientations() {
    let truth = mag_truth();
    let mut r = rng(9);
    let poses = [Vec3::x(), Vec3::y(), Vec3::new(0.0, 0.6, -0.8)];
    let dirs: Vec<Vec3> = (0..600).map(|k| poses[k % 3]).collect();
    let points = mag_samples(&mut r, &truth, &dirs, FIELD, 0.3);
    for (name, result) in every_mag_method(&points) {
        let text = refusal(name, &result);
        // Noise of 0.3 µT on 50 µT is 0.3°, far inside the 5° that makes readings one orientation.
        // A fit that failed is judged through its start or an algebraic fit, which may not pass
        // through the poses, so the count may include noise.
        assert!(
            text.contains("distinct orientations") || text.contains("a few orientations"),
            "{name}: {text}"
        );
    }
}

#[test]
fn one_static_pose_is_refused_as_one_orientation_not_as_a_tiny_ellipsoid() {
    let truth = mag_truth();
    let mut r = rng(10);
    let dirs = vec![Vec3::z(); 500];
    let points = mag_samples(&mut r, &truth, &dirs, FIELD, 0.3);
    for (name, result) in every_mag_method(&points) {
        let text = refusal(name, &result);
        assert!(
            text.contains("one orientation") || text.contains("do not trace an ellipsoid"),
            "{name}: {text}"
        );
    }
}

#[test]
fn six_faces_are_refused_by_the_norm_model_with_the_six_position_advice() {
    let spec = TruthSpec {
        scale_error: 0.03,
        cross_axis: 0.01,
        offset_ratio: 0.05,
        reference: 9.81,
        upper_triangular: true,
    };
    let truth = random_calibration(&mut rng(11), &spec);
    let mut r = rng(12);
    let dirs = directions(&mut r, PoseSet::SixFaces);
    // Each face held twice: 12 poses, still only 6 orientations.
    let twice: Vec<Vec3> = dirs.iter().chain(dirs.iter()).copied().collect();
    let poses = accel_poses(&mut r, &truth, &twice, 9.81, 0.02, 100);
    let text = refusal("lm", &fit_accel_lm(&poses, 9.81));
    assert!(
        text.starts_with("6 distinct orientations") && text.contains("--method six-position"),
        "{text}"
    );
}

#[test]
fn a_full_sphere_still_fits_within_the_noise_after_the_coverage_check() {
    let truth = mag_truth();
    let mut r = rng(13);
    let dirs = sphere_directions(&mut r, 300);
    let sigma = 0.5;
    let points = mag_samples(&mut r, &truth, &dirs, FIELD, sigma);
    for (name, result) in every_mag_method(&points) {
        if name == "axis-aligned" {
            continue; // the truth has cross terms the axis-aligned model cannot fit
        }
        let fit = result.unwrap_or_else(|e| panic!("{name}: {e}"));
        // Relative radial noise σ/H = 1 %; the RMS of 300 residuals is within 20 % of it.
        assert!(
            (fit.rms - sigma / FIELD).abs() < 0.2 * sigma / FIELD,
            "{name}: RMS {:.4}",
            fit.rms
        );
    }
}
