//! General ellipsoid fit after Li & Griffiths (2004) with the `M^½` construction of seed 000
//! (eq. 17–29).
//!
//! The quadric (eq. 17) `a x² + b y² + c z² + 2f yz + 2g xz + 2h xy + 2p x + 2q y + 2r z + d = 0`,
//! `v = [a b c f g h p q r d]ᵀ` (eq. 18), is fitted by minimising `vᵀSv` (`S = DᵀD`, one design row
//! `[x² y² z² 2yz 2xz 2xy 2x 2y 2z 1]` per sample) subject to Li & Griffiths' ellipsoid constraint
//! `kJ − I² = 1` with `k = 4` (`I = a+b+c`, `J = ab+bc+ca−f²−g²−h²`), written `v₁ᵀC₁v₁ = 1` on the
//! quadratic part `v₁ = [a b c f g h]ᵀ`. With `S` split into blocks (`S₁₁` 6×6, `S₁₂` 6×4, `S₂₂`
//! 4×4) the linear part is `v₂ = −S₂₂⁻¹S₂₁v₁`, and `v₁` is the eigenvector of
//! `C₁⁻¹(S₁₁ − S₁₂S₂₂⁻¹S₂₁)` with the one positive eigenvalue.
//!
//! Factor-of-two convention: with `M = [[a h g],[h b f],[g f c]]` and `n = [p q r]ᵀ` the quadric is
//! `xᵀMx + 2nᵀx + d = 0` (seed 000 eq. 19 omits the 2 of eq. 17), so completing the square
//! (eq. 21) gives the centre `b = −M⁻¹n` (eq. 22) and `C = bᵀMb − d` (eq. 23 as printed has `M⁻¹`,
//! which is not consistent with eq. 21). The semi-axes are `√(C/λ)` (eq. 24–25) and the calibration
//! is `A = (ref/√C)·M^½` (eq. 26–29), a symmetric matrix.
//!
//! Conditioning: samples are scaled to unit RMS radius about the chosen centre (the origin, or the
//! sample mean with [`LiOptions::subtract_mean`], the preconditioning of seed 000 Table 2) before
//! forming `S`; the centre and scale are mapped back afterwards.
//!
//! Speed: `D` (N×10) is never formed. Every entry of `S` is a sum of one monomial of degree ≤ 4
//! in the centred coordinates, so one pass accumulates the 35 such moments
//! ([`super::li_moments`]) and `S` is assembled from them; the rest works on 10×10 matrices.
//!
//! Degenerate case: noise-free samples make `S₁₁ − S₁₂S₂₂⁻¹S₂₁` singular, the wanted eigenvalue is
//! zero rather than positive, and "the positive one" is ill defined in rounding. Every eigenpair
//! is therefore scored: among eigenvectors with `v₁ᵀC₁v₁ > 0` (the constraint can be met) the one
//! with the smallest normalised cost `v₁ᵀMv₁ / v₁ᵀC₁v₁` is taken; for noisy data this is exactly
//! the positive eigenvalue, for exact data the zero one. The sign is fixed by making `M` positive
//! definite.

use nalgebra::{DMatrix, DVector};

use super::coverage::{check_coverage, guard_fit, CoverageHint, EllipsoidModel};
use super::li_moments::Moments;
use super::linalg::{singular_values, sqrt_spd, RANK_TOLERANCE};
use super::validate::{check_finite_points, check_reference};
use super::{Calibration, Fit, FitError, Mat3, Method, Vec3};

/// Largest accepted design condition number: the eigenproblem works on `S = DᵀD`, whose condition
/// is its square, so beyond 1e6 fewer than 4 of the 16 digits of the eigenvector remain.
pub const MAX_CONDITION: f64 = 1e6;

/// Options of the Li fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LiOptions {
    /// Subtract the sample mean before fitting and add it back to `b` (seed 000 Table 2); strongly
    /// improves conditioning when the offset is large next to the ellipsoid's radius.
    pub subtract_mean: bool,
}

/// Fit a general ellipsoid to `points` and return the calibration mapping it onto the sphere of
/// radius `reference`. Needs at least 10 points spread over the ellipsoid.
///
/// `condition_number` is the ratio of the largest to the second-smallest singular value of the
/// normalised design matrix: the fit is its (near-)null vector, whose sensitivity to noise is set
/// by the gap to the next singular value. Above [`MAX_CONDITION`] the fit is refused.
///
/// Before returning, the coverage rule of [`super::coverage`] is applied: a cloud that cannot
/// determine the ellipsoid (one plane, a few clusters) is refused with what to add.
pub fn fit_li(points: &[Vec3], reference: f64, opts: LiOptions) -> Result<Fit, FitError> {
    guard_fit(
        fit_li_unchecked(points, reference, opts),
        points,
        None,
        reference,
        EllipsoidModel::General,
        CoverageHint::Either,
        || li_start(points, reference),
    )
}

/// Li's ellipsoid about the sample mean, without the coverage rule: the lens through which the
/// coverage of a failed fit is judged. `None` when even this fit fails.
pub(crate) fn li_start(points: &[Vec3], reference: f64) -> Option<Calibration> {
    fit_li_unchecked(
        points,
        reference,
        LiOptions {
            subtract_mean: true,
        },
    )
    .ok()
    .map(|f| f.cal)
}

/// [`fit_li`] without the coverage rule (used to judge the coverage of failed fits).
pub(crate) fn fit_li_unchecked(
    points: &[Vec3],
    reference: f64,
    opts: LiOptions,
) -> Result<Fit, FitError> {
    let (cal, condition_number) = li_calibration(points, reference, opts)?;
    Ok(Fit::closed_form(
        Method::Li,
        cal,
        points,
        reference,
        condition_number,
    ))
}

/// The calibration of [`fit_li`] alone, when its coverage rule holds: a start for the iterative
/// fits, which need neither the residual of every point nor the fit's statistics (on a long
/// recording that would be one more pass over every sample). `None` when [`fit_li`] fails.
pub(crate) fn fit_li_start(
    points: &[Vec3],
    reference: f64,
    opts: LiOptions,
) -> Option<Calibration> {
    let (cal, _) = li_calibration(points, reference, opts).ok()?;
    check_coverage(
        points,
        None,
        &cal,
        reference,
        EllipsoidModel::General,
        CoverageHint::Either,
    )
    .ok()?;
    Some(cal)
}

/// The calibration of [`fit_li_unchecked`] with the design condition number.
fn li_calibration(
    points: &[Vec3],
    reference: f64,
    opts: LiOptions,
) -> Result<(Calibration, f64), FitError> {
    check_reference(reference)?;
    check_finite_points(points)?;
    if points.len() < 10 {
        return Err(FitError::Underdetermined(format!(
            "only {} samples; the general ellipsoid has 9 degrees of freedom and needs at least 10",
            points.len()
        )));
    }
    let centre = if opts.subtract_mean {
        points.iter().sum::<Vec3>() / points.len() as f64
    } else {
        Vec3::zeros()
    };
    let moments = Moments::about(points, &centre);
    let scale = moments.rms_radius();
    if scale.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return Err(FitError::Underdetermined(
            "all samples are at the origin; the sensor reads nothing".into(),
        ));
    }
    let scatter = moments.scatter(scale);
    let condition_number = design_condition_number(&scatter);
    if condition_number > MAX_CONDITION {
        return Err(FitError::Underdetermined(format!(
            "the samples are too far from the origin for their spread (condition number \
             {condition_number:.1e}); fit with mean subtraction"
        )));
    }
    let cal = calibration_from_scatter(&scatter, &centre, scale, reference)?;
    Ok((cal, condition_number))
}

/// Li & Griffiths' constraint matrix `C₁` for `k = 4`.
pub fn constraint_matrix() -> DMatrix<f64> {
    let k = 4.0;
    let o = k / 2.0 - 1.0;
    let mut c = DMatrix::zeros(6, 6);
    for i in 0..3 {
        for j in 0..3 {
            c[(i, j)] = if i == j { -1.0 } else { o };
        }
        c[(i + 3, i + 3)] = -k;
    }
    c
}

/// `σ₁/σ₉` of the design matrix `D` from its scatter matrix `S = DᵀD` (`σᵢ = √λᵢ(S)`): the
/// ratio of the largest to the second-smallest singular value. Forming `S` squares the
/// condition, so near [`MAX_CONDITION`] (`λ₉/λ₁` ≈ 1e-12) `λ₉` keeps about four digits, plenty
/// for a refusal threshold.
fn design_condition_number(scatter: &DMatrix<f64>) -> f64 {
    let mut eigenvalues: Vec<f64> = scatter
        .clone()
        .symmetric_eigenvalues()
        .iter()
        .copied()
        .collect();
    eigenvalues.sort_by(|a, b| b.total_cmp(a));
    match (eigenvalues.first(), eigenvalues.get(8)) {
        (Some(&l1), Some(&l9)) if l9 > 0.0 && l1 > 0.0 => (l1 / l9).sqrt(),
        _ => f64::INFINITY,
    }
}

/// The 10 quadric coefficients minimising `vᵀSv` (`S = DᵀD`) under the ellipsoid constraint
/// (an eigenvector: unit length, sign arbitrary).
pub(super) fn constrained_quadric(s: &DMatrix<f64>) -> Result<DVector<f64>, FitError> {
    let s11 = s.view((0, 0), (6, 6)).into_owned();
    let s12 = s.view((0, 6), (6, 4)).into_owned();
    let s22 = s.view((6, 6), (4, 4)).into_owned();
    let sv22 = singular_values(&s22);
    if sv22.last().copied().unwrap_or(0.0) <= sv22.first().copied().unwrap_or(0.0) * RANK_TOLERANCE
    {
        return Err(FitError::Underdetermined(
            "the samples lie in one plane; rotate the board about more than one axis".into(),
        ));
    }
    let s22_inv = s22
        .try_inverse()
        .ok_or_else(|| no_ellipsoid("the linear block is singular"))?;
    let reduced = &s11 - &s12 * &s22_inv * s12.transpose();
    let reduced = (&reduced + reduced.transpose()) * 0.5;
    let c1 = constraint_matrix();
    let c1_inv = c1
        .clone()
        .try_inverse()
        .ok_or_else(|| no_ellipsoid("constraint matrix is singular"))?;
    let e = &c1_inv * &reduced;

    let eigenvalues = e.complex_eigenvalues();
    let magnitude = eigenvalues
        .iter()
        .map(|l| l.norm())
        .fold(0.0, f64::max)
        .max(f64::MIN_POSITIVE);
    let mut best: Option<(f64, DVector<f64>)> = None;
    for lambda in eigenvalues.iter() {
        if lambda.im.abs() > 1e-8 * magnitude {
            continue;
        }
        // Eigenvector: the right singular vector of (E − λI) with the smallest singular value.
        let shifted = &e - DMatrix::identity(6, 6) * lambda.re;
        let svd = shifted.svd(false, true);
        let Some(vt) = svd.v_t else { continue };
        let Some(k) = svd
            .singular_values
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(b.1))
            .map(|(k, _)| k)
        else {
            continue;
        };
        let v1 = vt.row(k).transpose();
        let kappa = (v1.transpose() * &c1 * &v1)[(0, 0)];
        if kappa.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            continue;
        }
        let cost = (v1.transpose() * &reduced * &v1)[(0, 0)].abs() / kappa;
        if best.as_ref().is_none_or(|(c, _)| cost < *c) {
            best = Some((cost, v1));
        }
    }
    let (_, v1) =
        best.ok_or_else(|| no_ellipsoid("no eigenvector satisfies the ellipsoid constraint"))?;
    let v2 = -(&s22_inv * s12.transpose() * &v1);
    Ok(DVector::from_iterator(
        10,
        v1.iter().chain(v2.iter()).copied(),
    ))
}

/// The calibration from the scatter matrix of the points taken about `centre` and scaled by
/// `1/scale`: the constrained quadric, then `A` and `b` mapped back to the data's coordinates.
pub(super) fn calibration_from_scatter(
    scatter: &DMatrix<f64>,
    centre: &Vec3,
    scale: f64,
    reference: f64,
) -> Result<Calibration, FitError> {
    let v = constrained_quadric(scatter)?;
    let cal_q = calibration_from_quadric(&v, reference)?;
    // Undo the normalisation: q = (x − centre)/scale.
    let cal = Calibration {
        a: cal_q.a / scale,
        b: centre + cal_q.b * scale,
    };
    if !cal.a.iter().chain(cal.b.iter()).all(|x| x.is_finite()) {
        return Err(no_ellipsoid("the fitted parameters are not finite"));
    }
    Ok(cal)
}

/// `M`, the centre `c = −M⁻¹n` and `C = cᵀMc − d` of the quadric `v` (eq. 19–23, sign as
/// given); an error when `M` is singular or the quadric encloses no volume (`C ≤ 0`).
pub(super) fn quadric_centre(v: &[f64]) -> Result<(Mat3, Vec3, f64), FitError> {
    let m = Mat3::new(v[0], v[5], v[4], v[5], v[1], v[3], v[4], v[3], v[2]);
    let n = Vec3::new(v[6], v[7], v[8]);
    let m_inv = m
        .try_inverse()
        .ok_or_else(|| no_ellipsoid("the quadric matrix M is singular"))?;
    let centre = -(m_inv * n);
    let c = centre.dot(&(m * centre)) - v[9];
    if c.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return Err(no_ellipsoid(
            "the fitted quadric encloses no volume (C ≤ 0)",
        ));
    }
    Ok((m, centre, c))
}

/// Centre, `C` and `A = (ref/√C)·M^½` from the quadric coefficients (eq. 19–29).
fn calibration_from_quadric(v: &DVector<f64>, reference: f64) -> Result<Calibration, FitError> {
    let sign = if v[0] + v[1] + v[2] < 0.0 { -1.0 } else { 1.0 };
    let w: Vec<f64> = v.iter().map(|x| x * sign).collect();
    let (m, centre, c) = quadric_centre(&w)?;
    let root =
        sqrt_spd(&m).ok_or_else(|| no_ellipsoid("the fitted quadric is not an ellipsoid"))?;
    Ok(Calibration {
        a: root * (reference / c.sqrt()),
        b: centre,
    })
}

fn no_ellipsoid(why: &str) -> FitError {
    FitError::Underdetermined(format!(
        "no ellipsoid fits the samples ({why}); cover more orientations and check for outliers"
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::li_moments::explicit_design;

    /// The fit as first written: the explicit N×10 design matrix, `S = DᵀD` by matrix product and
    /// the condition number by its SVD.
    fn fit_with_explicit_design(points: &[Vec3], reference: f64) -> (Calibration, f64) {
        let centre = points.iter().sum::<Vec3>() / points.len() as f64;
        let scale = (points
            .iter()
            .map(|p| (p - centre).norm_squared())
            .sum::<f64>()
            / points.len() as f64)
            .sqrt();
        let design = explicit_design(points, &centre, scale);
        let sv = singular_values(&design);
        let v = constrained_quadric(&(design.transpose() * &design)).expect("quadric");
        let cal = calibration_from_quadric(&v, reference).expect("ellipsoid");
        let cal = Calibration {
            a: cal.a / scale,
            b: centre + cal.b * scale,
        };
        (cal, sv[0] / sv[8])
    }

    #[test]
    fn moment_accumulation_matches_the_explicit_design_matrix_fit() {
        // A tilted, offset ellipsoid with deterministic pseudo-noise of 0.5 % of its radius.
        let a_true = Mat3::new(1.1, 0.05, -0.02, 0.0, 0.93, 0.04, 0.0, 0.0, 1.02);
        let b_true = Vec3::new(25.0, -12.0, 40.0);
        let inverse = a_true.try_inverse().expect("invertible");
        let points: Vec<Vec3> = (0..5000)
            .map(|i| {
                let t = f64::from(i);
                let z = 1.0 - 2.0 * (t + 0.5) / 5000.0;
                let phi = t * 2.399_963_229_728_653; // golden angle
                let r = (1.0 - z * z).sqrt();
                let u =
                    Vec3::new(r * phi.cos(), r * phi.sin(), z) * (1.0 + 0.005 * (7.3 * t).sin());
                inverse * (u * 50.0) + b_true
            })
            .collect();
        let fit = fit_li(
            &points,
            50.0,
            LiOptions {
                subtract_mean: true,
            },
        )
        .expect("fit");
        let (cal, condition) = fit_with_explicit_design(&points, 50.0);
        // Both solve the same 10×10 problem; only summation order differs (well conditioned).
        let rel_a = (fit.cal.a - cal.a).amax() / cal.a.amax();
        let rel_b = (fit.cal.b - cal.b).amax() / cal.b.amax();
        assert!(rel_a < 1e-9 && rel_b < 1e-9, "A {rel_a:e}, b {rel_b:e}");
        // √(λ₁/λ₉) of S against σ₁/σ₉ of D: equal up to the rounding of forming S.
        let rel_cond = (fit.condition_number - condition).abs() / condition;
        assert!(
            rel_cond < 1e-9,
            "condition {} vs {condition}",
            fit.condition_number
        );
    }
}
