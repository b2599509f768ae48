//! Closing the loop end to end over the pseudo-terminal: a simulated board whose biases follow
//! its die temperature (an effect the host is not told about) goes through a guided session
//! while the temperature sweeps; the base set is written; the calibrated stream at rest is
//! measured across the sweep; the residual analysis of the session's poses finds the effect; the
//! extended set is written and the firmware applies it per sample; the stream is measured again.
//! A control board without the effect goes through the same steps and gets no extended terms.
//!
//! Run with `cargo test --release -p imucal --test closed_loop -- --nocapture` to see the
//! figures.

use imucal::analysis::{EffectStatus, RecordingAnalysis};
use imucal::device::{DeviceClient, UnitSample};
use imucal::fit::Vec3;
use imucal::session::{
    analyse_poses, extend_set, rest_errors, run_session, stream_for, ExtendedSet, SessionOptions,
    SessionOutcome, Unattended,
};
use imucal_hil_sim::board::PersonSchedule;
use imucal_hil_sim::serve::{SimHandle, SimOptions, SimServer};
use imucal_hil_sim::world::TemperatureProfile;
use imucal_protocol::StreamKind;
use std::time::Duration;

/// Simulated seconds per wall second (as in `calibrate_sim`: the serving loop keeps up on a
/// shared two-core machine).
const SPEED: f64 = 20.0;

/// Die temperature sweep, °C, and its period, s: the session's three rounds of twelve positions
/// span more than one period, so pose temperature is not a function of pose time.
const LOW_C: f64 = 10.0;
const HIGH_C: f64 = 40.0;
const PERIOD_S: f64 = 90.0;

/// Temperature bins of the at-rest check across the sweep.
const BINS: usize = 5;

/// Errors of the calibrated stream at rest in one temperature bin.
#[derive(Debug, Clone, Copy)]
struct BinErrors {
    temp_c: f64,
    accel_mg: f64,
    gyro_dps: f64,
    accel_noise_mg: f64,
}

struct ClosedLoop {
    _sim: SimHandle,
    outcome: SessionOutcome,
    analysis: RecordingAnalysis,
    extended: ExtendedSet,
    before: Vec<BinErrors>,
    after: Vec<BinErrors>,
}

/// One sweep period of calibrated samples at rest, split into `BINS` equal temperature bins.
fn sweep_errors(client: &mut DeviceClient, gravity: f64, field_ut: f64) -> Vec<BinErrors> {
    let samples = stream_for(
        client,
        StreamKind::Calibrated,
        PERIOD_S,
        Duration::from_secs(3),
    )
    .expect("the calibrated stream runs for a sweep period");
    let width = (HIGH_C - LOW_C) / BINS as f64;
    (0..BINS)
        .filter_map(|k| {
            let low = LOW_C + width * k as f64;
            let bin: Vec<UnitSample> = samples
                .iter()
                .filter(|s| s.temp_c >= low && s.temp_c < low + width)
                .copied()
                .collect();
            let errors = rest_errors(&bin, gravity, field_ut)?;
            Some(BinErrors {
                temp_c: low + 0.5 * width,
                accel_mg: errors.accel_error_mg,
                gyro_dps: errors.gyro_rate_dps,
                accel_noise_mg: errors.accel_noise_mg,
            })
        })
        .collect()
}

fn worst(bins: &[BinErrors], value: fn(&BinErrors) -> f64) -> f64 {
    bins.iter().map(value).fold(0.0, f64::max)
}

fn print_bins(label: &str, bins: &[BinErrors]) {
    for b in bins {
        eprintln!(
            "{label}: {:5.1} °C  |a| error {:7.3} mg (±{:.3})  gyro {:.4} °/s",
            b.temp_c, b.accel_mg, b.accel_noise_mg, b.gyro_dps
        );
    }
}

fn close_the_loop(seed: u64, effects: &[&str]) -> ClosedLoop {
    let mut sim_options = SimOptions::new(seed);
    sim_options.speed = SPEED;
    sim_options.schedule = PersonSchedule::Rounds(3);
    sim_options.board.temperature = Some(TemperatureProfile::Sweep {
        low_c: LOW_C,
        high_c: HIGH_C,
        period_s: PERIOD_S,
    });
    sim_options.effects = effects
        .iter()
        .map(|e| e.parse().expect("a known effect"))
        .collect();
    let sim = SimServer::start(sim_options).expect("the simulator starts");
    let truth = sim.truth();
    let gravity = truth.world.gravity_mps2;
    let field_ut = Vec3::from(truth.world.field_world_ut).norm();
    let mut client = DeviceClient::open(sim.port_path()).expect("connect to the simulator");
    let options = SessionOptions {
        gravity_mps2: gravity,
        field_ut: Some(field_ut),
        rounds: 3,
        ..SessionOptions::default()
    };
    let outcome =
        run_session(&mut client, &options, &mut Unattended).expect("the session completes");
    let before = sweep_errors(&mut client, gravity, field_ut);
    let analysis = analyse_poses(&outcome.poses, gravity);
    let extended = extend_set(&outcome.fit.set, &analysis);
    let after = if extended.extended() {
        client
            .write_params_verified(&extended.set)
            .expect("the extended set is accepted, committed and read back");
        sweep_errors(&mut client, gravity, field_ut)
    } else {
        Vec::new()
    };
    ClosedLoop {
        _sim: sim,
        outcome,
        analysis,
        extended,
        before,
        after,
    }
}

fn accepted(analysis: &RecordingAnalysis, sensor: usize) -> Vec<&'static str> {
    match &analysis.sensors[sensor].1 {
        Ok(a) => a
            .effects
            .iter()
            .filter(|e| e.status == EffectStatus::Accepted)
            .map(|e| e.kind.name())
            .collect(),
        Err(e) => panic!("sensor {sensor} was not analysed: {e}"),
    }
}

/// Sensors in the order `analyse_poses` returns them.
const ACCEL: usize = 0;
const GYRO: usize = 1;

#[test]
fn analysed_temperature_terms_cut_the_error_across_a_temperature_sweep() {
    // Twice the typical size: about 1 mg/°C and 0.02 °/s/°C per axis with quadratic and cubic
    // parts, i.e. ≈ 15 mg and 0.3 °/s at the ends of the ±15 °C sweep.
    let run = close_the_loop(31, &["accel.bias_temperature=2", "gyro.bias_temperature=2"]);
    let temps: Vec<f64> = run
        .outcome
        .poses
        .iter()
        .map(|p| f64::from(p.stats.temp_mean_c))
        .collect();
    eprintln!(
        "{} poses, temperatures {:.1}–{:.1} °C; added: {:?}; left out: {:?}",
        temps.len(),
        temps.iter().copied().fold(f64::INFINITY, f64::min),
        temps.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        run.extended.added,
        run.extended.left_out
    );
    print_bins("base set", &run.before);
    print_bins("extended", &run.after);

    // Three rounds of the twelve positions, each captured once per round, plus up to four
    // corner positions per round when the fit asks for them.
    assert!((3 * 12..=3 * 16).contains(&run.outcome.poses.len()));
    // The analysis names the effect for both sensors, and the written set carries it.
    assert!(accepted(&run.analysis, ACCEL).contains(&"bias_temperature"));
    assert!(accepted(&run.analysis, GYRO).contains(&"bias_temperature"));
    assert!(run.extended.set.accel.bias_temp.is_some());
    assert!(run.extended.set.gyro.bias_temp.is_some());
    // The set's residuals are the final models' (the board shows them), not the base fit's.
    for (sensor, written, scale) in [
        (
            ACCEL,
            run.extended.set.residuals.accel_rms,
            f64::from(run.extended.set.reference.gravity_mps2),
        ),
        (GYRO, run.extended.set.residuals.gyro_rms, 1.0),
    ] {
        let Ok(found) = &run.analysis.sensors[sensor].1 else {
            panic!("sensor {sensor} was not analysed");
        };
        let expected = found.rms_after * scale;
        assert!(
            ((f64::from(written) - expected) / expected).abs() < 1e-6,
            "sensor {sensor}: {written} written, final model {expected}"
        );
        assert!(found.rms_after < found.rms_before);
    }
    assert!(run.extended.set.residuals.accel_rms < run.outcome.fit.set.residuals.accel_rms);
    assert_eq!(run.before.len(), BINS, "every temperature bin was measured");
    assert_eq!(run.after.len(), BINS, "every temperature bin was measured");

    let accel_before = worst(&run.before, |b| b.accel_mg);
    let accel_after = worst(&run.after, |b| b.accel_mg);
    let gyro_before = worst(&run.before, |b| b.gyro_dps);
    let gyro_after = worst(&run.after, |b| b.gyro_dps);
    eprintln!(
        "worst over the sweep: |a| {accel_before:.3} → {accel_after:.3} mg, gyro \
         {gyro_before:.4} → {gyro_after:.4} °/s"
    );
    // Accelerometer: without the effect the same sweep leaves ≈ 0.15 mg (the control below;
    // bin noise ≈ 0.06 mg). The extended model adds up to nine coefficients fitted from 36
    // poses whose |a| carries ≈ 0.1 mg of noise each, so a few tenths of a mg remain (0.2–1.1 mg
    // over repeated runs: the simulated board is paced by the wall clock, so the hold lengths and
    // the chain's model vary between runs); the bound is the 2 mg accuracy budget, and the
    // ≈ 15 mg effect must fall at least fivefold.
    assert!(
        accel_after < 2.0,
        "|a| error after the extended set {accel_after:.3} mg ≥ the 2 mg budget"
    );
    assert!(
        accel_after * 5.0 < accel_before,
        "|a| error fell only from {accel_before:.3} to {accel_after:.3} mg"
    );
    // Gyroscope: the temperature terms are fitted from the holds' gyroscope means, which carry
    // the hand's slow sway (≈ 0.3 Hz, averaged over holds of under a second), and the selection
    // keeps a straight line for the cubic effect at that noise: ≈ 0.1 °/s remains in the worst
    // bin (0.094–0.104 °/s over six runs, the same before and after the session's changes of
    // 2026-11-28), bounded by 0.15 °/s; the ≈ 0.6 °/s effect must fall at least fourfold.
    assert!(
        gyro_after < 0.15,
        "gyro rest rate after the extended set {gyro_after:.4} °/s ≥ 0.15 °/s"
    );
    assert!(
        gyro_after * 4.0 < gyro_before,
        "gyro rest rate fell only from {gyro_before:.4} to {gyro_after:.4} °/s"
    );
}

#[test]
fn a_board_without_temperature_effects_gets_no_extended_terms() {
    let run = close_the_loop(32, &[]);
    print_bins("base set", &run.before);
    assert!((3 * 12..=3 * 16).contains(&run.outcome.poses.len()));
    assert_eq!(accepted(&run.analysis, ACCEL), Vec::<&str>::new());
    assert_eq!(accepted(&run.analysis, GYRO), Vec::<&str>::new());
    assert!(run.extended.added.is_empty() && run.extended.left_out.is_empty());
    assert_eq!(
        run.extended.set, run.outcome.fit.set,
        "the set is written unchanged"
    );
    let set = &run.extended.set;
    for sensor in [&set.accel, &set.gyro, &set.mag] {
        assert!(sensor.bias_temp.is_none() && sensor.scale_temp.is_none());
        assert!(sensor.nonlinearity.is_none());
    }
    assert!(set.gyro_g_sensitivity.is_none());
    // The base set alone holds the 2 mg budget across the same sweep when nothing depends on
    // temperature: the sweep itself does not disturb the calibration.
    assert_eq!(run.before.len(), BINS, "every temperature bin was measured");
    let accel = worst(&run.before, |b| b.accel_mg);
    assert!(accel < 2.0, "|a| error {accel:.3} mg across the sweep");
}
