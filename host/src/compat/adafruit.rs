//! The calibration of Adafruit's `Adafruit_Sensor_Calibration` library, made from an imucal fit.
//!
//! Checked against the public sources: `Adafruit_Sensor_Calibration.cpp` (`calibrate()`:
//! accel `−= accel_zerog` in m/s², gyro `−= gyro_zerorate` in rad/s, mag
//! `= mag_softiron·(raw − mag_hardiron)` with `mag_softiron` row-major, µT),
//! `Adafruit_Sensor_Calibration_SDFat.cpp` (the flash/SD backend: file `sensor_calib.json`, keys
//! `mag_hardiron`[3], `mag_softiron`[9], `mag_field`, `gyro_zerorate`[3], `accel_zerog`[3],
//! written in that order by ArduinoJson without spaces; missing keys read as 0, the soft iron's
//! diagonal as 1).
//!
//! The library applies offsets only to the accelerometer and gyroscope and a symmetric matrix to
//! the magnetometer, so an imucal fit maps as: `accel_zerog = b_accel`, `gyro_zerorate = b_gyro`,
//! `mag_hardiron = b_mag`, `mag_softiron = (AᵀA)^½` ([`super::gauge`]), `mag_field` = the fit's
//! field magnitude. What does not fit — accel scale and misalignment, gyro scale and
//! misalignment, g-sensitivity, temperature and non-linearity terms, the magnetometer frame
//! rotation — is listed by [`limitations`] with its cost on given poses.

use imucal_protocol::{CalibrationSet, SensorCalibration};
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

use super::gauge::symmetric_gauge;
use super::CompatError;
use crate::device::UnitSample;
use imucal_protocol::model::{apply as apply_set_model, NominalSample};

/// Standard gravity for expressing accelerometer errors in mg, m/s².
const G_MPS2: f64 = 9.806_65;

/// The values the Adafruit library stores and applies.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AdafruitCalibration {
    /// Accelerometer zero-g offsets, m/s² (subtracted).
    pub accel_zerog: [f32; 3],
    /// Gyroscope zero-rate offsets, rad/s (subtracted).
    pub gyro_zerorate: [f32; 3],
    /// Magnetometer hard-iron offsets, µT (subtracted before the soft iron).
    pub mag_hardiron: [f32; 3],
    /// Field magnitude the fit found, µT (informational; not applied).
    pub mag_field: f32,
    /// Magnetometer soft-iron matrix, row-major, symmetric.
    pub mag_softiron: [[f32; 3]; 3],
}

/// The mapping from an imucal set, with what it changed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Conversion {
    /// What the library will store.
    pub calibration: AdafruitCalibration,
    /// Rotation `R` taken out of the magnetometer matrix (`A = R·S`), row-major.
    pub mag_rotation: [[f64; 3]; 3],
    /// Angle of that rotation, degrees.
    pub mag_rotation_deg: f64,
}

/// The field magnitude `Adafruit_Sensor_Calibration` holds until a calibration sets it, µT.
pub const LIBRARY_DEFAULT_FIELD_UT: f32 = 50.0;

impl AdafruitCalibration {
    /// The library's defaults: no offsets, identity soft iron, field 0.
    pub const fn identity() -> Self {
        Self {
            accel_zerog: [0.0; 3],
            gyro_zerorate: [0.0; 3],
            mag_hardiron: [0.0; 3],
            mag_field: 0.0,
            mag_softiron: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        }
    }

    /// The part of `set` the library can apply (see the module documentation).
    pub fn from_set(set: &CalibrationSet) -> Result<Conversion, CompatError> {
        let gauge = symmetric_gauge(&set.mag.a)?;
        let s = gauge.symmetric;
        let calibration = Self {
            accel_zerog: set.accel.b,
            gyro_zerorate: set.gyro.b,
            mag_hardiron: set.mag.b,
            mag_field: set.reference.field_ut,
            // Symmetrise after rounding to f32 so the packet's six values describe it exactly.
            mag_softiron: [0, 1, 2]
                .map(|r| [0, 1, 2].map(|c| (0.5 * (s[(r, c)] + s[(c, r)])) as f32)),
        };
        calibration.check_finite()?;
        let r = gauge.rotation;
        Ok(Conversion {
            calibration,
            mag_rotation: [0, 1, 2].map(|i| [0, 1, 2].map(|j| r[(i, j)])),
            mag_rotation_deg: gauge.rotation_deg,
        })
    }

    /// Refuses NaN or infinite values, which must never reach a board.
    pub fn check_finite(&self) -> Result<(), CompatError> {
        let groups: [(&'static str, &[f32]); 4] = [
            ("accel_zerog", &self.accel_zerog),
            ("gyro_zerorate", &self.gyro_zerorate),
            ("mag_hardiron", &self.mag_hardiron),
            ("mag_field", std::slice::from_ref(&self.mag_field)),
        ];
        for (name, values) in groups {
            if values.iter().any(|v| !v.is_finite()) {
                return Err(CompatError::NotFinite(name));
            }
        }
        if self.mag_softiron.iter().flatten().any(|v| !v.is_finite()) {
            return Err(CompatError::NotFinite("mag_softiron"));
        }
        Ok(())
    }

    /// What the library's `calibrate()` makes of one reading (m/s², rad/s, µT), in f64.
    pub fn apply(&self, accel: [f64; 3], gyro: [f64; 3], mag: [f64; 3]) -> [[f64; 3]; 3] {
        let sub = |x: [f64; 3], o: [f32; 3]| [0, 1, 2].map(|i| x[i] - f64::from(o[i]));
        let u = sub(mag, self.mag_hardiron);
        let m = [0, 1, 2].map(|r| {
            (0..3)
                .map(|c| f64::from(self.mag_softiron[r][c]) * u[c])
                .sum()
        });
        [
            sub(accel, self.accel_zerog),
            sub(gyro, self.gyro_zerorate),
            m,
        ]
    }

    /// The `sensor_calib.json` the library's flash/SD backend reads (compact, its key order).
    pub fn to_sensor_calib_json(&self) -> String {
        let list = |v: &[f32]| {
            let items: Vec<String> = v.iter().map(|x| format!("{x:?}")).collect();
            format!("[{}]", items.join(","))
        };
        let soft: Vec<f32> = self.mag_softiron.iter().flatten().copied().collect();
        format!(
            "{{\"mag_hardiron\":{},\"mag_softiron\":{},\"mag_field\":{:?},\
             \"gyro_zerorate\":{},\"accel_zerog\":{}}}\n",
            list(&self.mag_hardiron),
            list(&soft),
            self.mag_field,
            list(&self.gyro_zerorate),
            list(&self.accel_zerog)
        )
    }

    /// Reads a `sensor_calib.json` as the library does (missing values take its defaults).
    pub fn from_sensor_calib_json(text: &str) -> Result<Self, serde_json::Error> {
        let doc: serde_json::Value = serde_json::from_str(text)?;
        let at = |key: &str, i: usize, default: f32| {
            doc.get(key)
                .and_then(|v| v.get(i))
                .and_then(serde_json::Value::as_f64)
                .map_or(default, |v| v as f32)
        };
        let three = |key: &str| [0, 1, 2].map(|i| at(key, i, 0.0));
        let soft = |r: usize, c: usize| at("mag_softiron", 3 * r + c, f32::from(r == c));
        Ok(Self {
            accel_zerog: three("accel_zerog"),
            gyro_zerorate: three("gyro_zerorate"),
            mag_hardiron: three("mag_hardiron"),
            mag_field: doc
                .get("mag_field")
                .and_then(serde_json::Value::as_f64)
                .map_or(0.0, |v| v as f32),
            mag_softiron: [0, 1, 2].map(|r| [0, 1, 2].map(|c| soft(r, c))),
        })
    }
}

/// A part of the imucal model the library cannot apply.
#[derive(Debug, Clone, PartialEq)]
pub struct UnappliedTerm {
    /// `accel`, `gyro` or `mag`.
    pub sensor: &'static str,
    /// What it is, in words.
    pub term: String,
}

/// What the library cannot apply and what that costs on the given poses.
#[derive(Debug, Clone, PartialEq)]
pub struct AdafruitLimitations {
    /// The terms of the fit that are dropped.
    pub unapplied: Vec<UnappliedTerm>,
    /// Largest accelerometer error over the poses, mg (library output vs. the full model).
    pub accel_error_mg: f64,
    /// Largest gyroscope error over the poses, °/s.
    pub gyro_error_dps: f64,
    /// Largest magnetometer error over the poses, % of the field, measured in the symmetric
    /// frame (the frame rotation is reported separately, it does not change the magnitude).
    pub mag_error_pct_of_field: f64,
    /// Rotation between imucal's magnetometer frame and the library's, degrees.
    pub mag_rotation_deg: f64,
    /// Number of poses measured on.
    pub poses: usize,
}

impl AdafruitLimitations {
    /// One line per dropped term and the costs, for the user.
    pub fn describe(&self) -> String {
        let mut text = String::new();
        // Printed to two decimals: a turn that shows as 0.00° is none to the user.
        let turned = self.mag_rotation_deg >= 0.005;
        if self.unapplied.is_empty() && !turned {
            text.push_str("The Adafruit library can apply every term of this calibration.\n");
        } else if self.unapplied.is_empty() {
            text.push_str(&format!(
                "The Adafruit library can apply every term of this calibration but the rotation \
                 in the magnetometer's matrix ({:.2}°): it holds a symmetric soft iron, so its \
                 headings differ from imucal's by up to that angle (imucal's are in the \
                 accelerometer's frame when the fit aligned the two).\n",
                self.mag_rotation_deg
            ));
        } else {
            text.push_str("The Adafruit library cannot apply:\n");
            for t in &self.unapplied {
                text.push_str(&format!("  - {}: {}\n", t.sensor, t.term));
            }
        }
        if self.poses == 0 {
            // Said above already when it is the only term left out.
            if turned && !self.unapplied.is_empty() {
                text.push_str(&format!(
                    "Magnetometer frame turned by {:.2}° (symmetric soft iron).\n",
                    self.mag_rotation_deg
                ));
            }
            return text;
        }
        text.push_str(&format!(
            "Cost on {} poses (largest): accelerometer {:.2} mg, gyroscope {:.4} °/s, \
             magnetometer {:.2} % of the field; magnetometer frame turned by {:.2}°.\n",
            self.poses,
            self.accel_error_mg,
            self.gyro_error_dps,
            self.mag_error_pct_of_field,
            self.mag_rotation_deg
        ));
        text
    }
}

/// Largest deviation of `m` from the identity.
fn off_identity(m: &[[f32; 3]; 3]) -> f64 {
    let mut worst = 0.0_f64;
    for (r, row) in m.iter().enumerate() {
        for (c, v) in row.iter().enumerate() {
            worst = worst.max((f64::from(*v) - f64::from(u8::from(r == c))).abs());
        }
    }
    worst
}

/// The dropped extended terms of one sensor.
fn extended_terms(sensor: &'static str, cal: &SensorCalibration, out: &mut Vec<UnappliedTerm>) {
    let mut push = |term: &str| {
        out.push(UnappliedTerm {
            sensor,
            term: term.to_owned(),
        })
    };
    if cal.bias_temp.is_some() {
        push("offset temperature dependence");
    }
    if cal.scale_temp.is_some() {
        push("scale temperature dependence");
    }
    if cal.nonlinearity.is_some() {
        push("scale non-linearity");
    }
}

/// What the library cannot apply of `set` and its cost, measured on `poses` (uncalibrated
/// readings in m/s², rad/s, µT, °C — e.g. the mean of each captured pose).
pub fn limitations(
    set: &CalibrationSet,
    poses: &[UnitSample],
) -> Result<AdafruitLimitations, CompatError> {
    let conversion = AdafruitCalibration::from_set(set)?;
    let cal = conversion.calibration;
    // Below f32 round-off of a unit scale a matrix term is no term at all.
    let negligible = 1e-6;
    let mut unapplied = Vec::new();
    if off_identity(&set.accel.a) > negligible {
        unapplied.push(UnappliedTerm {
            sensor: "accel",
            term: "scale and misalignment (matrix A)".into(),
        });
    }
    extended_terms("accel", &set.accel, &mut unapplied);
    if off_identity(&set.gyro.a) > negligible {
        unapplied.push(UnappliedTerm {
            sensor: "gyro",
            term: "scale and misalignment (matrix A)".into(),
        });
    }
    if set.gyro_g_sensitivity.is_some() {
        unapplied.push(UnappliedTerm {
            sensor: "gyro",
            term: "g-sensitivity".into(),
        });
    }
    extended_terms("gyro", &set.gyro, &mut unapplied);
    extended_terms("mag", &set.mag, &mut unapplied);

    let rotation = Matrix3::from_fn(|r, c| conversion.mag_rotation[r][c]);
    let field = f64::from(set.reference.field_ut).abs();
    let mut costs = [0.0_f64; 3];
    for pose in poses {
        let out = apply_set_model(
            set,
            &NominalSample {
                accel: pose.accel,
                gyro: pose.gyro,
                mag: pose.mag,
                temp_c: pose.temp_c,
            },
        );
        let full = [out.accel, out.gyro, out.mag];
        let lib = cal.apply(pose.accel, pose.gyro, pose.mag);
        let dist = |a: [f64; 3], b: [f64; 3]| (Vector3::from(a) - Vector3::from(b)).norm();
        costs[0] = costs[0].max(dist(full[0], lib[0]) / G_MPS2 * 1000.0);
        costs[1] = costs[1].max(dist(full[1], lib[1]).to_degrees());
        let full_sym = rotation.transpose() * Vector3::from(full[2]);
        let mag_err = (full_sym - Vector3::from(lib[2])).norm();
        costs[2] = costs[2].max(if field > 0.0 {
            100.0 * mag_err / field
        } else {
            0.0
        });
    }
    Ok(AdafruitLimitations {
        unapplied,
        accel_error_mg: costs[0],
        gyro_error_dps: costs[1],
        mag_error_pct_of_field: costs[2],
        mag_rotation_deg: conversion.mag_rotation_deg,
        poses: poses.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_turned_magnetometer_frame_is_not_called_every_term_applied() {
        let mut limits = AdafruitLimitations {
            unapplied: Vec::new(),
            accel_error_mg: 0.0,
            gyro_error_dps: 0.0,
            mag_error_pct_of_field: 0.0,
            mag_rotation_deg: 3.1,
            poses: 0,
        };
        let text = limits.describe();
        assert!(
            text.contains("but the rotation in the magnetometer's matrix"),
            "{text}"
        );
        // Said once, and not as a turn into the accelerometer's frame the fit may not have made.
        assert_eq!(text.matches("3.10°").count(), 1, "{text}");
        assert!(
            !text.contains("turn into the accelerometer frame"),
            "{text}"
        );
        limits.mag_rotation_deg = 0.0;
        assert!(limits
            .describe()
            .contains("can apply every term of this calibration.\n"));
    }

    fn pose(accel: [f64; 3], gyro: [f64; 3], mag: [f64; 3]) -> UnitSample {
        UnitSample {
            t_s: 0.0,
            accel,
            gyro,
            mag,
            temp_c: 25.0,
        }
    }

    #[test]
    fn dropped_accel_scale_and_gyro_scale_cost_what_they_change_on_the_poses() {
        let mut set = CalibrationSet::identity();
        // 1 % accel scale on x, 2 % gyro scale on z: on a 1 g x pose and a 0.5 rad/s z rate
        // the library is off by 0.01 g = 10 mg and 0.01 rad/s = 0.573 °/s.
        set.accel.a[0][0] = 1.01;
        set.gyro.a[2][2] = 1.02;
        set.reference.field_ut = 50.0;
        let poses = [
            pose([G_MPS2, 0.0, 0.0], [0.0, 0.0, 0.5], [50.0, 0.0, 0.0]),
            pose([0.0, G_MPS2, 0.0], [0.0, 0.0, 0.0], [0.0, 50.0, 0.0]),
        ];
        let lim = limitations(&set, &poses).unwrap();
        assert!(
            (lim.accel_error_mg - 10.0).abs() < 1e-3,
            "{}",
            lim.accel_error_mg
        );
        assert!((lim.gyro_error_dps - 0.01f64.to_degrees()).abs() < 1e-6);
        assert!(lim.mag_error_pct_of_field < 1e-9);
        let sensors: Vec<&str> = lim.unapplied.iter().map(|t| t.sensor).collect();
        assert_eq!(sensors, ["accel", "gyro"]);
        assert!(lim.describe().contains("10.00 mg"), "{}", lim.describe());
    }

    #[test]
    fn offsets_and_symmetric_soft_iron_carry_over_without_cost() {
        let mut set = CalibrationSet::identity();
        set.accel.b = [0.1, -0.2, 0.3];
        set.gyro.b = [0.01, 0.02, -0.03];
        set.mag.a = [[1.1, 0.02, 0.0], [0.02, 0.9, 0.01], [0.0, 0.01, 1.0]];
        set.mag.b = [10.0, -20.0, 5.0];
        set.reference.field_ut = 48.0;
        let poses = [pose([0.3, 9.0, 1.0], [0.2, -0.1, 0.0], [40.0, -10.0, 30.0])];
        let lim = limitations(&set, &poses).unwrap();
        assert!(lim.unapplied.is_empty());
        // f32 rounding of the soft iron only.
        assert!(lim.accel_error_mg < 1e-6 && lim.gyro_error_dps < 1e-6);
        assert!(
            lim.mag_error_pct_of_field < 1e-4,
            "{}",
            lim.mag_error_pct_of_field
        );
        assert!(
            lim.mag_rotation_deg < 1e-3,
            "a symmetric A needs no rotation"
        );
    }

    #[test]
    fn temperature_terms_are_listed_as_unapplied() {
        let mut set = CalibrationSet::identity();
        set.gyro.t_ref_c = 25.0;
        set.gyro.bias_temp = Some(imucal_protocol::BiasTemperature {
            coeffs: [[1e-3, 0.0, 0.0], [0.0; 3], [0.0; 3]],
        });
        // 10 °C away from the reference: 1e-2 rad/s of bias the library leaves in.
        let mut p = pose([0.0, 0.0, G_MPS2], [0.0; 3], [0.0, 0.0, 40.0]);
        p.temp_c = 35.0;
        let lim = limitations(&set, &[p]).unwrap();
        assert_eq!(lim.unapplied.len(), 1);
        assert_eq!(lim.unapplied[0].term, "offset temperature dependence");
        assert!((lim.gyro_error_dps - 0.01f64.to_degrees()).abs() < 1e-4);
    }

    #[test]
    fn sensor_calib_json_with_missing_keys_reads_the_library_defaults() {
        let cal = AdafruitCalibration::from_sensor_calib_json("{\"mag_field\": 45.5}").unwrap();
        assert_eq!(
            cal,
            AdafruitCalibration {
                mag_field: 45.5,
                ..AdafruitCalibration::identity()
            }
        );
    }
}
