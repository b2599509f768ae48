//! The board a parameter file was made for: its id, sensors, full-scale ranges and firmware,
//! from the board's `Welcome`. `flash` compares them with the board it talks to, so another
//! board's calibration (or one made under other ranges) is not written without a word.

use imucal_protocol::Welcome;
use serde::{Deserialize, Serialize};

use super::params_json::{ParamsFile, SensorJson};

/// Full-scale ranges the calibration was measured under.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RangesJson {
    /// Accelerometer, ± m/s².
    pub accel_mps2: f64,
    /// Gyroscope, ± rad/s.
    pub gyro_rads: f64,
    /// Magnetometer, ± µT.
    pub mag_ut: f64,
}

/// The board a parameter file belongs to.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DeviceJson {
    /// Device id as `imucal info` prints it.
    pub id: String,
    /// Sensors fitted on the board (`accel`, `gyro`, `mag`, `temp`).
    pub sensors: Vec<String>,
    /// Full-scale ranges.
    pub ranges: RangesJson,
    /// Firmware version, `major.minor.patch`.
    pub firmware: String,
}

/// Ranges are sent as `f32`; a relative difference beyond this is another configuration.
const RANGE_TOLERANCE: f64 = 1e-6;

fn sensor_names(welcome: &Welcome) -> Vec<String> {
    let s = welcome.sensors;
    [
        (s.accel, "accel"),
        (s.gyro, "gyro"),
        (s.mag, "mag"),
        (s.temp, "temp"),
    ]
    .into_iter()
    .filter(|(present, _)| *present)
    .map(|(_, name)| name.to_string())
    .collect()
}

impl DeviceJson {
    /// The board that sent `welcome`.
    pub fn from_welcome(welcome: &Welcome) -> Self {
        let fw = welcome.firmware_version;
        let s = welcome.scales;
        Self {
            id: welcome.device_id.to_string(),
            sensors: sensor_names(welcome),
            ranges: RangesJson {
                accel_mps2: f64::from(s.accel_range_mps2),
                gyro_rads: f64::from(s.gyro_range_rads),
                mag_ut: f64::from(s.mag_range_ut),
            },
            firmware: format!("{}.{}.{}", fw.major, fw.minor, fw.patch),
        }
    }

    /// Why this file does not belong to the board that sent `welcome` (one sentence per
    /// difference: id, sensor set, ranges); empty when it does. A firmware difference is not a
    /// mismatch (the parameter format is the protocol's) and is reported by [`Self::notes`].
    pub fn mismatches(&self, welcome: &Welcome) -> Vec<String> {
        let board = Self::from_welcome(welcome);
        let mut found = Vec::new();
        if self.id != board.id {
            found.push(format!(
                "it was made for device {}, but the board is device {}",
                self.id, board.id
            ));
        }
        if self.sensors != board.sensors {
            found.push(format!(
                "it was made for sensors [{}], but the board has [{}]",
                self.sensors.join(", "),
                board.sensors.join(", ")
            ));
        }
        let differs = |a: f64, b: f64| (a - b).abs() > RANGE_TOLERANCE * a.abs().max(b.abs());
        for (name, unit, file, now) in [
            (
                "accelerometer",
                "m/s²",
                self.ranges.accel_mps2,
                board.ranges.accel_mps2,
            ),
            (
                "gyroscope",
                "rad/s",
                self.ranges.gyro_rads,
                board.ranges.gyro_rads,
            ),
            (
                "magnetometer",
                "µT",
                self.ranges.mag_ut,
                board.ranges.mag_ut,
            ),
        ] {
            if differs(file, now) {
                found.push(format!(
                    "it was measured with the {name} range ±{file} {unit}, but the board now \
                     uses ±{now} {unit}"
                ));
            }
        }
        found
    }

    /// Differences worth a note that do not stop a flash (the firmware version).
    pub fn notes(&self, welcome: &Welcome) -> Vec<String> {
        let board = Self::from_welcome(welcome);
        if self.firmware == board.firmware {
            Vec::new()
        } else {
            vec![format!(
                "the file was made under firmware {}, the board runs {}",
                self.firmware, board.firmware
            )]
        }
    }
}

impl ParamsFile {
    /// Why the file's set cannot be this board's, from the set alone: a sensor it calibrates
    /// that the board that sent `welcome` lacks, or an offset no reading of the board's part
    /// could show (beyond its full-scale range less the reference magnitude the fit saw on top
    /// of it: gravity for the accelerometer, the field for the magnetometer). What `flash`
    /// checks when the file names no board (no `device` block) to compare ranges with; empty
    /// when the set fits.
    pub fn beyond_the_board(&self, welcome: &Welcome) -> Vec<String> {
        let present = welcome.sensors;
        let s = welcome.scales;
        let fitted = self.fitted_sensors();
        let sensors: [(&str, &str, &str, bool, &SensorJson, f64, f64); 3] = [
            (
                "accel",
                "accelerometer",
                "m/s²",
                present.accel,
                &self.accel,
                f64::from(s.accel_range_mps2),
                self.reference.gravity_mps2,
            ),
            (
                "gyro",
                "gyroscope",
                "rad/s",
                present.gyro,
                &self.gyro,
                f64::from(s.gyro_range_rads),
                0.0,
            ),
            (
                "mag",
                "magnetometer",
                "µT",
                present.mag,
                &self.mag,
                f64::from(s.mag_range_ut),
                self.reference.field_ut,
            ),
        ];
        let mut found = Vec::new();
        for (key, name, unit, on_board, sensor, range, reference) in sensors {
            if !fitted.contains(&key) {
                continue;
            }
            if !on_board {
                found.push(format!("it calibrates a {name}, but the board has none"));
                continue;
            }
            // A board that reports no range (an old firmware) gives nothing to check against.
            if !(range.is_finite() && range > 0.0) {
                continue;
            }
            let largest = sensor.b.iter().fold(0.0_f64, |m, b| m.max(b.abs()));
            if largest + reference > range {
                found.push(format!(
                "its {name} offset of {largest:.4} {unit} (with the reference of {reference:.4} \
                 {unit} on top) lies beyond the board's ±{range} {unit} range, so it was measured \
                 on a part with another range"
            ));
            }
        }
        found
    }
}
