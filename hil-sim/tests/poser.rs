//! Poser: the twelve positions point the right way, the tumble covers the sphere of field
//! directions, and schedules are reproducible from the seed.

use imucal_hil_sim::poser::{
    build_schedule, twelve_position_up_directions, PoserOptions, ScheduleKind,
};
use imucal_hil_sim::world::{EarthField, World};
use nalgebra::Vector3;

#[test]
fn twelve_positions_put_each_nominal_direction_up_within_the_placement_error() {
    let options = PoserOptions::default();
    let schedule =
        build_schedule(ScheduleKind::Twelve, &options, &EarthField::default(), 51).unwrap();
    let holds = schedule.trajectory.holds();
    assert_eq!(holds.len(), 12);
    for (hold, up) in holds.iter().zip(twelve_position_up_directions()) {
        let measured_up = hold.orientation.inverse() * Vector3::z();
        let angle = measured_up.angle(&up).to_degrees();
        assert!(
            angle <= options.placement_error_deg + 1e-9,
            "hold {}: {angle}°",
            hold.index
        );
        assert!((hold.end_s - hold.start_s - options.hold_s).abs() < 1e-12);
    }
}

#[test]
fn tumble_brings_the_field_within_twenty_degrees_of_every_body_direction() {
    let field = EarthField::default();
    let schedule =
        build_schedule(ScheduleKind::Tumble, &PoserOptions::default(), &field, 52).unwrap();
    let world = World::new(schedule.trajectory, schedule.temperature);
    let directions: Vec<Vector3<f64>> = (0..(world.trajectory.duration_s() * 50.0) as usize)
        .map(|k| world.state(k as f64 / 50.0).field_body.normalize())
        .collect();
    // 200 test directions evenly spread over the sphere (Fibonacci lattice).
    let n = 200;
    let golden = std::f64::consts::PI * (3.0 - 5.0_f64.sqrt());
    let mut worst: f64 = 0.0;
    for i in 0..n {
        let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
        let r = (1.0 - z * z).sqrt();
        let target = Vector3::new(
            r * (golden * i as f64).cos(),
            r * (golden * i as f64).sin(),
            z,
        );
        let nearest = directions
            .iter()
            .map(|d| d.angle(&target))
            .fold(f64::INFINITY, f64::min);
        worst = worst.max(nearest);
    }
    // The spiral's turns are ~33° apart, so no direction is farther than about half of that.
    assert!(
        worst.to_degrees() < 20.0,
        "largest gap {}°",
        worst.to_degrees()
    );
}

#[test]
fn schedules_are_reproducible_from_the_seed() {
    let options = PoserOptions::default();
    let field = EarthField::default();
    for kind in [
        ScheduleKind::Twelve,
        ScheduleKind::Tumble,
        ScheduleKind::Sweep,
    ] {
        let a = build_schedule(kind, &options, &field, 53).unwrap();
        let b = build_schedule(kind, &options, &field, 53).unwrap();
        assert_eq!(a, b);
    }
    let a = build_schedule(ScheduleKind::Twelve, &options, &field, 53).unwrap();
    let c = build_schedule(ScheduleKind::Twelve, &options, &field, 54).unwrap();
    assert_ne!(a, c);
}

#[test]
fn invalid_poser_options_are_rejected_with_the_setting_named() {
    let options = PoserOptions {
        hold_s: -1.0,
        ..PoserOptions::default()
    };
    let error =
        build_schedule(ScheduleKind::Twelve, &options, &EarthField::default(), 1).unwrap_err();
    assert!(error.to_string().contains("hold duration"), "{error}");
}
