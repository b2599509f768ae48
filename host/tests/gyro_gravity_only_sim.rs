//! The gyroscope's scale and misalignment without a usable field, end to end: a guided session
//! on the simulated board with a magnetised tool next to it during the positions
//! (`BoardConfig::positions_field_ut`), taken away before the tumble. The magnetometer is
//! fitted to the turning samples of both the moves (tool present) and the tumble (tool gone), so
//! at the moves' still ends it reads a field several % off the reference, beyond twice the `|m|`
//! budget: fewer moves than the joint fit needs keep their field (seeds 1–8: 0 to 3 of the 5
//! needed), the joint fit refuses, and the session falls back to the fit against gravity alone
//! (`session::gyro_fit`). That fit must still calibrate the gyroscope, and the session must say
//! that the field was not used.

use imucal::device::DeviceClient;
use imucal::fit::linalg::orthogonal_factor;
use imucal::fit::{Calibration, Mat3, Vec3};
use imucal::session::gyro_fit::full_turn_error_deg;
use imucal::session::{run_session, SessionOptions, Unattended};
use imucal_hil_sim::serve::{SimOptions, SimServer};

/// Simulated seconds per wall second, as in `calibrate_sim.rs`.
const SPEED: f64 = 5.0;

/// The tool's field relative to the Earth's, along it: the field keeps its direction (the
/// magnetometer's alignment from the poses sees the same dip throughout) and grows by 25 %
/// during the positions. The magnetometer's fit, half on each side, takes up part of it by
/// stretching along the directions the positions show; at 8 % two moves of seed 7 still kept
/// their field, at 25 % none does.
const TOOL_FIELD: f64 = 0.25;

/// Tolerance in standard deviations of the fit's own covariance, as in `calibrate_sim.rs`.
const K_SIGMA: f64 = 5.0;

fn matrix(rows: &[[f64; 3]; 3]) -> Mat3 {
    Mat3::from_fn(|r, c| rows[r][c])
}

#[test]
fn without_a_usable_field_the_gyroscope_is_fitted_against_gravity_alone() {
    let mut sim_options = SimOptions::new(7);
    sim_options.speed = SPEED;
    let earth = sim_options.board.earth_field.world_vector_ut();
    sim_options.board.positions_field_ut = Some((earth * TOOL_FIELD).into());
    let sim = SimServer::start(sim_options).expect("the simulator starts");
    let truth = sim.truth();
    let mut client = DeviceClient::open(sim.port_path()).expect("connect to the simulator");
    let options = SessionOptions {
        gravity_mps2: truth.world.gravity_mps2,
        field_ut: Some(earth.norm()),
        ..SessionOptions::default()
    };
    let outcome =
        run_session(&mut client, &options, &mut Unattended).expect("the session completes");

    // The session says the field was not used, and why.
    let gyro = outcome
        .gyro_scale
        .as_ref()
        .expect("the gyroscope's scale was fitted");
    eprintln!(
        "reason: {:?}; notes: {:?}",
        gyro.gravity_only_reason, outcome.fit.notes
    );
    assert!(!gyro.field_reference);
    assert_eq!(gyro.field_moves, 0);
    assert!(gyro.reduced_chi_square.is_none());
    let reason = gyro
        .gravity_only_reason
        .as_deref()
        .expect("a reason for leaving the field out");
    assert!(reason.contains("field"), "{reason}");
    assert!(
        outcome
            .fit
            .notes
            .iter()
            .any(|n| n.contains("fitted against gravity alone") && n.contains(reason)),
        "no note on the gravity-only fit: {:?}",
        outcome.fit.notes
    );

    // The gyroscope's A against the truth in the accelerometer's output frame.
    let a = outcome.fit.gyro.cal.a;
    let std = outcome.fit.gyro.std.expect("the fit has a covariance").a;
    let gyro_true = matrix(&truth.imu.gyro.a_true);
    let expected = orthogonal_factor(&matrix(&truth.imu.accel.a_true)).transpose() * gyro_true;
    // Not left at identity: the board's scale is off by more than 1 % on some axis.
    assert!((expected - Mat3::identity()).abs().max() > 0.01);
    assert!(
        (a - Mat3::identity()).abs().max() > 0.01,
        "the gyroscope's A stayed near identity: {a}"
    );
    let error = a * expected.try_inverse().expect("an invertible truth") - Mat3::identity();
    // Each entry within K_SIGMA of the σ the fit states (A's σ over the true column scale), and
    // within twice the product's targets: scale 0.2 %, misalignment 0.1°. Over seeds 1–8 of this
    // test the gravity-only fit was off by at most 0.077 % in scale, 0.048° in misalignment and
    // 2.5σ; a fit left at A = I is off by the board's 1–3 % scale errors.
    for r in 0..3 {
        for c in 0..3 {
            let sigma = std[(r, c)] / expected[(c, c)].abs();
            let e = error[(r, c)];
            eprintln!(
                "E{}{}: {:+.4} % (1σ {:.4} %)",
                r + 1,
                c + 1,
                e * 100.0,
                sigma * 100.0
            );
            assert!(
                e.abs() <= K_SIGMA * sigma,
                "E{}{} {e:.2e} is {:.1}σ",
                r + 1,
                c + 1,
                e.abs() / sigma
            );
            if r == c {
                assert!(e.abs() < 0.002, "gyro scale {} off by {e:.2e}", r + 1);
            } else {
                assert!(
                    e.abs().to_degrees() < 0.1,
                    "gyro misalignment {}{} {:.3}°",
                    r + 1,
                    c + 1,
                    e.abs().to_degrees()
                );
            }
        }
    }
    let gyro_inverse = gyro_true.try_inverse().expect("an invertible truth");
    let b_true = Vec3::from(truth.imu.gyro.b_true);
    let raw = |w: &Vec3| gyro_inverse * w + b_true;
    // A 360° turn about each axis within 0.4° after calibration (twice the 0.2° target; worst
    // 0.29° over seeds 1–8), from the 2–17° it is off uncalibrated.
    for axis in 0..3 {
        let before = full_turn_error_deg(&Calibration::identity(), raw, axis, 4.0, 119.0);
        let after = full_turn_error_deg(&outcome.fit.gyro.cal, raw, axis, 4.0, 119.0);
        eprintln!(
            "360° about axis {}: {before:.2}° before, {after:.3}° after",
            axis + 1
        );
        assert!(before > 2.0, "the board's gyroscope needs no calibration");
        assert!(
            after < 0.4,
            "a full turn about axis {} is off by {after:.3}°",
            axis + 1
        );
    }
}
