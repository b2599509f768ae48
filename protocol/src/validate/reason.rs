//! Why a calibration set was refused: which field, and which bound it broke.

use core::fmt;

use serde::{Deserialize, Serialize};

use super::limits::{
    GAIN_LIMITS, MAX_CONDITION_FROBENIUS, MAX_DELTA_T_C, MAX_G_SENSITIVITY, MAX_NONLINEAR_CHANGE,
    MAX_SCALE_TEMP_CHANGE, REFERENCE_TEMP_RANGE_C,
};
use crate::params::{SensorKind, PARAMS_FORMAT_VERSION};

/// A field of a [`crate::CalibrationSet`], named as in parameter files.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum ParamField {
    /// A sensor's matrix `A`.
    Matrix(SensorKind),
    /// A sensor's offset `b`.
    Offset(SensorKind),
    /// A sensor's reference temperature `t_ref_c`.
    ReferenceTemperature(SensorKind),
    /// A sensor's bias temperature polynomial.
    BiasTemperature(SensorKind),
    /// A sensor's scale temperature coefficients.
    ScaleTemperature(SensorKind),
    /// A sensor's non-linearity coefficients.
    Nonlinearity(SensorKind),
    /// The gyroscope's g-sensitivity matrix `K`.
    GyroGSensitivity,
    /// The reference magnitudes of the fit.
    Reference,
    /// The fit residuals.
    Residuals,
}

impl fmt::Display for ParamField {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (sensor, field) = match self {
            Self::Matrix(s) => (Some(s), "A"),
            Self::Offset(s) => (Some(s), "b"),
            Self::ReferenceTemperature(s) => (Some(s), "t_ref_c"),
            Self::BiasTemperature(s) => (Some(s), "bias_temp"),
            Self::ScaleTemperature(s) => (Some(s), "scale_temp"),
            Self::Nonlinearity(s) => (Some(s), "nonlinearity"),
            Self::GyroGSensitivity => (None, "gyro_g_sensitivity"),
            Self::Reference => (None, "reference"),
            Self::Residuals => (None, "residuals"),
        };
        match sensor {
            Some(s) => write!(f, "{}.{field}", s.name()),
            None => f.write_str(field),
        }
    }
}

/// Why a calibration set was refused; its `Display` is a sentence naming the field, the bound
/// and what to do.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum InvalidParamsReason {
    /// A value is NaN or infinite.
    NonFinite(ParamField),
    /// A matrix `A` is singular or its condition number exceeds [`MAX_CONDITION_FROBENIUS`].
    IllConditioned(SensorKind),
    /// An offset `b` lies outside the sensor's full-scale range.
    OffsetOutOfRange(SensorKind),
    /// A matrix `A` scales readings implausibly far from 1 ([`GAIN_LIMITS`]).
    GainOutOfRange(SensorKind),
    /// A reference temperature lies outside [`REFERENCE_TEMP_RANGE_C`].
    ReferenceTemperatureOutOfRange(SensorKind),
    /// A temperature, non-linearity or g-sensitivity term is implausibly large.
    ExtendedTermOutOfRange(ParamField),
    /// The set's `format_version` is not the one this side reads.
    UnsupportedFormat {
        /// The version found in the set.
        found: u16,
    },
    /// The accelerometer's or gyroscope's `A` reverses an axis (`det A < 0`): the sensor's axes
    /// are mapped wrongly into the board frame (protocol 3.1).
    MirroredAxes(SensorKind),
}

impl InvalidParamsReason {
    /// A fixed sentence of the cause and what to try, without the field (a short status line);
    /// `Display` gives the full sentence naming the field and the bound.
    pub fn describe(&self) -> &'static str {
        match self {
            Self::NonFinite(_) => {
                "the parameter set contains NaN or infinite values; refit the calibration from new data"
            }
            Self::IllConditioned(_) => {
                "a calibration matrix is singular or badly conditioned; check the fit (enough distinct poses?) and refit"
            }
            Self::OffsetOutOfRange(_) => {
                "an offset lies outside the sensor's range; check the units of the data used for the fit"
            }
            Self::GainOutOfRange(_) => {
                "a calibration matrix scales readings implausibly; check the units and reference magnitudes of the fit"
            }
            Self::ReferenceTemperatureOutOfRange(_) => {
                "a reference temperature is not one a part can have; set it to the temperature the fit was made at"
            }
            Self::ExtendedTermOutOfRange(_) => {
                "a temperature, non-linearity or g-sensitivity term is implausibly large; refit without that effect"
            }
            Self::UnsupportedFormat { .. } => {
                "the parameter format version is not the one this side reads; update the firmware or the host tool"
            }
            Self::MirroredAxes(_) => {
                "a calibration matrix reverses an axis, which no scale, misalignment or soft-iron error does; fix the sign of that axis in the driver's axis mapping and measure again"
            }
        }
    }

    /// What to try (the part of [`Self::describe`] after the cause).
    fn remedy(&self) -> &'static str {
        let sentence = self.describe();
        sentence
            .split_once("; ")
            .map_or(sentence, |(_, remedy)| remedy)
    }
}

impl fmt::Display for InvalidParamsReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let advice = self.remedy();
        match self {
            Self::NonFinite(field) => {
                write!(f, "{field} contains NaN or an infinite value; {advice}")
            }
            Self::IllConditioned(s) => write!(
                f,
                "{}.A is singular or its condition number ‖A‖·‖A⁻¹‖ exceeds {MAX_CONDITION_FROBENIUS}; {advice}",
                s.name()
            ),
            Self::OffsetOutOfRange(s) => write!(
                f,
                "{}.b lies outside the sensor's full-scale range; {advice}",
                s.name()
            ),
            Self::GainOutOfRange(s) => {
                let (low, high) = GAIN_LIMITS[*s as usize];
                write!(
                    f,
                    "{}.A has an RMS gain outside {low}…{high} (a fit in g instead of m/s² has 1/9.8); {advice}",
                    s.name()
                )
            }
            Self::ReferenceTemperatureOutOfRange(s) => {
                let (low, high) = REFERENCE_TEMP_RANGE_C;
                write!(
                    f,
                    "{}.t_ref_c lies outside {low}…{high} °C; {advice}",
                    s.name()
                )
            }
            Self::ExtendedTermOutOfRange(field) => {
                write!(f, "{field} ")?;
                match field {
                    ParamField::BiasTemperature(_) => write!(
                        f,
                        "moves the offset beyond the full-scale range within ±{MAX_DELTA_T_C} °C of t_ref_c"
                    )?,
                    ParamField::ScaleTemperature(_) => write!(
                        f,
                        "changes the scale by more than {} % within ±{MAX_DELTA_T_C} °C of t_ref_c",
                        MAX_SCALE_TEMP_CHANGE * 100.0
                    )?,
                    ParamField::Nonlinearity(_) => write!(
                        f,
                        "changes a full-scale reading by more than {MAX_NONLINEAR_CHANGE} of itself"
                    )?,
                    _ => write!(f, "has an entry above {MAX_G_SENSITIVITY} rad/s per m/s²")?,
                }
                write!(f, "; {advice}")
            }
            Self::UnsupportedFormat { found } => write!(
                f,
                "the parameter set has format {found}, this side reads format {PARAMS_FORMAT_VERSION}; {advice}"
            ),
            Self::MirroredAxes(s) => write!(
                f,
                "{}.A has a negative determinant: it mirrors the sensor's axes, which no scale, \
                 misalignment or soft-iron error does; {advice}",
                s.name()
            ),
        }
    }
}

impl core::error::Error for InvalidParamsReason {}
