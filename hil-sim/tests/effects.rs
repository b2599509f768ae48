//! Effects: each one, switched on for one sensor, changes that sensor's reading by exactly its
//! formula and leaves everything else (other sensors, the board's base errors, the noise) as is.

use imucal_hil_sim::effects::{EffectKind, EffectRequest, SensorEffects};
use imucal_hil_sim::physics::{matrix_from_rows, ImuSample, SensorKind};
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
            unreachable!("out-of-family effects are checked in tests/out_of_family.rs")
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
