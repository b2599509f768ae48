//! Reference values given by the user (`--gravity`, `--field-ut`, `--gyro-scale`), checked once
//! for every command against physically possible ranges, so that a typo (`--gravity 1e300`,
//! `--field-ut 0.0485` in tesla) is refused with a sentence instead of producing infinite or
//! meaningless output.

/// Local gravity accepted, m/s². Earth's surface gravity spans about 9.76 (high Andes) to
/// 9.834 (poles); the range leaves room for altitude and local anomalies, and refuses g-units
/// (1.0) and other mistakes.
pub const GRAVITY_RANGE_MPS2: (f64, f64) = (9.7, 9.9);

/// Field magnitude accepted, µT. Earth's main field is 22–67 µT at the surface; a coil cage or
/// a magnetised enclosure may differ, so the range is wide: from 1 µT (below which a
/// magnetometer's noise dominates) to 5 mT (above the full scale of common magnetometers).
pub const FIELD_RANGE_UT: (f64, f64) = (1.0, 5000.0);

/// Gyroscope scale accepted, rad/s per count: from 125 °/s over 2¹⁶ counts (the finest common
/// range, 3.3e-5) down a decade, to 4000 °/s over 2¹² counts (the coarsest, 0.034) up a decade.
pub const GYRO_SCALE_RANGE: (f64, f64) = (3e-6, 0.35);

/// A reference value outside its range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{flag} {shown} is outside {low}–{high} {unit} ({why}); {fix}")]
pub struct ReferenceError {
    /// The flag, e.g. `--gravity`.
    pub flag: &'static str,
    /// The value given.
    pub value: f64,
    /// The value as shown (scientific notation when very large or small).
    pub shown: String,
    /// Lower bound.
    pub low: f64,
    /// Upper bound.
    pub high: f64,
    /// Unit of the bounds.
    pub unit: &'static str,
    /// What the range is.
    pub why: &'static str,
    /// How to fix it.
    pub fix: &'static str,
}

/// Checked reference values.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct References {
    /// Local gravity, m/s².
    pub gravity_mps2: f64,
    /// Local field magnitude, µT (`None`: from `--location`, or normalised to 1).
    pub field_ut: Option<f64>,
    /// Gyroscope scale, rad/s per count (only for gyroscope data in counts).
    pub gyro_scale: Option<f64>,
}

fn in_range(
    flag: &'static str,
    value: f64,
    (low, high): (f64, f64),
    unit: &'static str,
    why: &'static str,
    fix: &'static str,
) -> Result<f64, ReferenceError> {
    if value.is_finite() && (low..=high).contains(&value) {
        Ok(value)
    } else {
        let magnitude = value.abs();
        let shown = if value == 0.0 || !value.is_finite() || (1e-3..1e6).contains(&magnitude) {
            format!("{value}")
        } else {
            format!("{value:e}")
        };
        Err(ReferenceError {
            flag,
            value,
            shown,
            low,
            high,
            unit,
            why,
            fix,
        })
    }
}

impl References {
    /// Check every value against its range.
    pub fn checked(
        gravity_mps2: f64,
        field_ut: Option<f64>,
        gyro_scale: Option<f64>,
    ) -> Result<Self, ReferenceError> {
        Ok(Self {
            gravity_mps2: in_range(
                "--gravity",
                gravity_mps2,
                GRAVITY_RANGE_MPS2,
                "m/s²",
                "gravity on the Earth's surface",
                "give local gravity in m/s², or leave the flag out for standard gravity",
            )?,
            field_ut: field_ut
                .map(|h| {
                    in_range(
                        "--field-ut",
                        h,
                        FIELD_RANGE_UT,
                        "µT",
                        "fields a magnetometer can measure",
                        "give the field magnitude in microtesla (1 gauss = 100 µT), or use --location",
                    )
                })
                .transpose()?,
            gyro_scale: gyro_scale
                .map(|s| {
                    in_range(
                        "--gyro-scale",
                        s,
                        GYRO_SCALE_RANGE,
                        "rad/s per count",
                        "the ranges of MEMS gyroscopes",
                        "give the data sheet's sensitivity in rad/s per count (°/s per count × π/180)",
                    )
                })
                .transpose()?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn absurd_reference_values_are_refused_with_the_flag_and_a_fix() {
        for (g, h, s, flag) in [
            (1e300, None, None, "--gravity"),
            (1.0, None, None, "--gravity"),
            (f64::NAN, None, None, "--gravity"),
            (9.81, Some(0.0485), None, "--field-ut"),
            (9.81, Some(f64::INFINITY), None, "--field-ut"),
            (9.81, None, Some(-1.0), "--gyro-scale"),
        ] {
            let message = References::checked(g, h, s)
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default();
            assert!(message.starts_with(flag), "{message}");
        }
    }

    #[test]
    fn ordinary_values_pass_unchanged() {
        let r = References::checked(9.80665, Some(48.5), Some(1.33e-4)).expect("in range");
        assert_eq!(r.gravity_mps2, 9.80665);
        assert_eq!(r.field_ut, Some(48.5));
        assert_eq!(r.gyro_scale, Some(1.33e-4));
    }
}
