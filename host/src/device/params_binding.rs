//! Binding a parameter file to a board: `flash` compares the board a file was made for
//! (`board_identity::DeviceJson`) with the board it talks to, so another board's calibration (or one made
//! under other ranges) is not written without a word.

use imucal_protocol::Welcome;

use super::params_json::{ParamsFile, SensorJson};

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
                // The board sends its range as f32: printed so, without f64's tail of digits.
                let range = range as f32;
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
