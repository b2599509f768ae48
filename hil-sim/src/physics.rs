//! True sensor error model of the simulated IMU, in the host's convention.
//!
//! The host calibrates with `y = A·(x − b)` (ARCHITECTURE.md; seed 000 eq. (3)–(8)), so the
//! raw reading is generated as `x = A⁻¹·y + b`, with, in this order:
//! 1. gyro only: `y ← ω + K·f` (g-sensitivity, calibrated units; correction `− K·f`);
//!    magnetometer: `y ← y + steel field` during the hold a steel object lies near;
//! 2. `u = A⁻¹·y` (scale, cross-axis, and for the magnetometer soft iron);
//! 3. `u_i ← u_i·(1 + k_i·ΔT)` (scale temperature), then `u_i ← u_i + q_i·u_i² + c_i·u_i³`,
//!    then the cross-axis products of [`crate::out_of_family`];
//! 4. `x = u + b + b_T(ΔT) + r·t + step + walk + hysteresis + g·dT/dt + bump + σ·n`,
//!    `n ~ N(0, I)`;
//! 5. counts `= round(x / LSB)` clamped to the 16-bit output register (saturation).
//!
//! `ΔT = T − 25 °C`. White noise follows the IEEE Std 952 convention: a density `N` (units/√Hz)
//! sampled at `f_s` gives `σ = N·√f_s` per sample, which is what an Allan deviation of the stream
//! returns as `N` at τ = 1 s. Sensitivities are the LSM9DS1's (datasheet DocID025715, table 3):
//! accel ±4 g 0.122 mg/LSB, gyro ±500 °/s 17.5 m°/s/LSB, mag ±4 gauss 0.14 mgauss/LSB,
//! temperature 16 LSB/°C with 0 at 25 °C. The die thermometer is modelled as exact.

use nalgebra::{Matrix3, Vector3};
use rand::Rng;
use rand_chacha::rand_core::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

use imucal_protocol::{RawSample, SensorScales};

use crate::effects::{draw_effects, EffectRequest, GSensitivity, SensorEffects};
use crate::error::{require_non_negative, require_positive, SimError};
use crate::world::{WorldState, STANDARD_GRAVITY_MPS2};

pub use crate::sensor_kind::{
    NominalScale, SensorKind, ACCEL_MPS2_PER_COUNT, GYRO_RADS_PER_COUNT, MAG_UT_PER_COUNT,
};

/// Die thermometer sensitivity, counts per °C.
pub const TEMP_COUNTS_PER_C: f64 = 16.0;
/// Temperature at zero counts, °C; also the reference temperature of every effect.
pub const TEMP_ZERO_C: f64 = 25.0;

/// Scale factors and nominal ranges of the simulated chip, as the device announces them.
pub fn lsm9ds1_scales(sample_rate_hz: f32) -> SensorScales {
    SensorScales {
        accel_mps2_per_count: ACCEL_MPS2_PER_COUNT as f32,
        gyro_rads_per_count: GYRO_RADS_PER_COUNT as f32,
        mag_ut_per_count: MAG_UT_PER_COUNT as f32,
        temp_c_per_count: (1.0 / TEMP_COUNTS_PER_C) as f32,
        temp_offset_c: TEMP_ZERO_C as f32,
        accel_range_mps2: (4.0 * STANDARD_GRAVITY_MPS2) as f32,
        gyro_range_rads: 500.0_f64.to_radians() as f32,
        mag_range_ut: 400.0,
        sample_rate_hz,
    }
}

/// Convert a row-major array to a matrix.
pub fn matrix_from_rows(rows: &[[f64; 3]; 3]) -> Matrix3<f64> {
    Matrix3::from_fn(|r, c| rows[r][c])
}

/// Convert a matrix to a row-major array.
pub fn rows_from_matrix(m: &Matrix3<f64>) -> [[f64; 3]; 3] {
    [0, 1, 2].map(|r| [0, 1, 2].map(|c| m[(r, c)]))
}

/// Ranges from which a board's true errors are drawn (uniformly, per axis).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SensorErrorRanges {
    /// Largest bias (hard iron for the magnetometer), sensor units.
    pub bias_max: f64,
    /// Largest relative scale error.
    pub scale_max: f64,
    /// Largest cross-axis coupling (off-diagonal of `A⁻¹`).
    pub cross_axis_max: f64,
    /// Largest soft-iron distortion (symmetric, magnetometer); 0 for other sensors.
    pub soft_iron_max: f64,
    /// White-noise density, sensor units per √Hz.
    pub noise_density: f64,
}

/// Error ranges of all three sensors.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ImuErrorRanges {
    /// Accelerometer.
    pub accel: SensorErrorRanges,
    /// Gyroscope.
    pub gyro: SensorErrorRanges,
    /// Magnetometer.
    pub mag: SensorErrorRanges,
}

impl Default for ImuErrorRanges {
    /// A consumer MEMS IMU before calibration: accel bias ±0.3 m/s², scale ±3 %, cross-axis
    /// ±1 %, 200 µg/√Hz; gyro bias ±0.05 rad/s (±3 °/s), 0.01 °/s/√Hz; magnetometer hard iron
    /// ±50 µT (board steel and currents), scale ±5 %, soft iron ±5 %, 0.03 µT/√Hz (≈ 0.3 µT rms at
    /// 100 Hz, the LSM9DS1's 3.2 mgauss rms at ±4 gauss).
    fn default() -> Self {
        Self {
            accel: SensorErrorRanges {
                bias_max: 0.3,
                scale_max: 0.03,
                cross_axis_max: 0.01,
                soft_iron_max: 0.0,
                noise_density: 200e-6 * STANDARD_GRAVITY_MPS2,
            },
            gyro: SensorErrorRanges {
                bias_max: 0.05,
                scale_max: 0.03,
                cross_axis_max: 0.01,
                soft_iron_max: 0.0,
                noise_density: 0.01_f64.to_radians(),
            },
            mag: SensorErrorRanges {
                bias_max: 50.0,
                scale_max: 0.05,
                cross_axis_max: 0.02,
                soft_iron_max: 0.05,
                noise_density: 0.03,
            },
        }
    }
}

impl ImuErrorRanges {
    /// Ranges of one sensor.
    pub fn sensor(&self, sensor: SensorKind) -> &SensorErrorRanges {
        match sensor {
            SensorKind::Accel => &self.accel,
            SensorKind::Gyro => &self.gyro,
            SensorKind::Mag => &self.mag,
        }
    }

    /// Ranges with every error and the noise set to zero: an ideal sensor (still quantised).
    pub fn ideal() -> Self {
        let zero = SensorErrorRanges {
            bias_max: 0.0,
            scale_max: 0.0,
            cross_axis_max: 0.0,
            soft_iron_max: 0.0,
            noise_density: 0.0,
        };
        Self {
            accel: zero,
            gyro: zero,
            mag: zero,
        }
    }

    fn validate(&self) -> Result<(), SimError> {
        for sensor in SensorKind::ALL {
            let r = self.sensor(sensor);
            require_non_negative("bias range", r.bias_max)?;
            require_non_negative("noise density", r.noise_density)?;
            // Keeps A⁻¹ diagonally dominant, hence invertible and well conditioned.
            let distortion = r.scale_max + 2.0 * r.cross_axis_max + 3.0 * r.soft_iron_max;
            for (name, v) in [
                ("scale error range", r.scale_max),
                ("cross-axis range", r.cross_axis_max),
                ("soft-iron range", r.soft_iron_max),
            ] {
                require_non_negative(name, v)?;
            }
            if distortion >= 0.5 {
                return Err(SimError::InvalidSetting {
                    name: "scale + 2·cross-axis + 3·soft-iron range",
                    value: distortion,
                    requirement: "below 0.5 so that the sensor matrix stays invertible",
                });
            }
        }
        Ok(())
    }
}

/// The true parameters of one sensor.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SensorTruth {
    /// The correct calibration matrix `A` (row-major): `y = A·(x − b)`.
    pub a_true: [[f64; 3]; 3],
    /// `A⁻¹` (row-major), the matrix the sensor applies: `x = A⁻¹·y + b`.
    pub a_true_inverse: [[f64; 3]; 3],
    /// Bias `b` at 25 °C and t = 0, nominal units.
    pub b_true: [f64; 3],
    /// White-noise density, units/√Hz.
    pub noise_density: f64,
    /// White-noise standard deviation per sample, `N·√f_s`, units.
    pub noise_sigma: f64,
    /// Nominal units per count.
    pub units_per_count: f64,
    /// Effects switched on for this sensor.
    pub effects: SensorEffects,
}

impl SensorTruth {
    /// `A` as a matrix.
    pub fn a(&self) -> Matrix3<f64> {
        matrix_from_rows(&self.a_true)
    }

    /// `A⁻¹` as a matrix.
    pub fn a_inverse(&self) -> Matrix3<f64> {
        matrix_from_rows(&self.a_true_inverse)
    }

    /// `b` as a vector.
    pub fn b(&self) -> Vector3<f64> {
        Vector3::from(self.b_true)
    }

    /// The base calibration applied to a reading: `A·(x − b)`.
    pub fn calibrate(&self, x: &Vector3<f64>) -> Vector3<f64> {
        self.a() * (x - self.b())
    }
}

/// True parameters of the whole IMU.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ImuTruth {
    /// Accelerometer (m/s²).
    pub accel: SensorTruth,
    /// Gyroscope (rad/s).
    pub gyro: SensorTruth,
    /// Magnetometer (µT).
    pub mag: SensorTruth,
    /// Gyro g-sensitivity `K`, if switched on.
    pub gyro_g_sensitivity: Option<GSensitivity>,
    /// Reference temperature of every temperature effect, °C.
    pub reference_temp_c: f64,
    /// Sample rate the noise σ refers to, Hz.
    pub sample_rate_hz: f64,
}

impl ImuTruth {
    /// Parameters of one sensor.
    pub fn sensor(&self, sensor: SensorKind) -> &SensorTruth {
        match sensor {
            SensorKind::Accel => &self.accel,
            SensorKind::Gyro => &self.gyro,
            SensorKind::Mag => &self.mag,
        }
    }

    /// Draw a board from `ranges` with `seed`, and the requested effects; `duration_s` is the
    /// recording length (it places bias steps).
    pub fn draw(
        seed: u64,
        ranges: &ImuErrorRanges,
        effects: &[EffectRequest],
        sample_rate_hz: f64,
        duration_s: f64,
    ) -> Result<Self, SimError> {
        require_positive("sample rate (Hz)", sample_rate_hz)?;
        require_non_negative("recording duration (s)", duration_s)?;
        ranges.validate()?;
        let drawn = draw_effects(effects, seed, duration_s)?;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(0);
        let mut uniform = |max: f64| {
            let u: f64 = rng.gen_range(-1.0..=1.0);
            u * max
        };
        let sensors = SensorKind::ALL.map(|sensor| {
            let r = ranges.sensor(sensor);
            let mut sensing: Matrix3<f64> = Matrix3::identity();
            for i in 0..3 {
                for j in 0..3 {
                    sensing[(i, j)] += if i == j {
                        uniform(r.scale_max)
                    } else {
                        uniform(r.cross_axis_max)
                    };
                }
            }
            let mut soft_iron: Matrix3<f64> = Matrix3::identity();
            for i in 0..3 {
                for j in i..3 {
                    let e = if i == j {
                        uniform(r.soft_iron_max)
                    } else {
                        uniform(0.5 * r.soft_iron_max)
                    };
                    soft_iron[(i, j)] += e;
                    if i != j {
                        soft_iron[(j, i)] += e;
                    }
                }
            }
            let inverse = soft_iron * sensing;
            let bias = [
                uniform(r.bias_max),
                uniform(r.bias_max),
                uniform(r.bias_max),
            ];
            (inverse, bias)
        });
        let mut truths = Vec::with_capacity(3);
        for (sensor, (inverse, bias)) in SensorKind::ALL.into_iter().zip(sensors.iter()) {
            let a = inverse.try_inverse().ok_or(SimError::InvalidSetting {
                name: "sensor matrix determinant",
                value: inverse.determinant(),
                requirement: "non-zero; reduce the scale, cross-axis or soft-iron ranges",
            })?;
            let density = ranges.sensor(sensor).noise_density;
            truths.push(SensorTruth {
                a_true: rows_from_matrix(&a),
                a_true_inverse: rows_from_matrix(inverse),
                b_true: *bias,
                noise_density: density,
                noise_sigma: density * sample_rate_hz.sqrt(),
                units_per_count: sensor.units_per_count(),
                effects: *drawn.sensor(sensor),
            });
        }
        Ok(Self {
            accel: truths[0],
            gyro: truths[1],
            mag: truths[2],
            gyro_g_sensitivity: drawn.g_sensitivity,
            reference_temp_c: TEMP_ZERO_C,
            sample_rate_hz,
        })
    }
}

/// One sensor's output for one sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorReading {
    /// The analogue reading before quantisation and saturation (noise included), units.
    pub analog: Vector3<f64>,
    /// Output register counts.
    pub counts: [i16; 3],
    /// Whether any axis hit the register limit.
    pub saturated: bool,
}

impl SensorReading {
    /// Counts times sensitivity: what an uncalibrated board reports in nominal units.
    pub fn nominal(&self, units_per_count: f64) -> Vector3<f64> {
        Vector3::from(self.counts.map(|c| f64::from(c) * units_per_count))
    }
}

/// One sample of every sensor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuSample {
    /// Time, s.
    pub t: f64,
    /// Accelerometer.
    pub accel: SensorReading,
    /// Gyroscope.
    pub gyro: SensorReading,
    /// Magnetometer.
    pub mag: SensorReading,
    /// All counts, as the chip would deliver them.
    pub raw: RawSample,
}

impl ImuSample {
    /// Reading of one sensor.
    pub fn sensor(&self, sensor: SensorKind) -> &SensorReading {
        match sensor {
            SensorKind::Accel => &self.accel,
            SensorKind::Gyro => &self.gyro,
            SensorKind::Mag => &self.mag,
        }
    }

    /// Die temperature as read by the chip, °C.
    pub fn temp_c(&self) -> f64 {
        TEMP_ZERO_C + f64::from(self.raw.temp) / TEMP_COUNTS_PER_C
    }
}

/// Quantise to a 16-bit output register; `as` saturates (and maps NaN to 0) without panicking.
fn quantise(value: f64, units_per_count: f64) -> (i16, bool) {
    let counts = (value / units_per_count).round();
    let saturated = !(f64::from(i16::MIN)..=f64::from(i16::MAX)).contains(&counts);
    (counts as i16, saturated)
}

/// The sensor physics of one board: turns world states into samples, one after another at the
/// sample rate (the random walk and hysteresis have memory).
#[derive(Debug, Clone)]
pub struct ImuPhysics {
    truth: ImuTruth,
    dt_s: f64,
    noise: ChaCha8Rng,
    walk: [Vector3<f64>; 3],
    /// Play-operator state of thermal hysteresis, per sensor.
    play_temp_c: [Option<f64>; 3],
    /// Temperature of the previous sample, for `dT/dt`.
    previous_temp_c: Option<f64>,
}

impl ImuPhysics {
    /// Physics for `truth`, with noise drawn from stream 1 of `seed`.
    pub fn new(truth: ImuTruth, seed: u64) -> Result<Self, SimError> {
        let rate = require_positive("sample rate (Hz)", truth.sample_rate_hz)?;
        let mut noise = ChaCha8Rng::seed_from_u64(seed);
        noise.set_stream(1);
        Ok(Self {
            truth,
            dt_s: 1.0 / rate,
            noise,
            walk: [Vector3::zeros(); 3],
            play_temp_c: [None; 3],
            previous_temp_c: None,
        })
    }

    /// The true parameters.
    pub fn truth(&self) -> &ImuTruth {
        &self.truth
    }

    /// Produce the next sample from the world's state. Call once per sample period, in order.
    pub fn sample(&mut self, state: &WorldState) -> ImuSample {
        // Always draw the same number of normals so that switching effects on or off leaves the
        // noise sequence unchanged.
        let mut normals = [0.0_f64; 18];
        for n in &mut normals {
            *n = self.noise.sample(StandardNormal);
        }
        let delta_t = state.temp_c - self.truth.reference_temp_c;
        let temp_rate = self
            .previous_temp_c
            .map_or(0.0, |previous| (state.temp_c - previous) / self.dt_s);
        self.previous_temp_c = Some(state.temp_c);
        let readings = SensorKind::ALL.map(|sensor| {
            let truth = self.truth.sensor(sensor);
            let effects = &truth.effects;
            let k = sensor.index();
            let mut y = match sensor {
                SensorKind::Accel => state.specific_force_body,
                SensorKind::Gyro => state.omega_body,
                SensorKind::Mag => state.field_body,
            };
            if let (SensorKind::Gyro, Some(g)) = (sensor, &self.truth.gyro_g_sensitivity) {
                y += matrix_from_rows(&g.matrix) * state.specific_force_body;
            }
            let extra = &effects.out_of_family;
            y += extra.external_field(state.t);
            let u = truth.a_inverse() * y;
            let u = effects.apply_nonlinearity(u.component_mul(&effects.scale_multiplier(delta_t)));
            let u = extra.apply_cross_axis(u);
            let mut bias = truth.b()
                + effects.memoryless_bias(delta_t, state.t)
                + extra.bias(state.t, temp_rate)
                + self.walk[k];
            if let Some(h) = &effects.thermal_hysteresis {
                if h.play_c > 0.0 {
                    let state_c = &mut self.play_temp_c[k];
                    let play = state_c
                        .unwrap_or(state.temp_c)
                        .clamp(state.temp_c - h.play_c, state.temp_c + h.play_c);
                    *state_c = Some(play);
                    bias += Vector3::from(h.amplitude) * ((state.temp_c - play) / h.play_c);
                }
            }
            if let Some(rw) = &effects.bias_random_walk {
                let step =
                    Vector3::new(normals[9 + 3 * k], normals[10 + 3 * k], normals[11 + 3 * k]);
                self.walk[k] += step * (rw.density * self.dt_s.sqrt());
            }
            let noise = Vector3::new(normals[3 * k], normals[3 * k + 1], normals[3 * k + 2]);
            let analog = u + bias + noise * truth.noise_sigma;
            let mut saturated = false;
            let counts = [0, 1, 2].map(|i| {
                let (c, s) = quantise(analog[i], truth.units_per_count);
                saturated |= s;
                c
            });
            SensorReading {
                analog,
                counts,
                saturated,
            }
        });
        let (temp_counts, _) = quantise(state.temp_c - TEMP_ZERO_C, 1.0 / TEMP_COUNTS_PER_C);
        let [accel, gyro, mag] = readings;
        ImuSample {
            t: state.t,
            accel,
            gyro,
            mag,
            raw: RawSample {
                accel: accel.counts,
                gyro: gyro.counts,
                mag: mag.counts,
                temp: temp_counts,
            },
        }
    }
}
