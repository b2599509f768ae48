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
    /// `σ_max / σ_min` of `X` with unit-length columns ([`equilibrated_condition_number`]).
    pub equilibrated_condition: f64,
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
    // XᵀX = V·Σ²·Vᵀ from the decomposition already made, not from another pass over X.
    let equilibrated_condition = match &svd.v_t {
        Some(vt) => {
            let s2 = DMatrix::from_diagonal(&svd.singular_values.map(|v| v * v));
            equilibrated_condition_from_normal_matrix(&(vt.transpose() * s2 * vt))
        }
        None => f64::INFINITY,
    };
    Ok(LeastSquares {
        solution,
        singular_values: sv,
        condition_number: cond,
        equilibrated_condition,
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

/// [`condition_number`] of `m` with each column scaled to unit length: the conditioning of the
/// parameters' estimation whatever units each is in (column scaling is within `√n` of the best
/// diagonal scaling, van der Sluis 1969), so fits that solve in raw counts and fits that solve
/// in scaled data report comparable figures. Infinite with a zero column.
pub fn equilibrated_condition_number(m: &DMatrix<f64>) -> f64 {
    let mut scaled = m.clone();
    for mut column in scaled.column_iter_mut() {
        let norm = column.norm();
        if norm.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            return f64::INFINITY;
        }
        column /= norm;
    }
    condition_number(&scaled)
}

/// [`equilibrated_condition_number`] of `J` from its normal matrix `JᵀJ`: the condition of
/// `D⁻¹·JᵀJ·D⁻¹` with `D = √diag(JᵀJ)`, square-rooted.
pub fn equilibrated_condition_from_normal_matrix(jtj: &DMatrix<f64>) -> f64 {
    let d: Vec<f64> = jtj.diagonal().iter().map(|v| v.sqrt()).collect();
    if d.iter()
        .any(|v| v.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater))
    {
        return f64::INFINITY;
    }
    condition_from_normal_matrix(&DMatrix::from_fn(jtj.nrows(), jtj.ncols(), |r, c| {
        jtj[(r, c)] / (d[r] * d[c])
    }))
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_equilibrated_condition_does_not_depend_on_the_parameters_units() {
        let j = DMatrix::from_row_slice(
            4,
            3,
            &[1.0, 0.2, 0.1, 0.3, 1.0, 0.0, 0.1, 0.4, 1.0, 0.5, 0.5, 0.5],
        );
        // The second parameter in units a thousand times smaller (raw counts, say).
        let mut rescaled = j.clone();
        rescaled.column_mut(1).scale_mut(1000.0);
        let (a, b) = (
            equilibrated_condition_number(&j),
            equilibrated_condition_number(&rescaled),
        );
        assert!((a - b).abs() < 1e-9 * a, "{a} against {b}");
        assert!(condition_number(&rescaled) > 100.0 * condition_number(&j));
        // The normal-matrix form and the least-squares solve give the same figure.
        let from_normal =
            equilibrated_condition_from_normal_matrix(&(rescaled.transpose() * &rescaled));
        assert!(
            (from_normal - a).abs() < 1e-6 * a,
            "{from_normal} against {a}"
        );
        let ls =
            least_squares(&rescaled, &DMatrix::from_element(4, 1, 1.0), "test").expect("solves");
        assert!((ls.equilibrated_condition - a).abs() < 1e-6 * a);
        assert!(equilibrated_condition_number(&DMatrix::zeros(3, 2)).is_infinite());
    }
}
