//! The Tedaldi gyroscope scale fit with motions of unequal noise: weighting each motion by the
//! inverse of its stated angle σ (generalised least squares) must beat weighing them alike, and
//! its reported σ must match the spread of its errors.
//!
//! Synthetic motions: constant-rate turns of 60–120° about random axes, read by a gyroscope with
//! a known `A`; the gravity direction after each turn is exact up to an added angle noise whose σ
//! alternates between a quiet and a ten times noisier motion (a short still end, say).

use imucal::fit::gyro_scale::{fit_gyro_scale, GyroMotion};
use imucal::fit::{Mat3, Vec3};
use imucal::synthetic::rng;
use nalgebra::{Rotation3, Unit};
use rand::Rng;
use rand_distr::StandardNormal;

/// Per-component angle noise of the quiet motions, rad; the others have ten times as much.
const QUIET_RAD: f64 = 2e-4;
const MOTIONS: usize = 24;
const TRIALS: u64 = 20;

fn normal(r: &mut impl Rng) -> f64 {
    r.sample(StandardNormal)
}

/// `MOTIONS` turns read by a gyroscope whose calibration is `truth`; `weighted` says whether
/// the motions state their angle σ.
fn motions(truth: &Mat3, seed: u64, weighted: bool) -> Vec<GyroMotion> {
    let mut r = rng(seed);
    let (dt, steps) = (0.01, 100);
    let to_raw = truth.try_inverse().expect("invertible truth");
    let mut gravity = Vec3::new(0.2, -0.3, 0.93).normalize();
    (0..MOTIONS)
        .map(|k| {
            let axis =
                Unit::new_normalize(Vec3::new(normal(&mut r), normal(&mut r), normal(&mut r)));
            let angle = r.gen_range(60f64..120.0).to_radians();
            let raw = to_raw * (axis.into_inner() * angle / (dt * steps as f64));
            let after = Rotation3::from_axis_angle(&axis, angle).inverse() * gravity;
            let sigma = if k % 2 == 0 {
                QUIET_RAD
            } else {
                10.0 * QUIET_RAD
            };
            let noise = Vec3::new(normal(&mut r), normal(&mut r), normal(&mut r)) * sigma;
            let motion = GyroMotion {
                gravity_before: gravity,
                gravity_after: (after + noise).normalize(),
                rates: vec![raw; steps + 1],
                dt,
                angle_sigma: weighted.then_some(sigma),
            };
            gravity = after;
            motion
        })
        .collect()
}

#[test]
fn weighing_motions_by_their_noise_beats_weighing_them_alike_and_states_an_honest_sigma() {
    let truth = Mat3::new(
        0.974, 0.008, -0.005, -0.006, 1.021, 0.004, 0.003, -0.009, 1.012,
    );
    let (mut weighted_sq, mut alike_sq, mut z_sq) = (0.0, 0.0, 0.0);
    for seed in 0..TRIALS {
        let weighted = fit_gyro_scale(&motions(&truth, seed, true), None).expect("fit");
        let alike = fit_gyro_scale(&motions(&truth, seed, false), None).expect("fit");
        let std = weighted.std.expect("a covariance").a;
        for (e, s) in (weighted.cal.a - truth).iter().zip(std.iter()) {
            weighted_sq += e * e;
            z_sq += (e / s).powi(2);
        }
        alike_sq += (alike.cal.a - truth).norm_squared();
    }
    // Half the motions at 10× the noise: least squares weighing them alike has about
    // (1 + 100)/2 ≈ 50 times the variance per motion of the quiet half, the weighted fit about
    // half of that of the quiet motions alone, so its mean square error is ≈ 1/25 of the other;
    // 1/4 leaves room for the scatter of 20 trials.
    assert!(
        weighted_sq < alike_sq / 4.0,
        "weighted {weighted_sq:.3e} vs alike {alike_sq:.3e}"
    );
    // The errors over their σ: RMS 1 when the σ is honest; 180 correlated z-values put the
    // RMS within ±0.3 of 1 by a wide margin.
    let z_rms = (z_sq / (9 * TRIALS) as f64).sqrt();
    assert!((0.7..1.3).contains(&z_rms), "RMS error/σ {z_rms:.2}");
}
