//! The datasheet bounds a board with no fleet is held to: working parts pass, and a gross fault
//! is named with its kind, its distance past the bound and a likely cause.

mod history_support;

use history_support::board_record;
use imucal::history::part_limits::{beyond_part_limits, LimitKind, MAX_ACCEL_OFFSET_G};

#[test]
fn boards_drawn_within_the_simulated_parts_error_ranges_pass() {
    for seed in 0..40 {
        let record = board_record(seed);
        assert_eq!(beyond_part_limits(&record), vec![], "seed {seed}");
    }
}

#[test]
fn an_offset_and_a_gain_past_their_bounds_are_named_farthest_past_first() {
    let mut record = board_record(1);
    let g = record.params.reference.gravity_mps2;
    // 1.2× the offset bound on accel x; a −15 % gain on accel z (1.5× the ±10 %); a gyro
    // offset of 60 °/s on y (2× the 30 °/s).
    record.params.accel.b[0] = 1.2 * MAX_ACCEL_OFFSET_G * g;
    record.params.accel.a[2] = [0.0, 0.0, 0.85];
    record.params.gyro.b[1] = 60f64.to_radians();
    let found = beyond_part_limits(&record);
    let names: Vec<_> = found.iter().map(|f| f.parameter.as_str()).collect();
    assert_eq!(names, ["gyro.b.y", "accel.gain.z", "accel.b.x"]);
    let kinds: Vec<_> = found.iter().map(|f| f.kind).collect();
    assert_eq!(
        kinds,
        [LimitKind::Offset, LimitKind::Gain, LimitKind::Offset]
    );
    // Distances past the bound in units of the bound; the gain's is measured from 1.
    for (finding, times) in found.iter().zip([2.0, 1.5, 1.2]) {
        assert!(
            (finding.times_limit() - times).abs() < 1e-9,
            "{finding:?}: {}",
            finding.times_limit()
        );
    }
    assert!(
        found[1].phrase().contains("-15.0 % off nominal"),
        "{}",
        found[1].phrase()
    );
    assert!(found[2].phrase().contains("m/s²"), "{}", found[2].phrase());
}

#[test]
fn a_sensor_the_record_does_not_calibrate_is_not_held_to_its_bounds() {
    let mut record = board_record(2);
    record.params.gyro.b = [1.0, 1.0, 1.0];
    record
        .params
        .not_fitted
        .insert("gyro".into(), "never rested".into());
    assert_eq!(beyond_part_limits(&record), vec![]);
}

#[test]
fn a_magnet_by_the_magnetometer_warns_without_refusing_and_one_past_the_range_refuses() {
    use imucal::history::part_limits::{refusal_phrase, warning_phrases};
    // Hard iron of a board with a magnet beside its magnetometer (≈ 220 µT).
    let mut record = board_record(7);
    record.params.mag.b = [144.3, -83.1, 138.6];
    let found = beyond_part_limits(&record);
    assert!(
        !found.is_empty(),
        "a magnet's offset is beyond the part and board allowance"
    );
    assert!(found.iter().all(|f| !f.refuses), "{found:?}");
    assert!(refusal_phrase(&found).is_none());
    let warnings = warning_phrases(&found);
    assert!(
        warnings[0].contains("magnet or magnetised steel near the magnetometer"),
        "{warnings:?}"
    );
    // A healthy board's hard iron (tens of µT) passes.
    record.params.mag.b = [45.8, -35.1, 40.0];
    assert_eq!(beyond_part_limits(&record), vec![]);
    // An offset that leaves the Earth's field no room in a ±400 µT range is refused.
    record.params.mag.b = [360.0, 0.0, 0.0];
    record.params.device = Some(imucal::device::params_json::DeviceJson {
        id: record.device_id.clone(),
        sensors: vec!["accel".into(), "gyro".into(), "mag".into()],
        ranges: imucal::device::params_json::RangesJson {
            accel_mps2: 39.2,
            gyro_rads: 8.7,
            mag_ut: 400.0,
        },
        firmware: "0.1.0".into(),
    });
    let found = beyond_part_limits(&record);
    assert!(refusal_phrase(&found).is_some(), "{found:?}");
}
