//! The residual analysis tried in an open world: simulated recordings (`imucal_hil_sim`) with one
//! hidden effect, analysed exactly as `imucal analyze` analyses a file (CSV written and loaded,
//! the same input checks, still detection, pipeline fits and [`analyse_calibration`] on them),
//! and the verdict reduced to
//! an [`Outcome`]. Used by the power sweep, the confusion matrix and the out-of-family cases
//! (`examples/analysis_power.rs`, `tests/analysis_open_world.rs`).
//!
//! **Detectable size.** For a family with `p` parameters tested among `m` candidates, the
//! detectable size is the effect size whose signal, beyond what the base model absorbs, has a
//! non-centrality `λ = Σᵢ‖eᵢ/σᵢ‖²` over the recording's poses equal to the critical value
//! `χ²_p(1 − α/m)` of the analysis's level `α` ([`crate::analysis::crossval::ALPHA`]): the size at
//! which a test that knew the effect's form would detect it about half the time. `σᵢ` is each
//! pose mean's noise (the floor) and the sum runs over the poses, so the size follows from the
//! noise floor and the pose count and nothing else. `λ` is measured as the mean rise of the base
//! model's χ² when the effect is switched on with the noise held fixed (same seed): for a
//! linear model that rise is `λ` plus a cross term of mean zero. `λ` grows with the square of the
//! size, so one calibration size gives every other.

use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};

use imucal_hil_sim::effects::{EffectKind as SimEffect, EffectRequest};
use imucal_hil_sim::physics::SensorKind;
use imucal_hil_sim::poser::ScheduleKind;
use imucal_hil_sim::{simulate_recording, write_csv, SimConfig};

use crate::analysis::crossval::ALPHA;
use crate::analysis::effects::{EffectKind, GYRO_FAMILIES, NORM_FAMILIES};
use crate::analysis::{analyse_calibration, AnalysisOptions, RecordingAnalysis, SensorAnalysis};
use crate::pipeline::input::InputOptions;
use crate::pipeline::{check_and_calibrate, FitOptions, References};
use crate::recording::{LoadOptions, Recording, Sensor};
use crate::stats::distributions::chi2_quantile_per_dof;
use crate::still::StillOptions;

/// The recording every trial simulates: the `sweep` schedule (the twelve positions repeated over
/// a temperature cycle of 5–45 °C).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RecordingShape {
    /// Rounds of the twelve positions (poses = 12 × repeats).
    pub repeats: usize,
    /// Temperature cycles over the recording.
    pub cycles: usize,
    /// Length of each hold, s.
    pub hold_s: f64,
}

impl RecordingShape {
    /// 72 poses of 4 s over two temperature cycles (the simulator's default sweep, ~9 minutes).
    pub const FULL: Self = Self {
        repeats: 6,
        cycles: 2,
        hold_s: 4.0,
    };
    /// 36 poses of 3 s over one temperature cycle (~4 minutes).
    pub const SHORT: Self = Self {
        repeats: 3,
        cycles: 1,
        hold_s: 3.0,
    };

    /// Number of poses.
    pub fn poses(&self) -> usize {
        12 * self.repeats
    }

    /// The simulator's configuration for `seed` with `effects` switched on.
    pub fn config(&self, seed: u64, effects: &[EffectRequest]) -> SimConfig {
        let mut c = SimConfig::new(seed, ScheduleKind::Sweep);
        c.poser.sweep_repeats = self.repeats;
        c.poser.sweep_cycles = self.cycles;
        c.poser.hold_s = self.hold_s;
        c.effects = effects.to_vec();
        c
    }
}

/// One hidden effect on one sensor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Case {
    /// The simulator's effect.
    pub effect: SimEffect,
    /// The sensor it is switched on for.
    pub sensor: SensorKind,
}

impl Case {
    /// The request for size `size` (1 = typical consumer part).
    pub fn request(&self, size: f64) -> EffectRequest {
        EffectRequest {
            kind: self.effect,
            sensor: Some(self.sensor),
            size,
        }
    }

    /// The analysed sensor.
    pub fn analysed(&self) -> Sensor {
        host_sensor(self.sensor)
    }

    /// `sensor.effect`, as on the simulator's command line.
    pub fn label(&self) -> String {
        format!("{}.{}", self.sensor.name(), self.effect.name())
    }

    /// The analysis family with the same name, if the effect is one the analysis can express.
    pub fn family(&self) -> Option<EffectKind> {
        candidate_families(self.sensor)
            .iter()
            .copied()
            .find(|f| f.name() == self.effect.name())
    }
}

/// The candidates the analysis tests for `sensor`.
pub fn candidate_families(sensor: SensorKind) -> &'static [EffectKind] {
    match sensor {
        SensorKind::Gyro => &GYRO_FAMILIES,
        SensorKind::Accel | SensorKind::Mag => &NORM_FAMILIES,
    }
}

/// The host's name for a simulator sensor.
pub fn host_sensor(sensor: SensorKind) -> Sensor {
    match sensor {
        SensorKind::Accel => Sensor::Accel,
        SensorKind::Gyro => Sensor::Gyro,
        SensorKind::Mag => Sensor::Mag,
    }
}

/// The five families of the power sweep, each on the sensor where it matters most: the four
/// norm-model families on the accelerometer, g-sensitivity on the gyroscope.
pub const POWER_CASES: [Case; 5] = [
    Case {
        effect: SimEffect::BiasTemperature,
        sensor: SensorKind::Accel,
    },
    Case {
        effect: SimEffect::ScaleTemperature,
        sensor: SensorKind::Accel,
    },
    Case {
        effect: SimEffect::BiasDrift,
        sensor: SensorKind::Accel,
    },
    Case {
        effect: SimEffect::ScaleNonlinearity,
        sensor: SensorKind::Accel,
    },
    Case {
        effect: SimEffect::GSensitivity,
        sensor: SensorKind::Gyro,
    },
];

/// Effects outside every family, on the sensors where they occur.
pub const OUT_OF_FAMILY_CASES: [Case; 13] = {
    const fn case(effect: SimEffect, sensor: SensorKind) -> Case {
        Case { effect, sensor }
    }
    use SensorKind::{Accel, Gyro, Mag};
    [
        case(SimEffect::ThermalHysteresis, Accel),
        case(SimEffect::ThermalHysteresis, Gyro),
        case(SimEffect::BiasRandomWalk, Accel),
        case(SimEffect::BiasRandomWalk, Gyro),
        case(SimEffect::BiasStep, Accel),
        case(SimEffect::BiasStep, Gyro),
        case(SimEffect::TemperatureRateBias, Accel),
        case(SimEffect::TemperatureRateBias, Gyro),
        case(SimEffect::CrossAxisNonlinearity, Accel),
        case(SimEffect::CrossAxisNonlinearity, Mag),
        case(SimEffect::BumpedHold, Accel),
        case(SimEffect::BumpedHold, Gyro),
        case(SimEffect::SteelNearHold, Mag),
    ]
};

/// What the analysis said about one sensor, reduced to what a user acts on.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// No family accepted and the residual is at the floor.
    Nothing,
    /// No family accepted and the residual is above the floor.
    Unexplained,
    /// Families accepted, residual at the floor after them.
    Explained(Vec<&'static str>),
    /// Families accepted, residual still above the floor (the report says it is partly explained).
    Partial(Vec<&'static str>),
    /// The sensor could not be analysed.
    Failed(String),
}

impl Outcome {
    /// The verdict of one sensor's analysis.
    pub fn of(analysis: &SensorAnalysis) -> Self {
        let accepted: Vec<&'static str> = analysis.accepted().map(|e| e.kind.name()).collect();
        match (accepted.is_empty(), analysis.unexplained) {
            (true, false) => Outcome::Nothing,
            (true, true) => Outcome::Unexplained,
            (false, false) => Outcome::Explained(accepted),
            (false, true) => Outcome::Partial(accepted),
        }
    }

    /// The verdict for `sensor` of a recording's analysis.
    pub fn of_sensor(analysis: &RecordingAnalysis, sensor: Sensor) -> Self {
        match analysis.sensors.iter().find(|(s, _)| *s == sensor) {
            Some((_, Ok(a))) => Outcome::of(a),
            Some((_, Err(e))) => Outcome::Failed(e.to_string()),
            None => Outcome::Failed(format!("no {sensor} in the recording")),
        }
    }

    /// Families accepted (empty for no claim).
    pub fn accepted(&self) -> &[&'static str] {
        match self {
            Outcome::Explained(f) | Outcome::Partial(f) => f,
            _ => &[],
        }
    }

    /// Short label for tables: `none`, `unexplained`, the accepted families joined by `+`, with
    /// ` (partial)` when a residual is left, or `failed`.
    pub fn label(&self) -> String {
        match self {
            Outcome::Nothing => "none".into(),
            Outcome::Unexplained => "unexplained".into(),
            Outcome::Explained(f) => f.join("+"),
            Outcome::Partial(f) => format!("{} (partial)", f.join("+")),
            Outcome::Failed(_) => "failed".into(),
        }
    }
}

/// Distinguishes the scratch files of trials running in parallel.
static SCRATCH: AtomicUsize = AtomicUsize::new(0);

/// Simulate `config` and analyse it as `imucal analyze FILE --field-ut H` would (the field is the
/// simulated one, the gravity the simulated one, the gyroscope in rad/s).
pub fn analyse_simulated(config: &SimConfig) -> Result<RecordingAnalysis, String> {
    let rec = simulate_recording(config).map_err(|e| format!("simulation: {e}"))?;
    let unique = SCRATCH.fetch_add(1, Ordering::Relaxed);
    let path: PathBuf = std::env::temp_dir().join(format!(
        "imucal-open-world-{}-{unique}.csv",
        std::process::id()
    ));
    let written = std::fs::File::create(&path)
        .map_err(|e| e.to_string())
        .and_then(|f| write_csv(&rec, f).map_err(|e| e.to_string()));
    let loaded = written
        .and_then(|()| Recording::load(&path, &LoadOptions::default()).map_err(|e| e.to_string()));
    let _ = std::fs::remove_file(&path);
    let recording = loaded?;
    let field = config.earth_field.magnitude_ut;
    let sensors = recording.sensors();
    let options = InputOptions {
        still: StillOptions::default(),
        max_mag_samples: 0,
    };
    let fit_options = FitOptions {
        references: Some(
            References::checked(config.gravity_mps2, Some(field), None)
                .map_err(|e| e.to_string())?,
        ),
        ..FitOptions::default()
    };
    let (checked, calibration) =
        check_and_calibrate(recording, &sensors, &options, Some(field), &fit_options)
            .map_err(|e| e.to_string())?;
    if !checked.unit_refusals.is_empty() {
        return Err(checked.unit_refusal_sentences().join("; "));
    }
    let still = checked
        .still
        .as_ref()
        .ok_or_else(|| "no still intervals".to_string())?;
    let options = AnalysisOptions {
        gravity: config.gravity_mps2,
        field_ut: Some(field),
        ..AnalysisOptions::default()
    };
    Ok(analyse_calibration(
        &checked.recording,
        still,
        &options,
        &calibration,
    ))
}

/// The base model's χ² of `sensor`, or `None` when it was not analysed.
pub fn base_chi2(analysis: &RecordingAnalysis, sensor: Sensor) -> Option<f64> {
    analysis
        .sensors
        .iter()
        .find(|(s, _)| *s == sensor)
        .and_then(|(_, r)| r.as_ref().ok())
        .map(|a| a.test_before.chi2)
}

/// The critical non-centrality of a family (see the module comment).
pub fn critical_noncentrality(family: EffectKind, candidates: usize) -> f64 {
    let p = family.param_count() as f64;
    chi2_quantile_per_dof(1.0 - ALPHA / candidates.max(1) as f64, p) * p
}

/// The detectable size of a family, and how it was measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetectableSize {
    /// Size factor (1 = the simulator's typical part) with `λ` at the critical value.
    pub size: f64,
    /// The critical non-centrality `χ²_p(1 − α/m)`.
    pub critical: f64,
    /// Mean `λ` measured at `calibration_size`.
    pub measured: f64,
    /// The size `λ` was measured at.
    pub calibration_size: f64,
}

/// Mean rise of the base χ² of the case's sensor at `size` over `seeds`, each against the same
/// seed without the effect (`clean[i]` is the clean base χ² of `seeds[i]`).
fn mean_chi2_rise(
    case: &Case,
    shape: &RecordingShape,
    size: f64,
    seeds: &[u64],
    clean: &[f64],
    threads: usize,
) -> Result<f64, String> {
    let rises = parallel_map(seeds, threads, |&seed| {
        let a = analyse_simulated(&shape.config(seed, &[case.request(size)]))?;
        base_chi2(&a, case.analysed()).ok_or_else(|| format!("seed {seed}: not analysed"))
    });
    let mut sum = 0.0;
    for (rise, c) in rises.into_iter().zip(clean) {
        sum += rise? - c;
    }
    Ok(sum / seeds.len().max(1) as f64)
}

/// Measure the detectable size of `case`'s family over `seeds` (see the module comment). `clean`
/// holds the base χ² of each seed without effects.
pub fn detectable_size(
    case: &Case,
    shape: &RecordingShape,
    seeds: &[u64],
    clean: &[f64],
    threads: usize,
) -> Result<DetectableSize, String> {
    let family = case
        .family()
        .ok_or_else(|| format!("{} is not a candidate family", case.label()))?;
    let critical = critical_noncentrality(family, candidate_families(case.sensor).len());
    // λ well above its own spread (2√λ) so that one calibration size is enough.
    const TARGET: f64 = 400.0;
    let mut size = 1.0;
    let mut measured = mean_chi2_rise(case, shape, size, seeds, clean, threads)?;
    if measured.is_nan() || measured <= 0.25 * TARGET || measured >= 100.0 * TARGET {
        size *= (TARGET / measured.max(1e-6)).sqrt().clamp(1e-3, 1e3);
        measured = mean_chi2_rise(case, shape, size, seeds, clean, threads)?;
    }
    if measured.is_nan() || measured <= 0.0 {
        return Err(format!(
            "{}: the effect does not raise the base χ² (λ = {measured:.3e} at size {size})",
            case.label()
        ));
    }
    Ok(DetectableSize {
        size: size * (critical / measured).sqrt(),
        critical,
        measured,
        calibration_size: size,
    })
}

/// `f` over `items` on `threads` threads (at least one), results in the order of `items`.
pub fn parallel_map<T: Sync, R: Send>(
    items: &[T],
    threads: usize,
    f: impl Fn(&T) -> R + Sync,
) -> Vec<R> {
    let next = AtomicUsize::new(0);
    let mut out: Vec<Option<R>> = (0..items.len()).map(|_| None).collect();
    let results = std::sync::Mutex::new(&mut out);
    std::thread::scope(|scope| {
        for _ in 0..threads.max(1) {
            scope.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(item) = items.get(i) else { break };
                let r = f(item);
                if let Ok(mut guard) = results.lock() {
                    guard[i] = Some(r);
                }
            });
        }
    });
    out.into_iter().flatten().collect()
}
