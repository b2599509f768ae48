//! Scalar calibration after Merayo, Brauer, Primdahl, Petersen & Nielsen (2000), "Scalar
//! calibration of vector magnetometers", Meas. Sci. Technol. 11, 120–132, the ellipsoid method
//! compared in seed 000 (Puc et al., section 3, Tables 1–2).
//!
//! What is done (an equivalent of their linear step): `(x − b)ᵀM(x − b) = k` with `M ∝ AᵀA`
//! expands to the quadric `xᵀMx + uᵀx = 1` once it is normalised by its constant term, which is
//! linear in the nine coefficients `(M, u)` and solved by least squares. (Li's fit, seed 000
//! eq. 17–23, instead normalises with the ellipsoid constraint `4J − I² = 1`.) This normalisation
//! depends on the origin, so — as in seed 000 Table 2 — the data may first be centred on their
//! mean (`subtract_mean`; the origin is then inside the ellipsoid and the constant term cannot
//! vanish); they are always scaled, which changes nothing but the conditioning. Then `b = −½M⁻¹u`, `M` is rescaled by the level `1 + bᵀMb` so that the
//! fitted surface is the unit sphere after calibration, and `A` is the upper-triangular Cholesky
//! factor of `M` (`M = AᵀA`, their matrix "T"), which is the norm-model gauge; the known field
//! magnitude `ref` sets the output scale. The
//! covariance propagates the linear fit's `σ̂²(XᵀX)⁻¹` through this map by finite differences.

use nalgebra::{DMatrix, DVector};

use super::covariance::{calibration_std, param_names, UPPER_TRIANGULAR_LAYOUT};
use super::coverage::{guard_fit, CoverageHint, EllipsoidModel};
use super::li::li_start;
use super::linalg::{least_squares, rms};
use super::uncertainty::{noise_scale, NoiseLevel, Z_95};
use super::{Calibration, Fit, FitError, Mat3, Method, Vec3};

/// Coefficients `(M, u)` in centred, scaled units → upper-triangular entries of `A` and `b`
/// (same units), or `None` when they do not describe an ellipsoid.
fn ellipsoid_params(theta: &DVector<f64>) -> Option<DVector<f64>> {
    let m = Mat3::new(
        theta[0], theta[3], theta[4], theta[3], theta[1], theta[5], theta[4], theta[5], theta[2],
    );
    let u = Vec3::new(theta[6], theta[7], theta[8]);
    let b = -0.5 * m.try_inverse()? * u;
    // On the fitted surface (x−b)ᵀM(x−b) = 1 + bᵀMb; rescale so that it is exactly 1.
    let level = 1.0 + b.dot(&(m * b));
    if !(level.is_finite() && level > 0.0) {
        return None;
    }
    let chol = (m / level).cholesky()?;
    let r = chol.l().transpose();
    Some(DVector::from_vec(vec![
        r[(0, 0)],
        r[(0, 1)],
        r[(0, 2)],
        r[(1, 1)],
        r[(1, 2)],
        r[(2, 2)],
        b.x,
        b.y,
        b.z,
    ]))
}

/// Fit `A` (upper-triangular) and `b` to readings whose calibrated norm is `reference`.
///
/// `subtract_mean`: centre the data on their mean before the linear fit (seed 000 Table 2, "Po").
/// The coverage rule of [`super::coverage`] is applied before returning.
pub fn fit_merayo(points: &[Vec3], reference: f64, subtract_mean: bool) -> Result<Fit, FitError> {
    guard_fit(
        fit_merayo_unchecked(points, reference, subtract_mean),
        points,
        None,
        reference,
        EllipsoidModel::General,
        CoverageHint::Either,
        || li_start(points, reference),
    )
}

fn fit_merayo_unchecked(
    points: &[Vec3],
    reference: f64,
    subtract_mean: bool,
) -> Result<Fit, FitError> {
    if !(reference.is_finite() && reference > 0.0) {
        return Err(FitError::Underdetermined(format!(
            "the reference magnitude must be a positive number, got {reference}; pass the field strength, or 1"
        )));
    }
    if let Some(i) = points.iter().position(|p| p.iter().any(|v| !v.is_finite())) {
        return Err(FitError::NonFinite(format!("reading {i}")));
    }
    let n = points.len();
    if n < 10 {
        return Err(FitError::Underdetermined(format!(
            "only {n} readings for the 9 ellipsoid coefficients; record at least 10 orientations"
        )));
    }
    let mean = if subtract_mean {
        points.iter().sum::<Vec3>() / n as f64
    } else {
        Vec3::zeros()
    };
    let s = (points
        .iter()
        .map(|p| (p - mean).norm_squared())
        .sum::<f64>()
        / n as f64)
        .sqrt();
    if !(s.is_finite() && s > 0.0) {
        return Err(FitError::Underdetermined(
            "all readings are identical; rotate the sensor".into(),
        ));
    }
    let scaled: Vec<Vec3> = points.iter().map(|p| (p - mean) / s).collect();
    let design = DMatrix::from_fn(n, 9, |i, k| {
        let x = &scaled[i];
        match k {
            0 => x.x * x.x,
            1 => x.y * x.y,
            2 => x.z * x.z,
            3 => 2.0 * x.x * x.y,
            4 => 2.0 * x.x * x.z,
            5 => 2.0 * x.y * x.z,
            6 => x.x,
            7 => x.y,
            _ => x.z,
        }
    });
    let rhs = DMatrix::from_element(n, 1, 1.0);
    let ls = least_squares(&design, &rhs, "Merayo ellipsoid")?;
    let theta = DVector::from_column_slice(ls.solution.column(0).as_slice());
    let not_ellipsoid = || {
        FitError::Underdetermined(
            "the readings do not lie on an ellipsoid (the fitted quadric is not closed); \
             turn the sensor through more orientations"
                .into(),
        )
    };
    let q = ellipsoid_params(&theta).ok_or_else(not_ellipsoid)?;
    let to_natural: Vec<f64> = (0..9)
        .map(|k| if k < 6 { reference / s } else { s })
        .collect();
    let a = Mat3::new(q[0], q[1], q[2], 0.0, q[3], q[4], 0.0, 0.0, q[5]) * (reference / s);
    let b = mean + Vec3::new(q[6], q[7], q[8]) * s;
    let cal = Calibration { a, b };

    // Covariance: residual variance of the linear fit, propagated through ellipsoid_params.
    let fit_residual = &design * &theta - DVector::from_element(n, 1.0);
    // Noise unknown: estimated from the residual by the common policy (`uncertainty`).
    let scale = noise_scale(fit_residual.norm_squared(), n, 9, NoiseLevel::Unknown);
    let coverage_factor = scale.map_or(Z_95, |s| s.coverage_factor);
    let sigma2 = scale.map(|s| s.variance_factor);
    let covariance = (design.transpose() * &design).cholesky().and_then(|c| {
        let cov_theta = c.inverse() * sigma2?;
        let mut g = DMatrix::zeros(9, 9);
        for k in 0..9 {
            let h = 1e-6 * theta[k].abs().max(1e-3);
            let mut plus = theta.clone();
            let mut minus = theta.clone();
            plus[k] += h;
            minus[k] -= h;
            let d = (ellipsoid_params(&plus)? - ellipsoid_params(&minus)?) / (2.0 * h);
            g.set_column(k, &d);
        }
        let cov = &g * cov_theta * g.transpose();
        Some(DMatrix::from_fn(9, 9, |i, j| {
            cov[(i, j)] * to_natural[i] * to_natural[j]
        }))
    });
    let std = covariance
        .as_ref()
        .map(|c| calibration_std(c, &UPPER_TRIANGULAR_LAYOUT));
    let residuals: Vec<f64> = points
        .iter()
        .map(|x| (cal.apply(x).norm() - reference) / reference)
        .collect();
    Ok(Fit {
        method: Method::Merayo,
        cal,
        rms: rms(&residuals),
        residuals,
        loo_rms: None,
        covariance,
        param_names: param_names(&UPPER_TRIANGULAR_LAYOUT),
        std,
        condition_number: ls.equilibrated_condition,
        iterations: 0,
        termination: None,
        coverage_factor,
        reference,
    })
}
