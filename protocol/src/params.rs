//! The calibration parameter set that the host fits and the device stores and applies.

use serde::{Deserialize, Serialize};

use crate::frame::crc32_of;
#[cfg(doc)]
use crate::validate::limits::MAX_DELTA_T_C;

/// Format version of [`CalibrationSet`] written by this crate.
///
/// Version 2 moved the reference temperature out of the bias polynomial into every sensor
/// ([`SensorCalibration::t_ref_c`]), so that a scale-temperature term has its own reference.
pub const PARAMS_FORMAT_VERSION: u16 = 2;

/// Upper bound of the postcard encoding of a [`CalibrationSet`], bytes.
///
/// Per sensor: `a` 36, `b` 12, `t_ref_c` 4, three option tags 3, bias temperature 36, scale
/// temperature 12, non-linearity 24, in all 127; three sensors 381; plus `format_version` ≤ 3 (varint),
/// `created_unix_s` ≤ 10 (varint), g-sensitivity 1 + 36, reference 8, residuals 12.
pub const PARAMS_MAX_ENCODED: usize = 3 * 127 + 3 + 10 + 37 + 8 + 12;

/// Temperature dependence of a sensor's offset: a cubic polynomial in `ΔT`, taken about the
/// sensor's [`SensorCalibration::t_ref_c`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BiasTemperature {
    /// `coeffs[k][axis]` is the degree-(k+1) coefficient for that raw axis, in the sensor's
    /// nominal unit per °C^(k+1); unused degrees are 0.
    pub coeffs: [[f32; 3]; 3],
}

/// Scale non-linearity of a sensor, applied element-wise to the offset-corrected reading.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Nonlinearity {
    /// Quadratic coefficients `q`, per axis, in 1 / nominal unit.
    pub quadratic: [f32; 3],
    /// Cubic coefficients `k`, per axis, in 1 / nominal unit².
    pub cubic: [f32; 3],
}

/// Reference temperature of an identity calibration, °C (room temperature; no term uses it).
pub const IDENTITY_T_REF_C: f32 = 25.0;

/// Which of the three calibrated sensors a value belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum SensorKind {
    /// Accelerometer (m/s²).
    Accel,
    /// Gyroscope (rad/s).
    Gyro,
    /// Magnetometer (µT).
    Mag,
}

impl SensorKind {
    /// The three sensors in the order a [`CalibrationSet`] holds them.
    pub const ALL: [SensorKind; 3] = [SensorKind::Accel, SensorKind::Gyro, SensorKind::Mag];

    /// The sensor's name as in parameter files: `accel`, `gyro`, `mag`.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Accel => "accel",
            Self::Gyro => "gyro",
            Self::Mag => "mag",
        }
    }

    /// The sensor named `accel`, `gyro` or `mag` ([`SensorKind::name`]), or `None`.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|s| s.name() == name)
    }

    /// Position in [`SensorKind::ALL`].
    pub const fn index(self) -> usize {
        match self {
            Self::Accel => 0,
            Self::Gyro => 1,
            Self::Mag => 2,
        }
    }
}

/// Calibration of one three-axis sensor; see [`CalibrationSet`] for how the terms combine.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SensorCalibration {
    /// Correction matrix `A`, row-major (`a[row][col]`), dimensionless.
    pub a: [[f32; 3]; 3],
    /// Offset `b` in the sensor's nominal unit (raw frame).
    pub b: [f32; 3],
    /// Reference temperature `T_ref` of every temperature term of this sensor, °C: the
    /// temperature the fit was made around. Always present, also when no term uses it.
    pub t_ref_c: f32,
    /// Temperature dependence of the offset, if modelled.
    pub bias_temp: Option<BiasTemperature>,
    /// Relative scale change per °C, per output axis (`s`), if modelled.
    pub scale_temp: Option<[f32; 3]>,
    /// Scale non-linearity, if modelled.
    pub nonlinearity: Option<Nonlinearity>,
}

impl SensorCalibration {
    /// `A = I`, `b = 0`, no extended terms: readings pass unchanged.
    pub const fn identity() -> Self {
        Self {
            a: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            b: [0.0; 3],
            t_ref_c: IDENTITY_T_REF_C,
            bias_temp: None,
            scale_temp: None,
            nonlinearity: None,
        }
    }
}

/// Reference magnitudes the calibration was fitted against.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ReferenceMagnitudes {
    /// Local gravity, m/s².
    pub gravity_mps2: f32,
    /// Local magnetic field magnitude, µT (1.0 when the fit left it as unit).
    pub field_ut: f32,
}

/// RMS residuals of the fit, in each sensor's nominal unit.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FitResiduals {
    /// Accelerometer residual RMS, m/s².
    pub accel_rms: f32,
    /// Gyroscope residual RMS, rad/s.
    pub gyro_rms: f32,
    /// Magnetometer residual RMS, µT.
    pub mag_rms: f32,
}

/// A complete calibration: what the host writes, the device stores, validates and applies.
///
/// Inputs are in nominal units (raw counts × the scale factor from `SensorScales`): `x` the
/// reading of one sensor, `T` the die temperature in °C. For each sensor:
///
/// ```text
/// ΔT    = clamp(T − T_ref, −MAX_DELTA_T_C, +MAX_DELTA_T_C)     (T_ref = the sensor's t_ref_c)
/// b(T)  = b + c1·ΔT + c2·ΔT² + c3·ΔT³          (bias_temp, if present; ck = coeffs[k-1])
/// u     = x − b(T)
/// u'    = u + q∘u² + k∘u³                       (nonlinearity, element-wise, if present)
/// y     = (1 + s·ΔT)∘(A·u')                     (scale_temp, if present)
/// y_gyro −= K·f                                  (gyro_g_sensitivity K, if present;
///                                                 f = the calibrated accelerometer output)
/// ```
///
/// Without extended terms this is `y = A·(x − b)`. `∘` is the element-wise product.
///
/// **The ΔT rule.** [`crate::validate`] checks every temperature term over
/// `|ΔT| ≤` [`MAX_DELTA_T_C`] (125 °C, the whole −40…85 °C industrial range from any plausible
/// reference), so every implementation clamps ΔT to that span: a thermometer reading on its
/// rail then still gives the checked, finite correction of the span's edge. The firmware, the
/// reference [`crate::model::apply`] and the generated C and Rust exports all apply this rule.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CalibrationSet {
    /// Layout version of this set ([`PARAMS_FORMAT_VERSION`] when written by this crate).
    pub format_version: u16,
    /// Creation time, seconds since the Unix epoch (0 when unknown).
    pub created_unix_s: u64,
    /// Accelerometer calibration, output in m/s².
    pub accel: SensorCalibration,
    /// Gyroscope calibration, output in rad/s.
    pub gyro: SensorCalibration,
    /// Magnetometer calibration, output in µT.
    pub mag: SensorCalibration,
    /// Gyro g-sensitivity `K`, row-major, rad/s per m/s².
    pub gyro_g_sensitivity: Option<[[f32; 3]; 3]>,
    /// Reference magnitudes of the fit.
    pub reference: ReferenceMagnitudes,
    /// Fit residuals.
    pub residuals: FitResiduals,
}

impl CalibrationSet {
    /// The calibration of one sensor.
    pub fn sensor(&self, kind: SensorKind) -> &SensorCalibration {
        match kind {
            SensorKind::Accel => &self.accel,
            SensorKind::Gyro => &self.gyro,
            SensorKind::Mag => &self.mag,
        }
    }

    /// The set that leaves every reading unchanged (what `ResetParams` installs).
    pub const fn identity() -> Self {
        Self {
            format_version: PARAMS_FORMAT_VERSION,
            created_unix_s: 0,
            accel: SensorCalibration::identity(),
            gyro: SensorCalibration::identity(),
            mag: SensorCalibration::identity(),
            gyro_g_sensitivity: None,
            reference: ReferenceMagnitudes {
                gravity_mps2: 9.806_65,
                field_ut: 1.0,
            },
            residuals: FitResiduals {
                accel_rms: 0.0,
                gyro_rms: 0.0,
                mag_rms: 0.0,
            },
        }
    }

    /// CRC-32 (ISO-HDLC) of the set's postcard encoding, as sent with `WriteParams`.
    pub fn crc32(&self) -> u32 {
        crc32_of(self)
    }
}

impl Default for CalibrationSet {
    fn default() -> Self {
        Self::identity()
    }
}
