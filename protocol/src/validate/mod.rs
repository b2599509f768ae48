//! Checks a calibration set before it may be stored, applied or exported.
//!
//! A set is accepted only when every number is finite and every term is physically plausible for
//! the board's sensors, so that applying it can never produce NaN, infinity or a reading that is
//! wrong by orders of magnitude. The firmware refuses to store what fails here, and the host
//! refuses to flash or export it; both call this one function. The bounds ([`limits`]):
//!
//! - **Condition number** of each `A`: `κ_F = ‖A‖_F·‖A⁻¹‖_F ≤` [`MAX_CONDITION_FROBENIUS`]. `κ_F`
//!   needs no eigenvalues: the inverse's norm comes from the adjugate and the determinant.
//! - **Gain** `‖A‖_F/√3` (the RMS singular value) within [`GAIN_LIMITS`] per sensor.
//! - **Handedness** of the accelerometer and gyroscope: `det A > 0`. Their chips' axes are
//!   right-handed, and scale errors and misalignment never reverse one; a reflection means an
//!   axis is mapped wrongly into the board frame (a sign in the driver's axis mapping), which a
//!   calibration must not hide. The magnetometer is exempt: some chips' magnetometer frame is a
//!   reflection of their accelerometer's (the LSM9DS1's X axis), and a set that maps one into
//!   the other rightly has `det A < 0`.
//! - **Offsets** `|b_i|` within the sensor's full-scale range: an offset beyond it would put
//!   every reading on the rail.
//! - **Reference temperature** of every sensor within [`REFERENCE_TEMP_RANGE_C`].
//! - **Extended terms** over the clamped span `|ΔT| ≤` [`MAX_DELTA_T_C`]: the bias shift stays
//!   within the full-scale range, the scale change within [`MAX_SCALE_TEMP_CHANGE`], the
//!   non-linearity at full scale within [`MAX_NONLINEAR_CHANGE`], and each g-sensitivity entry
//!   within [`MAX_G_SENSITIVITY`]. Real parts are one to two orders of magnitude inside these.

pub mod limits;
pub mod reason;

pub use limits::{
    GAIN_LIMITS, MAX_CONDITION_FROBENIUS, MAX_DELTA_T_C, MAX_G_SENSITIVITY, MAX_NONLINEAR_CHANGE,
    MAX_SCALE_TEMP_CHANGE, REFERENCE_TEMP_RANGE_C,
};
pub use reason::{InvalidParamsReason, ParamField};

use crate::math::sqrt_f64;
use crate::params::{CalibrationSet, SensorCalibration, SensorKind, PARAMS_FORMAT_VERSION};
use crate::sample::SensorScales;

/// Full-scale ranges (±) of the three sensors, in their nominal units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FullScale {
    /// Accelerometer, m/s².
    pub accel_mps2: f32,
    /// Gyroscope, rad/s.
    pub gyro_rads: f32,
    /// Magnetometer, µT.
    pub mag_ut: f32,
}

impl FullScale {
    /// The widest ranges of the parts imucal supports (±16 g, ±2000 °/s, ±16 gauss): the bounds
    /// for a set whose board is not known, such as one exported for other firmware.
    pub const WIDEST_SUPPORTED: FullScale = FullScale {
        accel_mps2: 16.0 * 9.806_65,
        gyro_rads: 2000.0 * core::f32::consts::PI / 180.0,
        mag_ut: 1600.0,
    };

    /// The ranges a board announces in its scales.
    pub fn of(scales: &SensorScales) -> Self {
        Self {
            accel_mps2: scales.accel_range_mps2,
            gyro_rads: scales.gyro_range_rads,
            mag_ut: scales.mag_range_ut,
        }
    }

    fn range(&self, kind: SensorKind) -> f32 {
        match kind {
            SensorKind::Accel => self.accel_mps2,
            SensorKind::Gyro => self.gyro_rads,
            SensorKind::Mag => self.mag_ut,
        }
    }
}

/// Check `set` for a board with these `scales`; `Ok` means it may be stored and applied.
pub fn validate(set: &CalibrationSet, scales: &SensorScales) -> Result<(), InvalidParamsReason> {
    validate_for_ranges(set, &FullScale::of(scales))
}

/// Check `set` against explicit full-scale ranges (see [`FullScale::WIDEST_SUPPORTED`]).
pub fn validate_for_ranges(
    set: &CalibrationSet,
    ranges: &FullScale,
) -> Result<(), InvalidParamsReason> {
    if set.format_version != PARAMS_FORMAT_VERSION {
        return Err(InvalidParamsReason::UnsupportedFormat {
            found: set.format_version,
        });
    }
    // Every finiteness check first, so that the numeric checks below only see numbers.
    let reference = [set.reference.gravity_mps2, set.reference.field_ut];
    let residuals = [
        set.residuals.accel_rms,
        set.residuals.gyro_rms,
        set.residuals.mag_rms,
    ];
    let g_sensitivity = set.gyro_g_sensitivity.unwrap_or([[0.0; 3]; 3]);
    finite(&reference, ParamField::Reference)?;
    finite(&residuals, ParamField::Residuals)?;
    finite(g_sensitivity.as_flattened(), ParamField::GyroGSensitivity)?;
    for kind in SensorKind::ALL {
        sensor_is_finite(set.sensor(kind), kind)?;
    }
    for kind in SensorKind::ALL {
        let sensor = set.sensor(kind);
        let range = ranges.range(kind);
        let (gain_low, gain_high) = GAIN_LIMITS[kind as usize];
        check_matrix(&sensor.a, gain_low, gain_high, kind)?;
        // A NaN range compares false and rejects: better no set than an unchecked one.
        if !sensor.b.iter().all(|b| b.abs() <= range) {
            return Err(InvalidParamsReason::OffsetOutOfRange(kind));
        }
        let (t_low, t_high) = REFERENCE_TEMP_RANGE_C;
        if !(t_low..=t_high).contains(&sensor.t_ref_c) {
            return Err(InvalidParamsReason::ReferenceTemperatureOutOfRange(kind));
        }
        check_extended(sensor, range, kind)?;
    }
    if !g_sensitivity
        .iter()
        .flatten()
        .all(|k| k.abs() <= MAX_G_SENSITIVITY)
    {
        return Err(InvalidParamsReason::ExtendedTermOutOfRange(
            ParamField::GyroGSensitivity,
        ));
    }
    Ok(())
}

/// The cofactors of `A` in `f64`, row by row (`adj(A) = Cᵀ`), and its determinant.
fn cofactors_and_determinant(a: &[[f32; 3]; 3]) -> ([f64; 9], f64) {
    let [[a00, a01, a02], [a10, a11, a12], [a20, a21, a22]] = a.map(|row| row.map(f64::from));
    let cofactors = [
        a11 * a22 - a12 * a21,
        a12 * a20 - a10 * a22,
        a10 * a21 - a11 * a20,
        a02 * a21 - a01 * a22,
        a00 * a22 - a02 * a20,
        a01 * a20 - a00 * a21,
        a01 * a12 - a02 * a11,
        a02 * a10 - a00 * a12,
        a00 * a11 - a01 * a10,
    ];
    let det = a00 * cofactors[0] + a01 * cofactors[1] + a02 * cofactors[2];
    (cofactors, det)
}

/// Determinant of `A`, computed in `f64`.
pub fn determinant(a: &[[f32; 3]; 3]) -> f64 {
    cofactors_and_determinant(a).1
}

/// Frobenius condition number `‖A‖_F·‖A⁻¹‖_F`, computed in `f64`; infinite when `A` is singular.
pub fn condition_frobenius(a: &[[f32; 3]; 3]) -> f64 {
    let m = a.map(|row| row.map(f64::from));
    // ‖adj(A)‖_F = ‖C‖_F.
    let (cofactors, det) = cofactors_and_determinant(a);
    let norm = sqrt_f64(m.iter().flatten().map(|v| v * v).sum::<f64>());
    let adjugate_norm = sqrt_f64(cofactors.iter().map(|v| v * v).sum::<f64>());
    if det == 0.0 {
        return f64::INFINITY;
    }
    norm * adjugate_norm / det.abs()
}

fn finite(values: &[f32], field: ParamField) -> Result<(), InvalidParamsReason> {
    if values.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(InvalidParamsReason::NonFinite(field))
    }
}

fn sensor_is_finite(
    sensor: &SensorCalibration,
    kind: SensorKind,
) -> Result<(), InvalidParamsReason> {
    finite(sensor.a.as_flattened(), ParamField::Matrix(kind))?;
    finite(&sensor.b, ParamField::Offset(kind))?;
    finite(&[sensor.t_ref_c], ParamField::ReferenceTemperature(kind))?;
    if let Some(t) = &sensor.bias_temp {
        finite(t.coeffs.as_flattened(), ParamField::BiasTemperature(kind))?;
    }
    if let Some(s) = &sensor.scale_temp {
        finite(s, ParamField::ScaleTemperature(kind))?;
    }
    if let Some(n) = &sensor.nonlinearity {
        finite(&n.quadratic, ParamField::Nonlinearity(kind))?;
        finite(&n.cubic, ParamField::Nonlinearity(kind))?;
    }
    Ok(())
}

fn check_matrix(
    a: &[[f32; 3]; 3],
    gain_low: f64,
    gain_high: f64,
    kind: SensorKind,
) -> Result<(), InvalidParamsReason> {
    let rms_gain = sqrt_f64(
        a.iter()
            .flatten()
            .map(|&v| f64::from(v) * f64::from(v))
            .sum::<f64>()
            / 3.0,
    );
    if !(gain_low..=gain_high).contains(&rms_gain) {
        return Err(InvalidParamsReason::GainOutOfRange(kind));
    }
    // NaN cannot reach here (finite inputs, non-zero gain); rejected anyway if it did.
    let kappa = condition_frobenius(a);
    if kappa.is_nan() || kappa > MAX_CONDITION_FROBENIUS {
        return Err(InvalidParamsReason::IllConditioned(kind));
    }
    // Well conditioned, so the sign of the determinant is not a rounding accident.
    if kind != SensorKind::Mag && determinant(a) < 0.0 {
        return Err(InvalidParamsReason::MirroredAxes(kind));
    }
    Ok(())
}

fn check_extended(
    sensor: &SensorCalibration,
    range: f32,
    kind: SensorKind,
) -> Result<(), InvalidParamsReason> {
    let dt = MAX_DELTA_T_C;
    let refuse = |field: ParamField| Err(InvalidParamsReason::ExtendedTermOutOfRange(field));
    if let Some(bias_temp) = sensor.bias_temp {
        for axis in 0..3 {
            let [c1, c2, c3] = bias_temp.coeffs.map(|degree| degree[axis].abs());
            let worst_shift = dt * (c1 + dt * (c2 + dt * c3));
            // Written so that a NaN range refuses too.
            let within = worst_shift <= range;
            if !within {
                return refuse(ParamField::BiasTemperature(kind));
            }
        }
    }
    if let Some(scale_temp) = sensor.scale_temp {
        if !scale_temp
            .iter()
            .all(|s| s.abs() * dt <= MAX_SCALE_TEMP_CHANGE)
        {
            return refuse(ParamField::ScaleTemperature(kind));
        }
    }
    if let Some(nonlinearity) = sensor.nonlinearity {
        for axis in 0..3 {
            // Relative deviation at full scale: |q|·r + |k|·r².
            let q = nonlinearity.quadratic[axis].abs();
            let k = nonlinearity.cubic[axis].abs();
            let within = range * (q + k * range) <= MAX_NONLINEAR_CHANGE;
            if !within {
                return refuse(ParamField::Nonlinearity(kind));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests;
