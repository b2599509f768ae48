//! The analysis on too few poses: a candidate whose unknowns the held-out folds cannot
//! determine is reported `not_fittable` with the number of poses still needed, never dropped.

use imucal::analysis::extended_fit::BaseKind;
use imucal::analysis::{analyse_observations, AnalysisError, EffectStatus, SensorSetup};
use imucal::fit::{Calibration, Vec3};
use imucal::pipeline::observations::Observation;
use imucal::recording::Sensor;

const GRAVITY: f64 = 9.81;

/// Gyroscope holds at rest with a small deterministic scatter (rad/s), warming by 2 °C per pose.
fn gyro_holds(count: usize) -> (Vec<Observation>, Vec<Vec3>) {
    let directions = [
        Vec3::new(0.0, 0.0, 1.0),
        Vec3::new(0.0, 0.0, -1.0),
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(-1.0, 0.0, 0.0),
        Vec3::new(0.0, 1.0, 0.0),
        Vec3::new(0.0, -1.0, 0.0),
    ];
    let sigma = 1e-4;
    let obs = (0..count)
        .map(|i| {
            let wobble = ((i as f64) * 1.7).sin() * sigma;
            Observation {
                mean: Vec3::new(0.01 + wobble, -0.02 - wobble, 0.005 + 0.5 * wobble),
                sigma_mean: Vec3::repeat(sigma),
                n: 1000,
                n_eff: 1000.0,
                noise_correlation: 0.0,
                temp_c: Some(25.0 + 2.0 * i as f64 + (i % 2) as f64 * 3.0),
                time_s: 30.0 * i as f64,
                accel_mean: None,
                label: None,
            }
        })
        .collect();
    let force = (0..count).map(|i| directions[i % 6] * GRAVITY).collect();
    (obs, force)
}

fn setup(force: Vec<Vec3>) -> SensorSetup<'static> {
    SensorSetup {
        sensor: Sensor::Gyro,
        base_model: "rest",
        base: BaseKind::Rest { scale: 1.0 },
        start: Calibration::identity(),
        force: Some(force),
        gravity: GRAVITY,
        unit: "rad/s",
    }
}

#[test]
fn g_sensitivity_on_five_poses_is_not_fittable_and_asks_for_one_more_pose() {
    // Rest base (3 unknowns) + g-sensitivity (9) = 12 unknowns; leave-one-out leaves 4 poses
    // × 3 axes = 12 residuals, not more than 12: one more pose makes every fold determined.
    let (obs, force) = gyro_holds(5);
    let analysis = analyse_observations(setup(force), obs).expect("base model fits on 5 poses");
    let g = analysis
        .effects
        .iter()
        .find(|e| e.kind.name() == "g_sensitivity")
        .expect("g_sensitivity is reported, not dropped");
    assert_eq!(g.status, EffectStatus::NotFittable, "{}", g.note);
    assert!(
        g.note.contains("1 more pose") && g.note.contains("6 in all"),
        "{}",
        g.note
    );
    // A candidate with fewer unknowns is still tested on the same poses.
    assert!(analysis
        .effects
        .iter()
        .any(|e| e.kind.name() == "bias_drift" && e.status != EffectStatus::NotFittable));
}

#[test]
fn a_base_model_on_too_few_poses_says_how_many_are_needed() {
    // Rest base: 3 unknowns, 3 residuals per pose; leave-one-out on 1 pose has no training pose.
    let (obs, force) = gyro_holds(1);
    match analyse_observations(setup(force), obs) {
        Err(AnalysisError::TooFewObservations { found, needed, .. }) => {
            assert_eq!((found, needed), (1, 3));
        }
        Err(e) => panic!("wrong refusal: {e}"),
        Ok(_) => panic!("one pose cannot be analysed held out"),
    }
}
