//! Parameter uncertainty shared by the fits: covariance from the Gauss–Newton normal matrix,
//! its mapping onto the entries of `A` and `b`, the reduced chi-square, and condition numbers.
//!
//! With residuals already divided by their noise σᵢ, the covariance of a least-squares estimate
//! is `(JᵀJ)⁻¹` (with known noise this is also the Cramér–Rao bound for the data set; see
//! ARCHITECTURE.md, "Uncertainty"). When the noise is only known up to a common factor, the
//! covariance is scaled by the reduced chi-square `χ²/(N − P)`.

use nalgebra::DMatrix;

use super::{CalibrationStd, Mat3, Vec3};

/// Which entry of a calibration a parameter is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ParamEntry {
    /// Entry `A[row][col]` (zero-based).
    A(usize, usize),
    /// Entry `b[index]` (zero-based).
    B(usize),
}

impl ParamEntry {
    /// One-based name, e.g. `"A12"` or `"b3"`.
    pub fn name(self) -> String {
        match self {
            ParamEntry::A(r, c) => format!("A{}{}", r + 1, c + 1),
            ParamEntry::B(i) => format!("b{}", i + 1),
        }
    }
}

/// Parameter order of the upper-triangular norm-model fits: `A11 A12 A13 A22 A23 A33 b1 b2 b3`.
pub const UPPER_TRIANGULAR_LAYOUT: [ParamEntry; 9] = [
    ParamEntry::A(0, 0),
    ParamEntry::A(0, 1),
    ParamEntry::A(0, 2),
    ParamEntry::A(1, 1),
    ParamEntry::A(1, 2),
    ParamEntry::A(2, 2),
    ParamEntry::B(0),
    ParamEntry::B(1),
    ParamEntry::B(2),
];

/// Parameter order of a full `A` (row-major) without offset, as in the gyroscope scale fit.
pub const FULL_MATRIX_LAYOUT: [ParamEntry; 9] = [
    ParamEntry::A(0, 0),
    ParamEntry::A(0, 1),
    ParamEntry::A(0, 2),
    ParamEntry::A(1, 0),
    ParamEntry::A(1, 1),
    ParamEntry::A(1, 2),
    ParamEntry::A(2, 0),
    ParamEntry::A(2, 1),
    ParamEntry::A(2, 2),
];

/// Names of the parameters of `layout`, in order.
pub fn param_names(layout: &[ParamEntry]) -> Vec<String> {
    layout.iter().map(|e| e.name()).collect()
}

/// Inverse of a symmetric positive semi-definite normal matrix, or `None` when it is singular
/// to working precision (some parameter is not determined by the data).
pub fn normal_covariance(jtj: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    if jtj.nrows() != jtj.ncols() || jtj.iter().any(|v| !v.is_finite()) {
        return None;
    }
    // Equilibrate first so that parameters of very different size do not look singular.
    let d: Vec<f64> = (0..jtj.nrows())
        .map(|i| jtj[(i, i)].max(0.0).sqrt())
        .collect();
    if d.contains(&0.0) {
        return None;
    }
    let scaled = DMatrix::from_fn(jtj.nrows(), jtj.ncols(), |i, j| jtj[(i, j)] / (d[i] * d[j]));
    let inv = scaled.cholesky()?.inverse();
    let cov = DMatrix::from_fn(inv.nrows(), inv.ncols(), |i, j| inv[(i, j)] / (d[i] * d[j]));
    cov.iter().all(|v| v.is_finite()).then_some(cov)
}

/// Ratio of the largest to the smallest singular value (∞ when rank-deficient); shared with
/// the algebraic fits.
pub use super::linalg::condition_number;

/// `χ²/(N − P)`: about 1 when the residuals match the assumed noise; `None` when `N ≤ P`.
pub fn reduced_chi_square(chi_square: f64, residuals: usize, params: usize) -> Option<f64> {
    (residuals > params).then(|| chi_square / (residuals - params) as f64)
}

/// One-sigma uncertainties of the entries named by `layout`, from the diagonal of `cov`
/// (entries not in `layout` are fixed and get zero).
pub fn calibration_std(cov: &DMatrix<f64>, layout: &[ParamEntry]) -> CalibrationStd {
    let mut a = Mat3::zeros();
    let mut b = Vec3::zeros();
    for (k, entry) in layout.iter().enumerate().take(cov.nrows().min(cov.ncols())) {
        let s = cov[(k, k)].max(0.0).sqrt();
        match *entry {
            ParamEntry::A(r, c) if r < 3 && c < 3 => a[(r, c)] = s,
            ParamEntry::B(i) if i < 3 => b[i] = s,
            _ => {}
        }
    }
    CalibrationStd { a, b }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn covariance_of_a_diagonal_normal_matrix_is_its_reciprocal() {
        let jtj = DMatrix::from_diagonal(&nalgebra::DVector::from_vec(vec![4.0, 1e-6, 1e8]));
        let cov = normal_covariance(&jtj).unwrap();
        // Exact up to round-off despite the 1e14 spread, thanks to equilibration.
        assert!((cov[(0, 0)] - 0.25).abs() < 1e-15);
        assert!((cov[(1, 1)] - 1e6).abs() < 1e-6);
        assert!((cov[(2, 2)] - 1e-8).abs() < 1e-22);
    }

    #[test]
    fn a_parameter_without_information_gives_no_covariance() {
        let jtj = DMatrix::from_row_slice(2, 2, &[1.0, 1.0, 1.0, 1.0]);
        assert!(normal_covariance(&jtj).is_none());
        assert!(normal_covariance(&DMatrix::from_diagonal_element(2, 2, 0.0)).is_none());
    }

    #[test]
    fn condition_number_is_the_singular_value_ratio() {
        let m = DMatrix::from_row_slice(3, 2, &[3.0, 0.0, 0.0, 0.5, 0.0, 0.0]);
        assert!((condition_number(&m) - 6.0).abs() < 1e-12);
        assert!(condition_number(&DMatrix::<f64>::zeros(3, 2)).is_infinite());
    }

    #[test]
    fn std_is_placed_on_the_named_entries_and_zero_elsewhere() {
        let cov = DMatrix::from_diagonal(&nalgebra::DVector::from_fn(9, |i, _| {
            ((i + 1) * (i + 1)) as f64
        }));
        let std = calibration_std(&cov, &UPPER_TRIANGULAR_LAYOUT);
        assert_eq!(std.a[(0, 1)], 2.0);
        assert_eq!(std.a[(2, 2)], 6.0);
        assert_eq!(std.a[(1, 0)], 0.0);
        assert_eq!(std.b[2], 9.0);
        assert_eq!(param_names(&UPPER_TRIANGULAR_LAYOUT)[4], "A23");
    }
}
