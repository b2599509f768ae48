//! The reference implementation of the calibration model documented on [`CalibrationSet`],
//! term by term in `f64`, on readings in nominal units.
//!
//! It is the yardstick for every faster or generated implementation (the firmware's folded
//! `f32` path, the C and Rust exports) and what the host uses to apply a set to recorded data.
//! It applies the one ΔT rule: `ΔT` is clamped to `±MAX_DELTA_T_C` ([`delta_t_c`]).

use crate::params::{CalibrationSet, SensorCalibration};
use crate::validate::MAX_DELTA_T_C;

/// One reading of all sensors in nominal units: m/s², rad/s, µT and °C.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct NominalSample {
    /// Accelerometer, m/s².
    pub accel: [f64; 3],
    /// Gyroscope, rad/s.
    pub gyro: [f64; 3],
    /// Magnetometer, µT.
    pub mag: [f64; 3],
    /// Die temperature, °C.
    pub temp_c: f64,
}

/// `ΔT = T − T_ref`, clamped to `±MAX_DELTA_T_C`: the span over which validation checked the
/// temperature terms. NaN stays NaN (a NaN temperature has no meaningful correction).
#[inline]
pub fn delta_t_c(temp_c: f32, t_ref_c: f32) -> f32 {
    (temp_c - t_ref_c).clamp(-MAX_DELTA_T_C, MAX_DELTA_T_C)
}

/// One sensor's calibrated output for the reading `x` at `temp_c` (every term present applied).
pub fn apply_sensor(cal: &SensorCalibration, x: [f64; 3], temp_c: f64) -> [f64; 3] {
    let limit = f64::from(MAX_DELTA_T_C);
    let dt = (temp_c - f64::from(cal.t_ref_c)).clamp(-limit, limit);
    let mut u = [0.0; 3];
    for (axis, value) in u.iter_mut().enumerate() {
        let mut offset = f64::from(cal.b[axis]);
        if let Some(t) = &cal.bias_temp {
            let [c1, c2, c3] = [0, 1, 2].map(|k| f64::from(t.coeffs[k][axis]));
            offset += dt * (c1 + dt * (c2 + dt * c3));
        }
        let mut v = x[axis] - offset;
        if let Some(n) = &cal.nonlinearity {
            v += v * v * (f64::from(n.quadratic[axis]) + f64::from(n.cubic[axis]) * v);
        }
        *value = v;
    }
    let mut y = [0.0; 3];
    for (row, out) in y.iter_mut().enumerate() {
        *out = (0..3).map(|c| f64::from(cal.a[row][c]) * u[c]).sum();
        if let Some(s) = &cal.scale_temp {
            *out *= 1.0 + f64::from(s[row]) * dt;
        }
    }
    y
}

/// The whole set applied to one sample: each sensor, then the gyroscope's g-sensitivity
/// correction from the calibrated accelerometer. The temperature passes unchanged.
pub fn apply(set: &CalibrationSet, sample: &NominalSample) -> NominalSample {
    let accel = apply_sensor(&set.accel, sample.accel, sample.temp_c);
    let mut gyro = apply_sensor(&set.gyro, sample.gyro, sample.temp_c);
    if let Some(k) = &set.gyro_g_sensitivity {
        for (row, out) in gyro.iter_mut().enumerate() {
            *out -= (0..3).map(|c| f64::from(k[row][c]) * accel[c]).sum::<f64>();
        }
    }
    NominalSample {
        accel,
        gyro,
        mag: apply_sensor(&set.mag, sample.mag, sample.temp_c),
        temp_c: sample.temp_c,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::BiasTemperature;

    #[test]
    fn scale_temperature_alone_uses_the_sensors_reference_temperature() {
        // s = 1e-4/°C about 25 °C: at 25 °C no scale change at all, at 35 °C exactly +0.1 %.
        let mut set = CalibrationSet::identity();
        set.accel.t_ref_c = 25.0;
        set.accel.scale_temp = Some([1e-4; 3]);
        let at = |temp_c| {
            apply(
                &set,
                &NominalSample {
                    accel: [0.0, 0.0, 9.81],
                    temp_c,
                    ..NominalSample::default()
                },
            )
            .accel[2]
        };
        assert_eq!(at(25.0), 9.81);
        // The coefficient is the f32 nearest 1e-4, exactly as stored.
        let s = f64::from(1e-4f32);
        assert!((at(35.0) - 9.81 * (1.0 + s * 10.0)).abs() < 1e-12);
    }

    #[test]
    fn delta_t_is_clamped_to_the_validated_span() {
        let mut set = CalibrationSet::identity();
        set.gyro.t_ref_c = 20.0;
        set.gyro.bias_temp = Some(BiasTemperature {
            coeffs: [[1e-4, 0.0, 0.0], [0.0; 3], [0.0; 3]],
        });
        let bias_at = |temp_c| -apply_sensor(&set.gyro, [0.0; 3], temp_c)[0];
        let edge = f64::from(1e-4f32) * f64::from(MAX_DELTA_T_C);
        assert!((bias_at(20.0 + 125.0) - edge).abs() < 1e-12);
        assert_eq!(bias_at(1e6), bias_at(20.0 + 125.0));
        assert_eq!(bias_at(-1e6), -bias_at(1e6));
        assert_eq!(delta_t_c(1e30, 25.0), MAX_DELTA_T_C);
        assert_eq!(delta_t_c(-300.0, 25.0), -MAX_DELTA_T_C);
        assert_eq!(delta_t_c(30.0, 25.0), 5.0);
    }
}
