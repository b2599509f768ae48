//! Sample the world and the sensor physics into a recording, and write it as the recording CSV of
//! ARCHITECTURE.md plus the truth as JSON.
//!
//! Columns: `t_s,ax,ay,az,gx,gy,gz,mx,my,mz,temp_c,pose` in s, m/s², rad/s, µT, °C. The values are
//! output counts times the nominal LSM9DS1 sensitivity, i.e. what an uncalibrated board streams.
//! `pose` is the hold label (0, 1, 2, … in order) during static holds and empty while the board
//! moves; an empty field means "not a hold", never a label.

use std::io::Write;
use std::path::Path;

use serde::{Deserialize, Serialize};

use imucal_protocol::{RawSample, SensorScales};

use crate::effects::EffectRequest;
use crate::error::{require_positive, SimError};
use crate::physics::{
    lsm9ds1_scales, ImuErrorRanges, ImuPhysics, ImuSample, ImuTruth, NominalScale, SensorKind,
    TEMP_COUNTS_PER_C, TEMP_ZERO_C,
};
use crate::poser::{build_schedule, PoserOptions, Schedule, ScheduleKind};
use crate::world::{
    EarthField, LocalDisturbance, TemperatureProfile, World, STANDARD_GRAVITY_MPS2,
};

/// Everything that determines a simulated recording.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SimConfig {
    /// Seed of every random draw (board errors, effects, noise, the person's motion).
    pub seed: u64,
    /// Which schedule the person follows.
    pub schedule: ScheduleKind,
    /// How the person moves.
    pub poser: PoserOptions,
    /// Sample rate, Hz.
    pub sample_rate_hz: f64,
    /// Magnitude of gravity, m/s².
    pub gravity_mps2: f64,
    /// The Earth's field.
    pub earth_field: EarthField,
    /// Optional local field disturbance.
    pub disturbance: Option<LocalDisturbance>,
    /// Replaces the schedule's own temperature profile when set.
    pub temperature: Option<TemperatureProfile>,
    /// Ranges the board's errors are drawn from.
    pub error_ranges: ImuErrorRanges,
    /// Effects switched on.
    pub effects: Vec<EffectRequest>,
}

impl SimConfig {
    /// Defaults at 100 Hz: standard gravity, 48 µT at 60° dip, consumer MEMS error ranges, no
    /// effects.
    pub fn new(seed: u64, schedule: ScheduleKind) -> Self {
        Self {
            seed,
            schedule,
            poser: PoserOptions::default(),
            sample_rate_hz: 100.0,
            gravity_mps2: STANDARD_GRAVITY_MPS2,
            earth_field: EarthField::default(),
            disturbance: None,
            temperature: None,
            error_ranges: ImuErrorRanges::default(),
            effects: Vec::new(),
        }
    }
}

/// World-level true values stored with a recording.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WorldTruth {
    /// Magnitude of gravity, m/s².
    pub gravity_mps2: f64,
    /// Earth's field magnitude and dip.
    pub earth_field: EarthField,
    /// Earth's field in the world frame (x north, y west, z up), µT.
    pub field_world_ut: [f64; 3],
    /// Local disturbance, if any.
    pub disturbance: Option<LocalDisturbance>,
    /// Die temperature over time.
    pub temperature: TemperatureProfile,
}

/// Every true parameter behind a recording.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Truth {
    /// The configuration that produced the recording.
    pub config: SimConfig,
    /// World constants.
    pub world: WorldTruth,
    /// The board's true sensor parameters and effects.
    pub imu: ImuTruth,
    /// Recording length, s.
    pub duration_s: f64,
}

/// One row of a recording.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RecordedSample {
    /// Time, s.
    pub t_s: f64,
    /// Chip counts.
    pub raw: RawSample,
    /// Hold label, or `None` while moving.
    pub pose: Option<usize>,
}

/// A simulated recording and its truth.
#[derive(Debug, Clone, PartialEq)]
pub struct Recording {
    /// Samples in time order.
    pub samples: Vec<RecordedSample>,
    /// Scale factors to nominal units.
    pub scales: SensorScales,
    /// The true parameters.
    pub truth: Truth,
}

/// A set-up simulation: the world, the board and its physics, ready to be sampled.
#[derive(Debug, Clone)]
pub struct Simulation {
    /// The world the board is in.
    pub world: World,
    /// The board's physics (holds the truth).
    pub physics: ImuPhysics,
    /// The schedule the world follows.
    pub schedule: Schedule,
    /// Sample rate, Hz.
    pub sample_rate_hz: f64,
    /// Number of samples in the recording.
    pub sample_count: usize,
}

impl Simulation {
    /// Set up the world and the board from `config`.
    pub fn new(config: &SimConfig) -> Result<Self, SimError> {
        let rate = require_positive("sample rate (Hz)", config.sample_rate_hz)?;
        let schedule = build_schedule(
            config.schedule,
            &config.poser,
            &config.earth_field,
            config.seed,
        )?;
        let world = World {
            trajectory: schedule.trajectory.clone(),
            gravity_mps2: config.gravity_mps2,
            earth_field: config.earth_field,
            disturbance: config.disturbance,
            temperature: config.temperature.unwrap_or(schedule.temperature),
        };
        world.validate()?;
        let duration = world.trajectory.duration_s();
        let mut truth = ImuTruth::draw(
            config.seed,
            &config.error_ranges,
            &config.effects,
            rate,
            duration,
        )?;
        let holds = world.trajectory.holds();
        for sensor in [&mut truth.accel, &mut truth.gyro, &mut truth.mag] {
            sensor.effects.out_of_family.place_on_holds(&holds);
        }
        let physics = ImuPhysics::new(truth, config.seed)?;
        // Whole samples within the trajectory: t_k = k / f_s < duration.
        let sample_count = (duration * rate).ceil() as usize;
        Ok(Self {
            world,
            physics,
            schedule,
            sample_rate_hz: rate,
            sample_count,
        })
    }

    /// Time of sample `k`, s.
    pub fn time_of(&self, k: usize) -> f64 {
        k as f64 / self.sample_rate_hz
    }

    /// Produce the next sample `k` (call with k = 0, 1, 2, … in order).
    pub fn sample(&mut self, k: usize) -> ImuSample {
        let state = self.world.state(self.time_of(k));
        self.physics.sample(&state)
    }
}

/// Simulate the recording described by `config`.
pub fn simulate_recording(config: &SimConfig) -> Result<Recording, SimError> {
    let mut sim = Simulation::new(config)?;
    let mut samples = Vec::with_capacity(sim.sample_count);
    for k in 0..sim.sample_count {
        let sample = sim.sample(k);
        samples.push(RecordedSample {
            t_s: sample.t,
            raw: sample.raw,
            pose: sim.world.trajectory.hold_index_at(sample.t),
        });
    }
    let truth = Truth {
        config: config.clone(),
        world: WorldTruth {
            gravity_mps2: sim.world.gravity_mps2,
            earth_field: sim.world.earth_field,
            field_world_ut: sim.world.earth_field.world_vector_ut().into(),
            disturbance: sim.world.disturbance,
            temperature: sim.world.temperature,
        },
        imu: *sim.physics.truth(),
        duration_s: sim.world.trajectory.duration_s(),
    };
    Ok(Recording {
        samples,
        scales: lsm9ds1_scales(sim.sample_rate_hz as f32),
        truth,
    })
}

/// The CSV header line (without newline).
pub const CSV_HEADER: &str = "t_s,ax,ay,az,gx,gy,gz,mx,my,mz,temp_c,pose";

/// Write `recording` as CSV. Values are counts times the f64 LSM9DS1 sensitivity, printed with
/// enough digits to recover the counts exactly.
pub fn write_csv<W: Write>(recording: &Recording, mut out: W) -> std::io::Result<()> {
    writeln!(out, "{CSV_HEADER}")?;
    let accel = SensorKind::Accel.units_per_count();
    let gyro = SensorKind::Gyro.units_per_count();
    let mag = SensorKind::Mag.units_per_count();
    for s in &recording.samples {
        let a = s.raw.accel.map(|c| f64::from(c) * accel);
        let g = s.raw.gyro.map(|c| f64::from(c) * gyro);
        let m = s.raw.mag.map(|c| f64::from(c) * mag);
        let temp = TEMP_ZERO_C + f64::from(s.raw.temp) / TEMP_COUNTS_PER_C;
        write!(
            out,
            "{:.6},{:.7},{:.7},{:.7},{:.8},{:.8},{:.8},{:.3},{:.3},{:.3},{:.4},",
            s.t_s, a[0], a[1], a[2], g[0], g[1], g[2], m[0], m[1], m[2], temp
        )?;
        match s.pose {
            Some(pose) => writeln!(out, "{pose}")?,
            None => writeln!(out)?,
        }
    }
    out.flush()
}

/// Write the CSV to `path`.
pub fn write_csv_file(recording: &Recording, path: &Path) -> Result<(), SimError> {
    let to_error = |source| SimError::Write {
        path: path.display().to_string(),
        source,
    };
    let file = std::fs::File::create(path).map_err(to_error)?;
    write_csv(recording, std::io::BufWriter::new(file)).map_err(to_error)
}

/// The truth as pretty-printed JSON.
pub fn truth_json(truth: &Truth) -> Result<String, SimError> {
    Ok(serde_json::to_string_pretty(truth)?)
}

/// Write the truth as JSON to `path`.
pub fn write_truth_file(truth: &Truth, path: &Path) -> Result<(), SimError> {
    let json = truth_json(truth)?;
    std::fs::write(path, json + "\n").map_err(|source| SimError::Write {
        path: path.display().to_string(),
        source,
    })
}
