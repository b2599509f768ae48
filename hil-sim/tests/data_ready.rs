//! The firmware samples on the LSM9DS1's data-ready bits: with the simulated chip converting on
//! its own drifting oscillator, repeated and lost conversions are counted in `ErrorCounters`,
//! and repeated magnetometer values are recognised as such.

use imucal_firmware::lsm9ds1::{AccelGyroDataRate, MagDataRate};
use imucal_hil_sim::board::{BoardConfig, SimBoard};
use imucal_protocol::ErrorCounters;

const RUN_S: f64 = 20.0;

fn counters_after_run(config: BoardConfig) -> (ErrorCounters, u64) {
    let mut board = SimBoard::new(config).unwrap();
    board.run_for(RUN_S).unwrap();
    let reads = board.samples_taken();
    let counters = board.device().unwrap().error_counters();
    (counters, reads)
}

fn config(odr_error: f64) -> BoardConfig {
    let mut config = BoardConfig::new(21);
    config.lsm9ds1_odr_error = Some(odr_error);
    config
}

/// Expected conversions of a sensor at `nominal_hz` on a clock `1 + odr_error` fast, in the run.
fn conversions(nominal_hz: f64, odr_error: f64) -> f64 {
    RUN_S * nominal_hz * (1.0 + odr_error)
}

#[test]
fn a_chip_clock_slower_than_the_read_timer_gives_repeats_that_are_counted_and_skipped() {
    let (counters, reads) = counters_after_run(config(-0.005));
    let reads = reads as f64;
    // Every read beyond the chip's conversions finds no new data; ±2 for the phase at each end.
    let repeats = reads - conversions(119.0, -0.005);
    assert!(
        (f64::from(counters.repeated_samples) - repeats).abs() <= 2.0,
        "{counters:?}, expected {repeats:.1} repeats in {reads} reads"
    );
    // 80 Hz under 119 Hz reads: about a third of the reads repeat the magnetometer.
    let mag_repeats = reads - conversions(80.0, -0.005);
    assert!(
        (f64::from(counters.mag_repeats) - mag_repeats).abs() <= 2.0,
        "{counters:?}, expected {mag_repeats:.1} magnetometer repeats"
    );
    assert_eq!(counters.mag_overruns, 0);
    assert_eq!(counters.missed_samples, 0);
}

#[test]
fn a_chip_clock_faster_than_the_read_timer_never_repeats() {
    let (counters, _) = counters_after_run(config(0.005));
    // The chip converts more often than it is read: every read is new except the one at power-on,
    // half a conversion period before the first conversion. Its lost A/G conversions are not
    // visible on the LSM9DS1 (no overrun flag outside the FIFO) and are not invented.
    assert_eq!(counters.repeated_samples, 1, "{counters:?}");
    assert_eq!(counters.missed_samples, 0, "{counters:?}");
}

#[test]
fn a_magnetometer_faster_than_the_reads_counts_its_overruns() {
    let mut config = config(0.0);
    config.chip.accel_gyro_rate = AccelGyroDataRate::Hz59_5;
    config.chip.mag_rate = MagDataRate::Hz80;
    let (counters, reads) = counters_after_run(config);
    // Each read interval with two magnetometer conversions loses one and flags an overrun.
    let overruns = conversions(80.0, 0.0) - reads as f64;
    assert!(
        (f64::from(counters.mag_overruns) - overruns).abs() <= 2.0,
        "{counters:?}, expected {overruns:.1} overruns in {reads} reads"
    );
    // Only the read at power-on, before the first conversion.
    assert_eq!(counters.mag_repeats, 1, "{counters:?}");
}

#[test]
fn without_a_chip_clock_every_read_is_new() {
    let mut config = BoardConfig::new(21);
    config.lsm9ds1_odr_error = None;
    let (counters, _) = counters_after_run(config);
    assert_eq!(counters, ErrorCounters::default());
}
