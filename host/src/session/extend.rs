//! Closing the loop after a session: the residual analysis of its poses ("Closing the loop" in
//! `ARCHITECTURE.md`, [`crate::analysis`]) and the parameter set extended with what it accepts.
//!
//! Each captured pose is one observation per sensor: the board's mean, its standard error
//! `√(var/n)`, the mean die temperature and the board time of the hold. The accelerometer is
//! analysed on the norm model `|A(v − b)| = g` (seed 003's twelve-position model), the gyroscope
//! on the rest model `ω̄ = b` (seed 000 eq. 9) with the accelerometer's calibrated specific force
//! for g-sensitivity. Candidates are accepted by held-out error, forward, as in `imucal analyze`.
//! The magnetometer is not analysed here: its fit uses the tumble, not the poses.
//!
//! [`extend_set`] replaces `b` and the extended terms of each sensor with an accepted effect
//! that the firmware can apply (bias temperature polynomial, scale temperature coefficient,
//! non-linearity, gyro g-sensitivity) by the analysis's final model, fitted jointly with them,
//! and the accelerometer's `A` too; the gyroscope keeps the session's `A`, which comes from the
//! turns the holds do not see. A sensor with nothing accepted keeps the session's values, so a
//! set without accepted effects is written unchanged. A replaced sensor's residual RMS is the
//! final model's, and [`extended_uncertainties`] its σ.

use imucal_protocol::{CalibrationSet, SensorCalibration};

use super::solve::{
    accel_of, gyro_of, max_norm_sigma_of, CapturedPose, Uncertainties, STANDARD_GRAVITY,
};
use crate::analysis::effects::EffectKind;
use crate::analysis::extended_fit::BaseKind;
use crate::analysis::{
    analyse_observations, AnalysisError, EffectStatus, RecordingAnalysis, SensorAnalysis,
    SensorSetup,
};
use crate::fit::gyro_bias::fit_gyro_bias;
use crate::fit::norm_lm::fit_accel_lm;
use crate::fit::{Mat3, Vec3};
use crate::pipeline::observations::{to_poses, Observation};
use crate::recording::Sensor;
use imucal_protocol::PoseStats;

/// Fewest poses the accelerometer analysis takes: the norm model has 9 parameters and a held-out
/// test of a three-parameter effect needs residual degrees of freedom beyond them (one round of
/// twelve leaves only three).
pub const MIN_ACCEL_POSES: usize = 16;

/// Fewest poses the gyroscope analysis takes (three components each; bias has 3 parameters).
pub const MIN_GYRO_POSES: usize = 3;

fn observation(pose: &CapturedPose, sensor: fn(&PoseStats) -> ([f32; 3], [f32; 3])) -> Observation {
    let (mean, var) = sensor(&pose.stats);
    let n = pose.stats.n.max(1) as usize;
    let sigma_mean = Vec3::from(var.map(|v| (f64::from(v).max(0.0) / n as f64).sqrt()));
    Observation {
        mean: Vec3::from(mean.map(f64::from)),
        sigma_mean,
        n,
        // The board reports a hold's mean and variance, not its autocorrelation, so the
        // effective sample size is unknown here: n_eff = n, and correlated samples show up as
        // excess scatter between holds, which the fits' Birge ratio absorbs (`fit::uncertainty`).
        n_eff: n as f64,
        noise_correlation: 0.0,
        temp_c: Some(f64::from(pose.stats.temp_mean_c)),
        time_s: pose.t_s,
        accel_mean: Some(Vec3::from(pose.stats.accel_mean.map(f64::from))),
        label: Some(pose.target.index as i64),
    }
}

fn usable(pose: &CapturedPose) -> bool {
    let s = &pose.stats;
    s.n > 1
        && s.accel_mean
            .iter()
            .chain(&s.accel_var)
            .chain(&s.gyro_mean)
            .chain(&s.gyro_var)
            .chain(std::iter::once(&s.temp_mean_c))
            .all(|v| v.is_finite())
        && pose.t_s.is_finite()
}

/// Says on the accelerometer's analysis of `analysis` that its base, the full norm model, is
/// not `chosen`, the model the session fitted and wrote, when it is not.
pub fn note_accel_base(analysis: &mut RecordingAnalysis, chosen: crate::fit::Method) {
    if chosen == crate::fit::Method::Lm {
        return;
    }
    for (sensor, result) in &mut analysis.sensors {
        if let (Sensor::Accel, Ok(a)) = (sensor, result) {
            a.base_note = Some(crate::analysis::result::full_base_note(
                chosen.name(),
                "the session",
            ));
        }
    }
}

/// Analyse the accelerometer and gyroscope of a session's poses (nominal units: m/s², rad/s)
/// against local gravity `gravity_mps2`. Poses with non-finite statistics are left out.
pub fn analyse_poses(poses: &[CapturedPose], gravity_mps2: f64) -> RecordingAnalysis {
    let usable: Vec<&CapturedPose> = poses.iter().filter(|p| usable(p)).collect();
    let too_few = |sensor: &'static str, needed: usize| AnalysisError::TooFewObservations {
        sensor,
        what: "still poses",
        found: usable.len(),
        needed,
    };

    let accel_obs: Vec<Observation> = usable.iter().map(|p| observation(p, accel_of)).collect();
    let accel = if accel_obs.len() < MIN_ACCEL_POSES {
        Err(too_few("accel", MIN_ACCEL_POSES))
    } else {
        match fit_accel_lm(&to_poses(&accel_obs), gravity_mps2) {
            Ok(start) => analyse_observations(
                SensorSetup {
                    sensor: Sensor::Accel,
                    base_model: "lm",
                    base: BaseKind::Norm {
                        reference: gravity_mps2,
                        axis_aligned: false,
                    },
                    start: start.cal,
                    force: None,
                    gravity: gravity_mps2,
                    unit: "m/s²",
                },
                accel_obs,
            ),
            Err(source) => Err(AnalysisError::BaseFit {
                sensor: "accel",
                source,
            }),
        }
    };

    let gyro_obs: Vec<Observation> = usable.iter().map(|p| observation(p, gyro_of)).collect();
    let gyro = if gyro_obs.len() < MIN_GYRO_POSES {
        Err(too_few("gyro", MIN_GYRO_POSES))
    } else {
        match fit_gyro_bias(&to_poses(&gyro_obs), 1.0) {
            Ok(start) => {
                // Specific force of each pose from the accelerometer's final calibration, when
                // it was analysed (g-sensitivity is then testable).
                let force = accel.as_ref().ok().map(|a| {
                    usable
                        .iter()
                        .map(|p| {
                            a.calibration
                                .apply(&Vec3::from(p.stats.accel_mean.map(f64::from)))
                        })
                        .collect()
                });
                analyse_observations(
                    SensorSetup {
                        sensor: Sensor::Gyro,
                        base_model: "gyro-bias",
                        base: BaseKind::Rest { scale: 1.0 },
                        start: start.cal,
                        force,
                        gravity: gravity_mps2,
                        unit: "rad/s",
                    },
                    gyro_obs,
                )
            }
            Err(source) => Err(AnalysisError::BaseFit {
                sensor: "gyro",
                source,
            }),
        }
    };
    RecordingAnalysis {
        sensors: vec![(Sensor::Accel, accel), (Sensor::Gyro, gyro)],
    }
}

/// A parameter set with the accepted effects of an analysis added.
#[derive(Debug, Clone, PartialEq)]
pub struct ExtendedSet {
    /// The set to write.
    pub set: CalibrationSet,
    /// The effects now in the set, e.g. `accel bias_temperature (degree 2)`.
    pub added: Vec<String>,
    /// Accepted effects the firmware has no term for (e.g. `gyro bias_drift`), left out.
    pub left_out: Vec<String>,
    /// The sensors whose terms now come from the analysis's final model.
    pub replaced: Vec<Sensor>,
}

impl ExtendedSet {
    /// Whether the set differs from the one it was built from.
    pub fn extended(&self) -> bool {
        !self.added.is_empty()
    }
}

fn describe(sensor: Sensor, kind: EffectKind) -> String {
    match kind {
        EffectKind::BiasTemperature(d) => {
            format!("{} {} (degree {d})", sensor.name(), kind.name())
        }
        _ => format!("{} {}", sensor.name(), kind.name()),
    }
}

/// `base` with every accepted effect of `analysis` that has a firmware term (see the module
/// documentation). Only the accelerometer and gyroscope are taken from the analysis.
pub fn extend_set(base: &CalibrationSet, analysis: &RecordingAnalysis) -> ExtendedSet {
    let mut set = *base;
    let mut added = Vec::new();
    let mut left_out = Vec::new();
    let mut replaced = Vec::new();
    for (sensor, result) in &analysis.sensors {
        let Ok(found) = result else { continue };
        let (with_term, without): (Vec<EffectKind>, Vec<EffectKind>) = accepted(found)
            .into_iter()
            .partition(|k| !matches!(k, EffectKind::BiasDrift | EffectKind::BinnedBias(_)));
        left_out.extend(without.iter().map(|k| describe(*sensor, *k)));
        if with_term.is_empty() {
            continue;
        }
        let terms = found.to_calibration_terms();
        // The set's residual is the model it carries: the analysis's final one (relative to
        // g for the accelerometer, rad/s for the gyroscope), not the base fit's.
        match sensor {
            Sensor::Accel => {
                set.accel = terms.sensor;
                set.residuals.accel_rms =
                    (found.rms_after * f64::from(set.reference.gravity_mps2)) as f32;
            }
            Sensor::Gyro => {
                // The holds fit the bias and its terms at rest, where A is only the unit's
                // scale: the session's A (scale and misalignment from the turns) stays.
                set.gyro = SensorCalibration {
                    a: base.gyro.a,
                    ..terms.sensor
                };
                set.residuals.gyro_rms = found.rms_after as f32;
                if let Some(k) = terms.gyro_g_sensitivity {
                    set.gyro_g_sensitivity = Some(g_sensitivity_through(
                        &base.gyro.a,
                        &found.calibration.a,
                        &k,
                    ));
                }
            }
            Sensor::Mag => continue,
        }
        added.extend(with_term.iter().map(|k| describe(*sensor, *k)));
        replaced.push(*sensor);
    }
    ExtendedSet {
        set,
        added,
        left_out,
        replaced,
    }
}

/// The session's uncertainties with those of each sensor [`extend_set`] replaced taken from the
/// analysis's final model ([`SensorAnalysis::base_covariance`]: at the reference temperature,
/// with the added terms' correlation): accelerometer offset, scale and `|a|` error, gyroscope
/// bias. Figures of sensors not replaced are `base`'s.
pub fn extended_uncertainties(
    base: &Uncertainties,
    extended: &ExtendedSet,
    analysis: &RecordingAnalysis,
    gravity_mps2: f64,
) -> Uncertainties {
    let mut out = *base;
    let mg = 1000.0 / STANDARD_GRAVITY;
    for (sensor, result) in &analysis.sensors {
        let Ok(found) = result else { continue };
        if !extended.replaced.contains(sensor) {
            continue;
        }
        let Some((names, cov)) = found.base_covariance() else {
            continue;
        };
        let sigma = |name: &str| {
            names
                .iter()
                .position(|n| n == name)
                .map_or(f64::NAN, |i| cov[(i, i)].max(0.0).sqrt())
        };
        match sensor {
            Sensor::Accel => {
                out.accel_bias_mg = ["b1", "b2", "b3"].map(|n| sigma(n) * mg);
                let a = &found.calibration.a;
                out.accel_scale_ppm = [("A11", 0), ("A22", 1), ("A33", 2)]
                    .map(|(n, i)| sigma(n) / a[(i, i)].abs().max(f64::MIN_POSITIVE) * 1e6);
                out.accel_norm_mg =
                    max_norm_sigma_of(&found.calibration, gravity_mps2, &names, &cov)
                        .map_or(f64::NAN, |s| s * mg);
            }
            Sensor::Gyro => {
                out.gyro_bias_dps = ["b1", "b2", "b3"].map(|n| sigma(n).to_degrees());
            }
            Sensor::Mag => {}
        }
    }
    out
}

/// The g-sensitivity `K` fitted with the analysis's `A` (`A_an(x − b) − K·f = 0` at rest) as the
/// firmware applies it after the set's `A` (`A(x − b) − K'·f`): `K' = A·A_an⁻¹·K`.
fn g_sensitivity_through(a: &[[f32; 3]; 3], a_analysis: &Mat3, k: &[[f32; 3]; 3]) -> [[f32; 3]; 3] {
    let to_mat = |m: &[[f32; 3]; 3]| Mat3::from_fn(|r, c| f64::from(m[r][c]));
    let Some(inverse) = a_analysis.try_inverse() else {
        return *k;
    };
    let through = to_mat(a) * inverse * to_mat(k);
    [0, 1, 2].map(|r| [0, 1, 2].map(|c| through[(r, c)] as f32))
}

fn accepted(analysis: &SensorAnalysis) -> Vec<EffectKind> {
    analysis
        .effects
        .iter()
        .filter(|e| e.status == EffectStatus::Accepted)
        .map(|e| e.kind)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::session::targets::twelve_positions;

    /// Poses of an ideal board at rest in the twelve positions at 25 °C, one second apart.
    fn ideal_poses(gravity: f64) -> Vec<CapturedPose> {
        twelve_positions()
            .into_iter()
            .enumerate()
            .map(|(i, target)| {
                let accel = (target.up * gravity).map(|v| v as f32);
                let stats = PoseStats {
                    n: 200,
                    accel_mean: [accel.x, accel.y, accel.z],
                    accel_var: [4e-4; 3],
                    gyro_mean: [0.0; 3],
                    gyro_var: [1e-5; 3],
                    mag_mean: [20.0, 0.0, 40.0],
                    mag_var: [0.1; 3],
                    temp_mean_c: 25.0,
                    temp_min_c: 25.0,
                    temp_max_c: 25.0,
                    duration_ms: 1500,
                };
                CapturedPose {
                    target,
                    stats,
                    t_s: i as f64,
                }
            })
            .collect()
    }

    #[test]
    fn one_round_is_too_few_for_the_accelerometer_and_says_how_many_are_needed() {
        let analysis = analyse_poses(&ideal_poses(9.81), 9.81);
        match &analysis.sensors[0] {
            (Sensor::Accel, Err(AnalysisError::TooFewObservations { found, needed, .. })) => {
                assert_eq!((*found, *needed), (12, MIN_ACCEL_POSES));
            }
            (sensor, other) => panic!("{sensor:?}: {other:?}"),
        }
        assert!(matches!(analysis.sensors[1], (Sensor::Gyro, Ok(_))));
    }

    #[test]
    fn non_finite_poses_are_left_out_instead_of_poisoning_the_analysis() {
        let mut poses = ideal_poses(9.81);
        poses[3].stats.gyro_mean[1] = f32::NAN;
        let analysis = analyse_poses(&poses, 9.81);
        let Ok(gyro) = &analysis.sensors[1].1 else {
            panic!(
                "the gyroscope was not analysed: {:?}",
                analysis.sensors[1].1
            );
        };
        assert_eq!(gyro.observations.len(), 11);
    }

    #[test]
    fn an_accepted_g_sensitivity_keeps_the_sessions_gyro_matrix_and_carries_k_through_it() {
        // Two rounds of the twelve positions; the gyroscope reads b + K·f at rest.
        let k_true = Mat3::new(2e-4, -3e-4, 1e-4, 4e-4, 1e-4, -2e-4, -1e-4, 3e-4, 2e-4);
        let b_true = Vec3::new(0.01, -0.02, 0.005);
        let mut poses = ideal_poses(9.81);
        let second: Vec<CapturedPose> = poses
            .iter()
            .map(|p| CapturedPose {
                t_s: p.t_s + 100.0,
                ..p.clone()
            })
            .collect();
        poses.extend(second);
        for p in &mut poses {
            let f = Vec3::from(p.stats.accel_mean.map(f64::from));
            let w = b_true + k_true * f;
            p.stats.gyro_mean = [w.x as f32, w.y as f32, w.z as f32];
        }
        let analysis = analyse_poses(&poses, 9.81);
        let mut base = CalibrationSet::identity();
        // The session's A from the turns: 2 % scale error and some misalignment.
        base.gyro.a = [[1.02, 0.01, 0.0], [0.0, 0.98, -0.01], [0.005, 0.0, 1.01]];
        let extended = extend_set(&base, &analysis);
        assert!(
            extended.added.iter().any(|a| a == "gyro g_sensitivity"),
            "{:?}",
            extended.added
        );
        assert_eq!(extended.set.gyro.a, base.gyro.a);
        // A(x − b) − K'·f = 0 at rest needs K' = A·K.
        let a = Mat3::from_fn(|r, c| f64::from(base.gyro.a[r][c]));
        let expected = a * k_true;
        let k = extended.set.gyro_g_sensitivity.expect("K written");
        for r in 0..3 {
            for c in 0..3 {
                assert!(
                    (f64::from(k[r][c]) - expected[(r, c)]).abs() < 2e-6,
                    "K'[{r}][{c}] = {} against A·K = {}",
                    k[r][c],
                    expected[(r, c)]
                );
            }
        }
        for axis in 0..3 {
            assert!((f64::from(extended.set.gyro.b[axis]) - b_true[axis]).abs() < 1e-5);
        }
        // The written set's σ: the gyroscope's from the joint fit, the accelerometer's (not
        // replaced) unchanged.
        let base_sigma = Uncertainties {
            accel_bias_mg: [0.1; 3],
            accel_scale_ppm: [100.0; 3],
            accel_norm_mg: 0.2,
            gyro_bias_dps: [1.0; 3],
            mag_bias_ut: [0.02; 3],
            mag_norm_pct: 0.1,
            alignment_deg: 0.02,
        };
        let sigma = extended_uncertainties(&base_sigma, &extended, &analysis, 9.81);
        assert_eq!(extended.replaced, vec![Sensor::Gyro]);
        assert_eq!(sigma.accel_bias_mg, base_sigma.accel_bias_mg);
        for s in sigma.gyro_bias_dps {
            // Exact data: the bias is known far better than the placeholder's 1 °/s.
            assert!(
                s.is_finite() && s > 0.0 && s < 0.1,
                "{:?}",
                sigma.gyro_bias_dps
            );
        }
    }

    #[test]
    fn an_analysis_without_accepted_effects_leaves_the_set_unchanged() {
        let base = CalibrationSet::identity();
        let analysis = analyse_poses(&ideal_poses(9.81), 9.81);
        let extended = extend_set(&base, &analysis);
        assert_eq!(extended.set, base);
        assert!(!extended.extended() && extended.left_out.is_empty());
    }
}
