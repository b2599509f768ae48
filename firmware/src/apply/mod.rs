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
mod tests;
