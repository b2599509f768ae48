//! End to end over the pseudo-terminal: an unattended guided session calibrates a simulated board
//! with seeded truth (the real firmware core behind the pty, a simulated person following the
//! prompts with hand tremor), and the result is checked against the truth, at rest, after a
//! reboot, and for the stream's wire cost and rate.

use std::time::{Duration, Instant};

use imucal::device::DeviceClient;
use imucal::fit::Calibration;
use imucal::fit::{Mat3, Vec3};
use imucal::session::gyro_fit::full_turn_error_deg;
use imucal::session::sim_screen::shown_on;
use imucal::session::{run_session, SessionOptions, SessionOutcome, Tapped, Unattended};
use imucal_hil_sim::board::SensorChip;
use imucal_hil_sim::physics::SensorTruth;
use imucal_hil_sim::serve::{SimHandle, SimOptions, SimServer};
use imucal_protocol::StreamKind;

/// Simulated seconds per wall second: fast enough for a modest test, slow enough that the
/// serving loop and an unoptimised host keep up with the full-rate stream on a shared two-core
/// machine.
const SPEED: f64 = 5.0;

/// Tolerance in standard deviations of the fit's own covariance (a 5σ miss on one of the ~20
/// compared numbers would happen by chance about once in 10⁵ runs).
const K_SIGMA: f64 = 5.0;

fn matrix(rows: &[[f64; 3]; 3]) -> Mat3 {
    Mat3::from_fn(|r, c| rows[r][c])
}

fn matrix_f32(rows: &[[f32; 3]; 3]) -> Mat3 {
    Mat3::from_fn(|r, c| f64::from(rows[r][c]))
}

/// `A = Q·R` with `R` upper-triangular with a positive diagonal: the gauge the norm fits use
/// (`|A·u| = |R·u|`), so `R` is what a fit of `A` should return.
fn upper_triangular_factor(a: &Mat3) -> (Mat3, Mat3) {
    let qr = a.qr();
    let (mut q, mut r) = (qr.q(), qr.r());
    for i in 0..3 {
        if r[(i, i)] < 0.0 {
            for c in 0..3 {
                r[(i, c)] = -r[(i, c)];
                q[(c, i)] = -q[(c, i)];
            }
        }
    }
    (q, r)
}

/// Every entry of the fitted upper-triangular `A` and of `b` within `K_SIGMA` of its σ (plus
/// `floor`, the f32 storage and quantisation floor) of the truth.
fn assert_matches_truth(name: &str, fit: &imucal::fit::Fit, truth: &SensorTruth, floor: f64) {
    let (_, r) = upper_triangular_factor(&matrix(&truth.a_true));
    let std = fit.std.expect("the fit has a covariance");
    for row in 0..3 {
        for col in row..3 {
            let error = (fit.cal.a[(row, col)] - r[(row, col)]).abs();
            let tolerance = K_SIGMA * std.a[(row, col)] + floor;
            assert!(
                error <= tolerance,
                "{name} A{}{}: fitted {}, true {}, error {error:.3e} > {tolerance:.3e}",
                row + 1,
                col + 1,
                fit.cal.a[(row, col)],
                r[(row, col)]
            );
        }
        let error = (fit.cal.b[row] - truth.b_true[row]).abs();
        let tolerance = K_SIGMA * std.b[row] + floor * truth.b_true[row].abs().max(1.0);
        assert!(
            error <= tolerance,
            "{name} b{}: fitted {}, true {}, error {error:.3e} > {tolerance:.3e}",
            row + 1,
            fit.cal.b[row],
            truth.b_true[row]
        );
    }
}

/// The gyroscope's written `A` against the truth in the accelerometer's output frame
/// (`Qᵀ·A_true`): scale within 0.1 % (the product's target, met on 10 of 10 simulator seeds,
/// worst 0.094 %), misalignment within 0.1° (twice the 0.05° target, which the session meets on 8
/// of 10 seeds, worst 0.060°: docs/RESULTS.md), each within K_SIGMA of the fit's own σ, and a
/// 360° turn about each axis within 0.4° (twice the 0.2° target, met on 7 of 10 seeds, worst
/// 0.36°, all misses the Z scale; the session's timing follows the host's, so one run is one
/// draw). A gyroscope left at `A = I` fails: the board's true scale is 0.974, and uncalibrated
/// turns are off by 5–20°.
fn assert_gyro_matches_truth(outcome: &SessionOutcome, truth: &imucal_hil_sim::physics::ImuTruth) {
    let gyro = outcome
        .gyro_scale
        .as_ref()
        .expect("the gyroscope's scale was fitted");
    let a = outcome.fit.gyro.cal.a;
    assert!(
        (a - Mat3::identity()).abs().max() > 0.01,
        "the gyroscope's A stayed near identity: {a}"
    );
    let (q_accel, _) = upper_triangular_factor(&matrix(&truth.accel.a_true));
    let expected = q_accel.transpose() * matrix(&truth.gyro.a_true);
    let error = a * expected.try_inverse().expect("an invertible truth") - Mat3::identity();
    for i in 0..3 {
        let scale_pct = error[(i, i)].abs() * 100.0;
        eprintln!(
            "gyro scale {}: error {scale_pct:.4} % (1σ {:.4} %)",
            i + 1,
            gyro.scale_sigma_pct[i]
        );
        assert!(
            scale_pct < 0.1,
            "gyro scale {} off by {scale_pct:.3} %",
            i + 1
        );
        assert!(scale_pct <= K_SIGMA * gyro.scale_sigma_pct[i]);
        for j in (0..3).filter(|&j| j != i) {
            let angle = error[(i, j)].abs().to_degrees();
            assert!(
                angle < 0.1,
                "gyro misalignment {}{} {angle:.3}°",
                i + 1,
                j + 1
            );
            assert!(angle <= K_SIGMA * gyro.misalignment_sigma_deg);
        }
    }
    let gyro_inverse = matrix(&truth.gyro.a_true)
        .try_inverse()
        .expect("an invertible truth");
    let b_true = Vec3::from(truth.gyro.b_true);
    let raw = |w: &Vec3| gyro_inverse * w + b_true;
    for axis in 0..3 {
        let before = full_turn_error_deg(&Calibration::identity(), raw, axis, 4.0, 119.0);
        let after = full_turn_error_deg(&outcome.fit.gyro.cal, raw, axis, 4.0, 119.0);
        eprintln!(
            "360° about axis {}: {before:.2}° before, {after:.3}° after",
            axis + 1
        );
        assert!(
            after < 0.4,
            "a full turn about axis {} is off by {after:.3}°",
            axis + 1
        );
    }
}

fn run_calibration(seed: u64, chip: SensorChip) -> (SimHandle, DeviceClient, SessionOutcome) {
    run_calibration_with(seed, |options| options.board.sensor = chip)
}

fn run_calibration_with(
    seed: u64,
    board: impl FnOnce(&mut SimOptions),
) -> (SimHandle, DeviceClient, SessionOutcome) {
    let mut sim_options = SimOptions::new(seed);
    sim_options.speed = SPEED;
    board(&mut sim_options);
    let sim = SimServer::start(sim_options).expect("the simulator starts");
    let truth = sim.truth();
    let mut client = DeviceClient::open(sim.port_path()).expect("connect to the simulator");
    let options = SessionOptions {
        gravity_mps2: truth.world.gravity_mps2,
        field_ut: Some(Vec3::from(truth.world.field_world_ut).norm()),
        ..SessionOptions::default()
    };
    // The simulated person reads the prompts off the screen, as with `imucal calibrate --sim`.
    let outcome = run_session(
        &mut client,
        &options,
        &mut Tapped {
            observer: &mut Unattended,
            tap: shown_on(&sim),
        },
    )
    .expect("the session completes");
    (sim, client, outcome)
}

/// The session's fit matches the board's truth and meets the product's at-rest targets.
fn assert_calibrated_to_truth(sim: &SimHandle, outcome: &SessionOutcome) {
    let truth = sim.truth();
    let fit = &outcome.fit;
    // Twelve positions, each captured once; at most four corners when the accelerometer fit's
    // covariance asked for them, and at most four holds after extra turns when the moves left
    // an axis of the gyroscope's scale undetermined; the verified write.
    let defaults = SessionOptions::default();
    let extra = defaults.max_extra_poses + defaults.max_gyro_moves;
    assert!(
        (12..=12 + extra).contains(&outcome.poses.len()),
        "{} poses: {}",
        outcome.poses.len(),
        outcome.extra_positions_note
    );
    assert!(outcome.verified && outcome.written);
    assert_eq!(outcome.lost_samples, 0);
    // The written set meets its targets at rest.
    let missed = imucal::session::summary(outcome).missed_targets;
    assert!(missed.is_empty(), "{missed:?}");

    // Fitted parameters against the truth, within K_SIGMA of each fit's own covariance. The
    // floors: accelerometer and magnetometer entries 1e-6 relative for f64 round-off of the
    // fits. The gyroscope bias has no floor: its σ already includes the scatter of the holds.
    assert_matches_truth("accel", &fit.accel, &truth.imu.accel, 1e-6);
    assert_matches_truth("mag", &fit.mag, &truth.imu.mag, 1e-6);
    let gyro_sigma = fit.uncertainties.gyro_bias_dps.map(f64::to_radians);
    for (axis, sigma) in gyro_sigma.iter().enumerate() {
        let error = (fit.gyro.cal.b[axis] - truth.imu.gyro.b_true[axis]).abs();
        eprintln!("gyro b{}: error {:.2}σ", axis + 1, error / sigma);
        let tolerance = K_SIGMA * sigma;
        assert!(
            error <= tolerance,
            "gyro b{}: error {error:.3e} rad/s > {tolerance:.3e}",
            axis + 1
        );
    }

    assert_gyro_matches_truth(outcome, &truth.imu);

    // The written magnetometer matrix is in the accelerometer's output frame: with
    // A_acc = Q·R, the true magnetometer correction in that frame is Qᵀ·A_mag.
    let (q_accel, _) = upper_triangular_factor(&matrix(&truth.imu.accel.a_true));
    let mag_in_accel_frame = q_accel.transpose() * matrix(&truth.imu.mag.a_true);
    let rotation_error = matrix_f32(&fit.set.mag.a) * mag_in_accel_frame.try_inverse().expect("A");
    // The error is a small rotation times a near-identity stretch: the rotation angle is the
    // length of its antisymmetric part (the symmetric part is scale, checked above).
    let skew = (rotation_error - rotation_error.transpose()) / 2.0;
    let angle = Vec3::new(skew[(2, 1)], skew[(0, 2)], skew[(1, 0)]).norm();
    let align = fit
        .alignment
        .as_ref()
        .expect("the magnetometer was aligned");
    // The rotation's σ per axis from the alignment fit, plus the magnetometer fit's relative
    // matrix σ (the non-rotation part of the error), both at K_SIGMA.
    let mag_relative = fit.mag.std.map_or(0.0, |s| s.a.max()) / fit.mag.cal.a.diagonal().min();
    let angle_tolerance = K_SIGMA * (align.rotation_std.norm() + mag_relative);
    assert!(
        angle <= angle_tolerance,
        "magnetometer frame off by {:.3}° > {:.3}°",
        angle.to_degrees(),
        angle_tolerance.to_degrees()
    );

    // At rest: the targets of the product, and a clear improvement over the raw readings.
    let after = outcome
        .after
        .as_ref()
        .expect("the calibrated rest measurement");
    assert!(
        after.accel_error_mg < 2.0,
        "|a| error {:.3} mg",
        after.accel_error_mg
    );
    assert!(
        after.mag_error_pct < 0.5,
        "|m| error {:.3} %",
        after.mag_error_pct
    );
    // A clear improvement: the raw error exceeds the calibrated one by more than three times
    // the fit's own expected |a| error. (A ratio fails on a board whose raw error at rest happens
    // to be small: 4.3 mg on seed 2024, against a calibrated error of the order of the fit's
    // 0.4 mg σ.)
    let expected_mg = outcome.fit.uncertainties.accel_norm_mg;
    assert!(
        outcome.before.accel_error_mg - after.accel_error_mg > 3.0 * expected_mg,
        "|a| at rest {:.3} mg before, {:.3} mg after, fit's expected error {expected_mg:.3} mg",
        outcome.before.accel_error_mg,
        after.accel_error_mg
    );
    // Gyro at rest: the bias left after the fit, within K_SIGMA of its σ plus the standard
    // error of a 3 s mean of white noise (σ/√n with n ≈ 357 samples).
    let gyro_noise = truth.imu.gyro.noise_sigma / (after.samples as f64).sqrt();
    let gyro_limit = (K_SIGMA * Vec3::from(gyro_sigma).norm() + 3.0 * gyro_noise).to_degrees();
    assert!(
        after.gyro_rate_dps < gyro_limit,
        "gyro at rest {:.4} °/s > {gyro_limit:.4}",
        after.gyro_rate_dps
    );
}

#[test]
fn an_unattended_session_calibrates_the_simulated_board_to_its_truth() {
    let wall = Instant::now();
    let (sim, mut client, outcome) = run_calibration(2024, SensorChip::Lsm9ds1);

    assert_calibrated_to_truth(&sim, &outcome);
    let fit = &outcome.fit;
    let after = outcome
        .after
        .as_ref()
        .expect("the calibrated rest measurement");

    // The set survives a power cycle.
    sim.reboot().expect("the board reboots");
    let back = client.get_params().expect("read back after the reboot");
    assert_eq!(back, fit.set);
    assert_eq!(client.status().expect("status").active_crc, fit.set.crc32());

    // Wire cost and sustained rate over the pty, raw and calibrated.
    let rate = f64::from(client.welcome().scales.sample_rate_hz);
    for kind in [StreamKind::Raw, StreamKind::Calibrated] {
        let before = sim.stats();
        let started = Instant::now();
        let samples = client
            .collect_samples(kind, Duration::from_secs_f64(4.0 / SPEED), &mut |_| {})
            .expect("stream");
        let wall_s = started.elapsed().as_secs_f64();
        let bytes = sim.stats().bytes_to_host - before.bytes_to_host;
        let span = samples.last().map_or(0.0, |s| s.t_s) - samples.first().map_or(0.0, |s| s.t_s);
        let board_rate = (samples.len() as f64 - 1.0) / span;
        let per_sample = bytes as f64 / samples.len() as f64;
        eprintln!(
            "{kind:?} stream: {} samples, {per_sample:.1} bytes/sample on the wire, {board_rate:.1} \
             samples per board second, {:.0} per wall second at speed {SPEED}",
            samples.len(),
            samples.len() as f64 / wall_s
        );
        // Every sample arrives (no index gap) at the board's rate; 1 % covers the rounding of
        // the sample period to whole microseconds.
        assert!(
            (board_rate - rate).abs() < 0.01 * rate,
            "{board_rate} vs {rate}"
        );
        // Packed sizes: raw 22 bytes, calibrated 10 f32 + time offset ≈ 43; plus per batch a
        // header, CRC and COBS framing of at most ~40 bytes shared by 20 (raw) or 10 samples.
        let limit = match kind {
            StreamKind::Raw => 22.0 + 40.0 / 20.0,
            StreamKind::Calibrated => 43.0 + 40.0 / 10.0,
        };
        assert!(per_sample <= limit, "{per_sample} bytes per sample");
    }
    assert_eq!(client.stats().lost_samples, 0);

    eprintln!(
        "session: {:.1} s simulated ({:.1} s wall), {} poses, {} tumble samples; after: |a| {:.3} \
         mg, |m| {:.3} %, gyro {:.4} °/s; before: |a| {:.1} mg, |m| {:.2} %, gyro {:.3} °/s; \
         test wall time {:.1} s",
        outcome.session_seconds,
        outcome.wall_seconds,
        outcome.poses.len(),
        outcome
            .mag_samples
            .iter()
            .filter(|m| m.phase == imucal::session::Phase::Tumble)
            .count(),
        after.accel_error_mg,
        after.mag_error_pct,
        after.gyro_rate_dps,
        outcome.before.accel_error_mg,
        outcome.before.mag_error_pct,
        outcome.before.gyro_rate_dps,
        wall.elapsed().as_secs_f64()
    );
}

#[test]
fn a_sensor_converting_slower_than_the_read_timer_still_gets_its_gyroscope_scale() {
    // 2 % slow: every 50th read finds no new conversion and the firmware leaves it out, so the
    // stream's stamps jump by two periods now and then. The moves are integrated on the
    // sensor's own period; before, every move was refused as having a gap and the gyroscope
    // kept A = I.
    let (sim, _client, outcome) = run_calibration_with(2024, |options| {
        options.board.lsm9ds1_odr_error = Some(-0.02);
    });
    let gyro = outcome.gyro_scale.as_ref().expect("the scale was fitted");
    assert!(
        gyro.moves_used + 2 >= gyro.moves_recorded,
        "{} of {} moves used",
        gyro.moves_used,
        gyro.moves_recorded
    );
    assert_gyro_matches_truth(&outcome, &sim.truth().imu);
}

#[test]
fn an_unattended_session_calibrates_the_simulated_rev2_board_with_bmi270_and_bmm150() {
    let (sim, _client, outcome) = run_calibration(2025, SensorChip::Bmi270);
    assert_calibrated_to_truth(&sim, &outcome);
    let after = outcome
        .after
        .as_ref()
        .expect("the calibrated rest measurement");
    eprintln!(
        "BMI270/BMM150 session: {:.1} s simulated; after: |a| {:.3} mg, |m| {:.3} %, gyro {:.4} °/s",
        outcome.session_seconds, after.accel_error_mg, after.mag_error_pct, after.gyro_rate_dps
    );
}
