//! Effects: each one, switched on for one sensor, changes that sensor's reading by exactly its
//! formula and leaves everything else (other sensors, the board's base errors, the noise) as is;
//! the hold-bound out-of-family effects act during exactly one hold.

use imucal_hil_sim::effects::{EffectKind, EffectRequest, SensorEffects};
use imucal_hil_sim::physics::{matrix_from_rows, ImuSample, NominalScale, SensorKind};
use imucal_hil_sim::poser::ScheduleKind;
use imucal_hil_sim::recording::{SimConfig, Simulation};
use imucal_hil_sim::world::WorldState;
use nalgebra::Vector3;

/// Differences between these are floating-point rounding of readings of at most ~100 units.
const ROUNDING: f64 = 1e-9;

/// A short sweep: the twelve positions once over one temperature cycle 5 → 45 → 5 °C.
fn config(seed: u64, effects: Vec<EffectRequest>) -> SimConfig {
    let mut config = SimConfig::new(seed, ScheduleKind::Sweep);
    config.poser.sweep_repeats = 1;
    config.poser.sweep_cycles = 1;
    config.poser.hold_s = 2.0;
    config.effects = effects;
    config
}

/// Run both simulations side by side, handing each pair of samples and the world state to `check`.
fn compare(
    seed: u64,
    request: EffectRequest,
    mut check: impl FnMut(&WorldState, &ImuSample, &ImuSample, &Simulation),
) {
    let mut off = Simulation::new(&config(seed, vec![])).unwrap();
    let mut on = Simulation::new(&config(seed, vec![request])).unwrap();
    for sensor in SensorKind::ALL {
        let (a, b) = (
            off.physics.truth().sensor(sensor),
            on.physics.truth().sensor(sensor),
        );
        assert_eq!(a.a_true, b.a_true, "base errors must not move");
        assert_eq!(a.b_true, b.b_true, "base errors must not move");
    }
    for k in 0..off.sample_count {
        let state = on.world.state(on.time_of(k));
        let (x_off, x_on) = (off.sample(k), on.sample(k));
        assert_eq!(x_off.raw.temp, x_on.raw.temp);
        check(&state, &x_off, &x_on, &on);
    }
}

fn true_input(sensor: SensorKind, state: &WorldState) -> Vector3<f64> {
    match sensor {
        SensorKind::Accel => state.specific_force_body,
        SensorKind::Gyro => state.omega_body,
        SensorKind::Mag => state.field_body,
    }
}

/// Expected change of the analog reading of `sensor` caused by its one memoryless effect.
fn expected_change(
    kind: EffectKind,
    sensor: SensorKind,
    state: &WorldState,
    sim: &Simulation,
) -> Vector3<f64> {
    let truth = sim.physics.truth();
    let s = truth.sensor(sensor);
    let effects: &SensorEffects = &s.effects;
    let dt = state.temp_c - truth.reference_temp_c;
    let u = s.a_inverse() * true_input(sensor, state);
    match kind {
        EffectKind::BiasTemperature => {
            let c = effects.bias_temperature.unwrap().per_axis;
            Vector3::from_fn(|i, _| c[i][0] * dt + c[i][1] * dt * dt + c[i][2] * dt * dt * dt)
        }
        EffectKind::ScaleTemperature => {
            let k = effects.scale_temperature.unwrap().per_degree;
            Vector3::from_fn(|i, _| u[i] * k[i] * dt)
        }
        EffectKind::BiasDrift => Vector3::from(effects.bias_drift.unwrap().per_second) * state.t,
        EffectKind::ScaleNonlinearity => {
            let n = effects.scale_nonlinearity.unwrap();
            Vector3::from_fn(|i, _| n.quadratic[i] * u[i].powi(2) + n.cubic[i] * u[i].powi(3))
        }
        EffectKind::GSensitivity => {
            let k = matrix_from_rows(&truth.gyro_g_sensitivity.unwrap().matrix);
            s.a_inverse() * (k * state.specific_force_body)
        }
        EffectKind::BiasStep => {
            let step = effects.bias_step.unwrap();
            if state.t >= step.time_s {
                Vector3::from(step.step)
            } else {
                Vector3::zeros()
            }
        }
        EffectKind::ThermalHysteresis | EffectKind::BiasRandomWalk => {
            unreachable!("effects with memory are checked by their own tests")
        }
        EffectKind::TemperatureRateBias
        | EffectKind::CrossAxisNonlinearity
        | EffectKind::BumpedHold
        | EffectKind::SteelNearHold => {
            unreachable!("out-of-family effects are checked by their own tests below")
        }
    }
}

fn assert_only_sensor_changed(target: SensorKind, off: &ImuSample, on: &ImuSample) {
    for other in SensorKind::ALL.into_iter().filter(|&s| s != target) {
        assert_eq!(
            off.sensor(other).analog,
            on.sensor(other).analog,
            "{} changed",
            other.name()
        );
    }
}

#[test]
fn each_memoryless_effect_changes_only_its_sensor_by_its_formula() {
    let kinds = [
        EffectKind::BiasTemperature,
        EffectKind::ScaleTemperature,
        EffectKind::BiasDrift,
        EffectKind::ScaleNonlinearity,
        EffectKind::GSensitivity,
        EffectKind::BiasStep,
    ];
    for kind in kinds {
        for sensor in SensorKind::ALL.into_iter().filter(|&s| kind.applies_to(s)) {
            // Size 10 so that even a drift is many counts within this 40 s recording.
            let request = EffectRequest {
                kind,
                sensor: Some(sensor),
                size: 10.0,
            };
            let mut largest: f64 = 0.0;
            compare(31, request, |state, off, on, sim| {
                assert_only_sensor_changed(sensor, off, on);
                let change = on.sensor(sensor).analog - off.sensor(sensor).analog;
                let expected = expected_change(kind, sensor, state, sim);
                assert!(
                    (change - expected).amax() < ROUNDING,
                    "{} on {} at t = {}: {change:?} vs {expected:?}",
                    kind.name(),
                    sensor.name(),
                    state.t
                );
                largest = largest.max(change.amax() / sensor.units_per_count());
            });
            // A switched-on effect must be visible in the counts, not lost below one LSB.
            assert!(
                largest > 1.0,
                "{} on {} peaks at {largest} counts",
                kind.name(),
                sensor.name()
            );
        }
    }
}

#[test]
fn effect_size_zero_changes_nothing_and_size_scales_the_coefficients() {
    let request = |size| EffectRequest {
        kind: EffectKind::BiasDrift,
        sensor: None,
        size,
    };
    compare(32, request(0.0), |_, off, on, _| assert_eq!(off, on));
    let one = Simulation::new(&config(32, vec![request(1.0)])).unwrap();
    let three = Simulation::new(&config(32, vec![request(3.0)])).unwrap();
    for sensor in SensorKind::ALL {
        let a = one
            .physics
            .truth()
            .sensor(sensor)
            .effects
            .bias_drift
            .unwrap()
            .per_second;
        let b = three
            .physics
            .truth()
            .sensor(sensor)
            .effects
            .bias_drift
            .unwrap()
            .per_second;
        for i in 0..3 {
            assert!((b[i] - 3.0 * a[i]).abs() <= 1e-15 * b[i].abs().max(1e-30));
        }
    }
}

#[test]
fn thermal_hysteresis_depends_on_the_direction_temperature_last_moved() {
    for sensor in SensorKind::ALL {
        let request = EffectRequest {
            kind: EffectKind::ThermalHysteresis,
            sensor: Some(sensor),
            size: 1.0,
        };
        let mut play: Option<f64> = None;
        let (mut rising, mut falling) = (0, 0);
        compare(33, request, |state, off, on, sim| {
            assert_only_sensor_changed(sensor, off, on);
            let h = sim
                .physics
                .truth()
                .sensor(sensor)
                .effects
                .thermal_hysteresis
                .unwrap();
            let w = h.play_c;
            let p = play
                .unwrap_or(state.temp_c)
                .clamp(state.temp_c - w, state.temp_c + w);
            play = Some(p);
            let expected = Vector3::from(h.amplitude) * ((state.temp_c - p) / w);
            let change = on.sensor(sensor).analog - off.sensor(sensor).analog;
            assert!((change - expected).amax() < ROUNDING);
            // At the same temperature the bias differs by 2h between heating and cooling.
            let branch = (state.temp_c - p) / w;
            if branch > 0.999 {
                rising += 1;
            } else if branch < -0.999 {
                falling += 1;
            }
        });
        assert!(
            rising > 100 && falling > 100,
            "rising {rising}, falling {falling}"
        );
    }
}

#[test]
fn bias_random_walk_increments_have_density_times_root_period() {
    let request = EffectRequest {
        kind: EffectKind::BiasRandomWalk,
        sensor: Some(SensorKind::Gyro),
        size: 1.0,
    };
    let mut previous: Option<Vector3<f64>> = None;
    let (mut sum_sq, mut n) = (0.0, 0usize);
    let mut density = 0.0;
    let mut rate = 0.0;
    compare(34, request, |_, off, on, sim| {
        assert_only_sensor_changed(SensorKind::Gyro, off, on);
        let walk = on.gyro.analog - off.gyro.analog;
        match previous {
            // The walk starts from zero at the first sample.
            None => assert!(walk.amax() < ROUNDING),
            Some(p) => {
                sum_sq += (walk - p).norm_squared();
                n += 3;
            }
        }
        previous = Some(walk);
        density = sim
            .physics
            .truth()
            .gyro
            .effects
            .bias_random_walk
            .unwrap()
            .density;
        rate = sim.sample_rate_hz;
    });
    let measured = (sum_sq / n as f64).sqrt();
    let expected = density / rate.sqrt();
    // ~12 000 increments: relative standard error of σ ≈ 1/√(2n) ≈ 0.65 %; allow 4 of them.
    assert!(
        (measured / expected - 1.0).abs() < 0.03,
        "{measured:e} vs {expected:e}"
    );
}

#[test]
fn effect_arguments_parse_with_optional_sensor_and_size() {
    let r: EffectRequest = "gyro.g_sensitivity=2.5".parse().unwrap();
    assert_eq!(
        r,
        EffectRequest {
            kind: EffectKind::GSensitivity,
            sensor: Some(SensorKind::Gyro),
            size: 2.5
        }
    );
    let r: EffectRequest = "bias_step".parse().unwrap();
    assert_eq!(
        r,
        EffectRequest {
            kind: EffectKind::BiasStep,
            sensor: None,
            size: 1.0
        }
    );
    for bad in [
        "mag.g_sensitivity",
        "bias_temperature=-1",
        "bias_temperature=NaN",
        "wobble",
        "baro.bias_drift",
    ] {
        let error = bad.parse::<EffectRequest>().unwrap_err().to_string();
        assert!(error.contains(bad), "{error}");
    }
}

// Out-of-family effects (`imucal_hil_sim::out_of_family`).

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
            assert_only_sensor_changed(sensor, off, on);
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
        assert_only_sensor_changed(sensor, off, on);
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
        assert_only_sensor_changed(sensor, off, on);
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
