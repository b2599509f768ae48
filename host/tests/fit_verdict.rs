//! `fit`'s verdict on its residual is a χ² test against the noise of the means it rests on, as
//! the residual analysis's is: each pose's residual against the standard error of that pose's
//! mean (corrected for correlated samples), and for the magnetometer the means of its
//! residual over short windows of the stream. So `fit` and `analyze` say alike whether a
//! recording's residual is at its noise, on simulated recordings with and without an effect the
//! model lacks and on real recordings. Run in release: each simulated recording takes a second.

use std::path::{Path, PathBuf};
use std::process::Command;

use imucal_hil_sim::effects::{EffectKind, EffectRequest};
use imucal_hil_sim::physics::SensorKind;
use imucal_hil_sim::poser::ScheduleKind;
use imucal_hil_sim::recording::write_csv_file;
use imucal_hil_sim::{simulate_recording, SimConfig};
use serde_json::Value;

fn run_json(args: &[&str], file: &Path) -> Value {
    let out = Command::new(env!("CARGO_BIN_EXE_imucal"))
        .args(args)
        .arg(file)
        .arg("--json")
        .output()
        .expect("imucal runs");
    serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "{args:?}: no JSON ({e}): {}",
            String::from_utf8_lossy(&out.stderr)
        )
    })
}

/// `(fit says consistent, analyze says consistent)` per sensor fitted by both.
fn verdicts(file: &Path, flags: &[&str]) -> Vec<(String, bool, bool)> {
    let fit = run_json(&[&["fit"], flags].concat(), file);
    let analysis = run_json(&[&["analyze"], flags].concat(), file);
    ["accel", "gyro", "mag"]
        .iter()
        .filter_map(|sensor| {
            let by_fit = fit[sensor]["noise_test"]["consistent"].as_bool()?;
            let by_analysis = analysis["sensors"][sensor]["consistent_with_noise"].as_bool()?;
            Some((sensor.to_string(), by_fit, by_analysis))
        })
        .collect()
}

fn simulated(config: &SimConfig, name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("imucal-fit-verdict-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch directory");
    let path = dir.join(format!("{name}-{}.csv", config.seed));
    let recording = simulate_recording(config).expect("simulation runs");
    write_csv_file(&recording, &path).expect("write csv");
    path
}

#[test]
fn on_clean_recordings_fit_and_analyze_find_the_residual_at_the_noise() {
    let mut inconsistent = Vec::new();
    for seed in 0..6 {
        let path = simulated(&SimConfig::new(seed, ScheduleKind::Twelve), "clean");
        let found = verdicts(&path, &[]);
        assert_eq!(
            found.len(),
            3,
            "seed {seed}: accel, gyro and mag judged by both: {found:?}"
        );
        eprintln!("seed {seed}: {found:?}");
        for (sensor, by_fit, by_analysis) in found {
            if !(by_fit && by_analysis) {
                inconsistent.push(format!(
                    "seed {seed} {sensor}: fit {by_fit}, analyze {by_analysis}"
                ));
            }
        }
        let _ = std::fs::remove_file(&path);
    }
    // Each test rejects a right model 1 % of the time: 18 tests by each command, so one
    // rejection is plausible (16 %), three would be a 10⁻³ event.
    assert!(inconsistent.len() <= 2, "{inconsistent:#?}");
}

#[test]
fn an_effect_the_model_lacks_is_above_the_noise_for_fit_and_analyze_alike() {
    let mut config = SimConfig::new(3, ScheduleKind::Twelve);
    config.effects.push(EffectRequest {
        kind: EffectKind::ScaleNonlinearity,
        sensor: Some(SensorKind::Accel),
        size: 1.0,
    });
    let path = simulated(&config, "nonlinear");
    let found = verdicts(&path, &[]);
    let _ = std::fs::remove_file(&path);
    let accel = found
        .iter()
        .find(|(s, ..)| s == "accel")
        .expect("accel judged by both");
    assert_eq!((accel.1, accel.2), (false, false), "{found:?}");
}

#[test]
fn on_real_recordings_fit_and_analyze_agree_on_the_residual() {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/real");
    for (file, flags) in [
        (
            "tsi_mpu6050_multipos.csv",
            &["--accel-unit", "counts", "--gyro-unit", "counts"][..],
        ),
        ("imucal_nilspod_ferraris.csv", &["--gyro-unit", "dps"][..]),
        (
            "tsm_qmc5883l_mag_rotation.csv",
            &["--mag-unit", "counts"][..],
        ),
        (
            "sf_mpu6050_hmc5883l_full_sphere.csv",
            &[
                "--accel-unit",
                "g",
                "--gyro-unit",
                "dps",
                "--mag-unit",
                "gauss",
            ][..],
        ),
    ] {
        let found = verdicts(&data.join(file), flags);
        assert!(!found.is_empty(), "{file}: nothing judged by both");
        for (sensor, by_fit, by_analysis) in &found {
            assert_eq!(by_fit, by_analysis, "{file} {sensor}");
        }
    }
}

#[test]
fn a_magnetometer_turned_through_its_sphere_is_judged_alike_with_and_without_a_lacking_effect() {
    // A tumble at constant temperature: the sample-level model is right.
    for seed in 0..3 {
        let path = simulated(&SimConfig::new(seed, ScheduleKind::Tumble), "tumble");
        let found = verdicts(&path, &[]);
        let _ = std::fs::remove_file(&path);
        let mag = found.iter().find(|(s, ..)| s == "mag").expect("mag judged");
        assert_eq!((mag.1, mag.2), (true, true), "seed {seed}: {found:?}");
    }
    // A temperature sweep with a bias that follows temperature, which the model lacks.
    let mut config = SimConfig::new(5, ScheduleKind::Sweep);
    config.effects.push(EffectRequest {
        kind: EffectKind::BiasTemperature,
        sensor: Some(SensorKind::Mag),
        size: 1.0,
    });
    let path = simulated(&config, "mag-bias-temperature");
    let found = verdicts(&path, &[]);
    let _ = std::fs::remove_file(&path);
    let mag = found.iter().find(|(s, ..)| s == "mag").expect("mag judged");
    assert_eq!((mag.1, mag.2), (false, false), "{found:?}");
}
