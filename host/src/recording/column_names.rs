//! Names in a header as loggers and spreadsheets write them: an imucal column name followed by
//! its unit in brackets or parentheses (`ax [m/s2]`, `gx (dps)`, `mx [uT]`), and names that
//! look like a sensor axis without being one of imucal's (`AccX`, `gyro_y`, `ax_raw`), which a
//! reader leaves unread and a command must not then pass over in silence; and the units the
//! names give the sensors ([`units_from_names`], for imucal's CSV and column mappings alike).

use std::path::Path;

use super::{display, RecordingError, Sensor, Units};

/// A header name split into its column name and the unit written after it: `ax [m/s2]` gives
/// `("ax", Some("m/s2"))`, `ax` gives `("ax", None)`. Only a unit that closes the name counts,
/// and the name before it must not be empty (`[ms]` alone is a name, not a unit).
pub fn split_unit(name: &str) -> (&str, Option<&str>) {
    let name = name.trim();
    for (open, close) in [('[', ']'), ('(', ')')] {
        let Some(inner) = name.strip_suffix(close) else {
            continue;
        };
        let Some(at) = inner.rfind(open) else {
            continue;
        };
        let (base, unit) = (inner[..at].trim(), inner[at + open.len_utf8()..].trim());
        if !base.is_empty() {
            return (base, Some(unit));
        }
    }
    (name, None)
}

/// How loggers name a sensor before its axis letter (`acc` in `AccX`, `gyro` in `gyro_y`).
fn prefixes(sensor: Sensor) -> &'static [&'static str] {
    match sensor {
        Sensor::Accel => &[
            "a",
            "acc",
            "accel",
            "accl",
            "accelerometer",
            "acceleration",
            "linacc",
            "linearacceleration",
        ],
        Sensor::Gyro => &[
            "g",
            "gyr",
            "gyro",
            "gyroscope",
            "w",
            "omega",
            "angvel",
            "angularvelocity",
            "angularrate",
            "rate",
        ],
        Sensor::Mag => &[
            "m",
            "mag",
            "magn",
            "magneto",
            "magnetometer",
            "compass",
            "magfield",
            "magneticfield",
        ],
    }
}

/// The sensor whose axis a header name looks like (`AccX`, `acc_x`, `Gyro.Y [dps]`, `ax_raw`,
/// `Magnetic Field x (µT)`, ROS's `field.angular_velocity.x`), `None` for any other name. Some
/// run of the name's alphanumeric words must spell a sensor prefix and an axis letter; what
/// comes before (`field.`) or after (`_raw`, `_mps2`) does not matter.
pub fn looks_like_axis(name: &str) -> Option<Sensor> {
    let (base, _) = split_unit(name);
    let lowered = base.to_lowercase();
    let words: Vec<&str> = lowered
        .split(|c: char| !c.is_ascii_alphanumeric())
        .filter(|w| !w.is_empty())
        .collect();
    (0..words.len()).find_map(|start| {
        let mut spelled = String::new();
        words[start..].iter().find_map(|word| {
            spelled.push_str(word);
            let stem = spelled.strip_suffix(['x', 'y', 'z'])?;
            Sensor::ALL
                .into_iter()
                .find(|s| prefixes(*s).contains(&stem))
        })
    })
}

/// `units` with each sensor's replaced by the unit written after the name of its column in
/// `unit_columns` (index into `names`, e.g. `ax [g]`), unless the user stated the sensor's unit
/// (`units_stated`) and the name says another, which is refused. Names without a unit, or
/// with one imucal does not read, leave the sensor's unit as it is.
pub fn units_from_names(
    path: &Path,
    names: &[String],
    unit_columns: &[(Sensor, usize)],
    mut units: Units,
    units_stated: &[Sensor],
) -> Result<Units, RecordingError> {
    let given = units;
    for &(sensor, column) in unit_columns {
        let Some(name) = names.get(column) else {
            continue;
        };
        let (_, Some(text)) = split_unit(name) else {
            continue;
        };
        let Some(written) = given.with_symbol(sensor, text) else {
            continue;
        };
        if units_stated.contains(&sensor) && written.symbol(sensor) != given.symbol(sensor) {
            return Err(RecordingError::UnitDisagrees {
                path: display(path),
                column: name.clone(),
                sensor,
                header_unit: written.symbol(sensor),
                flag: match sensor {
                    Sensor::Accel => "--accel-unit",
                    Sensor::Gyro => "--gyro-unit",
                    Sensor::Mag => "--mag-unit",
                },
                given: given.symbol(sensor),
            });
        }
        units = units.with_symbol(sensor, text).unwrap_or(units);
    }
    Ok(units)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_unit_in_brackets_or_parentheses_is_split_from_the_name() {
        assert_eq!(split_unit("ax [m/s2]"), ("ax", Some("m/s2")));
        assert_eq!(split_unit(" ax (m/s^2) "), ("ax", Some("m/s^2")));
        assert_eq!(split_unit("gx[dps]"), ("gx", Some("dps")));
        assert_eq!(split_unit("mx [uT]"), ("mx", Some("uT")));
        assert_eq!(split_unit("ax"), ("ax", None));
        assert_eq!(split_unit("[ms]"), ("[ms]", None));
        assert_eq!(split_unit("ax [m/s2] raw"), ("ax [m/s2] raw", None));
    }

    #[test]
    fn logger_names_of_sensor_axes_are_told_from_other_columns() {
        for (name, sensor) in [
            ("accx", Sensor::Accel),
            ("acc_y", Sensor::Accel),
            ("accel.z [g]", Sensor::Accel),
            ("ax_raw", Sensor::Accel),
            ("gyro_x", Sensor::Gyro),
            ("gyrz", Sensor::Gyro),
            ("magx", Sensor::Mag),
            ("mag_y_ut", Sensor::Mag),
            // phyphox and ROS (`rostopic echo -p`) exports.
            ("Magnetic Field x (µT)", Sensor::Mag),
            ("field.angular_velocity.x", Sensor::Gyro),
            ("linear_acceleration_y", Sensor::Accel),
            ("field.magnetic_field.z", Sensor::Mag),
        ] {
            assert_eq!(looks_like_axis(name), Some(sensor), "{name}");
        }
        for name in [
            "timestamp",
            "max",
            "temperature",
            "note",
            "extra",
            "pose",
            "xyz",
            "field.header.stamp",
            "orientation_covariance_0",
        ] {
            assert_eq!(looks_like_axis(name), None, "{name}");
        }
    }
}
