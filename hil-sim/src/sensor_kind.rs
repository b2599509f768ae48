//! The three vector sensors (the protocol's [`SensorKind`]), the LSM9DS1's nominal scale of
//! each, and the lower-case serde names the simulator's files use for them.

pub use imucal_protocol::SensorKind;

use crate::world::STANDARD_GRAVITY_MPS2;

/// Accelerometer sensitivity at ±4 g: 0.122 mg/LSB, in m/s² per count.
pub const ACCEL_MPS2_PER_COUNT: f64 = 0.122e-3 * STANDARD_GRAVITY_MPS2;
/// Gyroscope sensitivity at ±500 °/s: 17.5 m°/s per LSB, in rad/s per count.
pub const GYRO_RADS_PER_COUNT: f64 = 17.5e-3 * std::f64::consts::PI / 180.0;
/// Magnetometer sensitivity at ±4 gauss: 0.14 mgauss/LSB, in µT per count.
pub const MAG_UT_PER_COUNT: f64 = 0.014;

/// The simulated chip's nominal scale of a sensor.
pub trait NominalScale {
    /// Nominal units per count of the LSM9DS1.
    fn units_per_count(self) -> f64;
}

impl NominalScale for SensorKind {
    fn units_per_count(self) -> f64 {
        match self {
            SensorKind::Accel => ACCEL_MPS2_PER_COUNT,
            SensorKind::Gyro => GYRO_RADS_PER_COUNT,
            SensorKind::Mag => MAG_UT_PER_COUNT,
        }
    }
}

/// Serde for an optional [`SensorKind`] by its lower-case name (`"accel"`, `"gyro"`, `"mag"`,
/// or `null`), as the simulator's configuration and truth files have always written it; use with
/// `#[serde(with = "crate::sensor_kind::optional_name")]`.
pub mod optional_name {
    use serde::de::Error;
    use serde::{Deserialize, Deserializer, Serializer};

    use super::SensorKind;

    /// Write the sensor's name, or `null`.
    pub fn serialize<S: Serializer>(
        sensor: &Option<SensorKind>,
        serializer: S,
    ) -> Result<S::Ok, S::Error> {
        match sensor {
            Some(s) => serializer.serialize_some(s.name()),
            None => serializer.serialize_none(),
        }
    }

    /// Read a sensor's name, or `null`.
    pub fn deserialize<'de, D: Deserializer<'de>>(
        deserializer: D,
    ) -> Result<Option<SensorKind>, D::Error> {
        Option::<String>::deserialize(deserializer)?
            .map(|name| {
                SensorKind::from_name(&name).ok_or_else(|| {
                    D::Error::custom(format!(
                        "sensor `{name}` is unknown; use accel, gyro or mag"
                    ))
                })
            })
            .transpose()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde::{Deserialize, Serialize};

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    struct Holder {
        #[serde(with = "optional_name")]
        sensor: Option<SensorKind>,
    }

    #[test]
    fn sensors_are_written_by_their_lower_case_names_and_read_back() {
        for (sensor, text) in [
            (Some(SensorKind::Accel), r#"{"sensor":"accel"}"#),
            (Some(SensorKind::Gyro), r#"{"sensor":"gyro"}"#),
            (Some(SensorKind::Mag), r#"{"sensor":"mag"}"#),
            (None, r#"{"sensor":null}"#),
        ] {
            let holder = Holder { sensor };
            assert_eq!(serde_json::to_string(&holder).ok().as_deref(), Some(text));
            let back: Holder = serde_json::from_str(text).expect("reads back");
            assert_eq!(back, holder);
        }
    }

    #[test]
    fn an_unknown_sensor_name_is_an_error_naming_the_choices() {
        let err = serde_json::from_str::<Holder>(r#"{"sensor":"Gyro"}"#)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(err.contains("use accel, gyro or mag"), "{err}");
    }
}
