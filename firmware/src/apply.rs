//! The per-sample hot path: raw counts → nominal units → calibrated output.
//!
//! Implements the model documented on [`CalibrationSet`] (the architecture's
//! `y = A·(x − b(T)) − K·f`, sensor model (3)–(8) of Puc et al. extended with the temperature
//! polynomial of the practitioner's note):
//!
//! ```text
//! x = σ·c (counts c, sensitivity σ)   ΔT = T − T_ref
//! b(T) = b + c1·ΔT + c2·ΔT² + c3·ΔT³   u = x − b(T)   u' = u + q∘u² + k∘u³
//! y = (1 + s·ΔT)∘(A·u')                y_gyro −= K·f   (f = calibrated accelerometer)
//! ```
//!
//! [`Correction::new`] validates the set and folds it once, at load time, into flat `f32`
//! arrays: without non-linearity, `A·(σ·c − b(T)) = (A·σ)·c − (A·b + ΔT·(A·c1 + ΔT·(A·c2 +
//! ΔT·A·c3)))`, so a sensor costs nine multiply-adds plus three for each bias temperature degree.
//! The only branches are on which extended terms are present, never on the data, so the time per
//! sample is constant for a given set. Validated parameters and `i16` counts keep every
//! intermediate far from `f32` overflow, so no input produces NaN or infinity.
//!
//! When a sensor has a scale temperature coefficient but no bias temperature polynomial, the
//! reference temperature is 0 °C (`ΔT = T`).

use imucal_protocol::{CalibratedSample, CalibrationSet, InvalidParamsReason, SensorCalibration};

use crate::imu::{RawSample, SensorScales};
use crate::validate::validate;

type Vec3 = [f32; 3];
type Mat3 = [[f32; 3]; 3];

/// One sensor's correction, folded for the hot path.
#[derive(Debug, Clone, Copy, PartialEq)]
struct SensorCorrection {
    /// `A·σ` on the linear path (input counts), `A` on the non-linear path (input `u'`).
    matrix: Mat3,
    /// Offset polynomial coefficients: `A·b, A·c1, A·c2, A·c3` on the linear path (subtracted
    /// after `A`), `b, c1, c2, c3` on the non-linear path (subtracted before it).
    offset: [Vec3; 4],
    /// Count sensitivity σ, used by the non-linear path to form `u`.
    per_count: f32,
    t_ref_c: f32,
    /// Highest bias temperature degree present (0 = none, up to 3).
    bias_degree: u8,
    scale_temp: Option<Vec3>,
    /// Quadratic and cubic non-linearity coefficients.
    nonlinearity: Option<(Vec3, Vec3)>,
}

impl SensorCorrection {
    fn new(sensor: &SensorCalibration, per_count: f32) -> Self {
        let a = sensor.a;
        let (t_ref_c, coeffs) = sensor
            .bias_temp
            .map_or((0.0, [[0.0; 3]; 3]), |t| (t.t_ref_c, t.coeffs));
        // Degrees whose coefficients are all zero cost nothing at run time.
        let bias_degree = coeffs
            .iter()
            .rposition(|degree| degree.iter().any(|&c| c != 0.0))
            .map_or(0, |last| last as u8 + 1);
        let [c1, c2, c3] = coeffs;
        let nonlinearity = sensor
            .nonlinearity
            .map(|n| (n.quadratic, n.cubic))
            .filter(|(q, k)| q.iter().chain(k).any(|&v| v != 0.0));
        let (matrix, offset) = if nonlinearity.is_some() {
            (a, [sensor.b, c1, c2, c3])
        } else {
            (
                a.map(|row| row.map(|v| v * per_count)),
                [
                    mat_vec(&a, &sensor.b),
                    mat_vec(&a, &c1),
                    mat_vec(&a, &c2),
                    mat_vec(&a, &c3),
                ],
            )
        };
        Self {
            matrix,
            offset,
            per_count,
            t_ref_c,
            bias_degree,
            scale_temp: sensor.scale_temp.filter(|s| s.iter().any(|&v| v != 0.0)),
            nonlinearity,
        }
    }

    /// Offset polynomial `o0 + ΔT·(o1 + ΔT·(o2 + ΔT·o3))` up to the degree present (Horner).
    #[inline]
    fn offset_at(&self, dt: f32) -> Vec3 {
        let [o0, o1, o2, o3] = self.offset;
        let mut acc = [0.0f32; 3];
        for axis in 0..3 {
            acc[axis] = match self.bias_degree {
                0 => o0[axis],
                1 => o0[axis] + dt * o1[axis],
                2 => o0[axis] + dt * (o1[axis] + dt * o2[axis]),
                _ => o0[axis] + dt * (o1[axis] + dt * (o2[axis] + dt * o3[axis])),
            };
        }
        acc
    }

    #[inline]
    fn apply(&self, counts: [i16; 3], temp_c: f32) -> Vec3 {
        let c = counts.map(f32::from);
        let dt = temp_c - self.t_ref_c;
        let offset = self.offset_at(dt);
        let mut y = match self.nonlinearity {
            None => {
                let mc = mat_vec(&self.matrix, &c);
                [mc[0] - offset[0], mc[1] - offset[1], mc[2] - offset[2]]
            }
            Some((q, k)) => {
                let mut u = [0.0f32; 3];
                for axis in 0..3 {
                    let ui = self.per_count * c[axis] - offset[axis];
                    u[axis] = ui + ui * ui * (q[axis] + k[axis] * ui);
                }
                mat_vec(&self.matrix, &u)
            }
        };
        if let Some(s) = self.scale_temp {
            for axis in 0..3 {
                y[axis] *= 1.0 + s[axis] * dt;
            }
        }
        y
    }
}

/// A validated calibration set folded for the per-sample path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Correction {
    accel: SensorCorrection,
    gyro: SensorCorrection,
    mag: SensorCorrection,
    gyro_g_sensitivity: Option<Mat3>,
    temp_offset_c: f32,
    temp_c_per_count: f32,
}

impl Correction {
    /// Validate `set` for a board with `scales` and fold it; a rejected set is returned as the
    /// reason, and the caller keeps its previous correction.
    pub fn new(set: &CalibrationSet, scales: &SensorScales) -> Result<Self, InvalidParamsReason> {
        validate(set, scales)?;
        Ok(Self::fold(set, scales))
    }

    /// The identity correction: nominal units out, nothing else changed.
    pub fn identity(scales: &SensorScales) -> Self {
        Self::fold(&CalibrationSet::identity(), scales)
    }

    fn fold(set: &CalibrationSet, scales: &SensorScales) -> Self {
        Self {
            accel: SensorCorrection::new(&set.accel, scales.accel_mps2_per_count),
            gyro: SensorCorrection::new(&set.gyro, scales.gyro_rads_per_count),
            mag: SensorCorrection::new(&set.mag, scales.mag_ut_per_count),
            gyro_g_sensitivity: set
                .gyro_g_sensitivity
                .filter(|k| k.iter().flatten().any(|&v| v != 0.0)),
            temp_offset_c: scales.temp_offset_c,
            temp_c_per_count: scales.temp_c_per_count,
        }
    }

    /// Calibrate one raw sample.
    pub fn apply(&self, raw: &RawSample) -> CalibratedSample {
        let temp_c = self.temp_offset_c + self.temp_c_per_count * f32::from(raw.temp);
        let accel = self.accel.apply(raw.accel, temp_c);
        let mut gyro = self.gyro.apply(raw.gyro, temp_c);
        if let Some(k) = &self.gyro_g_sensitivity {
            let kf = mat_vec(k, &accel);
            for axis in 0..3 {
                gyro[axis] -= kf[axis];
            }
        }
        CalibratedSample {
            accel,
            gyro,
            mag: self.mag.apply(raw.mag, temp_c),
            temp_c,
        }
    }
}

#[inline]
fn mat_vec(m: &Mat3, v: &Vec3) -> Vec3 {
    m.map(|row| row[0] * v[0] + row[1] * v[1] + row[2] * v[2])
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

    /// A set using every extended term, with magnitudes of a poor but real MEMS part.
    fn extended_set() -> CalibrationSet {
        let mut set = CalibrationSet::identity();
        set.accel.a = [
            [1.02, 0.01, -0.005],
            [0.003, 0.98, 0.012],
            [-0.004, 0.006, 1.01],
        ];
        set.accel.b = [0.12, -0.3, 0.05];
        set.accel.bias_temp = Some(BiasTemperature {
            t_ref_c: 25.0,
            coeffs: [[2e-3, -1e-3, 5e-4], [1e-5, 0.0, -2e-5], [1e-7, 3e-7, 0.0]],
        });
        set.accel.scale_temp = Some([1e-4, -2e-4, 5e-5]);
        set.accel.nonlinearity = Some(Nonlinearity {
            quadratic: [1e-3, -5e-4, 2e-4],
            cubic: [1e-5, 0.0, -2e-5],
        });
        set.gyro.a = [[1.01, -0.02, 0.0], [0.015, 0.99, 0.004], [0.0, 0.01, 1.03]];
        set.gyro.b = [0.01, -0.02, 0.005];
        set.gyro.bias_temp = Some(BiasTemperature {
            t_ref_c: 30.0,
            coeffs: [[1e-4, -2e-4, 3e-5], [0.0; 3], [0.0; 3]],
        });
        set.gyro_g_sensitivity = Some([[1e-4, 2e-5, 0.0], [0.0, -2e-4, 1e-5], [3e-5, 0.0, 5e-5]]);
        set.mag.a = [
            [1.0 / 48.0, 0.001, 0.0],
            [0.0, 1.0 / 52.0, -0.0005],
            [0.0, 0.0, 1.0 / 45.0],
        ];
        set.mag.b = [30.0, -12.0, 80.0];
        set.mag.scale_temp = Some([0.0, 0.0, 3e-4]);
        set
    }

    /// The model of `CalibrationSet`, term by term in f64: the reference for the folded f32 path.
    fn reference_sensor(
        sensor: &SensorCalibration,
        counts: [i16; 3],
        per_count: f32,
        temp_c: f64,
    ) -> [f64; 3] {
        let (t_ref, coeffs) = sensor
            .bias_temp
            .map_or((0.0, [[0.0; 3]; 3]), |t| (f64::from(t.t_ref_c), t.coeffs));
        let dt = temp_c - t_ref;
        let mut u = [0.0f64; 3];
        for axis in 0..3 {
            let x = f64::from(counts[axis]) * f64::from(per_count);
            let bias = f64::from(sensor.b[axis])
                + f64::from(coeffs[0][axis]) * dt
                + f64::from(coeffs[1][axis]) * dt * dt
                + f64::from(coeffs[2][axis]) * dt * dt * dt;
            let ui = x - bias;
            u[axis] = match sensor.nonlinearity {
                Some(n) => {
                    ui + f64::from(n.quadratic[axis]) * ui * ui
                        + f64::from(n.cubic[axis]) * ui * ui * ui
                }
                None => ui,
            };
        }
        let mut y = [0.0f64; 3];
        for row in 0..3 {
            y[row] = (0..3)
                .map(|col| f64::from(sensor.a[row][col]) * u[col])
                .sum();
            if let Some(s) = sensor.scale_temp {
                y[row] *= 1.0 + f64::from(s[row]) * dt;
            }
        }
        y
    }

    fn reference(set: &CalibrationSet, raw: &RawSample) -> [[f64; 3]; 3] {
        let s = scales();
        let temp_c =
            f64::from(s.temp_offset_c) + f64::from(s.temp_c_per_count) * f64::from(raw.temp);
        let accel = reference_sensor(&set.accel, raw.accel, s.accel_mps2_per_count, temp_c);
        let mut gyro = reference_sensor(&set.gyro, raw.gyro, s.gyro_rads_per_count, temp_c);
        if let Some(k) = set.gyro_g_sensitivity {
            for row in 0..3 {
                gyro[row] -= (0..3)
                    .map(|col| f64::from(k[row][col]) * accel[col])
                    .sum::<f64>();
            }
        }
        let mag = reference_sensor(&set.mag, raw.mag, s.mag_ut_per_count, temp_c);
        [accel, gyro, mag]
    }

    /// Deterministic spread of samples over the whole count range and −40…85 °C.
    fn samples() -> impl Iterator<Item = RawSample> {
        let mut state = 0x2545_f491_u32;
        core::iter::repeat_with(move || {
            let mut next = || {
                state ^= state << 13;
                state ^= state >> 17;
                state ^= state << 5;
                (state >> 16) as u16 as i16
            };
            RawSample {
                accel: [next(), next(), next()],
                gyro: [next(), next(), next()],
                mag: [next(), next(), next()],
                // 1/16 °C per count around 25 °C: −40…85 °C is −1040…960 counts.
                temp: next() % 1000,
            }
        })
        .take(20_000)
    }

    /// Largest error relative to the sensor's full scale over all samples.
    fn worst_error_of_full_scale(set: &CalibrationSet) -> f64 {
        let correction = Correction::new(set, &scales()).unwrap();
        let s = scales();
        let full_scale = [s.accel_range_mps2, s.gyro_range_rads, s.mag_range_ut].map(f64::from);
        let mut worst = 0.0f64;
        for raw in samples() {
            let ours = correction.apply(&raw);
            let truth = reference(set, &raw);
            for (sensor, (values, fs)) in [ours.accel, ours.gyro, ours.mag]
                .iter()
                .zip(full_scale)
                .enumerate()
            {
                for axis in 0..3 {
                    let error = (f64::from(values[axis]) - truth[sensor][axis]).abs() / fs;
                    worst = worst.max(error);
                }
            }
        }
        worst
    }

    #[test]
    fn linear_set_equals_a_times_x_minus_b_in_f64() {
        let mut set = CalibrationSet::identity();
        set.accel.a = [
            [1.02, 0.01, -0.005],
            [0.003, 0.98, 0.012],
            [-0.004, 0.006, 1.01],
        ];
        set.accel.b = [0.12, -0.3, 0.05];
        set.mag.a = [
            [1.0 / 48.0, 0.001, 0.0],
            [0.0, 1.0 / 52.0, -0.0005],
            [0.0, 0.0, 1.0 / 45.0],
        ];
        set.mag.b = [30.0, -12.0, 80.0];
        // f32 carries 2^-24 ≈ 6e-8 relative; folding and the 3-term dot product add a few
        // roundings of full-scale-sized terms, so 1e-6 of full scale bounds the error.
        let worst = worst_error_of_full_scale(&set);
        assert!(worst < 1e-6, "worst error {worst:e} of full scale");
    }

    #[test]
    fn every_extended_term_matches_the_f64_model() {
        // As above, plus the cubic temperature and non-linearity terms, each a few more
        // roundings: 2e-6 of full scale.
        let worst = worst_error_of_full_scale(&extended_set());
        assert!(worst < 2e-6, "worst error {worst:e} of full scale");
    }

    #[test]
    fn the_extended_terms_change_the_output_measurably() {
        // Guards the test above against a reference that ignores the terms as well.
        let extended = Correction::new(&extended_set(), &scales()).unwrap();
        let mut plain_set = extended_set();
        plain_set.accel.bias_temp = None;
        plain_set.accel.scale_temp = None;
        plain_set.accel.nonlinearity = None;
        plain_set.gyro_g_sensitivity = None;
        let plain = Correction::new(&plain_set, &scales()).unwrap();
        let raw = RawSample {
            accel: [20_000, -10_000, 16_000],
            gyro: [100, 200, -300],
            mag: [0; 3],
            temp: 800, // 75 °C, 50 °C above the accelerometer reference
        };
        let difference = (extended.apply(&raw).accel[0] - plain.apply(&raw).accel[0]).abs();
        assert!(
            difference > 0.05,
            "extended terms moved the output by only {difference}"
        );
    }

    #[test]
    fn identity_gives_nominal_units() {
        let correction = Correction::identity(&scales());
        let raw = RawSample {
            accel: [1000, -2000, 16_384],
            gyro: [-5, 0, 5],
            mag: [100, 200, 300],
            temp: -16,
        };
        let out = correction.apply(&raw);
        assert_eq!(out.accel[2], 16_384.0 * scales().accel_mps2_per_count);
        assert_eq!(out.gyro[0], -5.0 * scales().gyro_rads_per_count);
        assert_eq!(out.temp_c, 24.0);
    }

    #[test]
    fn an_invalid_set_is_refused_with_its_reason() {
        let mut set = CalibrationSet::identity();
        set.gyro.b[1] = f32::NAN;
        assert_eq!(
            Correction::new(&set, &scales()),
            Err(InvalidParamsReason::NonFinite)
        );
    }

    #[test]
    fn extreme_counts_and_temperatures_stay_finite() {
        let correction = Correction::new(&extended_set(), &scales()).unwrap();
        for v in [i16::MIN, i16::MAX] {
            let out = correction.apply(&RawSample {
                accel: [v; 3],
                gyro: [v; 3],
                mag: [v; 3],
                temp: v,
            });
            let all = out
                .accel
                .iter()
                .chain(&out.gyro)
                .chain(&out.mag)
                .chain([&out.temp_c]);
            assert!(all.into_iter().all(|x| x.is_finite()), "{out:?}");
        }
    }
}
