//! Hardware faults a production line meets, applied to a drawn board: what makes a board an
//! outlier against its fleet. Sizes are those of real faults, far outside the consumer-MEMS
//! ranges of [`crate::physics::ImuErrorRanges`] (±0.3 m/s² accelerometer offset, ±3 % gain,
//! ±50 µT hard iron):
//! - an accelerometer axis with a gross offset (0.3 g: a cracked proof mass or a bad solder
//!   joint stressing the package) or a gross gain error (−20 %: a damaged axis);
//! - a magnet next to the magnetometer (a speaker, a reed-switch magnet): a constant field in the
//!   board's frame, i.e. 150 µT of extra hard iron;
//! - a gyroscope with excess white noise (×10 density: a damaged MEMS structure or a noisy supply;
//!   the reading model has one noise density per sensor, so all three axes get it).

use serde::{Deserialize, Serialize};

use crate::physics::{ImuTruth, SensorTruth};

/// One hardware fault.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "fault")]
pub enum HardwareFault {
    /// An accelerometer axis reads `offset_mps2` too much.
    AccelOffset {
        /// Axis 0, 1, 2 (x, y, z).
        axis: usize,
        /// Added offset, m/s².
        offset_mps2: f64,
    },
    /// An accelerometer axis has its gain multiplied by `gain`.
    AccelGain {
        /// Axis 0, 1, 2.
        axis: usize,
        /// Gain factor (1 = no fault).
        gain: f64,
    },
    /// A magnet fixed near the magnetometer adds `field_ut` in the board's frame.
    MagnetNearby {
        /// Added field, µT, body frame.
        field_ut: [f64; 3],
    },
    /// The gyroscope's white-noise density is multiplied by `factor`.
    GyroNoise {
        /// Noise factor (1 = no fault).
        factor: f64,
    },
}

impl HardwareFault {
    /// The `index`-th of the four realistic faults (cycling), on an axis chosen by `index`.
    pub fn realistic(index: usize) -> Self {
        let axis = (index / 4) % 3;
        match index % 4 {
            0 => Self::AccelOffset {
                axis,
                offset_mps2: 0.3 * crate::world::STANDARD_GRAVITY_MPS2,
            },
            1 => Self::MagnetNearby {
                field_ut: [150.0, -60.0, 90.0],
            },
            2 => Self::AccelGain { axis, gain: 0.8 },
            _ => Self::GyroNoise { factor: 10.0 },
        }
    }

    /// The fault in words.
    pub fn describe(&self) -> String {
        const AXES: [&str; 3] = ["x", "y", "z"];
        let axis_name = |axis: usize| AXES.get(axis).copied().unwrap_or("?");
        match self {
            Self::AccelOffset { axis, offset_mps2 } => format!(
                "accelerometer {} axis offset by {offset_mps2:.2} m/s²",
                axis_name(*axis)
            ),
            Self::AccelGain { axis, gain } => {
                format!("accelerometer {} axis gain ×{gain}", axis_name(*axis))
            }
            Self::MagnetNearby { field_ut } => {
                let size = field_ut.iter().map(|v| v * v).sum::<f64>().sqrt();
                format!("a magnet next to the magnetometer ({size:.0} µT)")
            }
            Self::GyroNoise { factor } => format!("gyroscope noise ×{factor}"),
        }
    }

    /// Apply the fault to `truth`.
    pub fn apply(&self, truth: &mut ImuTruth) {
        match *self {
            Self::AccelOffset { axis, offset_mps2 } => {
                if let Some(b) = truth.accel.b_true.get_mut(axis) {
                    *b += offset_mps2;
                }
            }
            Self::AccelGain { axis, gain } => scale_axis_gain(&mut truth.accel, axis, gain),
            Self::MagnetNearby { field_ut } => {
                for (b, extra) in truth.mag.b_true.iter_mut().zip(field_ut) {
                    *b += extra;
                }
            }
            Self::GyroNoise { factor } => {
                truth.gyro.noise_density *= factor;
                truth.gyro.noise_sigma *= factor;
            }
        }
    }
}

/// The sensor reads `x = A⁻¹·y + b`: a gain `g` on axis `i` multiplies row `i` of `A⁻¹` by `g`
/// and column `i` of `A` by `1/g`.
fn scale_axis_gain(sensor: &mut SensorTruth, axis: usize, gain: f64) {
    if axis > 2 || !gain.is_finite() || gain == 0.0 {
        return;
    }
    for v in sensor.a_true_inverse[axis].iter_mut() {
        *v *= gain;
    }
    for row in sensor.a_true.iter_mut() {
        row[axis] /= gain;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::ImuErrorRanges;

    fn board() -> ImuTruth {
        ImuTruth::draw(7, &ImuErrorRanges::default(), &[], 100.0, 0.0).expect("valid ranges")
    }

    #[test]
    fn a_gain_fault_keeps_a_the_inverse_of_the_sensors_matrix() {
        let mut truth = board();
        HardwareFault::AccelGain { axis: 1, gain: 0.8 }.apply(&mut truth);
        let product = truth.accel.a() * truth.accel.a_inverse();
        assert!((product - nalgebra::Matrix3::identity()).norm() < 1e-12);
        let clean = board();
        let ratio = truth.accel.a_true_inverse[1][1] / clean.accel.a_true_inverse[1][1];
        assert!((ratio - 0.8).abs() < 1e-12);
    }

    #[test]
    fn a_magnet_adds_its_field_to_the_hard_iron() {
        let mut truth = board();
        let clean = board();
        HardwareFault::MagnetNearby {
            field_ut: [150.0, -60.0, 90.0],
        }
        .apply(&mut truth);
        assert!((truth.mag.b_true[0] - clean.mag.b_true[0] - 150.0).abs() < 1e-12);
        assert!((truth.mag.b_true[1] - clean.mag.b_true[1] + 60.0).abs() < 1e-12);
    }
}
