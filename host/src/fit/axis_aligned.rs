//! Axis-aligned ellipsoid by linear least squares (seed 004 §1.2.3–1.2.5): the ellipsoid
//! `((x−x0)/A)² + ((y−y0)/B)² + ((z−z0)/C)² = 1` expands to `x² + a·y² + b·z² + c·x + d·y + e·z + f
//! = 0`, so each sample gives a row `[y² z² x y z 1]` with right-hand side `−x²`. Then
//! `x0 = −c/2`, `y0 = −d/(2a)`, `z0 = −e/(2b)`, `A² = x0² + a·y0² + b·z0² − f`, `B = A/√a`,
//! `C = A/√b`, and the calibration is `A = diag(ref/A, ref/B, ref/C)`, `b = (x0, y0, z0)`.
//!
//! The samples are first centred on their mean and scaled to unit RMS radius so the design matrix
//! is well conditioned; the model is invariant under this change of variables, and the centre and
//! radii are mapped back afterwards.
//!
//! The leave-one-pose-out RMS of the pose fit uses the rank-one downdate of the least-squares
//! solution (Sherman–Morrison), not one refit per pose.

use std::cmp::Ordering;

use nalgebra::DMatrix;

use super::covariance::{calibration_std, normal_covariance, param_names, ParamEntry};
use super::coverage::{guard_fit, CoverageHint, EllipsoidModel};
use super::li::li_start;
use super::linalg::{inverse_spd, least_squares, RANK_TOLERANCE};
use super::loo::held_out_rms;
use super::validate::{check_finite_points, check_finite_poses, check_reference};
use super::{Calibration, Fit, FitError, Mat3, Method, Pose, Vec3};

/// Fit an axis-aligned ellipsoid to `points` and return the calibration mapping it onto the sphere
/// of radius `reference`. Needs at least six points that are not all on one plane.
/// The coverage rule of [`super::coverage`] (6 unknowns) is applied before returning.
pub fn fit_axis_aligned(points: &[Vec3], reference: f64) -> Result<Fit, FitError> {
    guard_fit(
        fit_axis_aligned_unchecked(points, reference),
        points,
        None,
        reference,
        EllipsoidModel::AxisAligned,
        CoverageHint::Either,
        || li_start(points, reference),
    )
}

fn fit_axis_aligned_unchecked(points: &[Vec3], reference: f64) -> Result<Fit, FitError> {
    let (cal, condition_number) = solve(points, reference)?;
    Ok(Fit::closed_form(
        Method::AxisAligned,
        cal,
        points,
        reference,
        condition_number,
    ))
}

/// [`fit_axis_aligned`] on static pose means, with the leave-one-pose-out RMS and the
/// covariance of its six unknowns ([`pose_covariance`]).
pub fn fit_axis_aligned_poses(poses: &[Pose], reference: f64) -> Result<Fit, FitError> {
    check_finite_poses(poses)?;
    let means: Vec<Vec3> = poses.iter().map(|p| p.mean).collect();
    let mut fit = fit_axis_aligned(&means, reference)?;
    fit.loo_rms = leave_one_out_axis_aligned(poses, &means, reference);
    if let Some(cov) = pose_covariance(poses, &fit.cal) {
        fit.std = Some(calibration_std(&cov, &LAYOUT));
        fit.param_names = param_names(&LAYOUT);
        fit.covariance = Some(cov);
    }
    Ok(fit)
}

/// The six unknowns in covariance order: the diagonal of `A`, then `b`.
const LAYOUT: [ParamEntry; 6] = [
    ParamEntry::A(0, 0),
    ParamEntry::A(1, 1),
    ParamEntry::A(2, 2),
    ParamEntry::B(0),
    ParamEntry::B(1),
    ParamEntry::B(2),
];

/// Covariance of the six unknowns from the poses' own noise, to first order: the algebraic
/// solution sits where the norm model's residuals `|A(x − b)| − ref` are (near) least, so its
/// sensitivity to the pose means is the Gauss–Newton one, `(JᵀWJ)⁻¹` with `J` the residuals'
/// derivatives (`∂|y|/∂A_kk = y_k(x − b)_k/|y|`, `∂|y|/∂b_k = −A_kk·y_k/|y|`) and `W` the inverse
/// variance of each pose's residual, `|Aᵀŷ ∘ σ|²` from the standard errors of its mean. As
/// [`super::minmax`]'s, it is the noise's share only: an effect the model lacks is not in it.
/// `None` when a pose has no noise or the poses do not determine the six.
fn pose_covariance(poses: &[Pose], cal: &Calibration) -> Option<DMatrix<f64>> {
    let mut jtj = DMatrix::<f64>::zeros(6, 6);
    for pose in poses {
        let u = pose.mean - cal.b;
        let y = cal.a * u;
        let norm = y.norm();
        let dir = y / norm;
        let sigma = pose.var_of_mean().map(f64::sqrt);
        let var = (cal.a.transpose() * dir)
            .component_mul(&sigma)
            .norm_squared();
        if !(var > 0.0 && norm > 0.0 && var.is_finite()) {
            return None;
        }
        let row: [f64; 6] = [
            dir.x * u.x,
            dir.y * u.y,
            dir.z * u.z,
            -cal.a[(0, 0)] * dir.x,
            -cal.a[(1, 1)] * dir.y,
            -cal.a[(2, 2)] * dir.z,
        ];
        for i in 0..6 {
            for j in 0..6 {
                jtj[(i, j)] += row[i] * row[j] / var;
            }
        }
    }
    normal_covariance(&jtj)
}

/// The linear least-squares problem of the module comment in centred, scaled coordinates.
struct Design {
    mean: Vec3,
    spread: f64,
    x: DMatrix<f64>,
    y: DMatrix<f64>,
}

fn design(points: &[Vec3]) -> Result<Design, FitError> {
    let mean = points.iter().sum::<Vec3>() / points.len() as f64;
    let spread = (points
        .iter()
        .map(|p| (p - mean).norm_squared())
        .sum::<f64>()
        / points.len() as f64)
        .sqrt();
    if spread.partial_cmp(&0.0) != Some(Ordering::Greater) {
        return Err(FitError::Underdetermined(
            "all samples are identical; rotate the board between samples".into(),
        ));
    }
    let q: Vec<Vec3> = points.iter().map(|p| (p - mean) / spread).collect();
    let x = DMatrix::from_fn(q.len(), 6, |i, j| {
        let p = &q[i];
        [p.y * p.y, p.z * p.z, p.x, p.y, p.z, 1.0][j]
    });
    let y = DMatrix::from_fn(q.len(), 1, |i, _| -q[i].x * q[i].x);
    Ok(Design { mean, spread, x, y })
}

/// Leave-one-pose-out RMS by the rank-one downdate of linear least squares: without row `i`,
/// `β₋ᵢ = β − (XᵀX)⁻¹xᵢ·eᵢ/(1 − hᵢ)` with residual `eᵢ = yᵢ − xᵢᵀβ` and leverage
/// `hᵢ = xᵢᵀ(XᵀX)⁻¹xᵢ` (Sherman–Morrison). The model is invariant under the centring and scaling,
/// so the whole set's normalisation serves every fold. One fit in all instead of N.
fn leave_one_out_axis_aligned(poses: &[Pose], means: &[Vec3], reference: f64) -> Option<f64> {
    let fold = folds_without(means, reference)?;
    held_out_rms(poses, reference, |i| fold(i).map(|(cal, _)| cal))
}

/// The axis-aligned calibration of `means` without point `i`, for any `i`, by the rank-one
/// downdate above: the least-squares solution of the other points up to rounding, without the
/// coverage rule that [`fit_axis_aligned`] applies. `None` when there are six points or fewer,
/// or the full problem is singular.
pub fn calibrations_without(
    means: &[Vec3],
    reference: f64,
) -> Option<impl Fn(usize) -> Result<Calibration, FitError>> {
    let fold = folds_without(means, reference)?;
    Some(move |i: usize| fold(i).map(|(cal, _)| cal))
}

/// As [`calibrations_without`], with point `i`'s leverage in the design.
pub fn folds_without(
    means: &[Vec3],
    reference: f64,
) -> Option<impl Fn(usize) -> Result<(Calibration, f64), FitError>> {
    if means.len() <= 6 {
        return None;
    }
    let d = design(means).ok()?;
    let gram_inv = inverse_spd(&(d.x.transpose() * &d.x))?;
    let beta = &gram_inv * (d.x.transpose() * &d.y);
    Some(move |i: usize| {
        if i >= d.x.nrows() {
            return Err(FitError::Underdetermined(format!(
                "point {i} does not exist ({} points)",
                d.x.nrows()
            )));
        }
        let xi = d.x.row(i).transpose();
        let gx = &gram_inv * &xi;
        let leverage = xi.dot(&gx);
        // A pose with all the leverage is needed to determine the fit: without it the fold is
        // rank-deficient, as a refit would find.
        if 1.0 - leverage <= RANK_TOLERANCE.sqrt() {
            return Err(FitError::Underdetermined(
                "a pose determines the fit alone".into(),
            ));
        }
        let e = d.y[(i, 0)] - xi.dot(&beta.column(0));
        let fold = beta.column(0) - gx * (e / (1.0 - leverage));
        let v = [fold[0], fold[1], fold[2], fold[3], fold[4], fold[5]];
        calibration_from_coefficients(&v, &d, reference).map(|cal| (cal, leverage))
    })
}

/// The calibration and the condition number of the (normalised) design matrix.
fn solve(points: &[Vec3], reference: f64) -> Result<(Calibration, f64), FitError> {
    check_reference(reference)?;
    check_finite_points(points)?;
    if points.len() < 6 {
        return Err(FitError::Underdetermined(format!(
            "only {} samples; the axis-aligned ellipsoid needs at least 6",
            points.len()
        )));
    }
    let d = design(points)?;
    let ls = least_squares(&d.x, &d.y, "axis-aligned ellipsoid")?;
    let v = &ls.solution;
    let cal = calibration_from_coefficients(&[v[0], v[1], v[2], v[3], v[4], v[5]], &d, reference)?;
    Ok((cal, ls.equilibrated_condition))
}

/// The calibration from the coefficients `a b c d e f` of the normalised problem.
fn calibration_from_coefficients(
    v: &[f64; 6],
    d: &Design,
    reference: f64,
) -> Result<Calibration, FitError> {
    let [a, b, c, dy, e, f] = *v;
    let not_closed = || {
        FitError::Underdetermined(
            "the samples do not lie on a closed axis-aligned ellipsoid; cover more orientations \
             (every axis up and down)"
                .into(),
        )
    };
    if a.partial_cmp(&0.0) != Some(Ordering::Greater)
        || b.partial_cmp(&0.0) != Some(Ordering::Greater)
    {
        return Err(not_closed());
    }
    let centre = Vec3::new(-c / 2.0, -dy / (2.0 * a), -e / (2.0 * b));
    let rx_sq = centre.x * centre.x + a * centre.y * centre.y + b * centre.z * centre.z - f;
    if rx_sq.partial_cmp(&0.0) != Some(Ordering::Greater) {
        return Err(not_closed());
    }
    let rx = rx_sq.sqrt();
    let radii = Vec3::new(rx, rx / a.sqrt(), rx / b.sqrt()) * d.spread;
    let cal = Calibration {
        a: Mat3::from_diagonal(&radii.map(|r| reference / r)),
        b: d.mean + centre * d.spread,
    };
    if !cal.a.iter().chain(cal.b.iter()).all(|v| v.is_finite()) {
        return Err(not_closed());
    }
    Ok(cal)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::loo::leave_one_out_rms;

    #[test]
    fn rank_one_leave_one_out_equals_refitting_without_each_pose() {
        let poses: Vec<Pose> = (0..15)
            .map(|i| {
                let t = f64::from(i);
                let z = 1.0 - 2.0 * (t + 0.5) / 15.0;
                let phi = t * 2.399_963_229_728_653;
                let r = (1.0 - z * z).sqrt();
                let noise = 0.01 * (5.3 * t).sin();
                Pose {
                    mean: Vec3::new(1.05 * r * phi.cos() + 0.2, 0.95 * r * phi.sin(), z - 0.1)
                        * (9.81 + noise),
                    var: Vec3::repeat(1e-4),
                    n: 50,
                    label: None,
                }
            })
            .collect();
        let means: Vec<Vec3> = poses.iter().map(|p| p.mean).collect();
        let fast = leave_one_out_axis_aligned(&poses, &means, 9.81).expect("determined");
        let brute = leave_one_out_rms(&poses, 9.81, |rest| {
            let m: Vec<Vec3> = rest.iter().map(|p| p.mean).collect();
            solve(&m, 9.81).map(|(cal, _)| cal)
        })
        .expect("determined");
        // Exact algebra; the normal-equation downdate and the SVD refits round differently.
        assert!(
            (fast - brute).abs() <= 1e-9 * brute,
            "{fast:e} vs {brute:e}"
        );
        assert!(
            brute > 1e-4,
            "the held-out error is not trivially zero: {brute:e}"
        );
    }

    #[test]
    fn the_stated_standard_deviations_match_the_scatter_of_refits_on_new_noise() {
        use rand::{rngs::StdRng, SeedableRng};
        use rand_distr::{Distribution, Normal};
        // Fifteen directions over the sphere through a diagonal distortion (the model's own
        // form), each pose the mean of 50 samples of 0.02 m/s² noise.
        let (gain, offset) = (Vec3::new(1.04, 0.97, 1.01), Vec3::new(0.2, -0.15, 0.3));
        let sample_sigma: f64 = 0.02;
        let n = 50;
        let truth: Vec<Vec3> = (0..15)
            .map(|i| {
                let t = f64::from(i);
                let z = 1.0 - 2.0 * (t + 0.5) / 15.0;
                let phi = t * 2.399_963_229_728_653;
                let r = (1.0 - z * z).sqrt();
                Vec3::new(r * phi.cos(), r * phi.sin(), z).component_mul(&gain) * 9.81 + offset
            })
            .collect();
        let mut rng = StdRng::seed_from_u64(11);
        let noise = Normal::new(0.0, sample_sigma / (n as f64).sqrt()).expect("valid sigma");
        let trials = 400;
        let mut fits = Vec::new();
        for _ in 0..trials {
            let poses: Vec<Pose> = truth
                .iter()
                .map(|m| Pose {
                    mean: m + Vec3::from_fn(|_, _| noise.sample(&mut rng)),
                    var: Vec3::repeat(sample_sigma * sample_sigma),
                    n,
                    label: None,
                })
                .collect();
            fits.push(fit_axis_aligned_poses(&poses, 9.81).expect("fits"));
        }
        let stated = fits[0].std.expect("a covariance from the poses' noise");
        for k in 0..3 {
            let spread = |value: &dyn Fn(&Fit) -> f64| {
                let values: Vec<f64> = fits.iter().map(value).collect();
                let mean = values.iter().sum::<f64>() / trials as f64;
                (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (trials - 1) as f64)
                    .sqrt()
            };
            let b = spread(&|f: &Fit| f.cal.b[k]);
            let a = spread(&|f: &Fit| f.cal.a[(k, k)]);
            // 400 refits estimate a standard deviation to about 3.5 % (1σ); first-order
            // propagation is exact here up to terms of the noise squared. Allow 15 %.
            assert!(
                (stated.b[k] / b - 1.0).abs() < 0.15,
                "b[{k}]: {} vs {b}",
                stated.b[k]
            );
            assert!(
                (stated.a[(k, k)] / a - 1.0).abs() < 0.15,
                "A[{k}{k}]: {} vs {a}",
                stated.a[(k, k)]
            );
        }
    }
}
