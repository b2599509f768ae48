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

    /// The unit a header writes after a column name (`ax [m/s2]`), in any case and spacing;
    /// `None` when imucal does not read it. The spellings are [`AccelUnit::SPELLINGS`].
    pub fn from_symbol(text: &str) -> Option<Self> {
        match squashed(text).as_str() {
            "m/s2" | "m/s^2" | "m/s²" | "ms-2" | "ms^-2" | "m·s-2" | "m·s^-2" | "mps2" => {
                Some(AccelUnit::Mps2)
            }
            "g" => Some(AccelUnit::G),
            "counts" | "count" | "lsb" => Some(AccelUnit::Counts),
            _ => None,
        }
    }

    /// The units [`AccelUnit::from_symbol`] reads, for messages.
    pub const SPELLINGS: &'static str = "m/s2 (or m/s^2, m/s², mps2), g, counts (or lsb)";

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

    /// The unit a header writes after a column name (`gx [dps]`), in any case and spacing;
    /// `None` when imucal does not read it. The spellings are [`GyroUnit::SPELLINGS`].
    pub fn from_symbol(text: &str) -> Option<Self> {
        match squashed(text).as_str() {
            "rad/s" | "rads" | "rads-1" | "rads^-1" | "rad·s-1" | "rad·s^-1" => {
                Some(GyroUnit::Rads)
            }
            "dps" | "deg/s" | "°/s" | "º/s" | "degrees/s" | "degs-1" => Some(GyroUnit::Dps),
            "counts" | "count" | "lsb" => Some(GyroUnit::Counts),
            _ => None,
        }
    }

    /// The units [`GyroUnit::from_symbol`] reads, for messages.
    pub const SPELLINGS: &'static str = "rad/s (or rads), dps (or deg/s, °/s), counts (or lsb)";

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

    /// The unit a header writes after a column name (`mx [uT]`), in any case and spacing;
    /// `None` when imucal does not read it. The spellings are [`MagUnit::SPELLINGS`].
    pub fn from_symbol(text: &str) -> Option<Self> {
        match squashed(text).as_str() {
            // The micro sign (U+00B5) and the Greek mu (U+03BC) both occur.
            "ut" | "µt" | "μt" | "microtesla" => Some(MagUnit::Ut),
            "gauss" | "ga" => Some(MagUnit::Gauss),
            "counts" | "count" | "lsb" => Some(MagUnit::Counts),
            _ => None,
        }
    }

    /// The units [`MagUnit::from_symbol`] reads, for messages.
    pub const SPELLINGS: &'static str = "uT (or µT), gauss (or Ga), counts (or lsb)";

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

    /// These units with `sensor`'s set to the one a header writes as `text` (see
    /// [`AccelUnit::from_symbol`] and its siblings); `None` when imucal does not read it.
    pub fn with_symbol(self, sensor: Sensor, text: &str) -> Option<Self> {
        let mut units = self;
        match sensor {
            Sensor::Accel => units.accel = AccelUnit::from_symbol(text)?,
            Sensor::Gyro => units.gyro = GyroUnit::from_symbol(text)?,
            Sensor::Mag => units.mag = MagUnit::from_symbol(text)?,
        }
        Some(units)
    }

    /// The units a header may write for `sensor`'s columns, for messages.
    pub fn spellings(sensor: Sensor) -> &'static str {
        match sensor {
            Sensor::Accel => AccelUnit::SPELLINGS,
            Sensor::Gyro => GyroUnit::SPELLINGS,
            Sensor::Mag => MagUnit::SPELLINGS,
        }
    }

    /// Whether `sensor` is in raw counts (no known offset or scale).
    pub fn is_counts(&self, sensor: Sensor) -> bool {
        self.to_si(sensor).is_none()
    }
}

/// A unit as written, lower-case and without blanks (`M/S 2` and `m/s2` are one unit).
fn squashed(text: &str) -> String {
    text.chars()
        .filter(|c| !c.is_whitespace())
        .flat_map(char::to_lowercase)
        .collect()
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

    #[test]
    fn units_written_in_a_header_are_read_in_their_usual_spellings() {
        for text in ["m/s2", "m/s^2", "M/S²", "m s^-2", "mps2"] {
            assert_eq!(
                AccelUnit::from_symbol(text),
                Some(AccelUnit::Mps2),
                "{text}"
            );
        }
        assert_eq!(AccelUnit::from_symbol("G"), Some(AccelUnit::G));
        assert_eq!(GyroUnit::from_symbol("deg/s"), Some(GyroUnit::Dps));
        assert_eq!(GyroUnit::from_symbol("°/s"), Some(GyroUnit::Dps));
        assert_eq!(GyroUnit::from_symbol("rad/s"), Some(GyroUnit::Rads));
        assert_eq!(MagUnit::from_symbol("uT"), Some(MagUnit::Ut));
        assert_eq!(MagUnit::from_symbol("µT"), Some(MagUnit::Ut));
        assert_eq!(MagUnit::from_symbol("Gauss"), Some(MagUnit::Gauss));
        for text in ["mg", "ft/s2", "rpm", "nT", ""] {
            assert_eq!(AccelUnit::from_symbol(text), None, "{text}");
            assert_eq!(GyroUnit::from_symbol(text), None, "{text}");
            assert_eq!(MagUnit::from_symbol(text), None, "{text}");
        }
    }
}
