//! The board a parameter file was made for, as the file records it: its id, sensors,
//! full-scale ranges and firmware, from the board's `Welcome`, and how they differ from the
//! board connected now.

use imucal_protocol::Welcome;
use serde::{Deserialize, Serialize};

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
