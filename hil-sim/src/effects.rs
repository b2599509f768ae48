//! Sensor effects the host is not told about, and their realistic default sizes.
//!
//! Each effect is switched on per sensor with a size factor (1 = typical consumer MEMS part);
//! its per-axis coefficients are then drawn with magnitude in [0.5, 1]·size·typical and a random
//! sign, from a random stream of its own so that switching one effect on changes nothing else.
//! Where they enter the reading model is documented in [`crate::physics`].
//!
//! Typical sizes, from consumer 9-axis datasheets (ST LSM9DS1, InvenSense MPU-9250) and reasoning:
//! - `bias_temperature`: accel 0.5 mg/°C (LSM9DS1 zero-g change vs temperature), gyro 0.01 °/s/°C,
//!   mag 0.05 µT/°C; quadratic and cubic terms a few % of the linear one per °C.
//! - `scale_temperature`: accel 0.01 %/°C (LSM9DS1), gyro 0.02 %/°C, mag 0.03 %/°C.
//! - `bias_drift`: linear in time, e.g. gyro 2·10⁻⁶ rad/s per s (0.07 °/s over ten minutes).
//! - `scale_nonlinearity`: 0.1 % of a reference reading (g, 1 rad/s, 50 µT) from each of the
//!   quadratic and cubic terms at that reading.
//! - `g_sensitivity`: gyro only, 0.1 °/s per g per matrix entry (typical MEMS gyro).
//! - `bias_step`: accel 0.05 m/s², gyro 0.005 rad/s, mag 2 µT at a random time in the middle
//!   of the recording (a knock, a solder-joint stress release, a magnetised screw).
//! - `thermal_hysteresis`: package-stress hysteresis, a play operator of width 2 °C on
//!   temperature; the bias is ±amplitude depending on whether temperature last rose or fell.
//! - `bias_random_walk`: rate random walk, gyro 2·10⁻⁵ rad/s/√s, accel 5·10⁻⁵ m/s²/√s, mag
//!   5·10⁻³ µT/√s.
//!
//! `bias_step` and `thermal_hysteresis` lie outside every effect family a fitted model can
//! express (temperature, time, specific force, reading magnitude), so they test that the analysis
//! reports an unexplained residual instead of guessing; so do the effects of
//! [`crate::out_of_family`] (a bias following `dT/dt`, cross-axis non-linearity, a bumped hold,
//! a steel object near one hold).

use std::str::FromStr;

use nalgebra::Vector3;
use rand::Rng;
use rand_chacha::rand_core::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::error::SimError;
use crate::out_of_family::{
    CrossAxisNonlinearity, HoldEvent, OutOfFamily, TemperatureRateBias, THERMAL_LAG_S,
    TYPICAL_STEEL_FIELD_UT,
};
use crate::sensor_kind::SensorKind;

/// The effects that can be switched on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EffectKind {
    /// Bias polynomial (cubic) in the temperature difference from the reference.
    BiasTemperature,
    /// Relative scale linear in the temperature difference.
    ScaleTemperature,
    /// Bias linear in time.
    BiasDrift,
    /// Per-axis quadratic and cubic terms of the reading.
    ScaleNonlinearity,
    /// Gyro bias linear in specific force (3×3).
    GSensitivity,
    /// A sudden bias step at one time.
    BiasStep,
    /// Bias that depends on whether temperature last rose or fell.
    ThermalHysteresis,
    /// Bias random walk (rate random walk).
    BiasRandomWalk,
    /// Bias proportional to the rate of temperature change (see [`crate::out_of_family`]).
    TemperatureRateBias,
    /// Each axis picks up the product of the other two (see [`crate::out_of_family`]).
    CrossAxisNonlinearity,
    /// A bias offset during one hold (see [`crate::out_of_family`]).
    BumpedHold,
    /// A steel object's field during one hold, magnetometer only (see [`crate::out_of_family`]).
    SteelNearHold,
}

impl EffectKind {
    /// Every effect, in a fixed order.
    pub const ALL: [EffectKind; 12] = [
        EffectKind::BiasTemperature,
        EffectKind::ScaleTemperature,
        EffectKind::BiasDrift,
        EffectKind::ScaleNonlinearity,
        EffectKind::GSensitivity,
        EffectKind::BiasStep,
        EffectKind::ThermalHysteresis,
        EffectKind::BiasRandomWalk,
        EffectKind::TemperatureRateBias,
        EffectKind::CrossAxisNonlinearity,
        EffectKind::BumpedHold,
        EffectKind::SteelNearHold,
    ];

    /// Name as used on the command line and in JSON.
    pub fn name(self) -> &'static str {
        match self {
            EffectKind::BiasTemperature => "bias_temperature",
            EffectKind::ScaleTemperature => "scale_temperature",
            EffectKind::BiasDrift => "bias_drift",
            EffectKind::ScaleNonlinearity => "scale_nonlinearity",
            EffectKind::GSensitivity => "g_sensitivity",
            EffectKind::BiasStep => "bias_step",
            EffectKind::ThermalHysteresis => "thermal_hysteresis",
            EffectKind::BiasRandomWalk => "bias_random_walk",
            EffectKind::TemperatureRateBias => "temperature_rate_bias",
            EffectKind::CrossAxisNonlinearity => "cross_axis_nonlinearity",
            EffectKind::BumpedHold => "bumped_hold",
            EffectKind::SteelNearHold => "steel_near_hold",
        }
    }

    /// The only sensor the effect exists for (g-sensitivity: gyro; a steel object's field:
    /// magnetometer), or `None` when it exists for every sensor.
    pub fn only_sensor(self) -> Option<SensorKind> {
        match self {
            EffectKind::GSensitivity => Some(SensorKind::Gyro),
            EffectKind::SteelNearHold => Some(SensorKind::Mag),
            _ => None,
        }
    }

    /// Whether the effect exists for `sensor`.
    pub fn applies_to(self, sensor: SensorKind) -> bool {
        self.only_sensor().is_none_or(|only| only == sensor)
    }

    fn stream_index(self) -> u64 {
        EffectKind::ALL.iter().position(|&k| k == self).unwrap_or(0) as u64
    }
}

/// A request to switch an effect on: `[sensor.]name[=size]` on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EffectRequest {
    /// Which effect.
    pub kind: EffectKind,
    /// Only this sensor, or every sensor the effect applies to when `None`.
    #[serde(default, with = "crate::sensor_kind::optional_name")]
    pub sensor: Option<SensorKind>,
    /// Size relative to the typical part (1.0); 0 switches it off.
    pub size: f64,
}

impl FromStr for EffectRequest {
    type Err = SimError;

    fn from_str(text: &str) -> Result<Self, SimError> {
        let invalid = |reason: String| SimError::InvalidEffect {
            text: text.to_string(),
            reason,
        };
        let (target, size) = match text.split_once('=') {
            Some((target, size)) => {
                let size: f64 = size.trim().parse().map_err(|_| {
                    invalid(format!("size `{size}` is not a number; write e.g. `=2.5`"))
                })?;
                if !(size.is_finite() && size >= 0.0) {
                    return Err(invalid(format!(
                        "size {size} must be a finite number of zero or more"
                    )));
                }
                (target.trim(), size)
            }
            None => (text.trim(), 1.0),
        };
        let (sensor, name) = match target.split_once('.') {
            Some((sensor, name)) => {
                let sensor = SensorKind::from_name(sensor).ok_or_else(|| {
                    invalid(format!(
                        "sensor `{sensor}` is unknown; use accel, gyro or mag"
                    ))
                })?;
                (Some(sensor), name)
            }
            None => (None, target),
        };
        let kind = EffectKind::ALL
            .iter()
            .copied()
            .find(|k| k.name() == name)
            .ok_or_else(|| {
                let names: Vec<&str> = EffectKind::ALL.iter().map(|k| k.name()).collect();
                invalid(format!(
                    "`{name}` is not an effect; use one of {}",
                    names.join(", ")
                ))
            })?;
        if let Some(sensor) = sensor {
            if let Some(only) = kind.only_sensor().filter(|&only| only != sensor) {
                return Err(invalid(format!(
                    "{} exists only for the {}; write `{}.{}`",
                    kind.name(),
                    only.name(),
                    only.name(),
                    kind.name()
                )));
            }
        }
        Ok(EffectRequest { kind, sensor, size })
    }
}

/// Bias polynomial in `ΔT = T − T_ref`: `b_i += c1·ΔT + c2·ΔT² + c3·ΔT³`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BiasTemperature {
    /// Per axis `[c1, c2, c3]`, sensor units per °C, °C², °C³.
    pub per_axis: [[f64; 3]; 3],
}

/// Relative scale change per °C: the ideal reading is multiplied by `1 + k_i·ΔT` per axis.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ScaleTemperature {
    /// `k_i`, 1/°C.
    pub per_degree: [f64; 3],
}

/// Bias linear in time from t = 0: `b_i += r_i·t`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BiasDrift {
    /// `r_i`, sensor units per second.
    pub per_second: [f64; 3],
}

/// Per-axis non-linearity of the reading: `u_i ← u_i + q_i·u_i² + c_i·u_i³`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ScaleNonlinearity {
    /// `q_i`, 1/(sensor unit).
    pub quadratic: [f64; 3],
    /// `c_i`, 1/(sensor unit)².
    pub cubic: [f64; 3],
}

/// Gyro g-sensitivity in calibrated units: the gyro senses `ω + K·f`, so the correction is
/// `y = A·(x − b) − K·f`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GSensitivity {
    /// `K`, row-major, rad/s per m/s².
    pub matrix: [[f64; 3]; 3],
}

/// A bias step: `b_i += s_i` from `time_s` on.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BiasStep {
    /// When the step happens, s.
    pub time_s: f64,
    /// `s_i`, sensor units.
    pub step: [f64; 3],
}

/// Thermal hysteresis: a play operator `T_p = clamp(T_p, T − w, T + w)` (starting at the first
/// temperature) and `b_i += h_i·(T − T_p)/w`, i.e. `±h_i` once temperature has moved by `2w` in
/// one direction.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ThermalHysteresis {
    /// Play width `w`, °C.
    pub play_c: f64,
    /// `h_i`, sensor units.
    pub amplitude: [f64; 3],
}

/// Bias random walk: each sample adds `N(0, (density·√Δt)²)` per axis to the bias.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BiasRandomWalk {
    /// Rate random walk density, sensor units per √s.
    pub density: f64,
}

/// The effects switched on for one sensor (all off by default).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct SensorEffects {
    /// See [`BiasTemperature`].
    pub bias_temperature: Option<BiasTemperature>,
    /// See [`ScaleTemperature`].
    pub scale_temperature: Option<ScaleTemperature>,
    /// See [`BiasDrift`].
    pub bias_drift: Option<BiasDrift>,
    /// See [`ScaleNonlinearity`].
    pub scale_nonlinearity: Option<ScaleNonlinearity>,
    /// See [`BiasStep`].
    pub bias_step: Option<BiasStep>,
    /// See [`ThermalHysteresis`].
    pub thermal_hysteresis: Option<ThermalHysteresis>,
    /// See [`BiasRandomWalk`].
    pub bias_random_walk: Option<BiasRandomWalk>,
    /// Effects no calibration model has a term for (see [`crate::out_of_family`]).
    #[serde(default)]
    pub out_of_family: OutOfFamily,
}

impl SensorEffects {
    /// Per-axis scale multiplier `1 + k·ΔT` (ones when the effect is off).
    pub fn scale_multiplier(&self, delta_t_c: f64) -> Vector3<f64> {
        match &self.scale_temperature {
            Some(s) => Vector3::from(s.per_degree).map(|k| 1.0 + k * delta_t_c),
            None => Vector3::repeat(1.0),
        }
    }

    /// Apply the non-linearity to an ideal reading `u`.
    pub fn apply_nonlinearity(&self, u: Vector3<f64>) -> Vector3<f64> {
        match &self.scale_nonlinearity {
            Some(n) => Vector3::from_fn(|i, _| {
                let v = u[i];
                v + n.quadratic[i] * v * v + n.cubic[i] * v * v * v
            }),
            None => u,
        }
    }

    /// Bias added by the memoryless effects (temperature polynomial, drift, step) at `t` and
    /// temperature difference `delta_t_c`.
    pub fn memoryless_bias(&self, delta_t_c: f64, t: f64) -> Vector3<f64> {
        let mut bias = Vector3::zeros();
        if let Some(bt) = &self.bias_temperature {
            bias += Vector3::from_fn(|i, _| {
                let [c1, c2, c3] = bt.per_axis[i];
                delta_t_c * (c1 + delta_t_c * (c2 + delta_t_c * c3))
            });
        }
        if let Some(d) = &self.bias_drift {
            bias += Vector3::from(d.per_second) * t;
        }
        if let Some(s) = &self.bias_step {
            if t >= s.time_s {
                bias += Vector3::from(s.step);
            }
        }
        bias
    }
}

/// Typical size of each effect for each sensor (see the module comment).
struct Typical {
    /// Linear bias temperature coefficient, units/°C.
    bias_tempco: f64,
    scale_tempco: f64,
    drift_per_s: f64,
    /// Reading at which non-linearity terms are 0.1 % of it.
    nonlinearity_reference: f64,
    step: f64,
    hysteresis: f64,
    random_walk: f64,
}

fn typical(sensor: SensorKind) -> Typical {
    match sensor {
        SensorKind::Accel => Typical {
            bias_tempco: 0.5e-3 * crate::world::STANDARD_GRAVITY_MPS2,
            scale_tempco: 1e-4,
            drift_per_s: 2e-5,
            nonlinearity_reference: crate::world::STANDARD_GRAVITY_MPS2,
            step: 0.05,
            hysteresis: 0.01,
            random_walk: 5e-5,
        },
        SensorKind::Gyro => Typical {
            bias_tempco: 0.01_f64.to_radians(),
            scale_tempco: 2e-4,
            drift_per_s: 2e-6,
            nonlinearity_reference: 1.0,
            step: 0.005,
            hysteresis: 5e-4,
            random_walk: 2e-5,
        },
        SensorKind::Mag => Typical {
            bias_tempco: 0.05,
            scale_tempco: 3e-4,
            drift_per_s: 1e-3,
            nonlinearity_reference: 50.0,
            step: 2.0,
            hysteresis: 0.3,
            random_walk: 5e-3,
        },
    }
}

/// Typical gyro g-sensitivity per matrix entry: 0.1 °/s per g, in rad/s per m/s².
pub const TYPICAL_G_SENSITIVITY: f64 =
    0.1 * std::f64::consts::PI / 180.0 / crate::world::STANDARD_GRAVITY_MPS2;

/// Play width of thermal hysteresis, °C.
pub const HYSTERESIS_PLAY_C: f64 = 2.0;

/// Magnitude in [0.5, 1]·scale with a random sign.
fn signed(rng: &mut ChaCha8Rng, scale: f64) -> f64 {
    let magnitude = rng.gen_range(0.5..=1.0) * scale;
    if rng.gen_bool(0.5) {
        magnitude
    } else {
        -magnitude
    }
}

fn signed3(rng: &mut ChaCha8Rng, scale: f64) -> [f64; 3] {
    [signed(rng, scale), signed(rng, scale), signed(rng, scale)]
}

/// Effects drawn for the three sensors plus the gyro's g-sensitivity.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DrawnEffects {
    /// Accelerometer effects.
    pub accel: SensorEffects,
    /// Gyroscope effects.
    pub gyro: SensorEffects,
    /// Magnetometer effects.
    pub mag: SensorEffects,
    /// Gyro g-sensitivity.
    pub g_sensitivity: Option<GSensitivity>,
}

impl DrawnEffects {
    /// Effects of one sensor.
    pub fn sensor(&self, sensor: SensorKind) -> &SensorEffects {
        match sensor {
            SensorKind::Accel => &self.accel,
            SensorKind::Gyro => &self.gyro,
            SensorKind::Mag => &self.mag,
        }
    }

    fn sensor_mut(&mut self, sensor: SensorKind) -> &mut SensorEffects {
        match sensor {
            SensorKind::Accel => &mut self.accel,
            SensorKind::Gyro => &mut self.gyro,
            SensorKind::Mag => &mut self.mag,
        }
    }
}

/// Draw the parameters of every requested effect. Later requests for the same effect and sensor
/// replace earlier ones; `duration_s` places bias steps in the middle 40 % of the recording.
pub fn draw_effects(
    requests: &[EffectRequest],
    seed: u64,
    duration_s: f64,
) -> Result<DrawnEffects, SimError> {
    let mut drawn = DrawnEffects::default();
    for request in requests {
        if !(request.size.is_finite() && request.size >= 0.0) {
            return Err(SimError::InvalidEffect {
                text: request.kind.name().to_string(),
                reason: format!(
                    "size {} must be a finite number of zero or more",
                    request.size
                ),
            });
        }
        for sensor in SensorKind::ALL {
            if request.sensor.is_some_and(|s| s != sensor) || !request.kind.applies_to(sensor) {
                continue;
            }
            // One stream per (effect, sensor): enabling one effect never moves another's draw.
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            rng.set_stream(16 + 4 * request.kind.stream_index() + sensor.index() as u64);
            let size = request.size;
            let typ = typical(sensor);
            let on = size > 0.0;
            let effects = drawn.sensor_mut(sensor);
            match request.kind {
                EffectKind::BiasTemperature => {
                    effects.bias_temperature = on.then(|| {
                        let mut per_axis = [[0.0; 3]; 3];
                        for axis in &mut per_axis {
                            let c1 = signed(&mut rng, size * typ.bias_tempco);
                            *axis = [
                                c1,
                                signed(&mut rng, 0.03 * size * typ.bias_tempco),
                                signed(&mut rng, 0.001 * size * typ.bias_tempco),
                            ];
                        }
                        BiasTemperature { per_axis }
                    });
                }
                EffectKind::ScaleTemperature => {
                    effects.scale_temperature = on.then(|| ScaleTemperature {
                        per_degree: signed3(&mut rng, size * typ.scale_tempco),
                    });
                }
                EffectKind::BiasDrift => {
                    effects.bias_drift = on.then(|| BiasDrift {
                        per_second: signed3(&mut rng, size * typ.drift_per_s),
                    });
                }
                EffectKind::ScaleNonlinearity => {
                    let r = typ.nonlinearity_reference;
                    effects.scale_nonlinearity = on.then(|| ScaleNonlinearity {
                        quadratic: signed3(&mut rng, size * 1e-3 / r),
                        cubic: signed3(&mut rng, size * 1e-3 / (r * r)),
                    });
                }
                EffectKind::GSensitivity => {
                    drawn.g_sensitivity = on.then(|| {
                        let mut matrix = [[0.0; 3]; 3];
                        for row in &mut matrix {
                            *row = signed3(&mut rng, size * TYPICAL_G_SENSITIVITY);
                        }
                        GSensitivity { matrix }
                    });
                }
                EffectKind::BiasStep => {
                    effects.bias_step = on.then(|| BiasStep {
                        time_s: duration_s * rng.gen_range(0.3..=0.7),
                        step: signed3(&mut rng, size * typ.step),
                    });
                }
                EffectKind::ThermalHysteresis => {
                    effects.thermal_hysteresis = on.then(|| ThermalHysteresis {
                        play_c: HYSTERESIS_PLAY_C,
                        amplitude: signed3(&mut rng, size * typ.hysteresis),
                    });
                }
                EffectKind::BiasRandomWalk => {
                    effects.bias_random_walk = on.then_some(BiasRandomWalk {
                        density: size * typ.random_walk,
                    });
                }
                EffectKind::TemperatureRateBias => {
                    effects.out_of_family.temperature_rate_bias = on.then(|| TemperatureRateBias {
                        per_degree_per_second: signed3(
                            &mut rng,
                            size * typ.bias_tempco * THERMAL_LAG_S,
                        ),
                    });
                }
                EffectKind::CrossAxisNonlinearity => {
                    let r = typ.nonlinearity_reference;
                    effects.out_of_family.cross_axis_nonlinearity =
                        on.then(|| CrossAxisNonlinearity {
                            product: signed3(&mut rng, size * 1e-3 / r),
                        });
                }
                EffectKind::BumpedHold => {
                    effects.out_of_family.bumped_hold = on.then(|| {
                        let time_s = duration_s * rng.gen_range(0.3..=0.7);
                        HoldEvent {
                            start_s: time_s,
                            end_s: time_s,
                            value: signed3(&mut rng, size * typ.step),
                        }
                    });
                }
                EffectKind::SteelNearHold => {
                    effects.out_of_family.steel_near_hold = on.then(|| {
                        let time_s = duration_s * rng.gen_range(0.3..=0.7);
                        HoldEvent {
                            start_s: time_s,
                            end_s: time_s,
                            value: signed3(&mut rng, size * TYPICAL_STEEL_FIELD_UT),
                        }
                    });
                }
            }
        }
    }
    Ok(drawn)
}
