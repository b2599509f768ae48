//! Plain Gauss–Newton autocalibration in the manner of Frosio, Pedersini & Borghese (2009),
//! "Autocalibration of MEMS accelerometers", IEEE Trans. Instrum. Meas. 58(6), the iterative
//! method compared in seed 000 (Puc et al., section 3, Tables 1–2).
//!
//! Model: a symmetric sensitivity matrix `A` (6 unknowns) and an offset `b` (3), residual
//! `rᵢ = |A(xᵢ − b)|² − ref²` (the squared-norm form), undamped Gauss–Newton steps
//! `δ = −(JᵀJ)⁻¹Jᵀr` from the fixed start `A = I`, `b = 0` (or `b` = the data mean when
//! `subtract_mean` is set, the remedy of seed 000 section 3.2). There is deliberately no damping
//! or line search: with a large offset the iteration fails to converge, as seed 000 reports
//! ("konvergenca ni bila nikoli dosežena"), and this method returns `NotConverged` then.

use nalgebra::{DMatrix, DVector};

use super::covariance::normal_covariance;
use super::coverage::{guard_fit, CoverageHint, EllipsoidModel};
use super::li::li_start;
use super::linalg::{equilibrated_condition_number, rms};
use super::uncertainty::{scaled_covariance, NoiseLevel, Z_95};
use super::{Calibration, CalibrationStd, Fit, FitError, Mat3, Method, Vec3};

/// Options of [`fit_frosio`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrosioOptions {
    /// Start the offset at the mean of the data instead of zero.
    pub subtract_mean: bool,
    /// Gauss–Newton steps allowed.
    pub max_iterations: usize,
    /// Converged when the step is below this fraction of the parameter vector's size.
    pub step_tolerance: f64,
}

impl Default for FrosioOptions {
    fn default() -> Self {
        Self {
            subtract_mean: false,
            max_iterations: 50,
            step_tolerance: 1e-10,
        }
    }
}

const NAMES: [&str; 9] = ["A11", "A12", "A13", "A22", "A23", "A33", "b1", "b2", "b3"];

fn symmetric(p: &DVector<f64>) -> Mat3 {
    Mat3::new(p[0], p[1], p[2], p[1], p[3], p[4], p[2], p[4], p[5])
}

fn residuals_and_jacobian(
    p: &DVector<f64>,
    points: &[Vec3],
    reference: f64,
) -> (DVector<f64>, DMatrix<f64>) {
    let a = symmetric(p);
    let b = Vec3::new(p[6], p[7], p[8]);
    let mut r = DVector::zeros(points.len());
    let mut j = DMatrix::zeros(points.len(), 9);
    for (i, x) in points.iter().enumerate() {
        let u = x - b;
        let v = a * u;
        r[i] = v.norm_squared() - reference * reference;
        // d|v|²/dA_kl = 2 v_k u_l, and the symmetric pairs share one unknown.
        let d = |k: usize, l: usize| 2.0 * v[k] * u[l];
        let row = [
            d(0, 0),
            d(0, 1) + d(1, 0),
            d(0, 2) + d(2, 0),
            d(1, 1),
            d(1, 2) + d(2, 1),
            d(2, 2),
        ];
        for (k, val) in row.iter().enumerate() {
            j[(i, k)] = *val;
        }
        let db = -2.0 * (a.transpose() * v);
        for k in 0..3 {
            j[(i, 6 + k)] = db[k];
        }
    }
    (r, j)
}

/// Fit `A` (symmetric) and `b` to readings that should all have norm `reference`.
///
/// The coverage rule of [`super::coverage`] is applied before returning, and replaces a failure
/// to converge when the data cannot determine the parameters.
pub fn fit_frosio(points: &[Vec3], reference: f64, opts: &FrosioOptions) -> Result<Fit, FitError> {
    guard_fit(
        fit_frosio_unchecked(points, reference, opts),
        points,
        None,
        reference,
        EllipsoidModel::General,
        CoverageHint::Either,
        || li_start(points, reference),
    )
}

fn fit_frosio_unchecked(
    points: &[Vec3],
    reference: f64,
    opts: &FrosioOptions,
) -> Result<Fit, FitError> {
    let name = Method::Frosio.name();
    if !(reference.is_finite() && reference > 0.0) {
        return Err(FitError::Underdetermined(format!(
            "the reference magnitude must be a positive number, got {reference}; pass g or the field strength, or 1"
        )));
    }
    if let Some(i) = points.iter().position(|p| p.iter().any(|v| !v.is_finite())) {
        return Err(FitError::NonFinite(format!("reading {i}")));
    }
    if points.len() < 9 {
        return Err(FitError::Underdetermined(format!(
            "only {} readings for 9 unknowns; record at least 9 distinct orientations",
            points.len()
        )));
    }
    let mean = points.iter().sum::<Vec3>() / points.len() as f64;
    let b0 = if opts.subtract_mean {
        mean
    } else {
        Vec3::zeros()
    };
    let mut p = DVector::from_vec(vec![1.0, 0.0, 0.0, 1.0, 0.0, 1.0, b0.x, b0.y, b0.z]);
    let mut converged = false;
    let mut iterations = 0;
    while iterations < opts.max_iterations {
        iterations += 1;
        let (r, j) = residuals_and_jacobian(&p, points, reference);
        let jtj = j.transpose() * &j;
        let step = jtj.cholesky().map(|c| c.solve(&(-(j.transpose() * r))));
        let Some(step) = step.filter(|s| s.iter().all(|v| v.is_finite())) else {
            return Err(FitError::NotConverged {
                method: name,
                iterations,
                detail: "the normal matrix became singular (the iterate collapsed)".into(),
            });
        };
        p += &step;
        if p.iter().any(|v| !v.is_finite()) {
            return Err(FitError::NotConverged {
                method: name,
                iterations,
                detail: "the iterate diverged".into(),
            });
        }
        if step.norm() <= opts.step_tolerance * p.norm().max(reference) {
            converged = true;
            break;
        }
    }
    if !converged {
        return Err(FitError::NotConverged {
            method: name,
            iterations,
            detail: "the Gauss–Newton steps did not settle; try subtracting the mean or use the LM method".into(),
        });
    }
    let a = symmetric(&p);
    // |A u| = |−A u|: an iterate that ended with a negative determinant is still a valid fit,
    // but a singular one is not.
    if a.determinant().abs() <= f64::EPSILON * a.norm().powi(3) {
        return Err(FitError::NotConverged {
            method: name,
            iterations,
            detail: "the fitted matrix is singular".into(),
        });
    }
    let cal = Calibration {
        a,
        b: Vec3::new(p[6], p[7], p[8]),
    };
    let (r, j) = residuals_and_jacobian(&p, points, reference);
    let chi2 = r.norm_squared();
    // Noise unknown: estimated from the residual by the common policy (`uncertainty`).
    let scaled = scaled_covariance(
        normal_covariance(&(j.transpose() * &j)),
        chi2,
        points.len(),
        9,
        NoiseLevel::Unknown,
    );
    let coverage_factor = scaled.as_ref().map_or(Z_95, |s| s.coverage_factor);
    let covariance = scaled.map(|s| s.covariance);
    let std = covariance.as_ref().map(|c| {
        let s = |k: usize| c[(k, k)].max(0.0).sqrt();
        CalibrationStd {
            a: Mat3::new(s(0), s(1), s(2), s(1), s(3), s(4), s(2), s(4), s(5)),
            b: Vec3::new(s(6), s(7), s(8)),
        }
    });
    let residuals: Vec<f64> = points
        .iter()
        .map(|x| (cal.apply(x).norm() - reference) / reference)
        .collect();
    Ok(Fit {
        method: Method::Frosio,
        cal,
        rms: rms(&residuals),
        residuals,
        loo_rms: None,
        covariance,
        param_names: NAMES.iter().map(|s| s.to_string()).collect(),
        std,
        condition_number: equilibrated_condition_number(&j),
        iterations,
        termination: None,
        coverage_factor,
        reference,
    })
}
