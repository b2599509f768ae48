//! The guided session's magnetometer alignment from board-averaged poses: a spike the board
//! averaged into one position's field is screened out by the calibrated magnitude, named in
//! the fit's notes, and the rotation stays within its normal error. Synthetic poses and
//! tumble with a known mounting rotation between the two sensors. Also, on the same poses, the
//! verdict of a set extended by the residual analysis: the base fit's held-out reason replaced
//! by the extended model's.

use imucal::fit::Vec3;
use imucal::session::targets::twelve_positions;
use imucal::session::{fit_session, Budgets, CapturedPose};
use imucal_protocol::PoseStats;
use nalgebra::{Rotation3, Unit};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal, UnitSphere};

const G: f64 = 9.806_65;
const FIELD_UT: f64 = 48.0;
const DIP_DEG: f64 = 62.0;
const SAMPLES_PER_POSE: u32 = 1000;
const MAG_NOISE_UT: f64 = 0.3;

fn field_world() -> Vec3 {
    let dip = DIP_DEG.to_radians();
    Vec3::new(dip.cos(), 0.0, -dip.sin()) * FIELD_UT
}

/// Magnetometer frame → accelerometer frame, as mounted: 4° about an oblique axis.
fn mounting() -> Rotation3<f64> {
    Rotation3::from_axis_angle(
        &Unit::new_normalize(Vec3::new(0.2, 0.7, -0.4)),
        4.0_f64.to_radians(),
    )
}

fn mag_bias() -> Vec3 {
    Vec3::new(-12.0, 30.0, 7.5)
}

/// Raw magnetometer reading with the board turned by `body_to_world`.
fn raw_mag(body_to_world: &Rotation3<f64>) -> Vec3 {
    mounting().inverse() * (body_to_world.inverse() * field_world()) + mag_bias()
}

/// The twelve positions, each with its own heading, and the board's averaged statistics
/// (the means noise-free: a pose mean of 1000 samples is good to ~0.01 µT).
fn poses() -> Vec<CapturedPose> {
    twelve_positions()
        .into_iter()
        .enumerate()
        .map(|(k, target)| {
            let tilt = Rotation3::rotation_between(&target.up, &Vec3::z()).unwrap_or_else(|| {
                Rotation3::from_axis_angle(&Vec3::x_axis(), std::f64::consts::PI)
            });
            let body_to_world = Rotation3::from_axis_angle(&Vec3::z_axis(), 0.7 * k as f64) * tilt;
            let accel = target.up * G;
            let mag = raw_mag(&body_to_world);
            let f32s = |v: Vec3| [v.x as f32, v.y as f32, v.z as f32];
            CapturedPose {
                target,
                stats: PoseStats {
                    n: SAMPLES_PER_POSE,
                    accel_mean: f32s(accel),
                    accel_var: [4e-4; 3],
                    gyro_mean: [0.0; 3],
                    gyro_var: [1e-6; 3],
                    mag_mean: f32s(mag),
                    mag_var: [(MAG_NOISE_UT * MAG_NOISE_UT) as f32; 3],
                    temp_mean_c: 25.0,
                    temp_min_c: 25.0,
                    temp_max_c: 25.0,
                    duration_ms: 1000,
                },
                t_s: k as f64 * 5.0,
            }
        })
        .collect()
}

/// 1500 tumble samples over the whole sphere with white noise.
fn tumble() -> Vec<Vec3> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(5);
    let noise = Normal::new(0.0, MAG_NOISE_UT).expect("sigma");
    (0..1500)
        .map(|_| {
            let axis: [f64; 3] = UnitSphere.sample(&mut rng);
            let angle = rand::Rng::gen_range(&mut rng, 0.0..std::f64::consts::PI);
            let q = Rotation3::from_axis_angle(&Unit::new_normalize(Vec3::from(axis)), angle);
            raw_mag(&q) + Vec3::from_fn(|_, _| noise.sample(&mut rng))
        })
        .collect()
}

const BUDGETS: Budgets = Budgets {
    accel_mg: 2.0,
    mag_pct: 0.5,
};

/// Angle of the fitted mag→accel rotation away from the mounting rotation, degrees.
fn alignment_error_deg(poses: &[CapturedPose]) -> (f64, f64, Vec<String>) {
    let fit = fit_session(poses, &tumble(), G, Some(FIELD_UT), BUDGETS, 0).expect("fitted");
    let alignment = fit
        .alignment
        .as_ref()
        .expect("the magnetometer was aligned");
    // The norm fit leaves its output in an upper-triangular gauge; the alignment takes that
    // gauge into the accelerometer frame, so the written R·A maps raw readings as the mounting
    // rotation does (the reference is the true field, so the true A is that rotation).
    let a = fit.set.mag.a;
    let written = nalgebra::Matrix3::from_fn(|r, c| f64::from(a[r][c]));
    let error = written * mounting().inverse().matrix();
    let skew = (error - error.transpose()) / 2.0;
    let angle = Vec3::new(skew[(2, 1)], skew[(0, 2)], skew[(1, 0)]).norm();
    let sigma = alignment.rotation_std.norm();
    (angle.to_degrees(), sigma.to_degrees(), fit.notes.clone())
}

#[test]
fn clean_poses_align_the_magnetometer_to_its_mounting_rotation() {
    let (error, sigma, notes) = alignment_error_deg(&poses());
    // Tumble noise 0.3 µT over 1500 samples leaves the matrix good to ~1e-3 (0.06°).
    assert!(error < 0.1, "{error}° (σ {sigma}°)");
    assert!(notes.is_empty(), "{notes:?}");
}

#[test]
fn a_spike_averaged_into_one_position_is_left_out_of_the_alignment_and_named() {
    let mut poses = poses();
    // One read of 10⁵ µT among the 1000 samples the board averaged in position 5.
    let spike = 1e5 / f64::from(SAMPLES_PER_POSE);
    poses[5].stats.mag_mean[0] += spike as f32;
    let name = poses[5].target.name.clone();
    let (error, sigma, notes) = alignment_error_deg(&poses);
    assert!(
        error < 0.1,
        "{error}° (σ {sigma}°) with the spiked position"
    );
    assert_eq!(notes.len(), 1, "{notes:?}");
    assert!(
        notes[0].contains(&name) && notes[0].contains("left out of the alignment"),
        "{}",
        notes[0]
    );
}

#[test]
fn terms_that_explain_the_held_out_error_take_its_reason_and_level_out_of_the_verdict() {
    use imucal::session::solve::{heldout_reason, verdict_with_terms};
    use imucal::session::VerdictLevel;
    let mut fit = fit_session(&poses(), &tumble(), G, Some(FIELD_UT), BUDGETS, 0).expect("fitted");
    let clean = fit.verdict.clone();
    assert_ne!(clean.level, VerdictLevel::Poor, "{:?}", clean.reasons);
    let relative = |mg: f64| mg / 1000.0 * 9.806_65 / G;
    // The base fit as a temperature drift leaves it: a position left out is off by 11.5 mg,
    // more than five times the 2 mg budget, as the session's verdict says it.
    let (reason, far) = heldout_reason("accelerometer fit", 11.5, BUDGETS).expect("over budget");
    assert!(far);
    fit.accel.loo_rms = Some(relative(11.5));
    fit.verdict.reasons.push(reason);
    fit.verdict.level = VerdictLevel::Poor;
    // Terms that explain it: the reason goes, and the level is the clean fit's again.
    let explained = verdict_with_terms(&fit, relative(0.3));
    assert_eq!(explained, clean);
    // Terms that explain part of it: the reason names the extended model and its figure.
    let partly = verdict_with_terms(&fit, relative(3.0));
    assert_eq!(partly.level, VerdictLevel::Marginal, "{:?}", partly.reasons);
    assert_eq!(
        partly.reasons.len(),
        clean.reasons.len() + 1,
        "{:?}",
        partly.reasons
    );
    assert!(
        partly
            .reasons
            .iter()
            .any(|r| r.contains("model with the added terms is predicted with 3.00 mg")),
        "{:?}",
        partly.reasons
    );
    // Terms that do not help: still poor.
    assert_eq!(
        verdict_with_terms(&fit, relative(12.0)).level,
        VerdictLevel::Poor
    );
}
