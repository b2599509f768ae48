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
//!   ±20 °/s; BMI160 ±3 °/s; BMI270 ±0.5 °/s);
//! - magnetometer offset (hard iron), per axis: the widest zero-field offset of the common parts,
//!   100 µT (LSM9DS1 and LIS3MDL ±1 gauss zero-gauss level; BMM150 ±40 µT), plus a board
//!   allowance of 25 µT for the board's own magnetised parts (connector shells, crystal cans,
//!   battery contacts), the size of the weakest Earth field: parts of the board itself that add
//!   more field than the Earth's weakest are a magnet or magnetised steel near the
//!   magnetometer. The offset's length is held likewise, to √3·100 + 25 µT (every axis at the
//!   part's limit, plus the allowance). A magnetometer past these still measures (the fit takes
//!   the offset out for as long as the magnet stays put), so they warn and lower the verdict
//!   rather than refuse;
//! - magnetometer offset, refusing: an axis whose offset leaves less than the strongest Earth
//!   field (65 µT) to the part's range (from the file's `device` block) clips in some
//!   orientation, which no board can hold and still measure.
//!
//! A gyroscope's noise depends on the bandwidth the firmware sets; it is left to the fleet.
//!
//! Every path that writes a set holds it to these bounds with [`beyond_part_limits_of`]:
//! `calibrate` (one board or a batch) refuses a set past a refusing bound unless
//! `--accept-outlier`, `flash` the same, and `fit --params-out` warns.

use serde::Serialize;

use crate::device::ParamsFile;

/// Widest accelerometer zero-g offset of the common parts, in g (see the module comment).
pub const MAX_ACCEL_OFFSET_G: f64 = 0.25;
/// Widest accelerometer sensitivity tolerance of the common parts, relative.
pub const MAX_ACCEL_GAIN_ERROR: f64 = 0.10;
/// Widest gyroscope zero-rate offset of the common parts, °/s.
pub const MAX_GYRO_OFFSET_DPS: f64 = 30.0;
/// Widest magnetometer zero-field offset of the common parts, µT (LSM9DS1, LIS3MDL ±1 gauss).
pub const MAX_MAG_PART_OFFSET_UT: f64 = 100.0;
/// The board's own hard iron allowed on top of the part's offset, µT: the weakest Earth field.
pub const MAG_BOARD_ALLOWANCE_UT: f64 = 25.0;
/// The strongest Earth field, µT: what a magnetometer's range must leave room for.
pub const STRONGEST_EARTH_FIELD_UT: f64 = 65.0;
/// Why a set past a refusing bound is not written, as records and summaries say it.
pub const PART_LIMITS_REFUSAL: &str = "beyond the bounds of every common part's datasheet";
/// What fleet and the verdict name as the cause of a magnetometer offset past its bound.
pub const MAG_MAGNET_CAUSE: &str = "a magnet or magnetised steel near the magnetometer";

const AXES: [&str; 3] = ["x", "y", "z"];

/// The magnetometer offset against the part's offset plus the board allowance (a warning, per
/// axis and as a length) and against the part's range (a refusal, per axis).
fn mag_offset_findings(params: &ParamsFile) -> Vec<PartLimitFinding> {
    let b = params.mag.b;
    let mut findings = Vec::new();
    let range = params
        .device
        .as_ref()
        .map(|d| d.ranges.mag_ut)
        .filter(|r| r.is_finite() && *r > STRONGEST_EARTH_FIELD_UT);
    let per_axis = MAX_MAG_PART_OFFSET_UT + MAG_BOARD_ALLOWANCE_UT;
    for (axis, name) in AXES.iter().enumerate() {
        let offset = b[axis];
        if let Some(range) = range {
            let room = range - STRONGEST_EARTH_FIELD_UT;
            if !within(offset, room) {
                findings.push(PartLimitFinding {
                    parameter: format!("mag.b.{name}"),
                    kind: LimitKind::Offset,
                    value: offset,
                    limit: room,
                    unit: "µT",
                    likely_cause: "a magnetometer whose offset leaves the Earth field no room \
                                   in its range (it clips in some orientation): a strong magnet \
                                   at the sensor, or a damaged part",
                    refuses: true,
                });
                continue;
            }
        }
        if !within(offset, per_axis) {
            findings.push(PartLimitFinding {
                parameter: format!("mag.b.{name}"),
                kind: LimitKind::Offset,
                value: offset,
                limit: per_axis,
                unit: "µT",
                likely_cause: MAG_MAGNET_CAUSE,
                refuses: false,
            });
        }
    }
    let length = b.iter().map(|v| v * v).sum::<f64>().sqrt();
    let length_limit = 3f64.sqrt() * MAX_MAG_PART_OFFSET_UT + MAG_BOARD_ALLOWANCE_UT;
    if !within(length, length_limit) && findings.is_empty() {
        findings.push(PartLimitFinding {
            parameter: "mag.b.length".to_string(),
            kind: LimitKind::Offset,
            value: length,
            limit: length_limit,
            unit: "µT",
            likely_cause: MAG_MAGNET_CAUSE,
            refuses: false,
        });
    }
    findings
}

/// The findings of `findings` that refuse a set, as one phrase; `None` when none refuses.
pub fn refusal_phrase(findings: &[PartLimitFinding]) -> Option<String> {
    let refusing: Vec<String> = findings
        .iter()
        .filter(|f| f.refuses)
        .map(PartLimitFinding::phrase)
        .collect();
    (!refusing.is_empty()).then(|| refusing.join("; "))
}

/// The findings of `findings` that only warn, one phrase each.
pub fn warning_phrases(findings: &[PartLimitFinding]) -> Vec<String> {
    findings
        .iter()
        .filter(|f| !f.refuses)
        .map(PartLimitFinding::phrase)
        .collect()
}

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
    /// Whether the set is refused for it (without `--accept-outlier`); otherwise a warning
    /// that lowers the verdict.
    pub refuses: bool,
}

impl PartLimitFinding {
    /// How far past the bound, as the ratio of the excess to the bound's own size (1 = at it).
    pub fn times_limit(&self) -> f64 {
        (self.value - self.kind.nominal()).abs() / self.limit
    }

    /// One phrase: the parameter, its value and the bound.
    pub fn phrase(&self) -> String {
        if self.unit == "µT" {
            let bound = if self.refuses {
                format!(
                    "the {:.0} µT the part's range leaves beside the strongest Earth field",
                    self.limit
                )
            } else {
                format!(
                    "the {:.0} µT of the widest part offset ({MAX_MAG_PART_OFFSET_UT:.0} µT{}) and \
                     a board's own magnetised parts ({MAG_BOARD_ALLOWANCE_UT:.0} µT)",
                    self.limit,
                    if self.parameter.ends_with("length") {
                        " on each axis"
                    } else {
                        ""
                    }
                )
            };
            return format!(
                "{} {:.1} µT is beyond {bound}: {}",
                self.parameter, self.value, self.likely_cause
            );
        }
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

/// The parameters of `record` (a history record, or anything else that holds a parameter
/// file) beyond the bounds of the module comment, farthest first; sensors the record does not
/// calibrate are not looked at. The record's own gravity converts g.
pub fn beyond_part_limits(record: &impl AsRef<ParamsFile>) -> Vec<PartLimitFinding> {
    beyond_part_limits_of(record.as_ref())
}

/// The parameters of `params` beyond the bounds of the module comment, farthest first: the
/// check every path that writes a set applies.
pub fn beyond_part_limits_of(params: &ParamsFile) -> Vec<PartLimitFinding> {
    let gravity_mps2 = params.reference.gravity_mps2;
    let fitted = params.fitted_sensors();
    let mut findings = Vec::new();
    if fitted.contains(&"accel") {
        let accel = &params.accel;
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
                    refuses: true,
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
                    refuses: true,
                });
            }
        }
    }
    if fitted.contains(&"gyro") {
        let limit = MAX_GYRO_OFFSET_DPS.to_radians();
        for (axis, name) in AXES.iter().enumerate() {
            let offset = params.gyro.b[axis];
            if !within(offset, limit) {
                findings.push(PartLimitFinding {
                    parameter: format!("gyro.b.{name}"),
                    kind: LimitKind::Offset,
                    value: offset,
                    limit,
                    unit: "rad/s",
                    likely_cause: "a damaged gyroscope, or one still turning during the rest",
                    refuses: true,
                });
            }
        }
    }
    if fitted.contains(&"mag") {
        findings.extend(mag_offset_findings(params));
    }
    findings.sort_by(|a, b| b.times_limit().total_cmp(&a.times_limit()));
    findings
}
