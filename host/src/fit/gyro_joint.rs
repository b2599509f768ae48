//! Gyroscope scale and misalignment from two reference directions: gravity and the magnetic
//! field.
//!
//! Gravity part: Tedaldi, Pretto & Menegatti (2014), "A robust and easy to implement method for
//! IMU calibration without external equipments", ICRA 2014, §IV-B ([`super::gyro_scale`]). The
//! calibrated rate `ω = A·ω_raw` is integrated over a move between two still poses,
//! `q̇ = ½·q ⊗ (0, ω)`, giving `R` (end pose → start pose); the start's gravity direction turned
//! into the end pose, `Rᵀ·ĝ₀`, must equal the end's `ĝ₁`. Residual: the two components of
//! `Rᵀ·ĝ₀` perpendicular to `ĝ₁` (angle errors, rad).
//!
//! Field part: the same residual with the calibrated field direction `ĥ`, which the move turns
//! like gravity. Gravity alone cannot see a turn about the vertical; two non-parallel directions
//! fix the whole rotation (Wahba's problem; Shuster & Oh 1981, TRIAD), so every move constrains
//! all three axes. The field is written in its own calibration's frame, which the session aligns
//! to the accelerometer's with an uncertainty of its own; an error `Rₘ` of that alignment would
//! read as a gyroscope misalignment, so `Rₘ = exp([φ]×)` is fitted with `A`: field residual
//! `Fᵀ·Rₘᵀ·Rᵀ·Rₘ·ĥ₀` with `F` spanning the plane perpendicular to `ĥ₁`. Gravity fixes the frame of
//! `A`; the field, blind to that frame, adds the rotation about the vertical.
//!
//! Each residual is divided by its own one-sigma (the still ends' mean direction scatter and the
//! gyroscope's white noise over the move), so `χ²/ν` should be near 1. Gauss–Newton/LM over the
//! 9 entries of `A` and `φ`; the Jacobian in `A` is analytic, from the first-order perturbation of
//! the integrated rotation, `δθ = Rᵀ(T)·∫R(t)·δA·ω_raw(t) dt` (end-frame rotation vector), and in
//! `φ` by central differences (no integration needed). Covariance `(JᵀJ)⁻¹`, scaled by `χ²/ν`
//! when above 1 ([`super::uncertainty`], known noise).

use nalgebra::{DMatrix, DVector, Rotation3, UnitQuaternion};

use super::covariance::normal_covariance;
use super::gyro_scale::{gyro_matrix_fit, integrate_rotation, GyroMotion};
use super::lm::{levenberg_marquardt, LeastSquaresProblem, LmOptions};
use super::uncertainty::{noise_scale, NoiseLevel};
use super::{Fit, FitError, Mat3, Vec3};

/// The field directions at the two still ends of a move.
#[derive(Debug, Clone, PartialEq)]
pub struct FieldEnds {
    /// Calibrated field (mean) in the still pose before the move, in the field's frame.
    pub before: Vec3,
    /// Calibrated field (mean) in the still pose after the move.
    pub after: Vec3,
    /// One-sigma of each component of the move's field angle mismatch, radians.
    pub sigma: f64,
}

/// One move between still poses with both reference directions (the field when usable).
#[derive(Debug, Clone, PartialEq)]
pub struct JointMotion {
    /// Gravity directions, rates and the gravity angle σ (required here).
    pub gravity: GyroMotion,
    /// Field directions at the still ends; `None` when the move has no usable field.
    pub field: Option<FieldEnds>,
}

/// The joint fit and its statistics.
#[derive(Debug, Clone)]
pub struct JointFit {
    /// `A` (bias not fitted: `b = 0`), its 9×9 covariance and the moves' gravity angle errors.
    pub fit: Fit,
    /// Rotation of the field's frame into the accelerometer's found by the fit, radians.
    pub field_rotation: Vec3,
    /// `χ²/ν` of the noise-weighted residuals; `None` without degrees of freedom.
    pub reduced_chi_square: Option<f64>,
    /// Moves whose field was used.
    pub field_motions: usize,
}

/// Fewest moves with a usable field for the fit: the 12 unknowns need at least 12 residuals
/// beyond gravity's, and 5 moves with both directions give 20.
pub const MIN_FIELD_MOTIONS: usize = 5;

/// A prepared move: unit directions, the bases of the planes the residuals lie in, σs.
struct Prepared {
    g0: Vec3,
    g_basis: [Vec3; 2],
    g_sigma: f64,
    field: Option<(Vec3, [Vec3; 2], f64)>,
    rates: Vec<Vec3>,
    dt: f64,
}

/// Two orthonormal vectors perpendicular to the unit `v`.
fn perpendicular_basis(v: &Vec3) -> [Vec3; 2] {
    let not_parallel = if v.x.abs() < 0.9 {
        Vec3::x()
    } else {
        Vec3::y()
    };
    let e1 = v.cross(&not_parallel).normalize();
    [e1, v.cross(&e1)]
}

fn skew(v: &Vec3) -> Mat3 {
    Mat3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

fn field_rotation(p: &DVector<f64>) -> Mat3 {
    Rotation3::new(Vec3::new(p[9], p[10], p[11])).into_inner()
}

/// The rotation end → start and `∂δθ/∂Aᵢⱼ` (end-frame rotation vector per unit change of each
/// entry, row-major), by the trapezoid rule over the samples.
fn integrate_with_sensitivity(a: &Mat3, rates: &[Vec3], dt: f64) -> (Mat3, [Vec3; 9]) {
    // m[j] = Σ wₜ·ω_raw,j(t)·R(t): column i is the start-frame turn per unit Aᵢⱼ.
    let mut m = [Mat3::zeros(); 3];
    let mut q = UnitQuaternion::identity();
    let last = rates.len() - 1;
    for (k, w) in rates.iter().enumerate() {
        if k > 0 {
            q *= integrate_rotation(a, &rates[k - 1..=k], dt);
        }
        let weight = if k == 0 || k == last { 0.5 } else { 1.0 } * dt;
        let r = q.to_rotation_matrix().into_inner();
        for (j, mj) in m.iter_mut().enumerate() {
            *mj += r * (w[j] * weight);
        }
    }
    let rt = q.to_rotation_matrix().into_inner().transpose();
    let mut d = [Vec3::zeros(); 9];
    for i in 0..3 {
        for j in 0..3 {
            d[3 * i + j] = rt * m[j].column(i);
        }
    }
    (rt.transpose(), d)
}

struct JointProblem {
    moves: Vec<Prepared>,
    /// Row of each move's first residual.
    offsets: Vec<usize>,
    rows: usize,
}

impl JointProblem {
    fn new(moves: Vec<Prepared>) -> Self {
        let mut offsets = Vec::with_capacity(moves.len());
        let mut rows = 0;
        for m in &moves {
            offsets.push(rows);
            rows += if m.field.is_some() { 4 } else { 2 };
        }
        Self {
            moves,
            offsets,
            rows,
        }
    }

    /// Weighted residuals given every move's rotation `R` (end → start) and the field frame.
    fn residuals_from(&self, rotations: &[Mat3], rm: &Mat3) -> DVector<f64> {
        let mut r = DVector::zeros(self.rows);
        for ((m, rot), &o) in self.moves.iter().zip(rotations).zip(&self.offsets) {
            let predicted = rot.transpose() * m.g0;
            r[o] = m.g_basis[0].dot(&predicted) / m.g_sigma;
            r[o + 1] = m.g_basis[1].dot(&predicted) / m.g_sigma;
            if let Some((h0, basis, sigma)) = &m.field {
                let predicted = rm.transpose() * (rot.transpose() * (rm * h0));
                r[o + 2] = basis[0].dot(&predicted) / sigma;
                r[o + 3] = basis[1].dot(&predicted) / sigma;
            }
        }
        r
    }

    fn rotations(&self, a: &Mat3) -> Vec<Mat3> {
        self.moves
            .iter()
            .map(|m| {
                integrate_rotation(a, &m.rates, m.dt)
                    .to_rotation_matrix()
                    .into_inner()
            })
            .collect()
    }

    /// Unweighted gravity angle error of every move, radians.
    fn gravity_errors(&self, a: &Mat3) -> Vec<f64> {
        let rotations = self.rotations(a);
        let r = self.residuals_from(&rotations, &Mat3::identity());
        self.moves
            .iter()
            .zip(&self.offsets)
            .map(|(m, &o)| r[o].hypot(r[o + 1]) * m.g_sigma)
            .collect()
    }
}

impl LeastSquaresProblem for JointProblem {
    fn residuals(&self, p: &DVector<f64>) -> DVector<f64> {
        let a = Mat3::from_row_slice(&p.as_slice()[..9]);
        self.residuals_from(&self.rotations(&a), &field_rotation(p))
    }

    fn jacobian(&self, p: &DVector<f64>) -> DMatrix<f64> {
        let a = Mat3::from_row_slice(&p.as_slice()[..9]);
        let rm = field_rotation(p);
        let mut j = DMatrix::zeros(self.rows, 12);
        let mut rotations = Vec::with_capacity(self.moves.len());
        for (m, &o) in self.moves.iter().zip(&self.offsets) {
            let (rot, d) = integrate_with_sensitivity(&a, &m.rates, m.dt);
            // R' = R·exp([δθ]×) turns Rᵀx into Rᵀx + [Rᵀx]×·δθ.
            let dg = skew(&(rot.transpose() * m.g0));
            for (k, dk) in d.iter().enumerate() {
                let turn = dg * dk;
                j[(o, k)] = m.g_basis[0].dot(&turn) / m.g_sigma;
                j[(o + 1, k)] = m.g_basis[1].dot(&turn) / m.g_sigma;
            }
            if let Some((h0, basis, sigma)) = &m.field {
                let dh = rm.transpose() * skew(&(rot.transpose() * (rm * h0)));
                for (k, dk) in d.iter().enumerate() {
                    let turn = dh * dk;
                    j[(o + 2, k)] = basis[0].dot(&turn) / sigma;
                    j[(o + 3, k)] = basis[1].dot(&turn) / sigma;
                }
            }
            rotations.push(rot);
        }
        for k in 9..12 {
            // φ is O(1e-3) rad; 1e-6 balances truncation against round-off.
            let h = 1e-6;
            let (mut plus, mut minus) = (p.clone(), p.clone());
            plus[k] += h;
            minus[k] -= h;
            let d = (self.residuals_from(&rotations, &field_rotation(&plus))
                - self.residuals_from(&rotations, &field_rotation(&minus)))
                / (2.0 * h);
            j.set_column(k, &d);
        }
        j
    }
}

fn finite(v: &Vec3) -> bool {
    v.iter().all(|x| x.is_finite())
}

fn prepare(m: &JointMotion, i: usize) -> Result<Prepared, FitError> {
    let g = &m.gravity;
    if !(g.dt.is_finite() && g.dt > 0.0) || g.rates.len() < 2 {
        return Err(FitError::Underdetermined(format!(
            "move {i} has no usable gyroscope stream (interval {} s, {} samples)",
            g.dt,
            g.rates.len()
        )));
    }
    if !g.rates.iter().all(finite) {
        return Err(FitError::NonFinite(format!("move {i}")));
    }
    let g_sigma = g
        .angle_sigma
        .filter(|s| s.is_finite() && *s > 0.0)
        .ok_or_else(|| {
            FitError::Underdetermined(format!(
                "move {i} states no angle σ; the joint fit weighs each direction by its noise"
            ))
        })?;
    let unit = |v: &Vec3| v.try_normalize(0.0).filter(finite);
    let (Some(g0), Some(g1)) = (unit(&g.gravity_before), unit(&g.gravity_after)) else {
        return Err(FitError::Underdetermined(format!(
            "move {i} has a zero or non-finite gravity reading"
        )));
    };
    let field = match &m.field {
        Some(f) if f.sigma.is_finite() && f.sigma > 0.0 => {
            match (unit(&f.before), unit(&f.after)) {
                (Some(h0), Some(h1)) => Some((h0, perpendicular_basis(&h1), f.sigma)),
                _ => None,
            }
        }
        _ => None,
    };
    Ok(Prepared {
        g0,
        g_basis: perpendicular_basis(&g1),
        g_sigma,
        field,
        rates: g.rates.clone(),
        dt: g.dt,
    })
}

/// Largest condition number of the equilibrated information matrix accepted (half the digits
/// of a double: beyond it the worst-determined combination is fixed by round-off).
const MAX_INFORMATION_CONDITION: f64 = 6.7e7;

/// Largest one-sigma accepted on an entry of `A` (nominally 1): 10 % is not a calibration.
const MAX_ENTRY_STD: f64 = 0.1;

/// Fit the gyroscope's `A` (bias already removed from the rates) and the field frame's rotation
/// from moves with gravity and field directions at their ends; `start` defaults to the identity.
/// Needs at least [`MIN_FIELD_MOTIONS`] moves with a usable field.
pub fn fit_gyro_joint(motions: &[JointMotion], start: Option<&Mat3>) -> Result<JointFit, FitError> {
    let prepared = motions
        .iter()
        .enumerate()
        .map(|(i, m)| prepare(m, i))
        .collect::<Result<Vec<_>, _>>()?;
    let field_motions = prepared.iter().filter(|m| m.field.is_some()).count();
    if field_motions < MIN_FIELD_MOTIONS {
        return Err(FitError::Underdetermined(format!(
            "only {field_motions} moves with a usable field at both ends; the joint fit needs \
             {MIN_FIELD_MOTIONS}"
        )));
    }
    let problem = JointProblem::new(prepared);
    let a0 = start.copied().unwrap_or_else(Mat3::identity);
    if !a0.iter().all(|v| v.is_finite()) {
        return Err(FitError::NonFinite("the starting gyroscope matrix".into()));
    }
    let mut p0 = DVector::zeros(12);
    p0.rows_mut(0, 9)
        .copy_from(&DVector::from_row_slice(a0.transpose().as_slice()));
    let sol = levenberg_marquardt(&problem, p0, &LmOptions::default())
        .map_err(|e| e.into_fit_error("gyroscope scale (gravity and field)"))?;
    let d: Vec<f64> = (0..12).map(|i| sol.jtj[(i, i)].max(0.0).sqrt()).collect();
    if d.iter().any(|v| *v == 0.0 || !v.is_finite()) {
        return Err(FitError::Underdetermined(
            "the moves do not determine every entry of the gyroscope's matrix".into(),
        ));
    }
    let equilibrated = DMatrix::from_fn(12, 12, |i, j| sol.jtj[(i, j)] / (d[i] * d[j]));
    let eig = equilibrated.symmetric_eigenvalues();
    if !(eig.min() > 0.0 && eig.max() / eig.min() <= MAX_INFORMATION_CONDITION) {
        return Err(FitError::Underdetermined(
            "the moves and their gravity and field directions leave a combination of the \
             gyroscope's entries undetermined; turn the board about each of its axes"
                .into(),
        ));
    }
    let scale = noise_scale(sol.cost, sol.residuals.len(), 12, NoiseLevel::Known);
    let (factor, coverage_factor, reduced) = scale
        .map_or((1.0, super::uncertainty::Z_95, None), |s| {
            (s.variance_factor, s.coverage_factor, s.reduced_chi_square)
        });
    let full = normal_covariance(&sol.jtj).map(|c| c * factor);
    let covariance = full.map(|c| c.view((0, 0), (9, 9)).into_owned());
    if covariance
        .as_ref()
        .is_some_and(|c| (0..9).any(|i| c[(i, i)].max(0.0).sqrt() > MAX_ENTRY_STD))
    {
        return Err(FitError::Underdetermined(
            "the gyroscope's entries are known to worse than 10 %; turn the board further".into(),
        ));
    }
    let a = Mat3::from_row_slice(&sol.params.as_slice()[..9]);
    let residuals = problem.gravity_errors(&a);
    let fit = gyro_matrix_fit(a, residuals, covariance, &sol, coverage_factor);
    Ok(JointFit {
        fit,
        field_rotation: Vec3::new(sol.params[9], sol.params[10], sol.params[11]),
        reduced_chi_square: reduced,
        field_motions,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_analytic_sensitivity_matches_central_differences_of_the_integration() {
        let a = Mat3::new(1.02, 0.01, -0.004, 0.003, 0.97, 0.008, -0.006, 0.002, 1.01);
        let rates: Vec<Vec3> = (0..120)
            .map(|k| {
                let t = k as f64 * 0.01;
                Vec3::new(1.5 * t.sin(), 0.8, -1.2 * (2.0 * t).cos())
            })
            .collect();
        let (rot, d) = integrate_with_sensitivity(&a, &rates, 0.01);
        let exact = integrate_rotation(&a, &rates, 0.01);
        assert!((rot - exact.to_rotation_matrix().into_inner()).norm() < 1e-12);
        for (k, dk) in d.iter().enumerate() {
            let h = 1e-6;
            let mut plus = a;
            plus[(k / 3, k % 3)] += h;
            let moved = integrate_rotation(&plus, &rates, 0.01);
            let numeric = (exact.inverse() * moved).scaled_axis() / h;
            // Trapezoid sums against RK4 at 100 Hz with rates ≈ 1.5 rad/s: agreement to ~1e-3
            // of the turn, plenty for Gauss–Newton steps and a first-order covariance.
            assert!(
                (numeric - dk).norm() < 2e-3 * dk.norm().max(1.0),
                "{k}: {numeric} vs {dk}"
            );
        }
    }
}
