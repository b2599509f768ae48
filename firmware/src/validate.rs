//! Checks a calibration parameter set before it may become active.
//!
//! A set is accepted only when every number is finite and every term is physically plausible for
//! the board's sensors, so that applying it can never produce NaN, infinity or a reading that is
//! wrong by orders of magnitude. The bounds and their reasons:
//!
//! - **Condition number** of each `A`: the Frobenius condition number
//!   `κ_F = ‖A‖_F·‖A⁻¹‖_F` must not exceed [`MAX_CONDITION_FROBENIUS`] = 30. Since
//!   `κ₂ ≤ κ_F ≤ 3·κ₂`, every `A` with a 2-norm condition number up to 10 passes and none above 30
//!   does. Real sensors need far less (scale errors of a few %, cross-axis ≤ a few %, soft iron
//!   stretching one axis ≤ 2×); a larger value means a degenerate fit (too few distinct poses,
//!   partial magnetometer coverage) that would amplify noise along one direction. `κ_F` needs no
//!   eigenvalues: the inverse's norm comes from the adjugate and the determinant.
//! - **Gain** `‖A‖_F/√3` (the RMS singular value) within [`GAIN_LIMITS`] per sensor: catches fits
//!   done in the wrong units (g vs m/s² is 9.8×, °/s vs rad/s is 57×).
//! - **Offsets** `|b_i|` within the sensor's full-scale range: an offset beyond it would put
//!   every reading on the rail.
//! - **Extended terms** over the operating span `|ΔT| ≤` [`MAX_DELTA_T_C`]: the reference
//!   temperature of the bias polynomial lies in [`REFERENCE_TEMP_RANGE_C`] (without it a finite
//!   but absurd `T_ref` such as 10³⁰ °C makes `ΔT³` overflow and the output NaN), the temperature
//!   bias shift stays within the full-scale range, the temperature scale change within ±50 %, the
//!   non-linearity at full scale within half the reading, and each g-sensitivity entry within
//!   [`MAX_G_SENSITIVITY`]. Real parts are one to two orders of magnitude inside these.

use imucal_protocol::{
    CalibrationSet, InvalidParamsReason, SensorCalibration, SensorScales, PARAMS_FORMAT_VERSION,
};

use crate::math::sqrt_f64;

/// Largest accepted Frobenius condition number of a matrix `A` (see the module documentation).
pub const MAX_CONDITION_FROBENIUS: f64 = 30.0;

/// Accepted RMS gain of `A` per sensor, `(low, high)`: accelerometer, gyroscope, magnetometer.
///
/// Accelerometer and gyroscope output in their nominal units, so `A ≈ I`. The magnetometer may be
/// fitted to µT (gain ≈ 1, soft iron up to a few ×) or to the unit field (gain ≈ 1/|B|, about
/// 1/65 to 1/25 for the Earth's 25–65 µT), hence its wider window.
pub const GAIN_LIMITS: [(f64, f64); 3] = [(0.5, 2.0), (0.5, 2.0), (0.005, 4.0)];

/// Largest temperature excursion from the reference over which extended terms are checked, °C
/// (the −40…85 °C industrial range).
pub const MAX_DELTA_T_C: f32 = 125.0;

/// Accepted reference temperature `T_ref` of a bias temperature polynomial, °C: the widest
/// (military/automotive) die temperature range. A fit is always made at a temperature the part
/// can have.
pub const REFERENCE_TEMP_RANGE_C: (f32, f32) = (-55.0, 125.0);

/// Largest accepted gyro g-sensitivity entry, rad/s per m/s² (≈ 5.6 °/s per g; MEMS gyros are
/// specified at 0.01–0.2 °/s per g).
pub const MAX_G_SENSITIVITY: f32 = 0.01;

/// Check `set` for a board with these `scales`; `Ok` means it may be stored and applied.
pub fn validate(set: &CalibrationSet, scales: &SensorScales) -> Result<(), InvalidParamsReason> {
    if set.format_version != PARAMS_FORMAT_VERSION {
        return Err(InvalidParamsReason::UnsupportedFormat);
    }
    let sensors = [
        (&set.accel, scales.accel_range_mps2),
        (&set.gyro, scales.gyro_range_rads),
        (&set.mag, scales.mag_range_ut),
    ];
    // Every finiteness check first, so that the numeric checks below only see numbers.
    let metadata = [
        set.reference.gravity_mps2,
        set.reference.field_ut,
        set.residuals.accel_rms,
        set.residuals.gyro_rms,
        set.residuals.mag_rms,
    ];
    let g_sensitivity = set.gyro_g_sensitivity.unwrap_or([[0.0; 3]; 3]);
    if !metadata.iter().all(|v| v.is_finite())
        || !g_sensitivity.iter().flatten().all(|v| v.is_finite())
        || !sensors.iter().all(|(sensor, _)| sensor_is_finite(sensor))
    {
        return Err(InvalidParamsReason::NonFinite);
    }
    for ((sensor, range), (gain_low, gain_high)) in sensors.iter().zip(GAIN_LIMITS) {
        check_matrix(&sensor.a, gain_low, gain_high)?;
        // A NaN range compares false and rejects: better no set than an unchecked one.
        if !sensor.b.iter().all(|b| b.abs() <= *range) {
            return Err(InvalidParamsReason::OffsetOutOfRange);
        }
        check_extended(sensor, *range)?;
    }
    if !g_sensitivity
        .iter()
        .flatten()
        .all(|k| k.abs() <= MAX_G_SENSITIVITY)
    {
        return Err(InvalidParamsReason::ExtendedTermOutOfRange);
    }
    Ok(())
}

/// Frobenius condition number `‖A‖_F·‖A⁻¹‖_F`, computed in `f64`; infinite when `A` is singular.
pub fn condition_frobenius(a: &[[f32; 3]; 3]) -> f64 {
    let m = a.map(|row| row.map(f64::from));
    let [[a00, a01, a02], [a10, a11, a12], [a20, a21, a22]] = m;
    // Cofactors: adj(A) = Cᵀ, and ‖adj(A)‖_F = ‖C‖_F.
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
    let norm = sqrt_f64(m.iter().flatten().map(|v| v * v).sum::<f64>());
    let adjugate_norm = sqrt_f64(cofactors.iter().map(|v| v * v).sum::<f64>());
    if det == 0.0 {
        return f64::INFINITY;
    }
    norm * adjugate_norm / det.abs()
}

fn sensor_is_finite(sensor: &SensorCalibration) -> bool {
    let bias_temp = sensor.bias_temp.map_or([0.0; 10], |t| {
        let c = t.coeffs;
        [
            t.t_ref_c, c[0][0], c[0][1], c[0][2], c[1][0], c[1][1], c[1][2], c[2][0], c[2][1],
            c[2][2],
        ]
    });
    let nonlinearity = sensor.nonlinearity.map_or([0.0; 6], |n| {
        [
            n.quadratic[0],
            n.quadratic[1],
            n.quadratic[2],
            n.cubic[0],
            n.cubic[1],
            n.cubic[2],
        ]
    });
    sensor
        .a
        .iter()
        .flatten()
        .chain(&sensor.b)
        .chain(&bias_temp)
        .chain(&sensor.scale_temp.unwrap_or([0.0; 3]))
        .chain(&nonlinearity)
        .all(|v| v.is_finite())
}

fn check_matrix(
    a: &[[f32; 3]; 3],
    gain_low: f64,
    gain_high: f64,
) -> Result<(), InvalidParamsReason> {
    let rms_gain = sqrt_f64(
        a.iter()
            .flatten()
            .map(|&v| f64::from(v) * f64::from(v))
            .sum::<f64>()
            / 3.0,
    );
    if !(gain_low..=gain_high).contains(&rms_gain) {
        return Err(InvalidParamsReason::GainOutOfRange);
    }
    // NaN cannot reach here (finite inputs, non-zero gain); rejected anyway if it did.
    let kappa = condition_frobenius(a);
    if kappa.is_nan() || kappa > MAX_CONDITION_FROBENIUS {
        return Err(InvalidParamsReason::IllConditioned);
    }
    Ok(())
}

fn check_extended(sensor: &SensorCalibration, range: f32) -> Result<(), InvalidParamsReason> {
    let dt = MAX_DELTA_T_C;
    let mut plausible = true;
    if let Some(bias_temp) = sensor.bias_temp {
        let (t_low, t_high) = REFERENCE_TEMP_RANGE_C;
        plausible &= (t_low..=t_high).contains(&bias_temp.t_ref_c);
        for axis in 0..3 {
            let [c1, c2, c3] = bias_temp.coeffs.map(|degree| degree[axis].abs());
            let worst_shift = dt * (c1 + dt * (c2 + dt * c3));
            plausible &= worst_shift <= range;
        }
    }
    if let Some(scale_temp) = sensor.scale_temp {
        plausible &= scale_temp.iter().all(|s| s.abs() * dt <= 0.5);
    }
    if let Some(nonlinearity) = sensor.nonlinearity {
        for axis in 0..3 {
            // Relative deviation at full scale: |q|·r + |k|·r² ≤ ½.
            let q = nonlinearity.quadratic[axis].abs();
            let k = nonlinearity.cubic[axis].abs();
            plausible &= range * (q + k * range) <= 0.5;
        }
    }
    if plausible {
        Ok(())
    } else {
        Err(InvalidParamsReason::ExtendedTermOutOfRange)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use imucal_protocol::{BiasTemperature, Nonlinearity};

    fn scales() -> SensorScales {
        SensorScales {
            accel_mps2_per_count: 0.000_598_5,
            gyro_rads_per_count: 0.000_152_7,
            mag_ut_per_count: 0.014,
            temp_c_per_count: 1.0 / 16.0,
            temp_offset_c: 25.0,
            accel_range_mps2: 19.6,
            gyro_range_rads: 4.36,
            mag_range_ut: 400.0,
            sample_rate_hz: 100.0,
        }
    }

    fn diag(x: f32, y: f32, z: f32) -> [[f32; 3]; 3] {
        [[x, 0.0, 0.0], [0.0, y, 0.0], [0.0, 0.0, z]]
    }

    #[test]
    fn identity_and_a_realistic_set_pass() {
        assert_eq!(validate(&CalibrationSet::identity(), &scales()), Ok(()));
        let mut set = CalibrationSet::identity();
        set.accel.a = [[1.02, 0.01, -0.005], [0.0, 0.98, 0.012], [0.0, 0.0, 1.01]];
        set.accel.b = [0.12, -0.3, 0.05];
        set.mag.a = diag(1.0 / 48.0, 1.0 / 52.0, 1.0 / 45.0);
        set.mag.b = [30.0, -12.0, 80.0];
        set.reference.field_ut = 1.0;
        set.gyro_g_sensitivity = Some([[1e-4, 0.0, 0.0], [0.0, -2e-4, 0.0], [0.0, 0.0, 5e-5]]);
        assert_eq!(validate(&set, &scales()), Ok(()));
    }

    #[test]
    fn frobenius_condition_number_matches_the_diagonal_case() {
        // diag(1, 2, 4): ‖A‖_F = √21, ‖A⁻¹‖_F = √(1 + 1/4 + 1/16) = √21/4 → κ_F = 21/4.
        let kappa = condition_frobenius(&diag(1.0, 2.0, 4.0));
        assert!((kappa - 21.0 / 4.0).abs() < 1e-12);
        assert_eq!(condition_frobenius(&diag(1.0, 1.0, 0.0)), f64::INFINITY);
        // Identity: κ_F = 3 (its smallest possible value).
        assert!((condition_frobenius(&diag(1.0, 1.0, 1.0)) - 3.0).abs() < 1e-12);
    }

    #[test]
    fn nan_anywhere_is_non_finite() {
        let cases: [fn(&mut CalibrationSet); 5] = [
            |s| s.accel.a[1][2] = f32::NAN,
            |s| s.mag.b[0] = f32::INFINITY,
            |s| s.residuals.gyro_rms = f32::NAN,
            |s| s.gyro_g_sensitivity = Some([[0.0, f32::NAN, 0.0]; 3]),
            |s| {
                s.gyro.bias_temp = Some(BiasTemperature {
                    t_ref_c: f32::NAN,
                    coeffs: [[0.0; 3]; 3],
                })
            },
        ];
        for corrupt in cases {
            let mut set = CalibrationSet::identity();
            corrupt(&mut set);
            assert_eq!(
                validate(&set, &scales()),
                Err(InvalidParamsReason::NonFinite)
            );
        }
    }

    #[test]
    fn condition_bound_separates_stretch_ratios_of_ten_and_thirty_one() {
        // diag(1, 1, 1/r) has κ₂ = r; gain stays within limits for both.
        let mut set = CalibrationSet::identity();
        set.accel.a = diag(1.2, 1.2, 0.12);
        assert_eq!(validate(&set, &scales()), Ok(()));
        set.accel.a = diag(1.5, 1.5, 1.5 / 31.0);
        assert_eq!(
            validate(&set, &scales()),
            Err(InvalidParamsReason::IllConditioned)
        );
        // Singular but with a plausible gain.
        set.accel.a = [[1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        assert_eq!(
            validate(&set, &scales()),
            Err(InvalidParamsReason::IllConditioned)
        );
    }

    #[test]
    fn wrong_units_offsets_and_extended_terms_are_rejected() {
        let reject = |corrupt: fn(&mut CalibrationSet)| {
            let mut set = CalibrationSet::identity();
            corrupt(&mut set);
            validate(&set, &scales()).err()
        };
        // A fit in g instead of m/s²: gain 1/9.8.
        assert_eq!(
            reject(|s| s.accel.a = diag(0.102, 0.102, 0.102)),
            Some(InvalidParamsReason::GainOutOfRange)
        );
        assert_eq!(
            reject(|s| s.gyro.b = [0.0, 5.0, 0.0]),
            Some(InvalidParamsReason::OffsetOutOfRange)
        );
        assert_eq!(
            reject(|s| s.accel.scale_temp = Some([0.0, 0.005, 0.0])),
            Some(InvalidParamsReason::ExtendedTermOutOfRange)
        );
        assert_eq!(
            reject(|s| {
                s.accel.nonlinearity = Some(Nonlinearity {
                    quadratic: [0.03, 0.0, 0.0],
                    cubic: [0.0; 3],
                })
            }),
            Some(InvalidParamsReason::ExtendedTermOutOfRange)
        );
        assert_eq!(
            reject(|s| {
                // 0.01 m/s² per °C² → 156 m/s² at 125 °C: beyond the ±19.6 m/s² range.
                s.accel.bias_temp = Some(BiasTemperature {
                    t_ref_c: 25.0,
                    coeffs: [[0.0; 3], [0.01, 0.0, 0.0], [0.0; 3]],
                })
            }),
            Some(InvalidParamsReason::ExtendedTermOutOfRange)
        );
        assert_eq!(
            reject(|s| s.gyro_g_sensitivity = Some([[0.02, 0.0, 0.0]; 3])),
            Some(InvalidParamsReason::ExtendedTermOutOfRange)
        );
        assert_eq!(
            reject(|s| s.format_version = 99),
            Some(InvalidParamsReason::UnsupportedFormat)
        );
    }
}
