//! Moments of degree ≤ 4 of a point cloud, from which the Li ellipsoid fit's scatter matrix
//! `S = DᵀD` is assembled without forming the N×10 design matrix `D`.
//!
//! The design row is `φ = [x² y² z² 2yz 2xz 2xy 2x 2y 2z 1]` (seed 000 eq. 18), each entry a
//! coefficient `cₖ ∈ {1, 2}` times a monomial `x^a y^b z^c` of degree ≤ 2. So
//! `Sᵢⱼ = cᵢcⱼ·Σ x^(aᵢ+aⱼ) y^(bᵢ+bⱼ) z^(cᵢ+cⱼ)`: every entry is one of the 35 moments of degree ≤ 4.
//! One pass over the samples accumulates those 35 sums (≈ 20 multiplications and 35 additions a
//! sample, against 55 multiply-adds for `S` directly); scaling the cloud by `1/s` divides the
//! moment of degree `d` by `s^d`, so it is applied afterwards at no cost.

use nalgebra::DMatrix;

use super::Vec3;

/// Exponents `(a, b, c)` of the 35 monomials `x^a y^b z^c`, in the order they are accumulated.
const EXPONENTS: [[u8; 3]; 35] = [
    [0, 0, 0],
    // degree 1
    [1, 0, 0],
    [0, 1, 0],
    [0, 0, 1],
    // degree 2
    [2, 0, 0],
    [0, 2, 0],
    [0, 0, 2],
    [0, 1, 1],
    [1, 0, 1],
    [1, 1, 0],
    // degree 3
    [3, 0, 0],
    [0, 3, 0],
    [0, 0, 3],
    [2, 1, 0],
    [2, 0, 1],
    [1, 2, 0],
    [0, 2, 1],
    [1, 0, 2],
    [0, 1, 2],
    [1, 1, 1],
    // degree 4
    [4, 0, 0],
    [0, 4, 0],
    [0, 0, 4],
    [3, 1, 0],
    [3, 0, 1],
    [1, 3, 0],
    [0, 3, 1],
    [1, 0, 3],
    [0, 1, 3],
    [2, 2, 0],
    [2, 0, 2],
    [0, 2, 2],
    [2, 1, 1],
    [1, 2, 1],
    [1, 1, 2],
];

/// Design columns of the Li fit as (coefficient, monomial exponents).
const DESIGN: [(f64, [u8; 3]); 10] = [
    (1.0, [2, 0, 0]),
    (1.0, [0, 2, 0]),
    (1.0, [0, 0, 2]),
    (2.0, [0, 1, 1]),
    (2.0, [1, 0, 1]),
    (2.0, [1, 1, 0]),
    (2.0, [1, 0, 0]),
    (2.0, [0, 1, 0]),
    (2.0, [0, 0, 1]),
    (1.0, [0, 0, 0]),
];

/// The 35 monomials of one point, in [`EXPONENTS`] order.
#[inline(always)]
fn monomials(x: f64, y: f64, z: f64) -> [f64; 35] {
    let (xx, yy, zz, yz, xz, xy) = (x * x, y * y, z * z, y * z, x * z, x * y);
    [
        1.0,
        x,
        y,
        z,
        xx,
        yy,
        zz,
        yz,
        xz,
        xy,
        xx * x,
        yy * y,
        zz * z,
        xx * y,
        xx * z,
        x * yy,
        yy * z,
        x * zz,
        y * zz,
        xy * z,
        xx * xx,
        yy * yy,
        zz * zz,
        xx * xy,
        xx * xz,
        xy * yy,
        yy * yz,
        xz * zz,
        yz * zz,
        xx * yy,
        xx * zz,
        yy * zz,
        xx * yz,
        xy * yz,
        xy * zz,
    ]
}

/// Sums of the 35 monomials of degree ≤ 4 over points taken about a centre.
#[derive(Debug, Clone, PartialEq)]
pub struct Moments {
    sums: [f64; 35],
}

impl Moments {
    /// Moments of `points − centre`, in one pass.
    pub fn about(points: &[Vec3], centre: &Vec3) -> Self {
        let mut sums = [0.0; 35];
        for p in points {
            let m = monomials(p.x - centre.x, p.y - centre.y, p.z - centre.z);
            for (s, v) in sums.iter_mut().zip(m) {
                *s += v;
            }
        }
        Self { sums }
    }

    /// Moments about the points' mean, with the mean and the RMS radius about it (the scale
    /// of Li's fit about the mean); `None` for no points or all of them at their mean.
    pub fn about_mean(points: &[Vec3]) -> Option<(Self, Vec3, f64)> {
        if points.is_empty() {
            return None;
        }
        let centre = points.iter().sum::<Vec3>() / points.len() as f64;
        let moments = Self::about(points, &centre);
        let scale = moments.rms_radius();
        (scale.partial_cmp(&0.0) == Some(std::cmp::Ordering::Greater))
            .then_some((moments, centre, scale))
    }

    /// The moments without the point `p − centre` (for leave-one-out).
    pub fn without(&self, p: &Vec3, centre: &Vec3) -> Self {
        let m = monomials(p.x - centre.x, p.y - centre.y, p.z - centre.z);
        let mut sums = self.sums;
        for (s, v) in sums.iter_mut().zip(m) {
            *s -= v;
        }
        Self { sums }
    }

    /// Number of points (the moment of degree 0).
    pub fn count(&self) -> f64 {
        self.sums[0]
    }

    /// RMS distance of the points from the centre (0 for no points).
    pub fn rms_radius(&self) -> f64 {
        if self.count() <= 0.0 {
            return 0.0;
        }
        ((self.sums[4] + self.sums[5] + self.sums[6]) / self.count())
            .max(0.0)
            .sqrt()
    }

    /// The Li scatter matrix `DᵀD` of the points scaled by `1/scale` about the centre.
    pub fn scatter(&self, scale: f64) -> DMatrix<f64> {
        DMatrix::from_fn(10, 10, |i, j| {
            let (ci, ei) = DESIGN[i];
            let (cj, ej) = DESIGN[j];
            let e = [ei[0] + ej[0], ei[1] + ej[1], ei[2] + ej[2]];
            let degree = i32::from(e[0] + e[1] + e[2]);
            ci * cj * self.sums[moment_index(e)] / scale.powi(degree)
        })
    }
}

/// The 35 monomials of `(p − centre)·inverse_scale`, in the order of the moment sums: the basis
/// in which [`linear_form`] and [`quadratic_form`] give their coefficients; the linear form's
/// ten come first.
#[inline(always)]
pub(super) fn scaled_monomials(p: &Vec3, centre: &Vec3, inverse_scale: f64) -> [f64; 35] {
    let q = (p - centre) * inverse_scale;
    monomials(q.x, q.y, q.z)
}

/// Monomials of degree ≤ 2, the only ones a [`linear_form`] has coefficients for: the first
/// ten of [`scaled_monomials`].
pub(super) const LINEAR_TERMS: usize = 10;

/// Coefficients over the 35 monomials of the linear form `φ(q)ᵀw` (`φ` the design row, `w` 10
/// numbers; only the 10 monomials of degree ≤ 2 get one).
pub(super) fn linear_form(w: &[f64; 10]) -> [f64; 35] {
    let mut coefficients = [0.0; 35];
    for ((c, e), wi) in DESIGN.iter().zip(w) {
        coefficients[moment_index(*e)] += c * wi;
    }
    coefficients
}

/// Coefficients over the 35 monomials of the quadratic form `φ(q)ᵀPφ(q)` (`P` 10×10): the
/// product of design columns `j` and `k` is the monomial of the summed exponents.
pub(super) fn quadratic_form(p: &DMatrix<f64>) -> [f64; 35] {
    let mut coefficients = [0.0; 35];
    for (j, (cj, ej)) in DESIGN.iter().enumerate() {
        for (k, (ck, ek)) in DESIGN.iter().enumerate() {
            let e = [ej[0] + ek[0], ej[1] + ek[1], ej[2] + ek[2]];
            coefficients[moment_index(e)] += cj * ck * p[(j, k)];
        }
    }
    coefficients
}

/// Position of the monomial with exponents `e` in [`EXPONENTS`] (every degree ≤ 4 is present).
fn moment_index(e: [u8; 3]) -> usize {
    EXPONENTS.iter().position(|x| *x == e).unwrap_or(0)
}

/// The N×10 design matrix `D` written out row by row (seed 000 eq. 18) for the points moved by
/// `−centre` and divided by `scale`: the reference the moment form is checked against.
#[cfg(test)]
pub(crate) fn explicit_design(points: &[Vec3], centre: &Vec3, scale: f64) -> DMatrix<f64> {
    DMatrix::from_fn(points.len(), 10, |r, c| {
        let q = (points[r] - centre) / scale;
        let (x, y, z) = (q.x, q.y, q.z);
        [
            x * x,
            y * y,
            z * z,
            2.0 * y * z,
            2.0 * x * z,
            2.0 * x * y,
            2.0 * x,
            2.0 * y,
            2.0 * z,
            1.0,
        ][c]
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scatter_from_moments_equals_the_product_of_the_explicit_design_matrix() {
        let points: Vec<Vec3> = (0..50)
            .map(|i| {
                let t = f64::from(i);
                Vec3::new(
                    3.0 * (0.3 * t).sin() + 1.0,
                    2.0 * (0.7 * t).cos(),
                    0.5 * t - 4.0,
                )
            })
            .collect();
        let centre = Vec3::new(0.5, -0.2, 1.0);
        let scale = 2.5;
        let design = explicit_design(&points, &centre, scale);
        let explicit = design.transpose() * &design;
        let from_moments = Moments::about(&points, &centre).scatter(scale);
        // Only the order of the floating-point additions differs: agreement to ~1e-13 relative.
        let worst = (&explicit - &from_moments).amax() / explicit.amax();
        assert!(worst < 1e-13, "relative difference {worst:e}");
    }

    #[test]
    fn removing_a_point_equals_accumulating_without_it() {
        let points: Vec<Vec3> = (0..20)
            .map(|i| Vec3::new(f64::from(i), f64::from(i * i % 7), 1.5))
            .collect();
        let centre = Vec3::new(1.0, 2.0, 3.0);
        let full = Moments::about(&points, &centre);
        let without = full.without(&points[4], &centre);
        let mut rest = points.clone();
        rest.remove(4);
        let direct = Moments::about(&rest, &centre);
        let worst = (without.scatter(1.0) - direct.scatter(1.0)).amax();
        assert!(worst < 1e-9 * direct.scatter(1.0).amax(), "{worst:e}");
        assert_eq!(without.count(), 19.0);
    }
}
