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
//!
//! Which terms a set uses is decided once, at load time, and kept as the per-sample function:
//! a set with none of the extended terms (the common case) gets the plain path, `y = M·c − o`
//! per sensor with `M = A·σ`, `o = A·b`, straight-line code of three multiply-adds per axis and
//! no branch at all. Any extended term selects the extended path, whose only branches are on
//! which terms are present. No path branches on the data, so the time per sample is constant
//! for a given set. Validated parameters and `i16` counts keep every intermediate far from
//! `f32` overflow, so no input produces NaN or infinity.
//!
//! Validation is the protocol's [`imucal_protocol::validate()`], and ΔT follows its one rule
//! ([`imucal_protocol::delta_t_c`]: `T − T_ref` of the sensor, clamped to the validated span), so
//! the result matches the reference [`imucal_protocol::model::apply`] to f32 rounding.

use imucal_protocol::{
    delta_t_c, validate, CalibratedSample, CalibrationSet, InvalidParamsReason, SensorCalibration,
};

use crate::imu::{RawSample, SensorScales};

type Vec3 = [f32; 3];
type Mat3 = [[f32; 3]; 3];

/// A sensor's correction without extended terms, on counts: `y = M·c − o`, with `M = A·σ` and
/// `o = A·b`. Twelve consecutive `f32`, offset first, in the order [`affine_counts`] takes them.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
struct AffineSensor {
    /// `o = A·b`.
    offset: Vec3,
    /// `M = A·σ`, per count.
    matrix: Mat3,
}

impl AffineSensor {
    fn new(sensor: &SensorCalibration, per_count: f32) -> Self {
        Self {
            offset: mat_vec(&sensor.a, &sensor.b),
            matrix: sensor.a.map(|row| row.map(|v| v * per_count)),
        }
    }

    #[inline(always)]
    fn apply(&self, counts: &[i16; 3]) -> Vec3 {
        let [o0, o1, o2] = self.offset;
        let [[m00, m01, m02], [m10, m11, m12], [m20, m21, m22]] = self.matrix;
        affine_counts(
            o0, o1, o2, m00, m01, m02, m10, m11, m12, m20, m21, m22, counts,
        )
    }
}

/// Die temperature in °C as `offset_c + c_per_count·counts`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Thermometer {
    c_per_count: f32,
    offset_c: f32,
}

impl Thermometer {
    #[inline(always)]
    fn celsius(self, counts: i16) -> f32 {
        self.offset_c + self.c_per_count * f32::from(counts)
    }
}

/// The plain path's parameters, in the order it reads them. `repr(C)` keeps each sensor's
/// twelve coefficients contiguous, for the single load of [`affine_counts`]'s arguments.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
struct PlainSet {
    accel: AffineSensor,
    gyro: AffineSensor,
    mag: AffineSensor,
    thermometer: Thermometer,
}

impl PlainSet {
    /// `M·c − o` per sensor.
    #[inline(always)]
    fn apply(&self, raw: &RawSample) -> CalibratedSample {
        CalibratedSample {
            accel: self.accel.apply(&raw.accel),
            gyro: self.gyro.apply(&raw.gyro),
            mag: self.mag.apply(&raw.mag),
            temp_c: self.thermometer.celsius(raw.temp),
        }
    }
}

/// `M·c − o` for one sensor, per axis as `(m0·c0 − o) + m1·c1 + m2·c2`: a multiply-subtract
/// and two multiply-adds.
///
/// Out of line, with the coefficients as twelve scalar arguments, on purpose: on a hard-float
/// target they then travel in twelve consecutive FPU registers, so the caller fetches them with
/// one load-multiple instead of twelve loads, and the three results (returned through memory)
/// are written with one store-multiple straight into the caller's output. Inlined, the
/// register allocator scatters the values and every one costs its own load. This relies on
/// how the compiler passes arguments today, not on a guarantee; were that to change, only the
/// speed would (`cargo xtask firmware bench` checks it), never the result.
#[inline(never)]
#[allow(clippy::too_many_arguments)] // one argument per FPU register is the point
fn affine_counts(
    o0: f32,
    o1: f32,
    o2: f32,
    m00: f32,
    m01: f32,
    m02: f32,
    m10: f32,
    m11: f32,
    m12: f32,
    m20: f32,
    m21: f32,
    m22: f32,
    counts: &[i16; 3],
) -> Vec3 {
    let [c0, c1, c2] = counts.map(f32::from);
    [
        (m00 * c0 - o0) + m01 * c1 + m02 * c2,
        (m10 * c0 - o1) + m11 * c1 + m12 * c2,
        (m20 * c0 - o2) + m21 * c1 + m22 * c2,
    ]
}

/// One sensor's correction with any of the extended terms, folded for the hot path.
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
        let t_ref_c = sensor.t_ref_c;
        let coeffs = sensor.bias_temp.map_or([[0.0; 3]; 3], |t| t.coeffs);
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

    /// Whether no extended term survived folding (all-zero terms count as absent).
    fn is_affine(&self) -> bool {
        self.bias_degree == 0 && self.scale_temp.is_none() && self.nonlinearity.is_none()
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

    /// The sensor's output at `temp_c`. Always inlined: its one caller, the extended path, is
    /// out of line anyway, and three inlined copies cost 54 fewer instructions per sample for
    /// under 1 KiB of flash.
    #[inline(always)]
    fn apply(&self, counts: [i16; 3], temp_c: f32) -> Vec3 {
        let c = counts.map(f32::from);
        // Validation bounds the extended terms over the clamped span; a reading on the
        // thermometer's rail stays inside it.
        let dt = delta_t_c(temp_c, self.t_ref_c);
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

/// The three sensors and the gyroscope's g-sensitivity when some extended term is present.
#[derive(Debug, Clone, Copy, PartialEq)]
struct ExtendedSet {
    accel: SensorCorrection,
    gyro: SensorCorrection,
    mag: SensorCorrection,
    gyro_g_sensitivity: Option<Mat3>,
    thermometer: Thermometer,
}

impl ExtendedSet {
    fn apply(&self, raw: &RawSample) -> CalibratedSample {
        let temp_c = self.thermometer.celsius(raw.temp);
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

/// The per-sample function of a [`Correction`], chosen when the set is loaded. The sample comes
/// first: it is then already where the plain path passes the accelerometer counts on.
type Kernel = fn(&RawSample, &Correction) -> CalibratedSample;

/// A validated calibration set folded for the per-sample path.
///
/// The kind of correction is a function pointer chosen at load time rather than an enum
/// matched per sample: the call through it is the whole dispatch, and the plain path's
/// coefficients sit at the start of the structure (`repr(C)`), where it loads them from
/// without any address arithmetic.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct Correction {
    /// The set's affine part; the whole correction when `extended` is `None`.
    plain: PlainSet,
    kernel: Kernel,
    /// Present when the set uses an extended term.
    extended: Option<ExtendedSet>,
}

impl PartialEq for Correction {
    /// Equal parameters; the kernel follows from them, and function addresses are not
    /// meaningful to compare.
    fn eq(&self, other: &Self) -> bool {
        self.plain == other.plain && self.extended == other.extended
    }
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

    /// Whether the set folded into the plain `A·(x − b)` path, i.e. uses no extended term
    /// (terms whose coefficients are all zero count as absent).
    pub fn is_plain(&self) -> bool {
        self.extended.is_none()
    }

    fn fold(set: &CalibrationSet, scales: &SensorScales) -> Self {
        let thermometer = Thermometer {
            c_per_count: scales.temp_c_per_count,
            offset_c: scales.temp_offset_c,
        };
        let gyro_g_sensitivity = set
            .gyro_g_sensitivity
            .filter(|k| k.iter().flatten().any(|&v| v != 0.0));
        let accel = SensorCorrection::new(&set.accel, scales.accel_mps2_per_count);
        let gyro = SensorCorrection::new(&set.gyro, scales.gyro_rads_per_count);
        let mag = SensorCorrection::new(&set.mag, scales.mag_ut_per_count);
        let affine =
            gyro_g_sensitivity.is_none() && [accel, gyro, mag].iter().all(|s| s.is_affine());
        let extended = (!affine).then_some(ExtendedSet {
            accel,
            gyro,
            mag,
            gyro_g_sensitivity,
            thermometer,
        });
        Self {
            plain: PlainSet {
                accel: AffineSensor::new(&set.accel, scales.accel_mps2_per_count),
                gyro: AffineSensor::new(&set.gyro, scales.gyro_rads_per_count),
                mag: AffineSensor::new(&set.mag, scales.mag_ut_per_count),
                thermometer,
            },
            kernel: if extended.is_some() {
                Self::apply_extended
            } else {
                Self::apply_plain
            },
            extended,
        }
    }

    /// Calibrate one raw sample.
    pub fn apply(&self, raw: &RawSample) -> CalibratedSample {
        (self.kernel)(raw, self)
    }

    fn apply_plain(raw: &RawSample, correction: &Self) -> CalibratedSample {
        correction.plain.apply(raw)
    }

    fn apply_extended(raw: &RawSample, correction: &Self) -> CalibratedSample {
        // `extended` is always present when this kernel is chosen; the affine part is the
        // meaningful answer should that ever not hold.
        match &correction.extended {
            Some(extended) => extended.apply(raw),
            None => correction.plain.apply(raw),
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
    use imucal_protocol::{model, BiasTemperature, NominalSample, Nonlinearity, SensorKind};

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
        set.accel.t_ref_c = 25.0;
        set.accel.bias_temp = Some(BiasTemperature {
            coeffs: [[2e-3, -1e-3, 5e-4], [1e-5, 0.0, -2e-5], [1e-7, 3e-7, 0.0]],
        });
        set.accel.scale_temp = Some([1e-4, -2e-4, 5e-5]);
        set.accel.nonlinearity = Some(Nonlinearity {
            quadratic: [1e-3, -5e-4, 2e-4],
            cubic: [1e-5, 0.0, -2e-5],
        });
        set.gyro.a = [[1.01, -0.02, 0.0], [0.015, 0.99, 0.004], [0.0, 0.01, 1.03]];
        set.gyro.b = [0.01, -0.02, 0.005];
        set.gyro.t_ref_c = 30.0;
        set.gyro.bias_temp = Some(BiasTemperature {
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

    /// The protocol's f64 reference model on the same sample in nominal units.
    fn reference(set: &CalibrationSet, raw: &RawSample) -> [[f64; 3]; 3] {
        let s = scales();
        let nominal =
            |counts: [i16; 3], per_count: f32| counts.map(|c| f64::from(c) * f64::from(per_count));
        let out = model::apply(
            set,
            &NominalSample {
                accel: nominal(raw.accel, s.accel_mps2_per_count),
                gyro: nominal(raw.gyro, s.gyro_rads_per_count),
                mag: nominal(raw.mag, s.mag_ut_per_count),
                temp_c: f64::from(s.temp_offset_c)
                    + f64::from(s.temp_c_per_count) * f64::from(raw.temp),
            },
        );
        [out.accel, out.gyro, out.mag]
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
    fn scale_temperature_alone_scales_about_the_sensors_own_reference() {
        // s = 1e-4/°C about T_ref = 25 °C, no bias polynomial: y = (1 + s·(T − 25))·σ·c, so no
        // scale change at all at 25 °C (format 1 took T_ref = 0 here and scaled by 1.0025).
        let s = scales();
        let mut set = CalibrationSet::identity();
        set.accel.t_ref_c = 25.0;
        set.accel.scale_temp = Some([1e-4; 3]);
        let correction = Correction::new(&set, &s).unwrap();
        let counts = [16_384i16, -8_192, 4_000];
        // 10…40 °C in 1 °C steps: 16 counts per °C around 25 °C at 0 counts.
        for temp_c in 10..=40 {
            let raw = RawSample {
                accel: counts,
                temp: ((temp_c - 25) * 16) as i16,
                ..RawSample::default()
            };
            let out = correction.apply(&raw).accel;
            let gain = 1.0 + 1e-4 * f64::from(temp_c - 25);
            for axis in 0..3 {
                let expected = gain * f64::from(counts[axis]) * f64::from(s.accel_mps2_per_count);
                // f32 rounding of a ≈10 m/s² product: a few 1e-7 relative.
                let error = (f64::from(out[axis]) - expected).abs();
                assert!(
                    error <= 1e-6 * expected.abs(),
                    "{temp_c} °C axis {axis}: {error:e}"
                );
                if temp_c == 25 {
                    let nominal = f32::from(counts[axis]) * s.accel_mps2_per_count;
                    assert_eq!(out[axis], nominal, "no scale change at T_ref");
                }
            }
        }
    }

    #[test]
    fn temperatures_beyond_the_validated_span_get_its_edge_correction() {
        let s = scales();
        let set = extended_set();
        let correction = Correction::new(&set, &s).unwrap();
        // Thermometer rails: i16::MAX counts is 2073 °C, i16::MIN is −2023 °C.
        for rail in [i16::MIN, i16::MAX] {
            let raw = RawSample {
                accel: [12_000, -3_000, 9_000],
                gyro: [400, -200, 100],
                mag: [1_000, 2_000, -3_000],
                temp: rail,
            };
            let ours = correction.apply(&raw);
            let truth = reference(&set, &raw);
            for (values, truth) in [ours.accel, ours.gyro, ours.mag].iter().zip(truth) {
                for axis in 0..3 {
                    let error = (f64::from(values[axis]) - truth[axis]).abs();
                    assert!(error <= 1e-5 * truth[axis].abs().max(1.0), "{error:e}");
                }
            }
        }
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
    fn only_sets_with_a_nonzero_extended_term_leave_the_plain_path() {
        // The accuracy tests above go through whichever path a set selects; this pins which.
        let s = scales();
        assert!(Correction::identity(&s).is_plain());
        let mut zero_terms = extended_set();
        for sensor in [
            &mut zero_terms.accel,
            &mut zero_terms.gyro,
            &mut zero_terms.mag,
        ] {
            sensor.bias_temp = sensor.bias_temp.map(|_| BiasTemperature {
                coeffs: [[0.0; 3]; 3],
            });
            sensor.scale_temp = sensor.scale_temp.map(|_| [0.0; 3]);
            sensor.nonlinearity = sensor.nonlinearity.map(|_| Nonlinearity {
                quadratic: [0.0; 3],
                cubic: [0.0; 3],
            });
        }
        zero_terms.gyro_g_sensitivity = Some([[0.0; 3]; 3]);
        assert!(Correction::new(&zero_terms, &s).unwrap().is_plain());
        assert!(!Correction::new(&extended_set(), &s).unwrap().is_plain());
        let mut only_g_sensitivity = zero_terms;
        only_g_sensitivity.gyro_g_sensitivity = extended_set().gyro_g_sensitivity;
        assert!(!Correction::new(&only_g_sensitivity, &s).unwrap().is_plain());
    }

    #[test]
    fn zero_extended_terms_give_the_same_output_as_none() {
        // A set whose extended terms are present but zero takes the plain path, and must
        // calibrate exactly as the same set without them (both are the plain path's arithmetic).
        let s = scales();
        let mut plain = extended_set();
        for sensor in [&mut plain.accel, &mut plain.gyro, &mut plain.mag] {
            sensor.bias_temp = None;
            sensor.scale_temp = None;
            sensor.nonlinearity = None;
        }
        plain.gyro_g_sensitivity = None;
        let mut zero_terms = plain;
        zero_terms.accel.scale_temp = Some([0.0; 3]);
        zero_terms.gyro_g_sensitivity = Some([[0.0; 3]; 3]);
        let a = Correction::new(&plain, &s).unwrap();
        let b = Correction::new(&zero_terms, &s).unwrap();
        for raw in samples().take(1000) {
            assert_eq!(a.apply(&raw), b.apply(&raw));
        }
    }

    #[test]
    fn an_invalid_set_is_refused_with_its_reason() {
        let mut set = CalibrationSet::identity();
        set.gyro.b[1] = f32::NAN;
        assert_eq!(
            Correction::new(&set, &scales()),
            Err(InvalidParamsReason::NonFinite(
                imucal_protocol::ParamField::Offset(SensorKind::Gyro)
            ))
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
