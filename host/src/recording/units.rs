//! Units of the sensor columns in a recording and their factors to SI (m/s², rad/s, µT).
//!
//! A recording keeps its values exactly as read; the unit only says how to interpret them.
//! Raw counts have no factor: their scale is what a calibration determines.

use std::fmt;

/// Standard gravity, used to convert readings given in g to m/s² (ISO 80000-3).
pub const STANDARD_GRAVITY: f64 = 9.80665;

/// The three sensors a recording can carry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Sensor {
    /// Accelerometer (columns `ax ay az`).
    Accel,
    /// Gyroscope (columns `gx gy gz`).
    Gyro,
    /// Magnetometer (columns `mx my mz`).
    Mag,
}

impl Sensor {
    /// All sensors in their usual order.
    pub const ALL: [Sensor; 3] = [Sensor::Accel, Sensor::Gyro, Sensor::Mag];

    /// Name used on the command line and as a JSON key.
    pub fn name(self) -> &'static str {
        match self {
            Sensor::Accel => "accel",
            Sensor::Gyro => "gyro",
            Sensor::Mag => "mag",
        }
    }

    /// The three CSV column names of this sensor.
    pub fn columns(self) -> [&'static str; 3] {
        match self {
            Sensor::Accel => ["ax", "ay", "az"],
            Sensor::Gyro => ["gx", "gy", "gz"],
            Sensor::Mag => ["mx", "my", "mz"],
        }
    }
}

impl fmt::Display for Sensor {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Unit of accelerometer columns.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum AccelUnit {
    /// Metres per second squared (the format's default).
    #[default]
    Mps2,
    /// Multiples of standard gravity.
    G,
    /// Raw sensor counts (scale unknown until calibrated).
    Counts,
}

/// Unit of gyroscope columns.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum GyroUnit {
    /// Radians per second (the format's default).
    #[default]
    Rads,
    /// Degrees per second.
    Dps,
    /// Raw sensor counts (scale unknown unless given separately).
    Counts,
}

/// Unit of magnetometer columns.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MagUnit {
    /// Microtesla (the format's default).
    #[default]
    Ut,
    /// Gauss (1 G = 100 µT).
    Gauss,
    /// Raw sensor counts.
    Counts,
}

impl AccelUnit {
    /// Factor from this unit to m/s², if one exists.
    pub fn to_si(self) -> Option<f64> {
        match self {
            AccelUnit::Mps2 => Some(1.0),
            AccelUnit::G => Some(STANDARD_GRAVITY),
            AccelUnit::Counts => None,
        }
    }

    /// Parse a command-line name (`mps2`, `g`, `counts`).
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "mps2" => Some(AccelUnit::Mps2),
            "g" => Some(AccelUnit::G),
            "counts" => Some(AccelUnit::Counts),
            _ => None,
        }
    }

    /// Short symbol for reports.
    pub fn symbol(self) -> &'static str {
        match self {
            AccelUnit::Mps2 => "m/s²",
            AccelUnit::G => "g",
            AccelUnit::Counts => "counts",
        }
    }
}

impl GyroUnit {
    /// Factor from this unit to rad/s, if one exists.
    pub fn to_si(self) -> Option<f64> {
        match self {
            GyroUnit::Rads => Some(1.0),
            GyroUnit::Dps => Some(std::f64::consts::PI / 180.0),
            GyroUnit::Counts => None,
        }
    }

    /// Parse a command-line name (`rads`, `dps`, `counts`).
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "rads" => Some(GyroUnit::Rads),
            "dps" => Some(GyroUnit::Dps),
            "counts" => Some(GyroUnit::Counts),
            _ => None,
        }
    }

    /// Short symbol for reports.
    pub fn symbol(self) -> &'static str {
        match self {
            GyroUnit::Rads => "rad/s",
            GyroUnit::Dps => "°/s",
            GyroUnit::Counts => "counts",
        }
    }
}

impl MagUnit {
    /// Factor from this unit to µT, if one exists.
    pub fn to_si(self) -> Option<f64> {
        match self {
            MagUnit::Ut => Some(1.0),
            MagUnit::Gauss => Some(100.0),
            MagUnit::Counts => None,
        }
    }

    /// Parse a command-line name (`ut`, `gauss`, `counts`).
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "ut" => Some(MagUnit::Ut),
            "gauss" => Some(MagUnit::Gauss),
            "counts" => Some(MagUnit::Counts),
            _ => None,
        }
    }

    /// Short symbol for reports.
    pub fn symbol(self) -> &'static str {
        match self {
            MagUnit::Ut => "µT",
            MagUnit::Gauss => "gauss",
            MagUnit::Counts => "counts",
        }
    }
}

/// The units of every sensor column in one recording.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Units {
    /// Accelerometer unit.
    pub accel: AccelUnit,
    /// Gyroscope unit.
    pub gyro: GyroUnit,
    /// Magnetometer unit.
    pub mag: MagUnit,
}

impl Units {
    /// Factor from the file's unit of `sensor` to SI (m/s², rad/s, µT), if one exists.
    pub fn to_si(&self, sensor: Sensor) -> Option<f64> {
        match sensor {
            Sensor::Accel => self.accel.to_si(),
            Sensor::Gyro => self.gyro.to_si(),
            Sensor::Mag => self.mag.to_si(),
        }
    }

    /// Symbol of the file's unit of `sensor`.
    pub fn symbol(&self, sensor: Sensor) -> &'static str {
        match sensor {
            Sensor::Accel => self.accel.symbol(),
            Sensor::Gyro => self.gyro.symbol(),
            Sensor::Mag => self.mag.symbol(),
        }
    }

    /// Whether `sensor` is in raw counts (no known offset or scale).
    pub fn is_counts(&self, sensor: Sensor) -> bool {
        self.to_si(sensor).is_none()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn factors_to_si_are_the_defined_conversions() {
        assert_eq!(AccelUnit::G.to_si(), Some(9.80665));
        assert!((GyroUnit::Dps.to_si().unwrap_or(0.0) - 0.017453292519943295).abs() < 1e-18);
        assert_eq!(MagUnit::Gauss.to_si(), Some(100.0));
        assert_eq!(MagUnit::Counts.to_si(), None);
    }
}
