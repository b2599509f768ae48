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

/// Accelerometer holds on the six faces of a sensor with scale errors and offsets, each face
/// held `repeats[face]` times; readings carry a deterministic scatter of `sigma` (m/s²).
fn face_holds(repeats: [usize; 6], sigma: f64) -> Vec<Observation> {
    let faces = [
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(-1.0, 0.0, 0.0),
        Vec3::new(0.0, 1.0, 0.0),
        Vec3::new(0.0, -1.0, 0.0),
        Vec3::new(0.0, 0.0, 1.0),
        Vec3::new(0.0, 0.0, -1.0),
    ];
    let scale = Vec3::new(1.01, 0.98, 1.02);
    let offset = Vec3::new(0.3, -0.2, 0.1);
    let mut obs = Vec::new();
    for (face, &count) in faces.iter().zip(&repeats) {
        for _ in 0..count {
            let i = obs.len();
            let wobble = Vec3::new(
                ((i as f64) * 1.3).sin(),
                ((i as f64) * 2.9).cos(),
                ((i as f64) * 0.7).sin(),
            ) * sigma;
            obs.push(Observation {
                mean: face.component_mul(&scale) * GRAVITY + offset + wobble,
                sigma_mean: Vec3::repeat(sigma),
                n: 500,
                n_eff: 500.0,
                noise_correlation: 0.0,
                temp_c: None,
                time_s: 10.0 * i as f64,
                accel_mean: None,
                label: None,
            });
        }
    }
    obs
}

fn axis_aligned_setup() -> SensorSetup<'static> {
    SensorSetup {
        sensor: Sensor::Accel,
        base_model: "minmax+axis-aligned",
        base: BaseKind::Norm {
            reference: GRAVITY,
            axis_aligned: true,
        },
        start: Calibration::identity(),
        force: None,
        gravity: GRAVITY,
        unit: "m/s²",
    }
}

#[test]
fn six_faces_with_single_poses_are_held_out_one_at_a_time_over_the_poses_the_model_can_spare() {
    // 13 poses, as the NilsPod recording: three faces held once, three held several times.
    // Twelve folds of random pairs would leave out some single face whole, and the axis-aligned
    // model (6 unknowns) cannot be determined by five orientations.
    let sigma = 2e-3;
    let obs = face_holds([1, 3, 1, 3, 1, 4], sigma);
    let analysis =
        analyse_observations(axis_aligned_setup(), obs).expect("the base model fits 13 poses");
    assert_eq!(analysis.always_trained, 3, "the three single-pose faces");
    // The ten poses held out are each predicted from five other faces plus their own: their
    // error is of the order of the scatter (relative to g), not of an undetermined axis.
    let relative = sigma / GRAVITY;
    assert!(
        analysis.heldout_rms_before < 5.0 * relative,
        "held-out {:.3e} vs scatter {relative:.3e}",
        analysis.heldout_rms_before
    );
}

#[test]
fn poses_on_five_faces_cannot_be_tested_held_out_and_say_so() {
    // Enough poses (9) but five orientations: no training set determines the 6 unknowns, and
    // the solver's answer would predict a held-out pose from an unconstrained axis.
    let obs = face_holds([2, 2, 2, 2, 1, 0], 2e-3);
    match analyse_observations(axis_aligned_setup(), obs) {
        Err(e @ AnalysisError::Refit { distinct, .. }) => {
            assert_eq!(distinct, 5);
            assert!(e.to_string().contains("twelve positions"), "{e}");
        }
        Err(e) => panic!("wrong refusal: {e}"),
        Ok(a) => panic!(
            "five orientations were tested held out: {:.3e}",
            a.heldout_rms_before
        ),
    }
}
