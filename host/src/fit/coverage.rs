//! The coverage rule of the norm-model fits: whether readings can determine an ellipsoid at all,
//! judged through a calibration, and the guard every accelerometer and magnetometer fit applies
//! to its outcome before returning it.
//!
//! **Coverage rule of the norm-model fits** ([`check_coverage`], applied by every accelerometer
//! and magnetometer fit before it returns, and in place of a bare "did not converge"):
//!
//! 1. The readings are mapped through the fitted (or starting) calibration and reduced to unit
//!    directions `ŷᵢ`. Two directions closer than `τ = max(5°, 3σ_θ)` count as one orientation,
//!    where `σ_θ ≈ σ_rel` is the angular noise of one reading (relative radial noise: the larger of
//!    the pose variance and the fit residual, the latter scaled by `√(N/(N−P))` for the P fitted
//!    parameters): readings within three noise standard deviations of each
//!    other cannot be told apart. Fewer distinct orientations than unknowns (9 for the general
//!    ellipsoid, 6 for the axis-aligned one) cannot determine the parameters: refused. (A cloud
//!    of noise around one point, fitted by a tiny ellipsoid, has `σ_rel ≈ 0.4`, so `τ` is large
//!    and it collapses to a few orientations.)
//! 2. Fisher information of the linearised norm model at the unit sphere: each orientation gives
//!    a row `d = [y₁² y₂² y₃² 2y₁y₂ 2y₁y₃ 2y₂y₃ y₁ y₂ y₃]` of the quadric `yᵀMy + uᵀy = 1`
//!    (Merayo's form), whose equation noise is `2σ_rel` (per reading; the cluster's information
//!    is summed). `Cov(θ) = (Σ d dᵀ / (2σ_rel)²)⁻¹`; a change `δM_kk` is a relative scale change
//!    `δM_kk/2` and `δu` an offset change `δu·ref/2`, so `½·max σ(θ)` is the largest one-sigma
//!    uncertainty of a scale, cross term or offset relative to the reference. Refused when the
//!    matrix is singular (all directions on one circle: a circle lies on infinitely many
//!    ellipsoids) or when that uncertainty exceeds [`MAX_RELATIVE_SIGMA`]. The message names the
//!    RMS angle of the orientations out of their best plane (the smallest eigenvalue of their
//!    covariance), which is what makes the matrix singular.

use nalgebra::{DMatrix, SMatrix, SVector};

use super::covariance::normal_covariance;
use super::{Calibration, Fit, FitError, Mat3, Vec3};

/// Largest accepted one-sigma uncertainty of any scale, cross term or offset of a norm-model fit,
/// relative to the reference: the 3σ range must stay within 10 %. Beyond that a fit can be wrong
/// by as much as an uncalibrated MEMS sensor (scale errors of several %, offsets of a sizeable
/// fraction of the field), so it carries no usable calibration and is refused rather than
/// returned. Good coverage gives far less (0.04–0.3 % on the real magnetometer sweeps).
pub const MAX_RELATIVE_SIGMA: f64 = 0.1 / 3.0;

/// Relative scatter about the fitted ellipsoid above which readings are not a surface at all:
/// noise about a single point (a fitted "ellipsoid" the size of the noise) scatters by about
/// 40 %, while real sensors, even uncalibrated and moving, stay below 10 % (5 % on the raw
/// QMC5883L counts, the noisiest set).
const NOT_A_SURFACE: f64 = 0.1;

/// Smallest angle (degrees) at which two readings count as different orientations.
pub const MIN_DISTINCT_DEG: f64 = 5.0;

/// The coverage check works on at most this many readings (evenly thinned, each kept one standing
/// for the ones dropped) so that it stays linear in time on clouds of a million samples.
const MAX_CHECKED_READINGS: usize = 4000;

/// Which ellipsoid a norm-model fit determines.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EllipsoidModel {
    /// General ellipsoid (full symmetric `AᵀA` and offset): 9 unknowns.
    General,
    /// Axis-aligned ellipsoid (diagonal scale and offset): 6 unknowns.
    AxisAligned,
}

impl EllipsoidModel {
    /// Number of unknowns.
    pub fn unknowns(self) -> usize {
        match self {
            EllipsoidModel::General => 9,
            EllipsoidModel::AxisAligned => 6,
        }
    }
}

/// What the user should add when coverage is refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CoverageHint {
    /// Static poses (accelerometer).
    Poses,
    /// Samples while turning (magnetometer).
    Samples,
    /// Either (methods that take bare points).
    Either,
}

impl CoverageHint {
    fn advice(self) -> &'static str {
        match self {
            CoverageHint::Poses => {
                "add tilted poses (e.g. the six 45° positions) or use --method six-position, \
                 which needs only the six faces"
            }
            CoverageHint::Samples => {
                "turn the board through all orientations, including upside down"
            }
            CoverageHint::Either => {
                "add tilted poses (e.g. the six 45° positions), or turn the board through all \
                 orientations, including upside down"
            }
        }
    }
}

/// How well a set of readings covers the orientations, as seen through a calibration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Coverage {
    /// Distinct orientations (further apart than `tolerance_deg`).
    pub distinct: usize,
    /// Angle below which two readings count as one orientation, degrees.
    pub tolerance_deg: f64,
    /// RMS angle of the orientations out of their best-fitting plane, degrees.
    pub plane_rms_deg: f64,
    /// Axis of the sensor frame closest to that plane's normal (0 = X, 1 = Y, 2 = Z).
    pub least_sampled_axis: usize,
    /// Median relative noise of one reading (the larger of the stated and the residual).
    pub relative_noise: f64,
    /// Largest one-sigma uncertainty of a scale, cross term or offset relative to the reference
    /// (∞ when the information matrix is singular).
    pub max_relative_sigma: f64,
}

/// Measure the coverage of `points` through `cal` (see the module comment for the rule) without
/// judging it. `noise[i]`, if given, is the per-axis one-sigma noise of reading `i` in data units
/// (for a pose mean, that of the mean); it is propagated to `|A(xᵢ−b)|/ref`. The RMS relative
/// residual through `cal` is used where it is larger (or when no noise is given).
pub fn measure_coverage(
    points: &[Vec3],
    noise: Option<&[f64]>,
    cal: &Calibration,
    reference: f64,
    model: EllipsoidModel,
) -> Coverage {
    let stride = points.len().div_ceil(MAX_CHECKED_READINGS).max(1);
    let mut dirs: Vec<(Vec3, f64)> = Vec::with_capacity(points.len() / stride + 1);
    let mut sum_sq = 0.0;
    let mut used = 0usize;
    for (i, x) in points.iter().enumerate().step_by(stride) {
        let y = cal.apply(x) / reference;
        let Some(unit) = y
            .try_normalize(0.0)
            .filter(|u| u.iter().all(|v| v.is_finite()))
        else {
            continue;
        };
        let r = y.norm() - 1.0;
        sum_sq += r * r;
        used += 1;
        let axis_sigma = noise.and_then(|n| n.get(i)).copied().unwrap_or(0.0);
        let given = axis_sigma * (cal.a.transpose() * unit).norm() / reference;
        dirs.push((unit, if given.is_finite() { given } else { 0.0 }));
    }
    // The residual of a least-squares fit understates the noise by √((N − P)/N); undo that
    // (with no spare readings the residual says nothing and the stated noise alone counts).
    let unknowns = model.unknowns();
    let residual_rms = if used > unknowns {
        (sum_sq / (used - unknowns) as f64).sqrt()
    } else {
        0.0
    };
    // Noise of each reading: the larger of the stated noise and what the residual shows.
    let sigmas: Vec<f64> = dirs.iter().map(|(_, s)| s.max(residual_rms)).collect();
    let mut sorted = sigmas.clone();
    sorted.sort_by(f64::total_cmp);
    let typical = sorted
        .get(sorted.len() / 2)
        .copied()
        .unwrap_or(f64::INFINITY);
    let tolerance_rad = (3.0 * typical)
        .max(MIN_DISTINCT_DEG.to_radians())
        .min(std::f64::consts::PI);
    let cos_tol = tolerance_rad.cos();

    // Greedy clustering: each orientation is the normalised sum of its members, with their
    // information summed.
    let mut reps: Vec<(Vec3, Vec3, f64)> = Vec::new(); // (first direction, sum, information)
    for ((u, _), s) in dirs.iter().zip(&sigmas) {
        // Floored far below any real noise so that exact synthetic data stay finite.
        let info = stride as f64 / (2.0 * s.max(1e-12)).powi(2);
        match reps
            .iter_mut()
            .find(|(first, _, _)| first.dot(u) >= cos_tol)
        {
            Some((_, sum, total)) => {
                *sum += u;
                *total += info;
            }
            None => reps.push((*u, *u, info)),
        }
    }
    let oriented: Vec<(Vec3, f64)> = reps
        .iter()
        .filter_map(|(_, sum, info)| sum.try_normalize(0.0).map(|d| (d, *info)))
        .collect();

    // Out-of-plane spread: smallest eigenvalue of the (unweighted) covariance of the orientations.
    let n = oriented.len().max(1) as f64;
    let mean = oriented.iter().map(|(d, _)| d).sum::<Vec3>() / n;
    let cov = oriented
        .iter()
        .map(|(d, _)| (d - mean) * (d - mean).transpose())
        .sum::<Mat3>()
        / n;
    let eig = cov.symmetric_eigen();
    let k = eig.eigenvalues.imin();
    let plane_rms_deg = eig.eigenvalues[k]
        .max(0.0)
        .sqrt()
        .min(1.0)
        .asin()
        .to_degrees();
    let least_sampled_axis = eig.eigenvectors.column(k).iamax();

    let max_relative_sigma = fisher_sigma(&oriented, model);
    Coverage {
        distinct: oriented.len(),
        tolerance_deg: tolerance_rad.to_degrees(),
        plane_rms_deg,
        least_sampled_axis,
        relative_noise: typical,
        max_relative_sigma,
    }
}

/// `½·max σ(θ)` of the quadric coefficients (module comment, rule 2).
fn fisher_sigma(oriented: &[(Vec3, f64)], model: EllipsoidModel) -> f64 {
    let mut info = SMatrix::<f64, 9, 9>::zeros();
    for (y, w) in oriented {
        let d = SVector::<f64, 9>::from_column_slice(&[
            y.x * y.x,
            y.y * y.y,
            y.z * y.z,
            2.0 * y.x * y.y,
            2.0 * y.x * y.z,
            2.0 * y.y * y.z,
            y.x,
            y.y,
            y.z,
        ]);
        info += d * d.transpose() * *w;
    }
    let keep: &[usize] = match model {
        EllipsoidModel::General => &[0, 1, 2, 3, 4, 5, 6, 7, 8],
        EllipsoidModel::AxisAligned => &[0, 1, 2, 6, 7, 8],
    };
    let sub = DMatrix::from_fn(keep.len(), keep.len(), |i, j| info[(keep[i], keep[j])]);
    // Exact (noise-free) data give infinite information; treat it as determined.
    if sub.iter().any(|v| v.is_infinite()) {
        return 0.0;
    }
    match normal_covariance(&sub) {
        Some(cov) => {
            let worst = (0..keep.len()).map(|i| cov[(i, i)]).fold(0.0, f64::max);
            0.5 * worst.max(0.0).sqrt()
        }
        None => f64::INFINITY,
    }
}

/// Refuse readings that cannot determine a norm-model calibration (the rule of the module
/// comment), judged through `cal`; the message says what is missing and what to add.
pub fn check_coverage(
    points: &[Vec3],
    noise: Option<&[f64]>,
    cal: &Calibration,
    reference: f64,
    model: EllipsoidModel,
    hint: CoverageHint,
) -> Result<Coverage, FitError> {
    let c = measure_coverage(points, noise, cal, reference, model);
    let unknowns = model.unknowns();
    let what = match model {
        EllipsoidModel::General => "norm model",
        EllipsoidModel::AxisAligned => "axis-aligned ellipsoid",
    };
    if c.distinct <= 1 {
        return Err(FitError::Underdetermined(format!(
            "all readings come from one orientation, which cannot determine the {unknowns} \
             unknowns of the {what}; {}",
            hint.advice()
        )));
    }
    if c.relative_noise > NOT_A_SURFACE {
        return Err(FitError::Underdetermined(format!(
            "the readings do not trace an ellipsoid: they scatter by {:.0} % about the best one, as \
             readings from one or a few orientations do; {}",
            100.0 * c.relative_noise,
            hint.advice()
        )));
    }
    if c.distinct < unknowns {
        return Err(FitError::Underdetermined(format!(
            "{} distinct orientation{} (readings within {:.0}° counted as one) cannot determine the \
             {unknowns} unknowns of the {what}; {}",
            c.distinct,
            if c.distinct == 1 { "" } else { "s" },
            c.tolerance_deg,
            hint.advice()
        )));
    }
    if c.max_relative_sigma > MAX_RELATIVE_SIGMA {
        let axis = ["X", "Y", "Z"][c.least_sampled_axis.min(2)];
        let uncertainty = if c.max_relative_sigma.is_finite() {
            format!(
                "uncertain by {:.0} % of the reference (one sigma; at most {:.0} % is accepted)",
                100.0 * c.max_relative_sigma,
                100.0 * MAX_RELATIVE_SIGMA
            )
        } else {
            "not determined at all".to_string()
        };
        return Err(FitError::Underdetermined(format!(
            "the {} orientations (RMS {:.1}° out of their best plane, the sensor's {axis} axis the \
             least sampled) leave the scales and offsets {uncertainty}; {}",
            c.distinct,
            c.plane_rms_deg,
            hint.advice()
        )));
    }
    Ok(c)
}

/// Apply [`check_coverage`] to a fit's outcome before it is returned: a fit on data that cannot
/// determine it is refused, and a fit that failed (did not converge, found no ellipsoid, too few
/// readings) on such data is reported as the coverage problem it is. A failed fit is judged
/// through the calibration `lens` gives (e.g. the fit's start, or an algebraic ellipsoid), or
/// else [`sphere_start`]; `lens` runs only on failure. When the coverage is adequate the original
/// error is returned.
pub fn guard_fit(
    result: Result<Fit, FitError>,
    points: &[Vec3],
    noise: Option<&[f64]>,
    reference: f64,
    model: EllipsoidModel,
    hint: CoverageHint,
    lens: impl FnOnce() -> Option<Calibration>,
) -> Result<Fit, FitError> {
    match result {
        Ok(fit) => {
            check_coverage(points, noise, &fit.cal, fit.reference, model, hint)?;
            Ok(fit)
        }
        Err(error @ FitError::NonFinite(_)) => Err(error),
        Err(error) => {
            let usable = reference.is_finite()
                && reference > 0.0
                && !points.is_empty()
                && points.iter().all(|p| p.iter().all(|v| v.is_finite()));
            if usable {
                let cal = lens()
                    .filter(Calibration::is_finite)
                    .unwrap_or_else(|| sphere_start(points, reference));
                let coverage = check_coverage(points, noise, &cal, reference, model, hint)?;
                // Coverage within the rule can still leave the iteration creeping along its
                // least determined direction: say where that direction lies.
                if let FitError::NotConverged {
                    method,
                    iterations,
                    detail,
                } = error
                {
                    let axis = ["X", "Y", "Z"][coverage.least_sampled_axis.min(2)];
                    return Err(FitError::NotConverged {
                        method,
                        iterations,
                        detail: format!(
                            "{detail}; the {} orientations lie RMS {:.1}° out of their best \
                             plane, the sensor's {axis} axis the least sampled: readings with \
                             that axis turned up and down steady the fit",
                            coverage.distinct, coverage.plane_rms_deg
                        ),
                    });
                }
            }
            Err(error)
        }
    }
}

/// The sphere about the mean of `points` scaled to `reference`: the start of last resort for the
/// iterative fits, and the lens through which a cloud no method could fit is judged.
pub fn sphere_start(points: &[Vec3], reference: f64) -> Calibration {
    let n = points.len().max(1) as f64;
    let mean = points.iter().sum::<Vec3>() / n;
    let radius = (points
        .iter()
        .map(|p| (p - mean).norm_squared())
        .sum::<f64>()
        / n)
        .sqrt();
    let gain = if radius > 0.0 {
        reference / radius
    } else {
        1.0
    };
    Calibration {
        a: Mat3::identity() * gain,
        b: mean,
    }
}
