//! The out-of-family effects (`imucal_hil_sim::out_of_family`): each changes its sensor's reading
//! by its formula and nothing else; the hold-bound ones act during exactly one hold.

use imucal_hil_sim::effects::{EffectKind, EffectRequest};
use imucal_hil_sim::physics::{ImuSample, SensorKind};
use imucal_hil_sim::poser::ScheduleKind;
use imucal_hil_sim::recording::{SimConfig, Simulation};
use imucal_hil_sim::world::WorldState;
use nalgebra::Vector3;

/// Differences between these are floating-point rounding of readings of at most ~100 units.
const ROUNDING: f64 = 1e-9;

/// The twelve positions once over one temperature cycle 5 → 45 → 5 °C.
fn config(seed: u64, effects: Vec<EffectRequest>) -> SimConfig {
    let mut config = SimConfig::new(seed, ScheduleKind::Sweep);
    config.poser.sweep_repeats = 1;
    config.poser.sweep_cycles = 1;
    config.poser.hold_s = 2.0;
    config.effects = effects;
    config
}

/// Every sample of the recording with and without `kind` on `sensor` (size 10), with the state.
fn side_by_side(
    kind: EffectKind,
    sensor: SensorKind,
) -> (Simulation, Vec<(WorldState, ImuSample, ImuSample)>) {
    let request = EffectRequest {
        kind,
        sensor: Some(sensor),
        size: 10.0,
    };
    let mut off = Simulation::new(&config(41, vec![])).unwrap();
    let mut on = Simulation::new(&config(41, vec![request])).unwrap();
    let rows = (0..off.sample_count)
        .map(|k| (on.world.state(on.time_of(k)), off.sample(k), on.sample(k)))
        .collect();
    (on, rows)
}

fn change(sensor: SensorKind, off: &ImuSample, on: &ImuSample) -> Vector3<f64> {
    on.sensor(sensor).analog - off.sensor(sensor).analog
}

fn others_unchanged(sensor: SensorKind, off: &ImuSample, on: &ImuSample) {
    for other in SensorKind::ALL.into_iter().filter(|&s| s != sensor) {
        assert_eq!(off.sensor(other).analog, on.sensor(other).analog);
    }
}

#[test]
fn temperature_rate_bias_follows_the_rate_of_temperature_change() {
    for sensor in [SensorKind::Accel, SensorKind::Gyro] {
        let (sim, rows) = side_by_side(EffectKind::TemperatureRateBias, sensor);
        let g = sim.physics.truth().sensor(sensor).effects.out_of_family;
        let g = Vector3::from(g.temperature_rate_bias.unwrap().per_degree_per_second);
        let dt = 1.0 / sim.sample_rate_hz;
        let mut largest: f64 = 0.0;
        for pair in rows.windows(2) {
            let (previous, (state, off, on)) = (&pair[0].0, &pair[1]);
            others_unchanged(sensor, off, on);
            let expected = g * ((state.temp_c - previous.temp_c) / dt);
            assert!((change(sensor, off, on) - expected).amax() < ROUNDING);
            largest = largest.max(expected.amax() / sensor.units_per_count());
        }
        // Visible in the counts at some point of the temperature cycle.
        assert!(largest > 1.0, "{} peaks at {largest} counts", sensor.name());
    }
}

#[test]
fn cross_axis_nonlinearity_adds_the_product_of_the_other_two_axes() {
    let sensor = SensorKind::Accel;
    let (sim, rows) = side_by_side(EffectKind::CrossAxisNonlinearity, sensor);
    let truth = sim.physics.truth().sensor(sensor);
    let a = truth.effects.out_of_family.cross_axis_nonlinearity.unwrap();
    for (state, off, on) in &rows {
        others_unchanged(sensor, off, on);
        let u = truth.a_inverse() * state.specific_force_body;
        let expected = Vector3::new(
            a.product[0] * u.y * u.z,
            a.product[1] * u.z * u.x,
            a.product[2] * u.x * u.y,
        );
        assert!((change(sensor, off, on) - expected).amax() < ROUNDING);
    }
}

/// Labels of the holds during which the reading changed, and the largest change outside them.
fn holds_changed(
    sensor: SensorKind,
    sim: &Simulation,
    rows: &[(WorldState, ImuSample, ImuSample)],
) -> (Vec<usize>, f64) {
    let mut holds = Vec::new();
    let mut outside: f64 = 0.0;
    for (state, off, on) in rows {
        others_unchanged(sensor, off, on);
        let d = change(sensor, off, on).amax();
        match sim.world.trajectory.hold_index_at(state.t) {
            Some(h) if d > 0.0 => {
                if !holds.contains(&h) {
                    holds.push(h);
                }
            }
            _ => outside = outside.max(d),
        }
    }
    (holds, outside)
}

#[test]
fn a_bumped_hold_offsets_the_bias_during_exactly_one_whole_hold() {
    for sensor in [SensorKind::Accel, SensorKind::Gyro, SensorKind::Mag] {
        let (sim, rows) = side_by_side(EffectKind::BumpedHold, sensor);
        let bump = sim
            .physics
            .truth()
            .sensor(sensor)
            .effects
            .out_of_family
            .bumped_hold
            .unwrap();
        let (holds, outside) = holds_changed(sensor, &sim, &rows);
        assert_eq!(holds.len(), 1, "{}: {holds:?}", sensor.name());
        assert_eq!(outside, 0.0);
        // The whole hold carries the offset, and only the offset.
        for (state, off, on) in &rows {
            if sim.world.trajectory.hold_index_at(state.t) == Some(holds[0]) {
                let d = change(sensor, off, on) - Vector3::from(bump.value);
                assert!(d.amax() < ROUNDING);
            }
        }
    }
}

#[test]
fn a_steel_object_changes_the_magnetometer_during_exactly_one_hold() {
    let (sim, rows) = side_by_side(EffectKind::SteelNearHold, SensorKind::Mag);
    let truth = sim.physics.truth().mag;
    let steel = truth.effects.out_of_family.steel_near_hold.unwrap();
    let (holds, outside) = holds_changed(SensorKind::Mag, &sim, &rows);
    assert_eq!(holds.len(), 1, "{holds:?}");
    assert_eq!(outside, 0.0);
    // The field is sensed through the magnetometer's own scale and soft iron.
    let expected = truth.a_inverse() * Vector3::from(steel.value);
    for (state, off, on) in &rows {
        if sim.world.trajectory.hold_index_at(state.t) == Some(holds[0]) {
            assert!((change(SensorKind::Mag, off, on) - expected).amax() < ROUNDING);
        }
    }
    // A steel object is a magnetometer effect only.
    assert!("accel.steel_near_hold".parse::<EffectRequest>().is_err());
}
