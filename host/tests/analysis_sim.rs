//! Residual analysis on simulated recordings with effects the analysis is not told about
//! (the simulator's hidden effects at their typical consumer-MEMS sizes, see
//! `imucal_hil_sim::effects`), and controls without effects or with an effect outside every
//! family. Run in release (`cargo test --release`): each full recording takes a few seconds.

use std::path::PathBuf;

use imucal::analysis::{analyse_recording, AnalysisOptions, RecordingAnalysis, SensorAnalysis};
use imucal::recording::{LoadOptions, Recording, Sensor};
use imucal::still::{find_still, StillOptions};
use imucal_hil_sim::effects::{EffectKind as SimEffect, EffectRequest};
use imucal_hil_sim::physics::SensorKind;
use imucal_hil_sim::poser::ScheduleKind;
use imucal_hil_sim::world::TemperatureProfile;
use imucal_hil_sim::{simulate_recording, write_csv, SimConfig};

/// Distinguishes the files of tests running in parallel.
static FILE_COUNTER: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

fn analyse(config: &SimConfig, name: &str) -> RecordingAnalysis {
    let unique = FILE_COUNTER.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let rec = simulate_recording(config).expect("simulation runs");
    let dir = std::env::temp_dir().join(format!("imucal-analysis-tests-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path: PathBuf = dir.join(format!("{name}-{}-{unique}.csv", config.seed));
    write_csv(&rec, std::fs::File::create(&path).expect("create csv")).expect("write csv");
    let recording = Recording::load(&path, &LoadOptions::default()).expect("load");
    let _ = std::fs::remove_file(&path);
    let still = find_still(&recording, &StillOptions::default()).expect("still");
    let options = AnalysisOptions {
        gravity: config.gravity_mps2,
        field_ut: Some(config.earth_field.magnitude_ut),
        ..AnalysisOptions::default()
    };
    analyse_recording(&recording, &still, &options)
}

fn sensor(a: &RecordingAnalysis, s: Sensor) -> &SensorAnalysis {
    match a.sensors.iter().find(|(k, _)| *k == s) {
        Some((_, Ok(x))) => x,
        Some((_, Err(e))) => panic!("{s} not analysed: {e}"),
        None => panic!("{s} missing"),
    }
}

fn with_effect(mut c: SimConfig, kind: SimEffect, s: SensorKind) -> SimConfig {
    c.effects.push(EffectRequest {
        kind,
        sensor: Some(s),
        size: 1.0,
    });
    c
}

fn accepted(a: &SensorAnalysis) -> Vec<&'static str> {
    a.accepted().map(|e| e.kind.name()).collect()
}

fn describe(a: &SensorAnalysis) -> String {
    let effects: Vec<String> = a
        .effects
        .iter()
        .map(|e| {
            format!(
                "{} {:?} score {:.2} p {:.1e}",
                e.kind.name(),
                e.status,
                e.score,
                e.p_value
            )
        })
        .collect();
    format!(
        "{}: floor {:.2e}, χ²/dof {:.2} → {:.2}, held-out {:.2e} → {:.2e}; {}",
        a.sensor,
        a.noise_floor,
        a.test_before.reduced(),
        a.test_after.reduced(),
        a.heldout_rms_before,
        a.heldout_rms_after,
        effects.join("; ")
    )
}

/// For one family: the right effect (and only it) is accepted for the affected sensor, the
/// final residual is at the floor, and the held-out error falls to near that of a clean board.
fn check_detection(kind: SimEffect, s: SensorKind, sensor_name: Sensor, expected: &str) {
    let seed = 3;
    let clean = analyse(&SimConfig::new(seed, ScheduleKind::Sweep), "clean");
    let a = analyse(
        &with_effect(SimConfig::new(seed, ScheduleKind::Sweep), kind, s),
        expected,
    );
    let got = sensor(&a, sensor_name);
    let reference = sensor(&clean, sensor_name);
    eprintln!("{}", describe(got));
    assert_eq!(accepted(got), vec![expected], "{}", describe(got));
    // At the floor: χ²/dof of 1 ± a few √(2/dof) (dof ≥ 50 here); 1.5 allows for the
    // non-white part of the noise the floor does not model.
    assert!(got.test_after.reduced() < 1.5, "{}", describe(got));
    assert!(!got.unexplained);
    // Held-out error with the effect: within 2.5× the clean board's (the extra parameters,
    // fitted on 11/12 of the poses, add their own spread), and well below the base model's.
    assert!(
        got.heldout_rms_after < 2.5 * reference.heldout_rms_before,
        "{}",
        describe(got)
    );
    assert!(
        got.heldout_rms_after < 0.67 * got.heldout_rms_before,
        "{}",
        describe(got)
    );
}

#[test]
fn accel_bias_temperature_is_found() {
    check_detection(
        SimEffect::BiasTemperature,
        SensorKind::Accel,
        Sensor::Accel,
        "bias_temperature",
    );
}

#[test]
fn accel_scale_temperature_is_found() {
    check_detection(
        SimEffect::ScaleTemperature,
        SensorKind::Accel,
        Sensor::Accel,
        "scale_temperature",
    );
}

#[test]
fn accel_bias_drift_is_found() {
    check_detection(
        SimEffect::BiasDrift,
        SensorKind::Accel,
        Sensor::Accel,
        "bias_drift",
    );
}

#[test]
fn accel_scale_nonlinearity_is_found() {
    check_detection(
        SimEffect::ScaleNonlinearity,
        SensorKind::Accel,
        Sensor::Accel,
        "scale_nonlinearity",
    );
}

#[test]
fn gyro_bias_temperature_is_found() {
    check_detection(
        SimEffect::BiasTemperature,
        SensorKind::Gyro,
        Sensor::Gyro,
        "bias_temperature",
    );
}

#[test]
fn gyro_bias_drift_is_found() {
    check_detection(
        SimEffect::BiasDrift,
        SensorKind::Gyro,
        Sensor::Gyro,
        "bias_drift",
    );
}

#[test]
fn gyro_g_sensitivity_is_found_and_maps_onto_the_firmware_term() {
    check_detection(
        SimEffect::GSensitivity,
        SensorKind::Gyro,
        Sensor::Gyro,
        "g_sensitivity",
    );
    let config = with_effect(
        SimConfig::new(3, ScheduleKind::Sweep),
        SimEffect::GSensitivity,
        SensorKind::Gyro,
    );
    let truth = simulate_recording(&config)
        .expect("simulation")
        .truth
        .imu
        .gyro_g_sensitivity
        .expect("effect on");
    let a = analyse(&config, "gsens-terms");
    let terms = sensor(&a, Sensor::Gyro).to_calibration_terms();
    let k = terms
        .gyro_g_sensitivity
        .expect("accepted g-sensitivity has a firmware term");
    let largest = truth
        .matrix
        .iter()
        .flatten()
        .fold(0.0f64, |m, v| m.max(v.abs()));
    for (r, (fitted_row, true_row)) in k.iter().zip(&truth.matrix).enumerate() {
        for (c, (fitted, expected)) in fitted_row.iter().zip(true_row).enumerate() {
            // The accelerometer's fitted frame differs from the body frame by its small
            // misalignment and the gyro's scale errors by a few %: allow 15 % of the largest entry.
            let err = (f64::from(*fitted) - expected).abs();
            assert!(err < 0.15 * largest, "K[{r}][{c}] = {fitted} vs {expected}");
        }
    }
}

#[test]
fn mag_bias_temperature_is_found() {
    check_detection(
        SimEffect::BiasTemperature,
        SensorKind::Mag,
        Sensor::Mag,
        "bias_temperature",
    );
}

/// A small sweep (two rounds of the twelve positions, shorter holds): temperature varies from
/// 5 to 45 °C but has no effect.
fn small_sweep(seed: u64) -> SimConfig {
    let mut c = SimConfig::new(seed, ScheduleKind::Sweep);
    c.poser.sweep_repeats = 2;
    c.poser.sweep_cycles = 1;
    c.poser.hold_s = 3.0;
    c
}

#[test]
fn clean_recordings_accept_no_effect() {
    let mut false_accepts = Vec::new();
    let mut analysed = 0;
    for seed in 0..24u64 {
        // Two in three with a temperature sweep, one in three at constant temperature.
        let config = if seed % 3 == 2 {
            SimConfig::new(seed, ScheduleKind::Twelve)
        } else {
            small_sweep(seed)
        };
        let a = analyse(&config, "control");
        for (s, r) in &a.sensors {
            let Ok(x) = r else { continue };
            analysed += 1;
            if !accepted(x).is_empty() {
                false_accepts.push(format!("seed {seed} {s}: {}", describe(x)));
            }
        }
    }
    // Every sensor of at least 20 recordings must be analysed (the twelve-position recordings
    // have too few magnetometer poses only if the schedule changes).
    assert!(analysed >= 60, "only {analysed} sensor analyses ran");
    assert!(
        false_accepts.is_empty(),
        "{} false acceptances:\n{}",
        false_accepts.len(),
        false_accepts.join("\n")
    );
}

#[test]
fn a_bias_step_is_reported_unexplained_not_as_a_wrong_family() {
    for (s, name) in [
        (SensorKind::Accel, Sensor::Accel),
        (SensorKind::Gyro, Sensor::Gyro),
    ] {
        let a = analyse(
            &with_effect(
                SimConfig::new(5, ScheduleKind::Sweep),
                SimEffect::BiasStep,
                s,
            ),
            "step",
        );
        let got = sensor(&a, name);
        eprintln!("{}", describe(got));
        assert!(accepted(got).is_empty(), "{}", describe(got));
        assert!(got.unexplained, "{}", describe(got));
        let (variable, _) = got.best_correlate.clone().expect("a correlate is reported");
        assert!(variable.starts_with("time"), "best correlate {variable}");
    }
}

#[test]
fn temperature_rising_with_time_is_accepted_as_provisional_temperature() {
    let mut config = with_effect(
        SimConfig::new(7, ScheduleKind::Sweep),
        SimEffect::BiasTemperature,
        SensorKind::Accel,
    );
    // A ramp longer than the recording: temperature is a linear function of time.
    config.temperature = Some(TemperatureProfile::Ramp {
        start_c: 10.0,
        end_c: 40.0,
        duration_s: 1000.0,
    });
    let a = analyse(&config, "confounded");
    let got = sensor(&a, Sensor::Accel);
    eprintln!("{}", describe(got));
    assert!(
        got.temp_time_correlation
            .expect("temperature recorded")
            .abs()
            > 0.95
    );
    // The temperature term is kept (the firmware can apply it), marked provisional with the
    // recording that would confirm it; the time drift is not accepted beside it.
    let temperature = got
        .accepted()
        .find(|e| e.kind.name() == "bias_temperature")
        .unwrap_or_else(|| panic!("{}", describe(got)));
    assert!(
        temperature
            .note
            .starts_with("provisional: confounded with time")
            && temperature.note.contains("cool-down"),
        "{}",
        temperature.note
    );
    assert!(!accepted(got).contains(&"bias_drift"), "{}", describe(got));
}

#[test]
fn a_time_drift_during_warm_up_is_not_written_as_temperature_when_the_plateau_contradicts_it() {
    let mut config = with_effect(
        SimConfig::new(11, ScheduleKind::Sweep),
        SimEffect::BiasDrift,
        SensorKind::Accel,
    );
    // Warm-up with a short time constant: temperature follows time early on and then settles,
    // while the drift goes on; the plateau decorrelates the two.
    config.temperature = Some(TemperatureProfile::Warmup {
        ambient_c: 20.0,
        rise_c: 15.0,
        time_constant_s: 60.0,
    });
    let a = analyse(&config, "warmup-drift");
    let got = sensor(&a, Sensor::Accel);
    eprintln!("{}", describe(got));
    assert!(
        got.temp_time_correlation
            .expect("temperature recorded")
            .abs()
            < 0.95,
        "{}",
        describe(got)
    );
    assert!(
        !accepted(got).contains(&"bias_temperature")
            && !accepted(got).contains(&"scale_temperature"),
        "{}",
        describe(got)
    );
    assert!(accepted(got).contains(&"bias_drift"), "{}", describe(got));
}

/// `imucal analyze` starts from the model `fit` chose. On these sweeps `fit`'s leave-one-out
/// prefers the axis-aligned model (the temperature bias inflates every model's held-out error
/// alike), while the poses determine the full one: the analysis's base must still be the full
/// norm model, or the misalignment left out was accepted as a non-linearity (truth: none) and
/// the temperature bias itself rejected as "another form".
#[test]
fn analyze_finds_the_temperature_bias_alone_when_fit_chose_the_axis_aligned_model() {
    for (seed, size) in [(7, 2.0), (7, 1.0)] {
        let mut config = SimConfig::new(seed, ScheduleKind::Sweep);
        config.effects.push(EffectRequest {
            kind: SimEffect::BiasTemperature,
            sensor: Some(SensorKind::Accel),
            size,
        });
        let rec = simulate_recording(&config).expect("simulation runs");
        let dir = std::env::temp_dir().join(format!("imucal-analysis-cli-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let path = dir.join(format!("sweep-{seed}-{size}.csv"));
        write_csv(&rec, std::fs::File::create(&path).expect("create csv")).expect("write csv");
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_imucal"))
            .arg("analyze")
            .arg(&path)
            .arg("--json")
            .output()
            .expect("the imucal binary runs");
        let _ = std::fs::remove_file(&path);
        let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("analyze JSON");
        let accel = &json["sensors"]["accel"];
        assert_eq!(accel["base_model"], "lm", "seed {seed} × {size}: {accel}");
        let accepted: Vec<&str> = accel["effects"]
            .as_array()
            .expect("effects")
            .iter()
            .filter(|e| e["accepted"] == true)
            .filter_map(|e| e["name"].as_str())
            .collect();
        assert_eq!(accepted, ["bias_temperature"], "seed {seed} × {size}");
        if accel["base_fit"]["method"] != "lm" {
            assert!(
                accel["base_note"].is_string(),
                "the change of model is said"
            );
        }
    }
}

/// The fitted coefficient `name` of the accepted effect `family`: (value, standard deviation).
fn coefficient(a: &SensorAnalysis, family: &str, name: &str) -> (f64, f64) {
    let e = a
        .accepted()
        .find(|e| e.kind.name() == family)
        .unwrap_or_else(|| panic!("{family} not accepted: {}", describe(a)));
    let c = e
        .coefficients
        .iter()
        .find(|c| c.name == name)
        .unwrap_or_else(|| panic!("{family} has no {name}: {}", describe(a)));
    (c.value, c.std)
}

/// The simulator's bias polynomial `[c1, c2, c3]` about its reference temperature, re-expanded
/// about the analysis's reference `t_ref_c`.
fn about(c: [f64; 3], t_ref_c: f64) -> [f64; 3] {
    let d = t_ref_c - imucal_hil_sim::physics::TEMP_ZERO_C;
    [
        c[0] + 2.0 * c[1] * d + 3.0 * c[2] * d * d,
        c[1] + 3.0 * c[2] * d,
        c[2],
    ]
}

/// Every fitted coefficient of `family` named `{prefix}_{axis}` within `sigmas` of the truth.
fn assert_near_truth(a: &SensorAnalysis, family: &str, prefix: &str, truth: [f64; 3], sigmas: f64) {
    for (k, axis) in ["x", "y", "z"].iter().enumerate() {
        let name = format!("{prefix}_{axis}");
        let (value, std) = coefficient(a, family, &name);
        assert!(
            (value - truth[k]).abs() <= sigmas * std,
            "{family} {name} = {value:.4e} ± {std:.2e}, truth {:.4e} ({:.1} σ off)",
            truth[k],
            (value - truth[k]).abs() / std
        );
    }
}

fn with_effects(seed: u64, effects: &[(SimEffect, SensorKind)]) -> SimConfig {
    let mut c = SimConfig::new(seed, ScheduleKind::Sweep);
    for &(kind, s) in effects {
        c = with_effect(c, kind, s);
    }
    c
}

/// A temperature bias and a drift in time together: each alone inflates the floor the other is
/// tested against, and the drift is the slow change a free shape over time fits better than the
/// temperature polynomial. Both must be found, the residual left at the floor (χ²/dof < 1.5, as
/// for one effect) and the drift rate within 5 σ (the reported, Birge-inflated σ) of the truth.
#[test]
fn a_temperature_bias_and_a_drift_together_are_both_found() {
    for seed in 1..=3 {
        let config = with_effects(
            seed,
            &[
                (SimEffect::BiasTemperature, SensorKind::Accel),
                (SimEffect::BiasDrift, SensorKind::Accel),
            ],
        );
        let truth = simulate_recording(&config).expect("simulation").truth;
        let a = analyse(&config, "bt-drift");
        let got = sensor(&a, Sensor::Accel);
        eprintln!("seed {seed}: {}", describe(got));
        let mut names = accepted(got);
        names.sort_unstable();
        assert_eq!(
            names,
            ["bias_drift", "bias_temperature"],
            "seed {seed}: {}",
            describe(got)
        );
        assert!(
            got.test_after.reduced() < 1.5,
            "seed {seed}: {}",
            describe(got)
        );
        let rate = truth
            .imu
            .accel
            .effects
            .bias_drift
            .expect("drift on")
            .per_second;
        assert_near_truth(got, "bias_drift", "r", rate, 5.0);
    }
}

/// A gyroscope g-sensitivity and a temperature bias together: found jointly when neither passes
/// alone (seed 4), and the temperature polynomial's degree chosen again once g-sensitivity is in
/// the model, so that the residual reaches the floor (χ²/dof < 1.5) and c1 lies within 5 σ of
/// the truth.
#[test]
fn g_sensitivity_and_a_temperature_bias_together_reach_the_floor() {
    for seed in [1, 4] {
        let config = with_effects(
            seed,
            &[
                (SimEffect::GSensitivity, SensorKind::Gyro),
                (SimEffect::BiasTemperature, SensorKind::Gyro),
            ],
        );
        let truth = simulate_recording(&config).expect("simulation").truth;
        let a = analyse(&config, "gsens-bt");
        let got = sensor(&a, Sensor::Gyro);
        eprintln!("seed {seed}: {}", describe(got));
        let mut names = accepted(got);
        names.sort_unstable();
        assert_eq!(
            names,
            ["bias_temperature", "g_sensitivity"],
            "seed {seed}: {}",
            describe(got)
        );
        assert!(
            got.test_after.reduced() < 1.5,
            "seed {seed}: {}",
            describe(got)
        );
        let poly = truth
            .imu
            .gyro
            .effects
            .bias_temperature
            .expect("on")
            .per_axis;
        let c1 = [0, 1, 2].map(|k| about(poly[k], got.t_ref_c)[0]);
        assert_near_truth(got, "bias_temperature", "c1", c1, 5.0);
    }
}

/// A cubic temperature bias whose cubic term lowers χ² significantly is fitted at degree 3, and
/// its linear term is then within 5 σ of the truth (at degree 2 it absorbed the cubic part and
/// lay tens of σ off).
#[test]
fn a_cubic_temperature_bias_is_fitted_at_degree_three() {
    let config = with_effects(5, &[(SimEffect::BiasTemperature, SensorKind::Accel)]);
    let truth = simulate_recording(&config).expect("simulation").truth;
    let a = analyse(&config, "cubic");
    let got = sensor(&a, Sensor::Accel);
    eprintln!("{}", describe(got));
    let degree = got
        .accepted()
        .find_map(|e| match e.kind {
            imucal::analysis::effects::EffectKind::BiasTemperature(d) => Some(d),
            _ => None,
        })
        .unwrap_or_else(|| panic!("{}", describe(got)));
    assert_eq!(degree, 3, "{}", describe(got));
    let poly = truth
        .imu
        .accel
        .effects
        .bias_temperature
        .expect("on")
        .per_axis;
    for power in 0..3 {
        let c = [0, 1, 2].map(|k| about(poly[k], got.t_ref_c)[power]);
        assert_near_truth(got, "bias_temperature", &format!("c{}", power + 1), c, 5.0);
    }
    assert!(got.test_after.consistent(), "{}", describe(got));
}

/// Temperature and time correlated at ρ ≈ 0.97 (a ramp over the recording with a 3 °C wiggle of
/// period 47 s), the bias drifting linearly in time and not depending on temperature: the
/// wiggle lets the data tell the two apart (a drift beside the temperature polynomial lowers χ²
/// far beyond the noise, the polynomial beside the drift does not), so the drift is accepted,
/// not set aside as confounded, and its rate is within 5 σ of the truth.
#[test]
fn a_drift_is_told_from_temperature_when_the_data_separate_them_despite_high_correlation() {
    let config = SimConfig::new(1, ScheduleKind::Sweep);
    let rec = simulate_recording(&config).expect("simulation runs");
    let mut csv = Vec::new();
    write_csv(&rec, &mut csv).expect("write csv");
    let text = String::from_utf8(csv).expect("utf-8");
    let rate = 1e-4; // m/s² per second, on the x axis
    let mut lines = text.lines();
    let header = lines.next().expect("header");
    let cols: Vec<&str> = header.split(',').collect();
    let col = |name: &str| cols.iter().position(|c| *c == name).expect(name);
    let (t_col, ax_col, temp_col) = (col("t_s"), col("ax"), col("temp_c"));
    let mut out = format!("{header}\n");
    for line in lines {
        let mut f: Vec<String> = line.split(',').map(str::to_string).collect();
        let t: f64 = f[t_col].parse().expect("time");
        let ax: f64 = f[ax_col].parse().expect("ax");
        let temp = 25.0
            + 15.0 * (2.0 * t / 400.0 - 1.0)
            + 3.0 * (2.0 * std::f64::consts::PI * t / 47.0).sin();
        f[temp_col] = format!("{temp:.4}");
        f[ax_col] = format!("{:.7}", ax + rate * t);
        out.push_str(&f.join(","));
        out.push('\n');
    }
    let dir = std::env::temp_dir().join(format!("imucal-analysis-tests-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = dir.join("ramp-wiggle-drift.csv");
    std::fs::write(&path, out).expect("write");
    let recording = Recording::load(&path, &LoadOptions::default()).expect("load");
    let _ = std::fs::remove_file(&path);
    let still = find_still(&recording, &StillOptions::default()).expect("still");
    let options = AnalysisOptions {
        gravity: config.gravity_mps2,
        field_ut: Some(config.earth_field.magnitude_ut),
        ..AnalysisOptions::default()
    };
    let a = analyse_recording(&recording, &still, &options);
    let got = sensor(&a, Sensor::Accel);
    eprintln!("{}", describe(got));
    let rho = got.temp_time_correlation.expect("temperature recorded");
    assert!(rho.abs() > 0.95, "ρ = {rho}");
    assert_eq!(accepted(got), ["bias_drift"], "{}", describe(got));
    assert!(
        got.effects
            .iter()
            .all(|e| e.status != imucal::analysis::EffectStatus::Confounded),
        "{}",
        describe(got)
    );
    // The body-frame x drift is seen through the fitted A, close to the identity here.
    let (r_x, std) = coefficient(got, "bias_drift", "r_x");
    assert!(
        (r_x - rate).abs() <= 5.0 * std + 0.02 * rate,
        "r_x = {r_x:.4e} ± {std:.2e}"
    );
    assert!(!got.unexplained, "{}", describe(got));
}
