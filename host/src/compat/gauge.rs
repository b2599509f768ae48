//! The symmetric gauge of a magnetometer correction matrix (polar decomposition).
//!
//! A field fit determines `A` in `y = A·(x − b)` only up to a rotation `R` of the output frame:
//! `‖A·u‖ = ‖R·A·u‖`. imucal stores the upper-triangular representative; MotionCal and the
//! Adafruit library carry a symmetric one. Both are the same ellipsoid `AᵀA`, so the symmetric
//! representative is `S = (AᵀA)^½` (eigen-decomposition `AᵀA = V·Λ·Vᵀ`, `S = V·Λ^½·Vᵀ`), and
//! `A = R·S` with `R = A·S⁻¹` orthogonal: the polar decomposition. `S` gives the same field
//! magnitude as `A` for every reading; the output frame differs from imucal's by `R`, whose angle
//! is reported so the user knows how far the magnetometer frame was turned.

use nalgebra::{Matrix3, SymmetricEigen};

use super::CompatError;

/// `A` split as `R·S`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SymmetricGauge {
    /// Symmetric positive-definite part `S = (AᵀA)^½`.
    pub symmetric: Matrix3<f64>,
    /// Orthogonal part `R = A·S⁻¹` (the rotation removed; a reflection if `det A < 0`).
    pub rotation: Matrix3<f64>,
    /// Angle of `R`, degrees (of `−R` for a reflection).
    pub rotation_deg: f64,
}

/// Splits `a` into its symmetric part and the rotation removed.
pub fn symmetric_gauge(a: &[[f32; 3]; 3]) -> Result<SymmetricGauge, CompatError> {
    let a = Matrix3::from_fn(|r, c| f64::from(a[r][c]));
    if a.iter().any(|v| !v.is_finite()) {
        return Err(CompatError::DegenerateMagnetometer);
    }
    let eigen = SymmetricEigen::new(a.transpose() * a);
    let largest = eigen.eigenvalues.max();
    // Relative to the largest, an eigenvalue below f64 round-off means A is singular.
    if !largest.is_finite() || largest <= 0.0 || eigen.eigenvalues.min() <= largest * 1e-12 {
        return Err(CompatError::DegenerateMagnetometer);
    }
    let root = eigen.eigenvalues.map(f64::sqrt);
    let v = eigen.eigenvectors;
    let symmetric = v * Matrix3::from_diagonal(&root) * v.transpose();
    let inverse = v * Matrix3::from_diagonal(&root.map(|r| 1.0 / r)) * v.transpose();
    let rotation = a * inverse;
    let proper = if rotation.determinant() < 0.0 {
        -rotation
    } else {
        rotation
    };
    let cos = ((proper.trace() - 1.0) / 2.0).clamp(-1.0, 1.0);
    Ok(SymmetricGauge {
        symmetric,
        rotation,
        rotation_deg: cos.acos().to_degrees(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Rotation3, Vector3};

    #[test]
    fn symmetric_part_of_a_rotated_symmetric_matrix_is_recovered_with_the_rotation_angle() {
        let s = Matrix3::new(1.1, 0.05, -0.02, 0.05, 0.95, 0.03, -0.02, 0.03, 1.02);
        let r = Rotation3::from_axis_angle(&Vector3::z_axis(), 7f64.to_radians());
        let a64 = r.matrix() * s;
        let a = [0, 1, 2].map(|i| [0, 1, 2].map(|j| a64[(i, j)] as f32));
        let gauge = symmetric_gauge(&a).unwrap();
        // f32 storage of A limits the agreement to about 1e-7 relative.
        assert!((gauge.symmetric - s).abs().max() < 1e-6);
        assert!(
            (gauge.rotation_deg - 7.0).abs() < 1e-4,
            "{}",
            gauge.rotation_deg
        );
    }

    #[test]
    fn upper_triangular_and_symmetric_forms_give_the_same_magnitude() {
        let a = [[1.2, 0.1, -0.05], [0.0, 0.9, 0.07], [0.0, 0.0, 1.05]];
        let gauge = symmetric_gauge(&a).unwrap();
        let a64 = Matrix3::from_fn(|r, c| f64::from(a[r][c]));
        for u in [
            Vector3::new(30.0, -10.0, 5.0),
            Vector3::new(-3.0, 40.0, 22.0),
        ] {
            let rel = ((gauge.symmetric * u).norm() - (a64 * u).norm()).abs() / (a64 * u).norm();
            assert!(rel < 1e-12, "{rel}");
        }
    }

    #[test]
    fn singular_matrix_is_refused() {
        let a = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]];
        assert_eq!(
            symmetric_gauge(&a),
            Err(CompatError::DegenerateMagnetometer)
        );
    }
}
