//! Sensor physics: calibrating with the truth recovers the physical magnitudes to within the
//! noise, the noise has the stated σ, and readings are quantised and saturate like the chip.

use imucal_hil_sim::physics::{ImuErrorRanges, NominalScale, SensorKind, TEMP_COUNTS_PER_C};
use imucal_hil_sim::poser::ScheduleKind;
use imucal_hil_sim::recording::{SimConfig, Simulation};
use imucal_hil_sim::world::LocalDisturbance;
use imucal_hil_sim::{simulate_recording, Truth};
use nalgebra::Vector3;

/// Mean nominal reading (counts × sensitivity) of `sensor` over every hold, with sample counts.
fn hold_means(config: &SimConfig, sensor: SensorKind) -> (Vec<(Vector3<f64>, usize)>, Truth) {
    let recording = simulate_recording(config).unwrap();
    let lsb = sensor.units_per_count();
    let holds = recording
        .samples
        .iter()
        .filter_map(|s| s.pose)
        .max()
        .unwrap()
        + 1;
    let mut sums = vec![(Vector3::zeros(), 0usize); holds];
    for s in &recording.samples {
        if let Some(pose) = s.pose {
            let counts = match sensor {
                SensorKind::Accel => s.raw.accel,
                SensorKind::Gyro => s.raw.gyro,
                SensorKind::Mag => s.raw.mag,
            };
            sums[pose].0 += Vector3::from(counts.map(|c| f64::from(c) * lsb));
            sums[pose].1 += 1;
        }
    }
    let means = sums.into_iter().map(|(s, n)| (s / n as f64, n)).collect();
    (means, recording.truth)
}

#[test]
fn calibrating_accel_holds_with_the_truth_gives_gravity_within_the_noise() {
    let config = SimConfig::new(21, ScheduleKind::Twelve);
    let (means, truth) = hold_means(&config, SensorKind::Accel);
    let accel = truth.imu.accel;
    for (mean, n) in means {
        let error = accel.calibrate(&mean).norm() - truth.world.gravity_mps2;
        // σ of a hold mean is σ·‖A‖/√n (A ≈ I within 5 %); 4σ leaves a 1-in-16000 false alarm
        // per hold. Quantisation adds no bias: the noise (≈16 LSB) dithers it.
        let tolerance = 4.0 * 1.05 * accel.noise_sigma / (n as f64).sqrt();
        assert!(
            error.abs() < tolerance,
            "|a| − g = {error:e}, tolerance {tolerance:e}"
        );
    }
}

#[test]
fn calibrating_mag_holds_with_the_truth_gives_the_field_magnitude_within_the_noise() {
    let config = SimConfig::new(22, ScheduleKind::Twelve);
    let (means, truth) = hold_means(&config, SensorKind::Mag);
    let mag = truth.imu.mag;
    for (mean, n) in means {
        let error = mag.calibrate(&mean).norm() - truth.world.earth_field.magnitude_ut;
        // As for the accelerometer; ‖A‖ < 1.15 for ±5 % scale and soft iron plus ±2 % cross-axis.
        let tolerance = 4.0 * 1.15 * mag.noise_sigma / (n as f64).sqrt();
        assert!(
            error.abs() < tolerance,
            "|h| − H = {error:e}, tolerance {tolerance:e}"
        );
    }
}

#[test]
fn calibrating_gyro_holds_with_the_truth_gives_zero_rate_within_the_noise() {
    // Tremor returns to the hold attitude, so its mean rate over a hold is zero to second order
    // (≈ 1e-5 rad/s), far below the noise bound.
    let config = SimConfig::new(23, ScheduleKind::Twelve);
    let (means, truth) = hold_means(&config, SensorKind::Gyro);
    let gyro = truth.imu.gyro;
    for (mean, n) in means {
        let rate = gyro.calibrate(&mean);
        let tolerance = 4.0 * 1.05 * gyro.noise_sigma / (n as f64).sqrt() + 2e-5;
        assert!(
            rate.amax() < tolerance,
            "rate {rate:?}, tolerance {tolerance:e}"
        );
    }
}

#[test]
fn white_noise_sigma_is_density_times_root_sample_rate() {
    let mut config = SimConfig::new(24, ScheduleKind::Twelve);
    config.poser.tremor = false;
    config.poser.hold_s = 20.0;
    config.sample_rate_hz = 200.0;
    let mut sim = Simulation::new(&config).unwrap();
    let holds = sim.world.trajectory.holds();
    for sensor in SensorKind::ALL {
        let truth = *sim.physics.truth().sensor(sensor);
        assert!((truth.noise_sigma - truth.noise_density * 200.0_f64.sqrt()).abs() < 1e-15);
    }
    // Pooled variance of nominal readings about each hold's mean, per sensor and axis.
    let mut sums = vec![[[0.0_f64; 3]; 3]; holds.len()];
    let mut squares = vec![[[0.0_f64; 3]; 3]; holds.len()];
    let mut counts = vec![0usize; holds.len()];
    for k in 0..sim.sample_count {
        let t = sim.time_of(k);
        let sample = sim.sample(k);
        let Some(pose) = sim.world.trajectory.hold_index_at(t) else {
            continue;
        };
        counts[pose] += 1;
        for sensor in SensorKind::ALL {
            let v = sample.sensor(sensor).nominal(sensor.units_per_count());
            for axis in 0..3 {
                sums[pose][sensor.index()][axis] += v[axis];
                squares[pose][sensor.index()][axis] += v[axis] * v[axis];
            }
        }
    }
    for sensor in SensorKind::ALL {
        let truth = sim.physics.truth().sensor(sensor);
        let lsb = sensor.units_per_count();
        let mut pooled = 0.0;
        let mut dof = 0usize;
        for (pose, &n) in counts.iter().enumerate() {
            for axis in 0..3 {
                let s = sums[pose][sensor.index()][axis];
                pooled += squares[pose][sensor.index()][axis] - s * s / n as f64;
                dof += n - 1;
            }
        }
        let measured = (pooled / dof as f64).sqrt();
        // Rounding adds LSB²/12 of variance.
        let expected = (truth.noise_sigma.powi(2) + lsb * lsb / 12.0).sqrt();
        // ~144 000 degrees of freedom: the relative standard error of σ is 1/√(2·dof) ≈ 0.2 %.
        let relative = measured / expected - 1.0;
        assert!(
            relative.abs() < 0.01,
            "{}: σ {measured:e} vs {expected:e}",
            sensor.name()
        );
    }
}

#[test]
fn quantisation_rounds_the_analog_reading_to_the_nearest_count() {
    let mut sim = Simulation::new(&SimConfig::new(25, ScheduleKind::Tumble)).unwrap();
    for k in 0..sim.sample_count {
        let sample = sim.sample(k);
        for sensor in SensorKind::ALL {
            let reading = sample.sensor(sensor);
            assert!(!reading.saturated);
            let lsb = sensor.units_per_count();
            let error = (reading.nominal(lsb) - reading.analog).amax();
            // Half a count, plus floating-point slack.
            assert!(
                error <= 0.5 * lsb * (1.0 + 1e-9),
                "{}: {error:e}",
                sensor.name()
            );
        }
        let temp = sim.world.state(sample.t).temp_c;
        assert!((sample.temp_c() - temp).abs() <= 0.5 / TEMP_COUNTS_PER_C);
    }
}

#[test]
fn readings_beyond_full_scale_saturate_at_the_register_limits() {
    let mut config = SimConfig::new(26, ScheduleKind::Twelve);
    config.poser.tremor = false;
    // 6 g of "gravity" exceeds the ±4 g range; a 1000 µT field exceeds ±4 gauss (400 µT).
    config.gravity_mps2 = 6.0 * 9.80665;
    config.disturbance = Some(LocalDisturbance {
        field_world_ut: [0.0, 0.0, 1000.0],
        start_s: -1.0,
        end_s: 1e6,
        ramp_s: 0.0,
    });
    config.error_ranges = ImuErrorRanges::ideal();
    let mut sim = Simulation::new(&config).unwrap();
    let (mut accel_saturated, mut mag_saturated) = (0, 0);
    for k in 0..sim.sample_count {
        let sample = sim.sample(k);
        for sensor in [SensorKind::Accel, SensorKind::Mag] {
            let reading = sample.sensor(sensor);
            for axis in 0..3 {
                let counts = reading.counts[axis];
                let beyond = (reading.analog[axis] / sensor.units_per_count()).abs() > 32767.5;
                if beyond {
                    // Clamped at the limit with the right sign, never wrapped around.
                    assert_eq!(counts.signum() as f64, reading.analog[axis].signum());
                    assert!(counts == i16::MAX || counts == i16::MIN);
                    assert!(reading.saturated);
                    if sensor == SensorKind::Accel {
                        accel_saturated += 1;
                    } else {
                        mag_saturated += 1;
                    }
                }
            }
        }
    }
    // Every face-up hold (half the twelve positions) drives one axis far past full scale.
    assert!(
        accel_saturated > 1000,
        "accel saturated {accel_saturated} times"
    );
    assert!(mag_saturated > 1000, "mag saturated {mag_saturated} times");
}

#[test]
fn drawn_errors_lie_within_the_stated_ranges() {
    let ranges = ImuErrorRanges::default();
    for seed in 0..20 {
        let sim = Simulation::new(&SimConfig::new(seed, ScheduleKind::Twelve)).unwrap();
        for sensor in SensorKind::ALL {
            let truth = sim.physics.truth().sensor(sensor);
            let r = ranges.sensor(sensor);
            assert!(truth.b().amax() <= r.bias_max);
            let forward = truth.a_inverse();
            // Soft iron (diagonal ±s, off-diagonal ±s/2) multiplies the sensing matrix.
            let diagonal_bound = r.scale_max + r.soft_iron_max + 0.02;
            let off_bound = r.cross_axis_max + r.soft_iron_max + 0.01;
            for i in 0..3 {
                for j in 0..3 {
                    let e = forward[(i, j)] - if i == j { 1.0 } else { 0.0 };
                    let bound = if i == j { diagonal_bound } else { off_bound };
                    assert!(e.abs() <= bound, "{} ({i},{j}) = {e}", sensor.name());
                }
            }
            assert!((truth.a() * forward - nalgebra::Matrix3::identity()).amax() < 1e-12);
        }
    }
}

#[test]
fn truth_survives_a_json_round_trip() {
    let recording = simulate_recording(&SimConfig::new(27, ScheduleKind::Twelve)).unwrap();
    let json = imucal_hil_sim::recording::truth_json(&recording.truth).unwrap();
    let back: Truth = serde_json::from_str(&json).unwrap();
    assert_eq!(back, recording.truth);
}
