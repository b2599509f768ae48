//! The MotionCal client against the simulated sketch board: readings come from `Uni:` lines, a
//! magnetometer and gyro-offset fit made with imucal's methods is sent as the 68-byte packet,
//! the board's `Cal1:`/`Cal2:` echo matches, and its EEPROM holds exactly the packet's values.

use std::time::Duration;

use imucal::compat::motioncal::RawAccelScaling;
use imucal::compat::{AdafruitCalibration, MotionCalClient};
use imucal::fit::li::{fit_li, LiOptions};
use imucal::fit::Vec3;
use imucal_hil_sim::motioncal_serve::MotionCalHandle;
use imucal_protocol::CalibrationSet;

/// Simulated seconds per wall second.
const SPEED: f64 = 20.0;
/// Sketch loops per simulated second.
const LOOP_HZ: f64 = 100.0;

#[test]
fn fit_sent_to_the_simulated_sketch_board_is_echoed_and_stored_exactly() {
    let handle = MotionCalHandle::start(11, SPEED).unwrap();
    let mut client =
        MotionCalClient::open(handle.port_path(), RawAccelScaling::AdafruitSketch).unwrap();
    let count = (handle.schedule_duration_s() * LOOP_HZ) as usize;
    let readings = client
        .collect_readings(count, Duration::from_secs(5))
        .expect("the board streams readings");
    assert!(
        client.has_unified_lines(),
        "readings should come from Uni: lines"
    );
    assert_eq!(client.malformed_lines(), 0);

    let mag: Vec<Vec3> = readings.iter().map(|r| Vec3::from(r.mag)).collect();
    let field = mag.iter().map(|m| m.norm()).sum::<f64>() / mag.len() as f64;
    let fit = fit_li(
        &mag,
        field,
        LiOptions {
            subtract_mean: true,
        },
    )
    .expect("mag fit");
    // The schedule opens with a 4 s hold; its first 3 s give the gyro offset.
    let still = &readings[..300];
    let gyro_b = still.iter().map(|r| Vec3::from(r.gyro)).sum::<Vec3>() / still.len() as f64;

    let mut set = CalibrationSet::identity();
    set.mag.a = [0, 1, 2].map(|r| [0, 1, 2].map(|c| fit.cal.a[(r, c)] as f32));
    set.mag.b = [0, 1, 2].map(|i| fit.cal.b[i] as f32);
    set.gyro.b = [0, 1, 2].map(|i| gyro_b[i] as f32);
    set.reference.field_ut = field as f32;
    let sent = AdafruitCalibration::from_set(&set).unwrap().calibration;

    let echo = client
        .send_calibration(&sent, Duration::from_secs(10))
        .expect("the board echoes the calibration");
    // Cal2 prints 4 decimals, Cal1 3: the echo agrees within those.
    assert!(
        echo.max_difference <= 5e-4 + 1e-4,
        "{}",
        echo.max_difference
    );

    let stored = handle.eeprom().expect("the EEPROM holds the packet");
    assert_eq!(handle.stored_count(), 1);
    assert_eq!(stored.accel_zerog, sent.accel_zerog);
    assert_eq!(stored.gyro_zerorate, sent.gyro_zerorate);
    assert_eq!(stored.mag_hardiron, sent.mag_hardiron);
    assert_eq!(stored.mag_field, sent.mag_field);
    let soft: Vec<f32> = sent.mag_softiron.iter().flatten().copied().collect();
    assert_eq!(stored.mag_softiron.to_vec(), soft);

    // The fitted hard iron is the board's true one: with thousands of tumble readings the Li
    // fit's offset is within 1 µT (2 % of the field), well above its noise.
    let truth = handle.truth().mag.b();
    for i in 0..3 {
        let fitted = f64::from(sent.mag_hardiron[i]);
        assert!(
            (fitted - truth[i]).abs() < 1.0,
            "axis {i}: {fitted} vs {}",
            truth[i]
        );
    }
    // Applied as the library does, the field magnitude is constant within 1 % over the schedule
    // (single readings: the simulated magnetometer noise alone spreads it by about 0.6 %).
    let norms: Vec<f64> = readings
        .iter()
        .map(|r| Vec3::from(sent.apply(r.accel, r.gyro, r.mag)[2]).norm())
        .collect();
    let mean = norms.iter().sum::<f64>() / norms.len() as f64;
    let spread =
        (norms.iter().map(|n| (n - mean).powi(2)).sum::<f64>() / norms.len() as f64).sqrt() / mean;
    assert!(spread < 0.01, "calibrated field spread {spread}");
    let hard_iron_error = (0..3)
        .map(|i| (f64::from(sent.mag_hardiron[i]) - truth[i]).abs())
        .fold(0.0, f64::max);
    eprintln!(
        "MotionCal board: {} readings, hard iron off by at most {hard_iron_error:.3} µT, \
         calibrated |B| spread {:.3} %, echo within {:.1e}",
        readings.len(),
        100.0 * spread,
        echo.max_difference
    );
}
