//! Small dense linear-algebra helpers shared by the fits: least squares by SVD with a rank test,
//! condition numbers, the upper-triangular gauge of the norm model, symmetric square roots.

use nalgebra::{DMatrix, DVector};

use super::{FitError, Mat3};

/// Singular values below this fraction of the largest are treated as zero: the matrix is then
/// rank-deficient for the purpose of a fit in f64 (about 1e4 machine epsilons).
pub const RANK_TOLERANCE: f64 = 1e-12;

/// Solution of a linear least-squares problem `X·β ≈ Y`.
#[derive(Debug, Clone)]
pub struct LeastSquares {
    /// The minimiser `β̂` (columns of `Y` solved independently).
    pub solution: DMatrix<f64>,
    /// Singular values of `X`, largest first.
    pub singular_values: Vec<f64>,
    /// `σ_max / σ_min` of `X`.
    pub condition_number: f64,
}

/// Solve `X·β ≈ Y` in the least-squares sense by SVD.
///
/// Refuses (`Underdetermined` with `what` naming the problem) when `X` has fewer rows than
/// columns or is numerically rank-deficient, instead of returning a minimum-norm answer that
/// would look like a calibration.
pub fn least_squares(
    x: &DMatrix<f64>,
    y: &DMatrix<f64>,
    what: &str,
) -> Result<LeastSquares, FitError> {
    if x.nrows() < x.ncols() {
        return Err(FitError::Underdetermined(format!(
            "{what}: {} equations for {} unknowns; add more poses or samples",
            x.nrows(),
            x.ncols()
        )));
    }
    if x.iter().chain(y.iter()).any(|v| !v.is_finite()) {
        return Err(FitError::NonFinite(format!("{what}: design matrix")));
    }
    let svd = x.clone().svd(true, true);
    let sv = sorted_desc(svd.singular_values.as_slice());
    let cond = condition_from(&sv);
    if !cond.is_finite() || cond * RANK_TOLERANCE > 1.0 {
        return Err(FitError::Underdetermined(format!(
            "{what}: the design matrix is rank-deficient (condition number {cond:.3e}); \
             the data does not vary enough to separate the parameters"
        )));
    }
    let solution = svd
        .solve(y, 0.0)
        .map_err(|e| FitError::Underdetermined(format!("{what}: {e}")))?;
    Ok(LeastSquares {
        solution,
        singular_values: sv,
        condition_number: cond,
    })
}

/// Singular values of `m`, largest first.
pub fn singular_values(m: &DMatrix<f64>) -> Vec<f64> {
    sorted_desc(m.clone().svd(false, false).singular_values.as_slice())
}

/// `σ_max / σ_min` of `m` (infinite when `σ_min` is zero or the matrix is empty).
pub fn condition_number(m: &DMatrix<f64>) -> f64 {
    condition_from(&singular_values(m))
}

/// `σ_max / σ_min` of a matrix `J` from its normal matrix `JᵀJ` (`σᵢ = √λᵢ(JᵀJ)`), without
/// forming `J`; infinite when `JᵀJ` is singular. Forming `JᵀJ` squares the condition, so the
/// result keeps about `16 − 2·log₁₀(cond)` digits: ample to judge a fit's conditioning.
pub fn condition_from_normal_matrix(jtj: &DMatrix<f64>) -> f64 {
    if jtj.is_empty() || jtj.iter().any(|v| !v.is_finite()) {
        return f64::INFINITY;
    }
    let sym = (jtj + jtj.transpose()) * 0.5;
    let eigenvalues = sym.symmetric_eigenvalues();
    let (max, min) = (eigenvalues.max(), eigenvalues.min());
    if min > 0.0 {
        (max / min).sqrt()
    } else {
        f64::INFINITY
    }
}

fn condition_from(sv: &[f64]) -> f64 {
    match (sv.first(), sv.last()) {
        (Some(&max), Some(&min)) if min > 0.0 => max / min,
        _ => f64::INFINITY,
    }
}

fn sorted_desc(values: &[f64]) -> Vec<f64> {
    let mut v = values.to_vec();
    v.sort_by(|a, b| b.total_cmp(a));
    v
}

/// The norm-model gauge of `A`: the upper-triangular `R` with positive diagonal such that
/// `A = Q·R` with `Q` orthogonal, hence `|A·u| = |R·u|` for every `u`.
pub fn upper_triangular_gauge(a: &Mat3) -> Mat3 {
    let qr = a.qr();
    let mut r = qr.r();
    for i in 0..3 {
        if r[(i, i)] < 0.0 {
            // Flipping a row of R (and the matching column of Q) keeps A = Q·R.
            for j in 0..3 {
                r[(i, j)] = -r[(i, j)];
            }
        }
    }
    r
}

/// The orthogonal `Q` of the same factorisation `A = Q·R` (`R` with positive diagonal, as in
/// [`upper_triangular_gauge`]): the rotation (or reflection) the norm-model gauge leaves out, so
/// a norm fit's output frame is `Qᵀ` times the sensor's.
pub fn orthogonal_factor(a: &Mat3) -> Mat3 {
    let qr = a.qr();
    let (mut q, r) = (qr.q(), qr.r());
    for i in 0..3 {
        if r[(i, i)] < 0.0 {
            for c in 0..3 {
                q[(c, i)] = -q[(c, i)];
            }
        }
    }
    q
}

/// Square root of a symmetric positive-definite matrix, `V·Λ^½·Vᵀ`; `None` if not positive definite.
pub fn sqrt_spd(m: &Mat3) -> Option<Mat3> {
    let sym = (m + m.transpose()) * 0.5;
    let eig = sym.symmetric_eigen();
    if eig
        .eigenvalues
        .iter()
        .any(|&l| l.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater))
    {
        return None;
    }
    let root = Mat3::from_diagonal(&eig.eigenvalues.map(f64::sqrt));
    Some(eig.eigenvectors * root * eig.eigenvectors.transpose())
}

/// Root mean square of `values` (0 for an empty slice).
pub fn rms(values: &[f64]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    (values.iter().map(|v| v * v).sum::<f64>() / values.len() as f64).sqrt()
}

/// Inverse of a symmetric positive-definite matrix via Cholesky; `None` if it is not.
pub fn inverse_spd(m: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let chol = m.clone().cholesky()?;
    let inv = chol.inverse();
    inv.iter().all(|v| v.is_finite()).then_some(inv)
}

/// `sqrt` of the diagonal of a covariance matrix.
pub fn std_from_covariance(cov: &DMatrix<f64>) -> DVector<f64> {
    DVector::from_iterator(
        cov.nrows(),
        (0..cov.nrows()).map(|i| cov[(i, i)].max(0.0).sqrt()),
    )
}
