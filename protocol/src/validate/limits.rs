//! The bounds a calibration set must satisfy, with the reason for each (see [`super`]).

/// Largest accepted Frobenius condition number `‖A‖_F·‖A⁻¹‖_F` of a matrix `A`.
///
/// Since `κ₂ ≤ κ_F ≤ 3·κ₂`, every `A` with a 2-norm condition number up to 10 passes and none
/// above 30 does. Real sensors need far less (scale errors of a few %, cross-axis ≤ a few %,
/// soft iron stretching one axis ≤ 2×); a larger value means a degenerate fit that would
/// amplify noise along one direction.
pub const MAX_CONDITION_FROBENIUS: f64 = 30.0;

/// Accepted RMS gain `‖A‖_F/√3` of `A` per sensor, `(low, high)`: accelerometer, gyroscope,
/// magnetometer.
///
/// Accelerometer and gyroscope output in their nominal units, so `A ≈ I`; the window catches
/// fits done in the wrong units (g vs m/s² is 9.8×, °/s vs rad/s is 57×). The magnetometer may
/// be fitted to µT (gain ≈ 1, soft iron up to a few ×) or to the unit field (gain ≈ 1/|B|,
/// about 1/65 to 1/25 for the Earth's 25–65 µT), hence its wider window.
pub const GAIN_LIMITS: [(f64, f64); 3] = [(0.5, 2.0), (0.5, 2.0), (0.005, 4.0)];

/// Largest temperature excursion from the reference over which temperature terms are checked,
/// and to which every implementation clamps `ΔT`, °C (the −40…85 °C industrial range).
pub const MAX_DELTA_T_C: f32 = 125.0;

/// Accepted reference temperature `T_ref` of a sensor, °C: the widest (military/automotive) die
/// temperature range. A fit is always made at a temperature the part can have; without this
/// bound a finite but absurd `T_ref` such as 10³⁰ °C would make `ΔT³` overflow.
pub const REFERENCE_TEMP_RANGE_C: (f32, f32) = (-55.0, 125.0);

/// Largest accepted relative scale change of a scale-temperature term over `|ΔT| ≤`
/// [`MAX_DELTA_T_C`]: ±50 %.
pub const MAX_SCALE_TEMP_CHANGE: f32 = 0.5;

/// Largest accepted relative change of a full-scale reading by the non-linearity terms,
/// `|q|·r + |k|·r²`: one half.
pub const MAX_NONLINEAR_CHANGE: f32 = 0.5;

/// Largest accepted gyro g-sensitivity entry, rad/s per m/s² (≈ 5.6 °/s per g; MEMS gyros are
/// specified at 0.01–0.2 °/s per g).
pub const MAX_G_SENSITIVITY: f32 = 0.01;
