//! What a board is held to when it has no fleet to be compared with: bounds that no working part
//! of the common consumer MEMS accelerometers and gyroscopes exceeds, from their datasheets.
//!
//! The fleet test ([`super::fleet`]) learns the spread of the line's own part and is the sharper
//! test; it needs boards already calibrated. On a new line, or a batch too small to be compared
//! within, a board with a gross fault (a cracked proof mass, a damaged axis) would otherwise be
//! written unexamined. These bounds catch such faults only: each is the widest figure of the
//! common parts, so a board within every datasheet always passes.
//!
//! Bounds, in the parameter file's units (m/s², rad/s):
//! - accelerometer zero-g offset, per axis: 250 mg, the widest initial offset of the common parts
//!   (ADXL345 Z axis ±250 mg; ADXL345 X/Y ±150 mg, LSM9DS1 ±90 mg, MPU-6050 ±50/±80 mg, BMI160
//!   ±40 mg, BMI270 ±20 mg);
//! - accelerometer sensitivity, per axis (the norm of a row of `A`, its gain on that axis): within
//!   ±10 % of nominal, the widest initial tolerance (ADXL345 230–282 LSB/g about 256; MPU-6050
//!   ±3 %);
//! - gyroscope zero-rate offset, per axis: 30 °/s, the widest (LSM9DS1 ±30 °/s; MPU-6050
//!   ±20 °/s; BMI160 ±3 °/s; BMI270 ±0.5 °/s).
//!
//! Not bounded here: the magnetometer's offset is the board's hard iron as much as the part's,
//! and a gyroscope's noise depends on the bandwidth the firmware sets; both are left to the fleet.

use serde::Serialize;

use super::record::CalibrationRecord;

/// Widest accelerometer zero-g offset of the common parts, in g (see the module comment).
pub const MAX_ACCEL_OFFSET_G: f64 = 0.25;
/// Widest accelerometer sensitivity tolerance of the common parts, relative.
pub const MAX_ACCEL_GAIN_ERROR: f64 = 0.10;
/// Widest gyroscope zero-rate offset of the common parts, °/s.
pub const MAX_GYRO_OFFSET_DPS: f64 = 30.0;

const AXES: [&str; 3] = ["x", "y", "z"];

/// `|value| ≤ limit`; false for a value that is not a number, which no working part gives.
fn within(value: f64, limit: f64) -> bool {
    value.abs() <= limit
}

/// What a part limit bounds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum LimitKind {
    /// An offset, bounded in magnitude about 0.
    Offset,
    /// A gain, bounded in its distance from the nominal 1.
    Gain,
}

impl LimitKind {
    /// The value a working part is centred on: 0 for an offset, 1 for a gain.
    pub fn nominal(self) -> f64 {
        match self {
            Self::Offset => 0.0,
            Self::Gain => 1.0,
        }
    }
}

/// A parameter beyond what any working common part shows.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PartLimitFinding {
    /// The parameter, e.g. `accel.b.x` or `accel.gain.y`.
    pub parameter: String,
    /// Whether the bound is on an offset or on a gain.
    pub kind: LimitKind,
    /// Its value, in `unit`.
    pub value: f64,
    /// The bound on its distance from [`LimitKind::nominal`], in `unit`.
    pub limit: f64,
    /// Unit of `value` and `limit`.
    pub unit: &'static str,
    /// The likely cause, in words.
    pub likely_cause: &'static str,
}

impl PartLimitFinding {
    /// How far past the bound, as the ratio of the excess to the bound's own size (1 = at it).
    pub fn times_limit(&self) -> f64 {
        (self.value - self.kind.nominal()).abs() / self.limit
    }

    /// One phrase: the parameter, its value and the bound.
    pub fn phrase(&self) -> String {
        if self.kind == LimitKind::Gain {
            format!(
                "{} {:.3} is {:+.1} % off nominal, beyond the ±{:.0} % of every common part: {}",
                self.parameter,
                self.value,
                (self.value - 1.0) * 100.0,
                self.limit * 100.0,
                self.likely_cause
            )
        } else {
            format!(
                "{} {:.4} {} is beyond the ±{:.4} {} of every common part: {}",
                self.parameter, self.value, self.unit, self.limit, self.unit, self.likely_cause
            )
        }
    }
}

/// The parameters of `record` beyond the bounds of the module comment, farthest first; sensors
/// the record does not calibrate are not looked at. The record's own gravity converts g.
pub fn beyond_part_limits(record: &CalibrationRecord) -> Vec<PartLimitFinding> {
    let gravity_mps2 = record.params.reference.gravity_mps2;
    let fitted = record.params.fitted_sensors();
    let mut findings = Vec::new();
    if fitted.contains(&"accel") {
        let accel = &record.params.accel;
        let offset_limit = MAX_ACCEL_OFFSET_G * gravity_mps2;
        for (axis, name) in AXES.iter().enumerate() {
            let offset = accel.b[axis];
            if !within(offset, offset_limit) {
                findings.push(PartLimitFinding {
                    parameter: format!("accel.b.{name}"),
                    kind: LimitKind::Offset,
                    value: offset,
                    limit: offset_limit,
                    unit: "m/s²",
                    likely_cause: "a damaged accelerometer (cracked proof mass) or a package \
                                   stressed by a bad solder joint",
                });
            }
            let gain = accel.a[axis].iter().map(|v| v * v).sum::<f64>().sqrt();
            if !within(gain - 1.0, MAX_ACCEL_GAIN_ERROR) {
                findings.push(PartLimitFinding {
                    parameter: format!("accel.gain.{name}"),
                    kind: LimitKind::Gain,
                    value: gain,
                    limit: MAX_ACCEL_GAIN_ERROR,
                    unit: "relative",
                    likely_cause: "a damaged accelerometer axis",
                });
            }
        }
    }
    if fitted.contains(&"gyro") {
        let limit = MAX_GYRO_OFFSET_DPS.to_radians();
        for (axis, name) in AXES.iter().enumerate() {
            let offset = record.params.gyro.b[axis];
            if !within(offset, limit) {
                findings.push(PartLimitFinding {
                    parameter: format!("gyro.b.{name}"),
                    kind: LimitKind::Offset,
                    value: offset,
                    limit,
                    unit: "rad/s",
                    likely_cause: "a damaged gyroscope, or one still turning during the rest",
                });
            }
        }
    }
    findings.sort_by(|a, b| b.times_limit().total_cmp(&a.times_limit()));
    findings
}
