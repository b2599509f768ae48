//! The joint gyroscope fit with gravity and the magnetic field as reference directions
//! (`fit::gyro_joint`) on synthetic moves with a known `A`, most of them turns about the
//! vertical, where gravity alone sees nothing of the Z axis.
//!
//! The board lies about +Z up; eight moves turn it 60–120° about the vertical (each ending with
//! a tilt of ≈0.6°), eight tilt it by 86° about X or Y and back. Rates are exact; the still
//! ends' gravity and field directions carry Gaussian angle noise of known σ (gravity 0.2 mrad,
//! the field 0.6 mrad per component, about what the session's still ends give), and the field
//! is read in a frame turned 1.5° from the accelerometer's (the alignment's error), which the fit
//! must absorb. The σ the fit states must match the spread of its errors, and its σ of `A₃₃`
//! must be what the field's noise allows for the turns about the vertical.

use imucal::fit::gyro_joint::{fit_gyro_joint, FieldEnds, JointMotion};
use imucal::fit::gyro_scale::{fit_gyro_scale, GyroMotion};
use imucal::fit::{Mat3, Vec3};
use imucal::synthetic::rng;
use nalgebra::{Rotation3, Unit};
use rand::Rng;
use rand_distr::StandardNormal;

const GRAVITY_SIGMA: f64 = 2e-4;
const FIELD_SIGMA: f64 = 6e-4;
/// Field dip below the horizontal (a mid-latitude 60°).
const DIP_DEG: f64 = 60.0;
const TRIALS: u64 = 20;

fn normal(r: &mut impl Rng) -> f64 {
    r.sample(StandardNormal)
}

/// The unit `v` turned by a random small angle, σ per component perpendicular to it.
fn noisy(v: &Vec3, sigma: f64, r: &mut impl Rng) -> Vec3 {
    v + Vec3::new(normal(r), normal(r), normal(r)).cross(v) * sigma
}

/// The moves, and the sum of the squared angles turned about the vertical.
fn moves(truth: &Mat3, seed: u64) -> (Vec<JointMotion>, f64) {
    let mut r = rng(seed);
    let (dt, steps) = (0.01, 150);
    let to_raw = truth.try_inverse().expect("invertible truth");
    let up = Vec3::z();
    let dip = DIP_DEG.to_radians();
    let field_world = Vec3::new(dip.cos(), 0.0, -dip.sin());
    // The field's frame, turned from the accelerometer's by 1.5° about a skew axis.
    let field_frame = Rotation3::from_axis_angle(
        &Unit::new_normalize(Vec3::new(1.0, -2.0, 0.5)),
        1.5f64.to_radians(),
    );
    // Body → world.
    let mut attitude = Rotation3::from_euler_angles(0.03, -0.02, 0.4);
    let mut vertical_sq = 0.0;
    let mut out = Vec::new();
    for k in 0..16 {
        let (axis_body, angle) = if k % 4 >= 2 {
            // A tilt about body X or Y, then back to about +Z up.
            let axis = if k % 8 < 4 { Vec3::x() } else { Vec3::y() };
            (axis, if k % 4 == 2 { 1.5 } else { -1.5 })
        } else {
            let mut angle = r.gen_range(60f64..120.0).to_radians();
            if r.gen_bool(0.5) {
                angle = -angle;
            }
            vertical_sq += angle * angle;
            (attitude.inverse() * up, angle)
        };
        let axis_body = Unit::new_normalize(axis_body);
        let turn = Rotation3::from_axis_angle(&axis_body, angle);
        let raw = to_raw * (axis_body.into_inner() * angle / (dt * steps as f64));
        let before = attitude;
        let mut after = attitude * turn;
        let gravity = |att: &Rotation3<f64>| att.inverse() * up;
        let field = |att: &Rotation3<f64>| field_frame.inverse() * (att.inverse() * field_world);
        let motion = JointMotion {
            gravity: GyroMotion {
                gravity_before: noisy(&gravity(&before), GRAVITY_SIGMA / 2f64.sqrt(), &mut r),
                gravity_after: noisy(&gravity(&after), GRAVITY_SIGMA / 2f64.sqrt(), &mut r),
                rates: vec![raw; steps + 1],
                dt,
                angle_sigma: Some(GRAVITY_SIGMA),
            },
            field: Some(FieldEnds {
                before: noisy(&field(&before), FIELD_SIGMA / 2f64.sqrt(), &mut r),
                after: noisy(&field(&after), FIELD_SIGMA / 2f64.sqrt(), &mut r),
                sigma: FIELD_SIGMA,
            }),
        };
        out.push(motion);
        // The hand sets the board down a little tilted; the next move starts from there.
        if k % 4 < 2 {
            let tilt = Vec3::new(normal(&mut r), normal(&mut r), 0.0) * 0.01;
            after = Rotation3::new(tilt) * after;
        }
        attitude = after;
    }
    (out, vertical_sq)
}

#[test]
fn gravity_and_field_recover_the_z_column_where_gravity_alone_cannot() {
    let truth = Mat3::new(
        0.974, 0.008, -0.005, -0.006, 1.021, 0.004, 0.003, -0.009, 1.012,
    );
    let mut z_sq = 0.0;
    for seed in 0..TRIALS {
        let (motions, vertical_sq) = moves(&truth, seed);
        let joint = fit_gyro_joint(&motions, None).expect("the joint fit");
        let std = joint.fit.std.expect("a covariance").a;
        let error = joint.fit.cal.a - truth;
        for (e, s) in error.iter().zip(std.iter()) {
            z_sq += (e / s).powi(2);
        }
        // A turn θ about the vertical moves the field's horizontal part, cos(dip) of it, by θ:
        // each move measures θ to σ_f/cos(dip), so A₃₃ (the board is near +Z up) to
        // σ_f/(cos(dip)·√Σθ²) from the field alone; gravity and the tilts only add to it.
        // The stated σ is scaled by χ²/ν when above 1; with ν = 52 that stays below 1.6 (√: 1.26)
        // but once in a thousand fits, and the vertical is ≈1° off body Z: 1.5 covers both.
        let field_only = FIELD_SIGMA / (DIP_DEG.to_radians().cos() * vertical_sq.sqrt());
        assert!(
            std[(2, 2)] <= field_only * 1.5,
            "seed {seed}: σ(A33) {:.2e} against {field_only:.2e} from the field's noise",
            std[(2, 2)]
        );
        // The 1.5° of the field's frame is found, to its own few σ.
        let found = joint.field_rotation.norm().to_degrees();
        assert!(
            (found - 1.5).abs() < 0.2,
            "seed {seed}: field frame {found:.3}°"
        );
        let gravity: Vec<GyroMotion> = motions.iter().map(|m| m.gravity.clone()).collect();
        // Gravity alone: either refused, or Z's scale known far worse (the tilts about X and Y
        // turn about Z only through the hand's small tilts).
        if let Ok(alone) = fit_gyro_scale(&gravity, None) {
            let alone_sigma = alone.std.expect("a covariance").a[(2, 2)];
            assert!(
                alone_sigma > 3.0 * std[(2, 2)],
                "seed {seed}: gravity alone σ(A33) {alone_sigma:.2e}, joint {:.2e}",
                std[(2, 2)]
            );
        }
        assert!(joint.reduced_chi_square.is_some_and(|c| c < 3.0));
    }
    // Errors over their stated σ: RMS 1 when the σ is honest; 180 z-values, correlated within a
    // trial, put it within ±0.3 of 1 by a wide margin.
    let z_rms = (z_sq / (9 * TRIALS) as f64).sqrt();
    assert!((0.7..1.3).contains(&z_rms), "RMS error/σ {z_rms:.2}");
}

#[test]
fn without_enough_field_the_joint_fit_refuses() {
    let truth = Mat3::identity();
    let (mut motions, _) = moves(&truth, 1);
    for m in motions.iter_mut().skip(4) {
        m.field = None;
    }
    assert!(fit_gyro_joint(&motions, None).is_err());
}
