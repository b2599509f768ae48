//! The simulated world: the board's orientation over time, gravity, the Earth's field and temperature.
//!
//! Frames: world x = magnetic north (horizontal), y = west, z = up; `q_body_to_world` rotates body
//! vectors into the world frame. Turns are minimum-jerk slerps, `s(τ) = 10τ³ − 15τ⁴ + 6τ⁵`
//! (Flash & Hogan 1985), so `q(t) = q₀ ⊗ Exp(s·φ)` and the body rate is `ω = ṡ·φ`. Holds may carry a
//! small hand tremor `q = q_hold ⊗ Exp(δ(t))` with `ω = J_r(δ)·δ̇` (right Jacobian of SO(3)). Both
//! satisfy `q̇ = ½ q ⊗ (0, ω_body)` exactly, so integrating the rate reproduces the orientation.
//! The board turns about its sensor point and does not translate, so the specific force is
//! `f_body = q⁻¹ · (0, 0, g)`.

use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::error::{require_finite, require_non_negative, require_positive, SimError};

/// Standard gravity, m/s² (CGPM 1901), the default magnitude of gravity.
pub const STANDARD_GRAVITY_MPS2: f64 = 9.80665;

/// One sinusoidal component of hand tremor: a small rotation about a body axis.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TremorComponent {
    /// Unit rotation axis in the body frame.
    pub axis: [f64; 3],
    /// Peak rotation angle, rad.
    pub amplitude_rad: f64,
    /// Frequency, Hz.
    pub frequency_hz: f64,
    /// Phase at the start of the hold, rad.
    pub phase_rad: f64,
}

/// Hand tremor during a hold: a sum of sinusoidal small rotations, faded in and out at the
/// hold's edges so that orientation and rate stay continuous with the neighbouring turns.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Tremor {
    /// Components added together as a rotation vector.
    pub components: Vec<TremorComponent>,
    /// Fade-in and fade-out time at each end of the hold, s.
    pub edge_ramp_s: f64,
}

impl Tremor {
    /// Rotation vector δ and its time derivative δ̇ at `tau` seconds into a hold of `duration_s`.
    fn rotation_vector_and_rate(&self, tau: f64, duration_s: f64) -> (Vector3<f64>, Vector3<f64>) {
        let ramp = self.edge_ramp_s.min(duration_s / 2.0);
        let (window, window_rate) = if ramp <= 0.0 {
            (1.0, 0.0)
        } else {
            let (w_in, dw_in) = smoothstep(tau / ramp);
            let (w_out, dw_out) = smoothstep((duration_s - tau) / ramp);
            (w_in * w_out, (dw_in * w_out - w_in * dw_out) / ramp)
        };
        let mut signal = Vector3::zeros();
        let mut signal_rate = Vector3::zeros();
        for c in &self.components {
            let axis = Vector3::from(c.axis);
            let omega = 2.0 * std::f64::consts::PI * c.frequency_hz;
            let phase = omega * tau + c.phase_rad;
            signal += axis * (c.amplitude_rad * phase.sin());
            signal_rate += axis * (c.amplitude_rad * omega * phase.cos());
        }
        (signal * window, signal_rate * window + signal * window_rate)
    }
}

/// `3x² − 2x³` clamped to [0, 1], and its derivative; zero slope at both ends.
fn smoothstep(x: f64) -> (f64, f64) {
    if x <= 0.0 {
        (0.0, 0.0)
    } else if x >= 1.0 {
        (1.0, 0.0)
    } else {
        (x * x * (3.0 - 2.0 * x), 6.0 * x * (1.0 - x))
    }
}

/// Minimum-jerk profile `s(τ)` and `ds/dτ` for τ in [0, 1].
fn minimum_jerk(tau: f64) -> (f64, f64) {
    let t = tau.clamp(0.0, 1.0);
    let t2 = t * t;
    let s = t2 * t * (10.0 - 15.0 * t + 6.0 * t2);
    let ds = 30.0 * t2 * (1.0 - 2.0 * t + t2);
    (s, ds)
}

/// Skew-symmetric cross-product matrix `[v]×`.
fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// Right Jacobian of SO(3): `R(φ)ᵀ Ṙ(φ) = [J_r(φ) φ̇]×`.
fn right_jacobian(phi: &Vector3<f64>) -> Matrix3<f64> {
    let theta = phi.norm();
    let k = skew(phi);
    if theta < 1e-4 {
        // Taylor series; the closed form loses precision for tiny angles.
        Matrix3::identity() - k * 0.5 + k * k / 6.0
    } else {
        let t2 = theta * theta;
        Matrix3::identity() - k * ((1.0 - theta.cos()) / t2)
            + k * k * ((theta - theta.sin()) / (t2 * theta))
    }
}

/// One piece of the board's motion.
#[derive(Debug, Clone, PartialEq)]
pub enum Segment {
    /// The board held still (up to tremor) in one orientation.
    Hold {
        /// Orientation, body to world.
        orientation: UnitQuaternion<f64>,
        /// Length of the hold, s.
        duration_s: f64,
        /// Optional hand tremor.
        tremor: Option<Tremor>,
    },
    /// A minimum-jerk turn along the shortest rotation from one orientation to another.
    Turn {
        /// Orientation at the start, body to world.
        from: UnitQuaternion<f64>,
        /// Orientation at the end, body to world.
        to: UnitQuaternion<f64>,
        /// Length of the turn, s.
        duration_s: f64,
    },
}

impl Segment {
    fn duration_s(&self) -> f64 {
        match self {
            Segment::Hold { duration_s, .. } | Segment::Turn { duration_s, .. } => *duration_s,
        }
    }
}

/// A static hold in a trajectory, with its label and time span.
#[derive(Debug, Clone, PartialEq)]
pub struct HoldSpan {
    /// Hold label: 0, 1, 2, … in order of appearance.
    pub index: usize,
    /// Start time, s.
    pub start_s: f64,
    /// End time, s.
    pub end_s: f64,
    /// Nominal orientation (without tremor), body to world.
    pub orientation: UnitQuaternion<f64>,
}

/// Orientation and body rate at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Motion {
    /// Orientation, body to world.
    pub q_body_to_world: UnitQuaternion<f64>,
    /// Angular rate in the body frame, rad/s.
    pub omega_body: Vector3<f64>,
}

/// A continuous sequence of holds and turns, built with [`TrajectoryBuilder`].
#[derive(Debug, Clone, PartialEq)]
pub struct Trajectory {
    segments: Vec<Segment>,
    starts_s: Vec<f64>,
    hold_indices: Vec<Option<usize>>,
    duration_s: f64,
}

impl Trajectory {
    /// Total length, s.
    pub fn duration_s(&self) -> f64 {
        self.duration_s
    }

    /// The segments in time order.
    pub fn segments(&self) -> &[Segment] {
        &self.segments
    }

    /// Every hold with its label and time span.
    pub fn holds(&self) -> Vec<HoldSpan> {
        self.segments
            .iter()
            .zip(&self.starts_s)
            .zip(&self.hold_indices)
            .filter_map(|((segment, &start_s), index)| match (segment, index) {
                (
                    Segment::Hold {
                        orientation,
                        duration_s,
                        ..
                    },
                    Some(index),
                ) => Some(HoldSpan {
                    index: *index,
                    start_s,
                    end_s: start_s + duration_s,
                    orientation: *orientation,
                }),
                _ => None,
            })
            .collect()
    }

    /// Index of the segment active at `t` (clamped to the trajectory).
    fn segment_at(&self, t: f64) -> usize {
        let after = self.starts_s.partition_point(|&start| start <= t);
        after
            .saturating_sub(1)
            .min(self.segments.len().saturating_sub(1))
    }

    /// Label of the hold active at `t`, or `None` while turning or outside the trajectory.
    pub fn hold_index_at(&self, t: f64) -> Option<usize> {
        if !(0.0..self.duration_s).contains(&t) {
            return None;
        }
        self.hold_indices.get(self.segment_at(t)).copied().flatten()
    }

    /// Orientation and body rate at `t`; before the start and after the end the board rests in
    /// its first or last orientation.
    pub fn motion_at(&self, t: f64) -> Motion {
        let i = self.segment_at(t);
        let (Some(segment), Some(&start)) = (self.segments.get(i), self.starts_s.get(i)) else {
            return Motion {
                q_body_to_world: UnitQuaternion::identity(),
                omega_body: Vector3::zeros(),
            };
        };
        let tau = (t - start).clamp(0.0, segment.duration_s());
        match segment {
            Segment::Hold {
                orientation,
                duration_s,
                tremor,
            } => match tremor {
                Some(tremor) if t >= 0.0 && t < self.duration_s => {
                    let (delta, delta_rate) = tremor.rotation_vector_and_rate(tau, *duration_s);
                    Motion {
                        q_body_to_world: orientation * UnitQuaternion::from_scaled_axis(delta),
                        omega_body: right_jacobian(&delta) * delta_rate,
                    }
                }
                _ => Motion {
                    q_body_to_world: *orientation,
                    omega_body: Vector3::zeros(),
                },
            },
            Segment::Turn {
                from,
                to,
                duration_s,
            } => {
                let rotation = (from.inverse() * to).scaled_axis();
                let (s, ds) = minimum_jerk(tau / duration_s);
                let moving = t >= 0.0 && t < self.duration_s;
                Motion {
                    q_body_to_world: from * UnitQuaternion::from_scaled_axis(rotation * s),
                    omega_body: if moving {
                        rotation * (ds / duration_s)
                    } else {
                        Vector3::zeros()
                    },
                }
            }
        }
    }
}

/// Builds a [`Trajectory`] whose segments join without jumps: each turn starts where the last
/// segment ended.
#[derive(Debug, Clone)]
pub struct TrajectoryBuilder {
    current: UnitQuaternion<f64>,
    segments: Vec<Segment>,
}

impl TrajectoryBuilder {
    /// Start in orientation `start` (body to world).
    pub fn new(start: UnitQuaternion<f64>) -> Self {
        Self {
            current: start,
            segments: Vec::new(),
        }
    }

    /// The orientation the next segment starts from.
    pub fn current(&self) -> UnitQuaternion<f64> {
        self.current
    }

    /// Hold the current orientation for `duration_s`, optionally with tremor.
    pub fn hold(mut self, duration_s: f64, tremor: Option<Tremor>) -> Result<Self, SimError> {
        require_positive("hold duration (s)", duration_s)?;
        if let Some(tremor) = &tremor {
            require_non_negative("tremor edge ramp (s)", tremor.edge_ramp_s)?;
            for c in &tremor.components {
                require_finite("tremor amplitude (rad)", c.amplitude_rad)?;
                require_non_negative("tremor frequency (Hz)", c.frequency_hz)?;
                require_finite("tremor phase (rad)", c.phase_rad)?;
                let norm = Vector3::from(c.axis).norm();
                if (norm - 1.0).abs() >= 1e-9 || norm.is_nan() {
                    return Err(SimError::InvalidSetting {
                        name: "tremor axis length",
                        value: norm,
                        requirement: "1 (a unit vector)",
                    });
                }
            }
        }
        self.segments.push(Segment::Hold {
            orientation: self.current,
            duration_s,
            tremor,
        });
        Ok(self)
    }

    /// Turn from the current orientation to `to` in `duration_s`.
    pub fn turn_to(mut self, to: UnitQuaternion<f64>, duration_s: f64) -> Result<Self, SimError> {
        require_positive("turn duration (s)", duration_s)?;
        if !to.coords.iter().all(|c| c.is_finite()) {
            return Err(SimError::InvalidSetting {
                name: "turn target orientation",
                value: f64::NAN,
                requirement: "a finite unit quaternion",
            });
        }
        self.segments.push(Segment::Turn {
            from: self.current,
            to,
            duration_s,
        });
        self.current = to;
        Ok(self)
    }

    /// Finish; fails when no segment was added.
    pub fn build(self) -> Result<Trajectory, SimError> {
        if self.segments.is_empty() {
            return Err(SimError::EmptyTrajectory);
        }
        let mut starts_s = Vec::with_capacity(self.segments.len());
        let mut hold_indices = Vec::with_capacity(self.segments.len());
        let mut t = 0.0;
        let mut holds = 0;
        for segment in &self.segments {
            starts_s.push(t);
            t += segment.duration_s();
            if matches!(segment, Segment::Hold { .. }) {
                hold_indices.push(Some(holds));
                holds += 1;
            } else {
                hold_indices.push(None);
            }
        }
        Ok(Trajectory {
            segments: self.segments,
            starts_s,
            hold_indices,
            duration_s: t,
        })
    }
}

/// The Earth's magnetic field at the site: magnitude and inclination (dip, positive downwards).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EarthField {
    /// Total intensity, µT.
    pub magnitude_ut: f64,
    /// Inclination below the horizontal, degrees.
    pub dip_deg: f64,
}

impl Default for EarthField {
    /// 48 µT at 60° dip: mid-latitude Europe (IGRF, e.g. Ljubljana ≈ 48 µT, 61°).
    fn default() -> Self {
        Self {
            magnitude_ut: 48.0,
            dip_deg: 60.0,
        }
    }
}

impl EarthField {
    /// Field vector in the world frame (x north, z up), µT.
    pub fn world_vector_ut(&self) -> Vector3<f64> {
        let dip = self.dip_deg.to_radians();
        Vector3::new(dip.cos(), 0.0, -dip.sin()) * self.magnitude_ut
    }
}

/// A local field added to the Earth's field for a while (a steel object or a running motor near
/// the board), faded in and out smoothly.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LocalDisturbance {
    /// Added field in the world frame at full strength, µT.
    pub field_world_ut: [f64; 3],
    /// Time the fade-in begins, s.
    pub start_s: f64,
    /// Time the fade-out ends, s.
    pub end_s: f64,
    /// Fade-in and fade-out time, s.
    pub ramp_s: f64,
}

impl LocalDisturbance {
    /// Strength between 0 and 1 at `t`.
    fn weight(&self, t: f64) -> f64 {
        if self.ramp_s <= 0.0 {
            return if (self.start_s..self.end_s).contains(&t) {
                1.0
            } else {
                0.0
            };
        }
        let (w_in, _) = smoothstep((t - self.start_s) / self.ramp_s);
        let (w_out, _) = smoothstep((self.end_s - t) / self.ramp_s);
        w_in * w_out
    }
}

/// Die temperature over time.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum TemperatureProfile {
    /// The same temperature throughout.
    Constant {
        /// Temperature, °C.
        temp_c: f64,
    },
    /// Linear change from `start_c` to `end_c` over `duration_s`, constant outside.
    Ramp {
        /// Temperature at t = 0, °C.
        start_c: f64,
        /// Temperature from `duration_s` on, °C.
        end_c: f64,
        /// Length of the ramp, s.
        duration_s: f64,
    },
    /// Self-heating after power-up: `ambient + rise·(1 − e^(−t/τ))`.
    Warmup {
        /// Temperature at power-up, °C.
        ambient_c: f64,
        /// Final rise above ambient, °C.
        rise_c: f64,
        /// Time constant τ, s.
        time_constant_s: f64,
    },
    /// Up and down between `low_c` and `high_c`: `low + (high − low)·(1 − cos 2πt/P)/2`.
    /// Over whole periods temperature is uncorrelated with time, so temperature effects can be
    /// told apart from drift.
    Sweep {
        /// Lowest temperature (at t = 0, P, 2P, …), °C.
        low_c: f64,
        /// Highest temperature (at t = P/2, …), °C.
        high_c: f64,
        /// Period P, s.
        period_s: f64,
    },
}

impl TemperatureProfile {
    /// Temperature at `t`, °C.
    pub fn at(&self, t: f64) -> f64 {
        match *self {
            TemperatureProfile::Constant { temp_c } => temp_c,
            TemperatureProfile::Ramp {
                start_c,
                end_c,
                duration_s,
            } => start_c + (end_c - start_c) * (t / duration_s).clamp(0.0, 1.0),
            TemperatureProfile::Warmup {
                ambient_c,
                rise_c,
                time_constant_s,
            } => ambient_c + rise_c * (1.0 - (-t.max(0.0) / time_constant_s).exp()),
            TemperatureProfile::Sweep {
                low_c,
                high_c,
                period_s,
            } => {
                let phase = 2.0 * std::f64::consts::PI * t / period_s;
                low_c + (high_c - low_c) * 0.5 * (1.0 - phase.cos())
            }
        }
    }

    fn validate(&self) -> Result<(), SimError> {
        match *self {
            TemperatureProfile::Constant { temp_c } => {
                require_finite("temperature (°C)", temp_c)?;
            }
            TemperatureProfile::Ramp {
                start_c,
                end_c,
                duration_s,
            } => {
                require_finite("ramp start temperature (°C)", start_c)?;
                require_finite("ramp end temperature (°C)", end_c)?;
                require_positive("ramp duration (s)", duration_s)?;
            }
            TemperatureProfile::Warmup {
                ambient_c,
                rise_c,
                time_constant_s,
            } => {
                require_finite("ambient temperature (°C)", ambient_c)?;
                require_finite("warm-up rise (°C)", rise_c)?;
                require_positive("warm-up time constant (s)", time_constant_s)?;
            }
            TemperatureProfile::Sweep {
                low_c,
                high_c,
                period_s,
            } => {
                require_finite("sweep low temperature (°C)", low_c)?;
                require_finite("sweep high temperature (°C)", high_c)?;
                require_positive("sweep period (s)", period_s)?;
            }
        }
        Ok(())
    }
}

/// Everything the sensors could sense at one instant, in true physical units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorldState {
    /// Time, s.
    pub t: f64,
    /// Orientation, body to world.
    pub q_body_to_world: UnitQuaternion<f64>,
    /// Angular rate in the body frame, rad/s.
    pub omega_body: Vector3<f64>,
    /// Specific force (what an ideal accelerometer reads) in the body frame, m/s².
    pub specific_force_body: Vector3<f64>,
    /// Magnetic field in the body frame, µT.
    pub field_body: Vector3<f64>,
    /// Die temperature, °C.
    pub temp_c: f64,
}

/// The board's surroundings and motion.
#[derive(Debug, Clone, PartialEq)]
pub struct World {
    /// The board's motion.
    pub trajectory: Trajectory,
    /// Magnitude of gravity, m/s².
    pub gravity_mps2: f64,
    /// The Earth's field.
    pub earth_field: EarthField,
    /// Optional local field disturbance.
    pub disturbance: Option<LocalDisturbance>,
    /// Die temperature over time.
    pub temperature: TemperatureProfile,
}

impl World {
    /// A world with standard gravity, the default Earth's field and no disturbance.
    pub fn new(trajectory: Trajectory, temperature: TemperatureProfile) -> Self {
        Self {
            trajectory,
            gravity_mps2: STANDARD_GRAVITY_MPS2,
            earth_field: EarthField::default(),
            disturbance: None,
            temperature,
        }
    }

    /// Check every setting; a world that passes never produces NaN.
    pub fn validate(&self) -> Result<(), SimError> {
        require_positive("gravity (m/s²)", self.gravity_mps2)?;
        require_non_negative("field magnitude (µT)", self.earth_field.magnitude_ut)?;
        let dip = require_finite("field dip (degrees)", self.earth_field.dip_deg)?;
        if dip.abs() > 90.0 {
            return Err(SimError::InvalidSetting {
                name: "field dip (degrees)",
                value: dip,
                requirement: "between −90 and 90",
            });
        }
        if let Some(d) = &self.disturbance {
            for v in d.field_world_ut {
                require_finite("disturbance field (µT)", v)?;
            }
            require_finite("disturbance start (s)", d.start_s)?;
            require_finite("disturbance end (s)", d.end_s)?;
            require_non_negative("disturbance ramp (s)", d.ramp_s)?;
        }
        self.temperature.validate()
    }

    /// Gravity vector in the world frame (pointing down), m/s².
    pub fn gravity_world(&self) -> Vector3<f64> {
        Vector3::new(0.0, 0.0, -self.gravity_mps2)
    }

    /// Total magnetic field in the world frame at `t`, µT.
    pub fn field_world_at(&self, t: f64) -> Vector3<f64> {
        let earth = self.earth_field.world_vector_ut();
        match &self.disturbance {
            Some(d) => earth + Vector3::from(d.field_world_ut) * d.weight(t),
            None => earth,
        }
    }

    /// The state of the world at `t`.
    pub fn state(&self, t: f64) -> WorldState {
        let motion = self.trajectory.motion_at(t);
        let to_body = motion.q_body_to_world.inverse();
        WorldState {
            t,
            q_body_to_world: motion.q_body_to_world,
            omega_body: motion.omega_body,
            specific_force_body: to_body * (-self.gravity_world()),
            field_body: to_body * self.field_world_at(t),
            temp_c: self.temperature.at(t),
        }
    }
}
