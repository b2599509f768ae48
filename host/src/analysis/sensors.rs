//! Observations and base model of each sensor of a recording: the accelerometer from its still
//! poses, started at the default chain's model; the gyroscope's bias with the specific force for
//! g-sensitivity; the magnetometer from still poses or short windows of the stream.

use super::earth_rate::vertical_earth_rate;
use super::extended_fit::BaseKind;
use super::result::{AnalysisError, AnalysisOptions, RecordingAnalysis, SensorAnalysis};
use super::selection::{analyse_observations, SensorSetup};
use crate::fit::coverage::sphere_start;
use crate::fit::gyro_bias::fit_gyro_bias;
use crate::fit::li::{fit_li, LiOptions};
use crate::fit::norm_lm::fit_mag_lm;
use crate::fit::Method;
use crate::fit::{Calibration, Vec3};
use crate::pipeline::chain::{default_accel_chain, unknowns, CandidateOutcome};
use crate::pipeline::observations::{self as dataset, to_poses};
use crate::pipeline::RecordingCalibration;
use crate::recording::{Recording, Sensor};
use crate::still::StillReport;

/// Analyse every sensor of a recording. The accelerometer is analysed first: its final
/// calibration gives the specific force for the gyroscope's g-sensitivity.
pub fn analyse_recording(
    recording: &Recording,
    still: &StillReport,
    options: &AnalysisOptions,
) -> RecordingAnalysis {
    analyse_each(recording, |sensor, accel_cal| {
        analyse_sensor(recording, still, options, sensor, accel_cal)
    })
}

/// Analyse every sensor of a recording on top of the pipeline's `calibration` of it (what `fit`
/// prints for the same data and options): a sensor the pipeline could not fit is not analysed,
/// with the pipeline's reason. The accelerometer's analysis starts from the model the pipeline
/// fitted, and its base is the full norm model whenever the pipeline could determine it (an
/// effect must not be credited with what misalignment explains, however the pipeline's
/// leave-one-out chose among its models); the axis-aligned model (6 unknowns) only where the
/// pipeline refused the full one. The analysis says when its base is not the model `fit` chose.
pub fn analyse_calibration(
    recording: &Recording,
    still: &StillReport,
    options: &AnalysisOptions,
    calibration: &RecordingCalibration,
) -> RecordingAnalysis {
    analyse_each(recording, |sensor, accel_cal| {
        let outcome = calibration.sensor(sensor);
        match outcome.map(|o| &o.fit) {
            Some(Err(reason)) => Err(AnalysisError::Refused(format!("not fitted: {reason}"))),
            Some(Ok(fit)) if sensor == Sensor::Accel => {
                let obs = accel_observations(recording, still)?;
                // The pipeline's chain says whether it could determine the full model; a method
                // given by name leaves that to the chain's own test on these poses.
                let full_refused = match outcome.and_then(|o| o.chain.as_ref()) {
                    Some(chain) => lm_refused(&chain.candidates),
                    None => default_accel_chain(&to_poses(&obs), options.gravity)
                        .map_or(unknowns(fit.method) == 6, |c| lm_refused(&c.candidates)),
                };
                let chosen = fit.method.name();
                let base = NormBase {
                    // Min/max, axis-aligned and their mean share the 6 unknowns.
                    model: match (full_refused, unknowns(fit.method)) {
                        (true, 6) => chosen,
                        (true, _) => "axis-aligned",
                        (false, _) => "lm",
                    },
                    axis_aligned: full_refused,
                    start: fit.cal,
                };
                let mut analysis = analyse_accel(recording, options, obs, base)?;
                if !full_refused && fit.method != Method::Lm {
                    analysis.base_note = Some(super::result::full_base_note(chosen, "`fit`"));
                }
                Ok(analysis)
            }
            _ => analyse_sensor(recording, still, options, sensor, accel_cal),
        }
    })
}

/// Whether the chain refused the full norm model (the poses cannot determine it).
fn lm_refused(candidates: &[crate::pipeline::chain::Candidate]) -> bool {
    candidates
        .iter()
        .any(|c| c.method == Method::Lm && matches!(c.outcome, CandidateOutcome::Refused(_)))
}

/// `analyse` of each sensor of `recording` in turn, the accelerometer's final calibration
/// handed to those after it.
fn analyse_each(
    recording: &Recording,
    mut analyse: impl FnMut(Sensor, Option<&Calibration>) -> Result<SensorAnalysis, AnalysisError>,
) -> RecordingAnalysis {
    let mut sensors = Vec::new();
    let mut accel_cal: Option<Calibration> = None;
    for sensor in recording.sensors() {
        let result = analyse(sensor, accel_cal.as_ref());
        if let (Sensor::Accel, Ok(a)) = (sensor, &result) {
            accel_cal = Some(a.calibration);
        }
        sensors.push((sensor, result));
    }
    RecordingAnalysis { sensors }
}

/// The accelerometer's still poses, refused when too few for the analysis.
fn accel_observations(
    recording: &Recording,
    still: &StillReport,
) -> Result<Vec<dataset::Observation>, AnalysisError> {
    let obs = dataset::pose_observations(recording, still, Sensor::Accel);
    if obs.len() < 10 {
        return Err(AnalysisError::TooFewObservations {
            sensor: Sensor::Accel.name(),
            what: "still poses",
            found: obs.len(),
            needed: 10,
        });
    }
    Ok(obs)
}

/// The norm model the accelerometer's analysis starts from.
struct NormBase {
    model: &'static str,
    axis_aligned: bool,
    start: Calibration,
}

/// The accelerometer's analysis of `obs` from `base`.
fn analyse_accel(
    recording: &Recording,
    options: &AnalysisOptions,
    obs: Vec<dataset::Observation>,
    base: NormBase,
) -> Result<SensorAnalysis, AnalysisError> {
    let setup = SensorSetup {
        sensor: Sensor::Accel,
        base_model: base.model,
        base: BaseKind::Norm {
            reference: options.gravity,
            axis_aligned: base.axis_aligned,
        },
        start: base.start,
        force: None,
        gravity: options.gravity,
        unit: recording.units.symbol(Sensor::Accel),
    };
    analyse_observations(setup, obs)
}

/// Analyse one sensor; `accel_cal` (the accelerometer's calibration) enables g-sensitivity.
pub fn analyse_sensor(
    recording: &Recording,
    still: &StillReport,
    options: &AnalysisOptions,
    sensor: Sensor,
    accel_cal: Option<&Calibration>,
) -> Result<SensorAnalysis, AnalysisError> {
    if !recording.has(sensor) {
        return Err(AnalysisError::NoSensor(sensor.name()));
    }
    let unit = recording.units.symbol(sensor);
    let too_few = |what, found, needed| AnalysisError::TooFewObservations {
        sensor: sensor.name(),
        what,
        found,
        needed,
    };
    match sensor {
        Sensor::Accel => {
            let obs = accel_observations(recording, still)?;
            // The default chain's model starts the extended fit. The base is the full norm model
            // (an effect must not be credited with what misalignment explains) unless `fit`
            // refused it because the poses cannot determine it (e.g. six faces, or a plane of
            // tilts): then the axis-aligned model (6 unknowns), which `fit` can determine. When every model
            // of the chain refuses, the generic solver restarts from the sphere.
            let base = match default_accel_chain(&to_poses(&obs), options.gravity) {
                Ok(choice) => {
                    let axis_aligned = lm_refused(&choice.candidates);
                    NormBase {
                        model: if axis_aligned { "axis-aligned" } else { "lm" },
                        axis_aligned,
                        start: choice.fit.cal,
                    }
                }
                Err(source) => {
                    let means: Vec<Vec3> = obs.iter().map(|o| o.mean).collect();
                    let base = NormBase {
                        model: "lm",
                        axis_aligned: false,
                        start: sphere_start(&means, options.gravity),
                    };
                    return analyse_accel(recording, options, obs, base).map_err(|_| {
                        AnalysisError::BaseFit {
                            sensor: "accel",
                            source,
                        }
                    });
                }
            };
            analyse_accel(recording, options, obs, base)
        }
        Sensor::Gyro => {
            let obs = dataset::pose_observations(recording, still, Sensor::Gyro);
            if obs.len() < 3 {
                return Err(too_few("still poses", obs.len(), 3));
            }
            // Specific force from the accelerometer's calibration, else from its nominal unit.
            let accel_si = recording.units.to_si(Sensor::Accel);
            let force = obs
                .iter()
                .map(|o| match (accel_cal, accel_si) {
                    (Some(cal), _) => o.accel_mean.map(|a| cal.apply(&a)),
                    (None, Some(k)) => o.accel_mean.map(|a| a * k),
                    (None, None) => None,
                })
                .collect::<Option<Vec<Vec3>>>();
            // The Earth's vertical rate is known from each hold's up direction: remove it so that
            // neither the bias nor a g-sensitivity absorbs it.
            let mut obs = obs;
            if let (Some(lat), Some(f)) = (options.latitude_deg, &force) {
                for (o, fi) in obs.iter_mut().zip(f) {
                    o.mean -= vertical_earth_rate(lat, fi) / options.gyro_scale;
                }
            }
            let start = fit_gyro_bias(&to_poses(&obs), options.gyro_scale).map_err(|source| {
                AnalysisError::BaseFit {
                    sensor: "gyro",
                    source,
                }
            })?;
            let setup = SensorSetup {
                sensor,
                base_model: "gyro-bias",
                base: BaseKind::Rest {
                    scale: options.gyro_scale,
                },
                start: start.cal,
                force,
                gravity: options.gravity,
                unit,
            };
            analyse_observations(setup, obs).map(|mut a| {
                if !options.gyro_scale_known {
                    // Without a scale the residual and every coefficient are in counts.
                    a.residual_unit = "counts";
                    for c in a.effects.iter_mut().flat_map(|e| e.coefficients.iter_mut()) {
                        c.unit = c.unit.replace("rad/s", "counts");
                    }
                }
                a
            })
        }
        Sensor::Mag => {
            let obs = dataset::mag_observations(
                recording,
                Some(still),
                options.mag_window,
                options.max_mag_windows,
            );
            if obs.len() < 12 {
                return Err(too_few("magnetometer windows", obs.len(), 12));
            }
            let reference = options.field_ut.unwrap_or(1.0);
            let means: Vec<Vec3> = obs.iter().map(|o| o.mean).collect();
            // The `fit` default, else Li's ellipsoid, else the sphere, refined by the solver here.
            let start = match fit_mag_lm(&means, reference) {
                Ok(fit) => fit.cal,
                Err(_) => fit_li(
                    &means,
                    reference,
                    LiOptions {
                        subtract_mean: true,
                    },
                )
                .map(|f| f.cal)
                .unwrap_or_else(|_| sphere_start(&means, reference)),
            };
            let setup = SensorSetup {
                sensor,
                base_model: "lm",
                base: BaseKind::Norm {
                    reference,
                    axis_aligned: false,
                },
                start,
                force: None,
                gravity: options.gravity,
                unit,
            };
            analyse_observations(setup, obs)
        }
    }
}
