//! Effects a calibration model has no term for, to test that a residual analysis answers
//! "unexplained" rather than naming a wrong cause. Each is a real mechanism of a hand-held
//! calibration:
//!
//! - `temperature_rate_bias`: a bias proportional to `dT/dt`. The die thermometer and the sensing
//!   element are not at the same temperature while the board heats or cools; with a thermal lag
//!   `τ` the element lags the die by `τ·dT/dt`, so its bias is off by `c₁·τ·dT/dt`. Typical size:
//!   the sensor's typical linear bias tempco times `τ` = [`THERMAL_LAG_S`].
//! - `cross_axis_nonlinearity`: each axis picks up the product of the other two,
//!   `u_x += a_x·u_y·u_z` (and cyclically), as from a proof mass coupled between axes; typical
//!   0.1 % of the reference reading at the reference reading on both other axes, like
//!   `scale_nonlinearity`. A per-axis polynomial cannot express it.
//! - `bumped_hold`: the board is pressed or knocked during one hold and its bias is off for that
//!   hold only (package stress that relaxes when the hand lets go); typical as `bias_step`.
//! - `steel_near_hold` (magnetometer): a steel object lies near the board during one hold and adds
//!   its own field at the sensor, fixed in the world, hence constant in the body while the board is
//!   still; typical 5 µT (a screwdriver a few cm away).
//!
//! The hold-bound effects are drawn with a time in the middle of the recording; the simulation
//! then places them on the hold nearest that time ([`OutOfFamily::place_on_holds`]).

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::world::HoldSpan;

/// Thermal lag between the die thermometer and the sensing element, s.
pub const THERMAL_LAG_S: f64 = 10.0;

/// Typical field of a steel object near the board, µT.
pub const TYPICAL_STEEL_FIELD_UT: f64 = 5.0;

/// Bias proportional to the rate of temperature change: `b_i += g_i·dT/dt`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TemperatureRateBias {
    /// `g_i`, sensor units per °C/s.
    pub per_degree_per_second: [f64; 3],
}

/// Each axis gains the product of the other two: `u_x += a_x·u_y·u_z`, `u_y += a_y·u_z·u_x`,
/// `u_z += a_z·u_x·u_y`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CrossAxisNonlinearity {
    /// `a_i`, 1/(sensor unit).
    pub product: [f64; 3],
}

/// A vector added during one hold only (`start_s ≤ t < end_s`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct HoldEvent {
    /// Start of the hold it is placed on, s (the drawn time until placed).
    pub start_s: f64,
    /// End of that hold, s (equal to `start_s` until placed).
    pub end_s: f64,
    /// The added vector, sensor units.
    pub value: [f64; 3],
}

impl HoldEvent {
    /// The added vector at `t`.
    pub fn at(&self, t: f64) -> Vector3<f64> {
        if (self.start_s..self.end_s).contains(&t) {
            Vector3::from(self.value)
        } else {
            Vector3::zeros()
        }
    }

    /// Move onto the hold whose middle is nearest the drawn time.
    fn place(&mut self, holds: &[HoldSpan]) {
        let drawn = self.start_s;
        if let Some(h) = holds.iter().min_by(|a, b| {
            let mid = |h: &HoldSpan| (0.5 * (h.start_s + h.end_s) - drawn).abs();
            mid(a).total_cmp(&mid(b))
        }) {
            self.start_s = h.start_s;
            self.end_s = h.end_s;
        }
    }
}

/// The out-of-family effects of one sensor (all off by default).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct OutOfFamily {
    /// See [`TemperatureRateBias`].
    pub temperature_rate_bias: Option<TemperatureRateBias>,
    /// See [`CrossAxisNonlinearity`].
    pub cross_axis_nonlinearity: Option<CrossAxisNonlinearity>,
    /// A bias offset during one hold.
    pub bumped_hold: Option<HoldEvent>,
    /// An external field at the sensor during one hold (magnetometer), body frame, µT.
    pub steel_near_hold: Option<HoldEvent>,
}

impl OutOfFamily {
    /// Bias added at `t` with the temperature changing at `temp_rate_c_per_s`.
    pub fn bias(&self, t: f64, temp_rate_c_per_s: f64) -> Vector3<f64> {
        let mut bias = Vector3::zeros();
        if let Some(r) = &self.temperature_rate_bias {
            bias += Vector3::from(r.per_degree_per_second) * temp_rate_c_per_s;
        }
        if let Some(h) = &self.bumped_hold {
            bias += h.at(t);
        }
        bias
    }

    /// Field added to what the sensor senses at `t` (before its own scale and soft iron).
    pub fn external_field(&self, t: f64) -> Vector3<f64> {
        self.steel_near_hold
            .as_ref()
            .map_or_else(Vector3::zeros, |s| s.at(t))
    }

    /// Apply the cross-axis products to a reading `u` (after the per-axis non-linearity).
    pub fn apply_cross_axis(&self, u: Vector3<f64>) -> Vector3<f64> {
        match &self.cross_axis_nonlinearity {
            Some(c) => Vector3::new(
                u.x + c.product[0] * u.y * u.z,
                u.y + c.product[1] * u.z * u.x,
                u.z + c.product[2] * u.x * u.y,
            ),
            None => u,
        }
    }

    /// Place the hold-bound effects on the holds nearest their drawn times.
    pub fn place_on_holds(&mut self, holds: &[HoldSpan]) {
        for event in [&mut self.bumped_hold, &mut self.steel_near_hold]
            .into_iter()
            .flatten()
        {
            event.place(holds);
        }
    }
}
