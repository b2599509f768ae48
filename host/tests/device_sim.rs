//! The device client against the simulated board (the real firmware core behind a pty): pose
//! capture in nominal units, and the closed loop of flashing the true calibration and reading
//! gravity back from the calibrated stream.

use std::time::Duration;

use imucal::device::DeviceClient;
use imucal_hil_sim::board::PersonSchedule;
use imucal_hil_sim::serve::{SimOptions, SimServer};
use imucal_protocol::{CalibrationSet, StillThresholds, StreamKind};

fn resting_board(seed: u64) -> imucal_hil_sim::serve::SimHandle {
    let mut options = SimOptions::new(seed);
    options.schedule = PersonSchedule::Rest;
    options.board.poser.tremor = false;
    SimServer::start(options).expect("the simulator starts")
}

fn norm(v: [f64; 3]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

fn mat_vec(m: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    m.map(|row| row[0] * v[0] + row[1] * v[1] + row[2] * v[2])
}

#[test]
fn a_captured_pose_corrected_by_the_true_model_has_the_magnitude_of_gravity() {
    let sim = resting_board(11);
    let truth = sim.truth();
    let mut client = DeviceClient::open(sim.port_path()).expect("connect to the simulator");
    let accel = &truth.imu.accel;
    let stats = client
        .capture_pose(
            &imucal::device::PoseRequest {
                min_still: Duration::from_secs(1),
                thresholds: StillThresholds {
                    accel_std_mps2: 0.1,
                    gyro_std_rads: 0.02,
                },
                timeout: Duration::from_secs(10),
            },
            &mut |_| {},
        )
        .expect("the resting board is still");
    let rate = f64::from(client.welcome().scales.sample_rate_hz);
    assert!(f64::from(stats.n) >= rate * 0.95, "n = {}", stats.n);
    let mean = stats.accel_mean.map(f64::from);
    let corrected = mat_vec(&accel.a_true, [0, 1, 2].map(|i| mean[i] - accel.b_true[i]));
    // Mean of n samples: 5σ/√n per axis, plus one count of quantisation and f32 rounding.
    let tolerance = 5.0 * accel.noise_sigma / f64::from(stats.n).sqrt() + accel.units_per_count;
    let error = norm(corrected) - truth.world.gravity_mps2;
    assert!(
        error.abs() < tolerance,
        "error {error} m/s², tolerance {tolerance}"
    );
}

#[test]
fn flashing_the_true_accelerometer_calibration_makes_the_calibrated_stream_read_gravity() {
    let sim = resting_board(12);
    let truth = sim.truth();
    let accel = &truth.imu.accel;
    let mut client = DeviceClient::open(sim.port_path()).expect("connect to the simulator");
    let mut set = CalibrationSet::identity();
    set.accel.a = accel.a_true.map(|row| row.map(|v| v as f32));
    set.accel.b = accel.b_true.map(|v| v as f32);
    set.reference.gravity_mps2 = truth.world.gravity_mps2 as f32;
    let status = client.write_params_verified(&set).expect("verified write");
    assert_eq!(status.active_crc, set.crc32());
    let samples = client
        .collect_samples(StreamKind::Calibrated, Duration::from_secs(1), &mut |_| {})
        .expect("calibrated stream");
    assert!(
        samples.len() >= 100,
        "{} samples in 1 s at 119 Hz",
        samples.len()
    );
    let n = samples.len() as f64;
    let mean = [0, 1, 2].map(|i| samples.iter().map(|s| s.accel[i]).sum::<f64>() / n);
    // As above: 5σ/√n of the mean plus one count; A ≈ I so σ passes unchanged.
    let tolerance = 5.0 * accel.noise_sigma / n.sqrt() + accel.units_per_count;
    let error = norm(mean) - truth.world.gravity_mps2;
    assert!(
        error.abs() < tolerance,
        "error {error} m/s², tolerance {tolerance}"
    );
    assert_eq!(client.stats().lost_samples, 0);
}
