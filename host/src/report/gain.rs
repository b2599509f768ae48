//! Calibration matrices in a form a person can read: each axis' sensitivity against nominal and
//! the angles between the sensing axes, with the unit conversion taken out (an `A` of 9.675 for
//! data in g is a 1.3 % scale error, which the bare number hides). For `y = A·(x − b)` the rows
//! of `M = A⁻¹` are the sensing axes expressed in the data's unit: `|Mᵢ|·k` (with `k` the factor
//! from the data's unit to the output unit) is axis i's sensitivity relative to nominal, and the
//! angle between rows i and j departs from 90° by their non-orthogonality.

use crate::fit::Mat3;

/// Which parts of a [`Gain`] the fit estimated. A model that fixes the axes at 90° (the
/// axis-aligned models) leaves the off-diagonal entries of `A` exactly zero, and one that fixes
/// the scale too (the bias-only gyroscope fit) leaves `A` an exact multiple of the identity;
/// no fitted value lands exactly there, and printing `+0.000 %` or `+0.000°` for them would read
/// as a measurement.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Estimated {
    /// The sensitivities (the diagonal of `A`).
    pub scale: bool,
    /// The angles between the axes (the off-diagonal entries).
    pub axes: bool,
}

impl Estimated {
    /// What the model behind `a` estimated (see the type's comment).
    pub fn of(a: &Mat3) -> Self {
        let axes = (0..3).any(|i| (0..3).any(|j| i != j && a[(i, j)] != 0.0));
        let scale = axes || a[(0, 0)] != a[(1, 1)] || a[(1, 1)] != a[(2, 2)];
        Self { scale, axes }
    }
}

/// Sensitivities and axis non-orthogonality of one calibration matrix.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gain {
    /// Sensitivity of x, y, z relative to nominal (1 = nominal).
    pub scale: [f64; 3],
    /// Departure from 90° of the angles between the axis pairs yz, xz, xy, degrees.
    pub skew_deg: [f64; 3],
}

/// The axis pairs of [`Gain::skew_deg`].
const PAIRS: [(usize, usize); 3] = [(1, 2), (0, 2), (0, 1)];

/// Sensitivities and non-orthogonality of `a`, whose input is `to_nominal` output units per data
/// unit; `None` when `a` is singular or not finite.
pub fn gain(a: &Mat3, to_nominal: f64) -> Option<Gain> {
    let m = a
        .try_inverse()
        .filter(|m| m.iter().all(|v| v.is_finite()))?;
    let rows = [0, 1, 2].map(|i| m.row(i).transpose());
    let norms = rows.map(|r| r.norm());
    if norms.iter().any(|n| *n <= 0.0) {
        return None;
    }
    let skew_deg = PAIRS.map(|(i, j)| {
        let cos = (rows[i].dot(&rows[j]) / (norms[i] * norms[j])).clamp(-1.0, 1.0);
        90.0 - cos.acos().to_degrees()
    });
    Some(Gain {
        scale: norms.map(|n| n * to_nominal),
        skew_deg,
    })
}

/// [`gain_text`] saying "not estimated" for the parts the model fixed.
pub fn gain_text_of(gain: &Gain, digits: usize, estimated: Estimated) -> String {
    match (estimated.scale, estimated.axes) {
        (true, true) => gain_text(gain, digits),
        (true, false) => format!(
            "{}; axes taken as at 90° (not estimated by this model)",
            scale_text(gain, digits)
        ),
        (false, true) => format!(
            "scale not estimated (fixed by this model); {}",
            axes_text(gain)
        ),
        (false, false) => {
            "scale and axis angles not estimated (this model fits the offset only)".to_string()
        }
    }
}

/// `scale [+1.300 %, …]; axes off 90° by yz …°, xz …°, xy …°` with `digits` decimals of percent.
pub fn gain_text(gain: &Gain, digits: usize) -> String {
    format!("{}; {}", scale_text(gain, digits), axes_text(gain))
}

fn scale_text(gain: &Gain, digits: usize) -> String {
    let scale: Vec<String> = gain
        .scale
        .iter()
        .map(|s| format!("{:+.digits$} %", (s - 1.0) * 100.0))
        .collect();
    format!("scale error [{}] of nominal", scale.join(", "))
}

fn axes_text(gain: &Gain) -> String {
    let skew: Vec<String> = ["yz", "xz", "xy"]
        .iter()
        .zip(gain.skew_deg)
        .map(|(pair, d)| format!("{pair} {d:+.3}°"))
        .collect();
    format!("axes off 90° by {}", skew.join(", "))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::Vec3;

    #[test]
    fn unit_conversion_is_removed_and_a_scale_error_shows_in_percent() {
        // Data in g read 1.3 % high on x: A = diag(9.80665 / 1.013, 9.80665, 9.80665).
        let g = 9.80665;
        let a = Mat3::from_diagonal(&Vec3::new(g / 1.013, g, g));
        let found = gain(&a, g).expect("invertible");
        assert!((found.scale[0] - 1.013).abs() < 1e-12, "{:?}", found.scale);
        assert!((found.scale[1] - 1.0).abs() < 1e-12);
        assert!(found.skew_deg.iter().all(|d| d.abs() < 1e-9));
        assert!(gain_text(&found, 3).contains("+1.300 %"));
    }

    #[test]
    fn a_sheared_axis_shows_its_angle_to_the_others() {
        // x senses 0.1° towards y: rows of M = A⁻¹ are x' = (cos, sin, 0), y, z.
        let t = 0.1_f64.to_radians();
        let m = Mat3::new(t.cos(), t.sin(), 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0);
        let a = m.try_inverse().expect("invertible");
        let found = gain(&a, 1.0).expect("invertible");
        assert!(
            (found.skew_deg[2] - 0.1).abs() < 1e-9,
            "{:?}",
            found.skew_deg
        );
        assert!(found.skew_deg[0].abs() < 1e-9 && found.skew_deg[1].abs() < 1e-9);
    }

    #[test]
    fn a_singular_matrix_has_no_gain() {
        assert_eq!(gain(&Mat3::zeros(), 1.0), None);
    }

    #[test]
    fn terms_a_model_fixes_are_not_shown_as_measured() {
        let g = gain(&(Mat3::identity() * 0.0174533), 57.29578).expect("invertible");
        let bias_only = Estimated::of(&(Mat3::identity() * 0.0174533));
        assert_eq!(
            bias_only,
            Estimated {
                scale: false,
                axes: false
            }
        );
        assert!(gain_text_of(&g, 3, bias_only).contains("not estimated"));
        let diagonal = Mat3::from_diagonal(&Vec3::new(1.003, 0.997, 0.977));
        let axis_aligned = Estimated::of(&diagonal);
        assert!(axis_aligned.scale && !axis_aligned.axes);
        let text = gain_text_of(&gain(&diagonal, 1.0).expect("invertible"), 3, axis_aligned);
        assert!(
            text.contains("-0.299 %") && text.contains("axes taken as at 90°"),
            "{text}"
        );
        let full = Mat3::new(1.0, 0.01, 0.0, 0.0, 1.0, 0.002, 0.0, 0.0, 0.99);
        assert_eq!(
            Estimated::of(&full),
            Estimated {
                scale: true,
                axes: true
            }
        );
    }
}
