//! World consistency: the body rate integrates to the orientation, the specific force at rest is
//! gravity, the field keeps its magnitude and dip, and the sweep decorrelates temperature and time.

use imucal_hil_sim::poser::{build_schedule, PoserOptions, ScheduleKind};
use imucal_hil_sim::world::{
    EarthField, LocalDisturbance, TemperatureProfile, World, STANDARD_GRAVITY_MPS2,
};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};

fn world_for(kind: ScheduleKind, tremor: bool, seed: u64) -> World {
    let options = PoserOptions {
        tremor,
        ..PoserOptions::default()
    };
    let schedule = build_schedule(kind, &options, &EarthField::default(), seed).unwrap();
    World::new(schedule.trajectory, schedule.temperature)
}

/// `q̇ = ½ q ⊗ (0, ω)`.
fn q_dot(q: &Quaternion<f64>, omega: &Vector3<f64>) -> Quaternion<f64> {
    q * Quaternion::from_imag(*omega) * 0.5
}

/// Integrate the body rate with classical RK4 at 1 ms and return the largest angle between the
/// integrated and the true orientation, checked at every 0.1 s.
fn largest_integration_error_rad(world: &World) -> f64 {
    let h = 1e-3;
    let steps = (world.trajectory.duration_s() / h).round() as usize;
    let mut q = *world.state(0.0).q_body_to_world.quaternion();
    let mut worst: f64 = 0.0;
    for k in 0..steps {
        let t = k as f64 * h;
        let w = |t: f64| world.state(t).omega_body;
        let k1 = q_dot(&q, &w(t));
        let k2 = q_dot(&(q + k1 * (h / 2.0)), &w(t + h / 2.0));
        let k3 = q_dot(&(q + k2 * (h / 2.0)), &w(t + h / 2.0));
        let k4 = q_dot(&(q + k3 * h), &w(t + h));
        q += (k1 + k2 * 2.0 + k3 * 2.0 + k4) * (h / 6.0);
        if (k + 1) % 100 == 0 {
            let truth = world.state((k + 1) as f64 * h).q_body_to_world;
            let integrated = UnitQuaternion::from_quaternion(q);
            worst = worst.max(integrated.angle_to(&truth));
        }
    }
    worst
}

#[test]
fn integrating_body_rate_reproduces_twelve_position_orientation_with_tremor() {
    // RK4 at 1 ms has a local error ~(ω h)⁵ ≈ 1e-15 per step for ω ≲ 5 rad/s; 1e-6 rad over the
    // whole schedule leaves room only for a wrong rate formula, not for integration error.
    let world = world_for(ScheduleKind::Twelve, true, 11);
    let error = largest_integration_error_rad(&world);
    assert!(error < 1e-6, "orientation error {error:e} rad");
}

#[test]
fn integrating_body_rate_reproduces_tumble_orientation() {
    let world = world_for(ScheduleKind::Tumble, false, 12);
    let error = largest_integration_error_rad(&world);
    assert!(error < 1e-6, "orientation error {error:e} rad");
}

#[test]
fn specific_force_at_rest_is_gravity_in_the_body_frame() {
    let world = world_for(ScheduleKind::Twelve, false, 5);
    for hold in world.trajectory.holds() {
        let t = 0.5 * (hold.start_s + hold.end_s);
        let state = world.state(t);
        let expected = hold.orientation.inverse() * Vector3::new(0.0, 0.0, STANDARD_GRAVITY_MPS2);
        // Only floating-point rounding separates the two.
        assert!((state.specific_force_body - expected).norm() < 1e-12);
        assert!((state.specific_force_body.norm() - STANDARD_GRAVITY_MPS2).abs() < 1e-12);
        assert_eq!(state.omega_body, Vector3::zeros());
    }
}

#[test]
fn field_in_the_body_frame_keeps_magnitude_and_angle_to_gravity() {
    let world = world_for(ScheduleKind::Tumble, false, 9);
    let mut t = 0.0;
    while t < world.trajectory.duration_s() {
        let s = world.state(t);
        assert!((s.field_body.norm() - 48.0).abs() < 1e-9);
        // Field 60° below the horizontal is 150° from "up" (the specific force at rest).
        let angle = s.field_body.angle(&s.specific_force_body).to_degrees();
        assert!((angle - 150.0).abs() < 1e-7, "angle {angle}");
        t += 0.37;
    }
}

#[test]
fn sweep_temperature_spans_its_range_and_is_uncorrelated_with_time() {
    let world = world_for(ScheduleKind::Sweep, false, 2);
    let options = PoserOptions::default();
    let n = 20_000;
    let duration = world.trajectory.duration_s();
    let samples: Vec<(f64, f64)> = (0..n)
        .map(|k| {
            let t = duration * k as f64 / n as f64;
            (t, world.state(t).temp_c)
        })
        .collect();
    let mean = |f: &dyn Fn(&(f64, f64)) -> f64| samples.iter().map(f).sum::<f64>() / n as f64;
    let (mt, mtemp) = (mean(&|s| s.0), mean(&|s| s.1));
    let cov = mean(&|s| (s.0 - mt) * (s.1 - mtemp));
    let var_t = mean(&|s| (s.0 - mt).powi(2));
    let var_temp = mean(&|s| (s.1 - mtemp).powi(2));
    let correlation = cov / (var_t * var_temp).sqrt();
    // Whole cycles of a cosine are exactly uncorrelated with time; 1e-3 covers the sampling grid.
    assert!(correlation.abs() < 1e-3, "correlation {correlation}");
    let low = samples.iter().map(|s| s.1).fold(f64::INFINITY, f64::min);
    let high = samples
        .iter()
        .map(|s| s.1)
        .fold(f64::NEG_INFINITY, f64::max);
    assert!((low - options.sweep_low_c).abs() < 0.01, "low {low}");
    assert!((high - options.sweep_high_c).abs() < 0.01, "high {high}");
}

#[test]
fn temperature_profiles_follow_their_formulas() {
    let ramp = TemperatureProfile::Ramp {
        start_c: 20.0,
        end_c: 40.0,
        duration_s: 100.0,
    };
    assert_eq!(ramp.at(50.0), 30.0);
    assert_eq!(ramp.at(500.0), 40.0);
    let warmup = TemperatureProfile::Warmup {
        ambient_c: 20.0,
        rise_c: 10.0,
        time_constant_s: 60.0,
    };
    assert!((warmup.at(60.0) - (20.0 + 10.0 * (1.0 - (-1.0_f64).exp()))).abs() < 1e-12);
}

#[test]
fn local_disturbance_adds_its_field_only_while_present() {
    let mut world = world_for(ScheduleKind::Twelve, false, 3);
    world.disturbance = Some(LocalDisturbance {
        field_world_ut: [0.0, 30.0, 0.0],
        start_s: 10.0,
        end_s: 20.0,
        ramp_s: 1.0,
    });
    let earth = world.earth_field.world_vector_ut();
    assert_eq!(world.field_world_at(5.0), earth);
    assert_eq!(world.field_world_at(25.0), earth);
    assert!((world.field_world_at(15.0) - earth - Vector3::new(0.0, 30.0, 0.0)).norm() < 1e-12);
    // Half-way up the smooth ramp the disturbance is at half strength.
    assert!((world.field_world_at(10.5) - earth - Vector3::new(0.0, 15.0, 0.0)).norm() < 1e-12);
}

#[test]
fn invalid_world_settings_are_reported_not_propagated_as_nan() {
    let mut world = world_for(ScheduleKind::Twelve, false, 3);
    world.gravity_mps2 = f64::NAN;
    let message = world.validate().unwrap_err().to_string();
    assert!(message.contains("gravity"), "{message}");
    world.gravity_mps2 = 9.8;
    world.earth_field.dip_deg = 120.0;
    assert!(world.validate().is_err());
}
