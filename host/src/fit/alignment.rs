//! Magnetometer-to-accelerometer frame alignment from static poses.
//!
//! In every still pose the angle between gravity and the Earth's field is the same (the dip),
//! whatever the board's orientation (ARCHITECTURE.md, "The fitting problems, precisely"). With
//! calibrated accelerometer readings `gᵢ` (specific force, pointing up when still) and calibrated
//! magnetometer readings `mᵢ` from the same poses, find the rotation `R` (magnetometer frame →
//! accelerometer frame) and the dip `δ` minimising `Σ (ĝᵢᵀ R m̂ᵢ + sin δ)²` — the "dot-product
//! invariance" formulation also used by Kok & Schön and by Li et al. for the same problem.
//! Solved by Levenberg–Marquardt over a rotation vector (`R = exp([w]×)·R₀`) and `δ`; started
//! from each of the 24 axis permutations `R₀` (mounting of a separate magnetometer die often
//! swaps or inverts axes) and the best minimum kept.

use nalgebra::{DMatrix, DVector, Rotation3};

use super::covariance::normal_covariance;
use super::lm::{levenberg_marquardt, LeastSquaresProblem, LmOptions};
use super::uncertainty::{scaled_covariance, NoiseLevel};
use super::{Calibration, FitError, Mat3, Vec3};

/// The fitted alignment.
#[derive(Debug, Clone)]
pub struct Alignment {
    /// Rotation taking magnetometer-frame vectors into the accelerometer frame.
    pub rotation: Mat3,
    /// Dip (inclination) of the field below the horizontal, in radians.
    pub dip: f64,
    /// One-sigma uncertainty of the small rotation about each accelerometer axis, in radians
    /// (NaN for noise-free data, where the noise cannot be estimated).
    pub rotation_std: Vec3,
    /// One-sigma uncertainty of the dip, in radians.
    pub dip_std: f64,
    /// RMS of `ĝᵢᵀ R m̂ᵢ + sin δ` (dimensionless; ≈ angle noise in radians).
    pub rms: f64,
    /// Covariance of (rotation vector about the accelerometer axes, dip); noise from the residual.
    pub covariance: Option<DMatrix<f64>>,
    /// Iterations of the best start.
    pub iterations: usize,
}

impl Alignment {
    /// The magnetometer calibration expressed in the accelerometer frame: `A' = R·A`.
    pub fn apply_to(&self, mag: &Calibration) -> Calibration {
        Calibration {
            a: self.rotation * mag.a,
            b: mag.b,
        }
    }
}

struct DipProblem {
    gravity: Vec<Vec3>,
    field: Vec<Vec3>,
    base: Rotation3<f64>,
}

impl DipProblem {
    fn rotation(&self, p: &DVector<f64>) -> Rotation3<f64> {
        Rotation3::new(Vec3::new(p[0], p[1], p[2])) * self.base
    }
}

impl LeastSquaresProblem for DipProblem {
    fn residuals(&self, p: &DVector<f64>) -> DVector<f64> {
        let r = self.rotation(p);
        let s = p[3].sin();
        DVector::from_iterator(
            self.gravity.len(),
            self.gravity
                .iter()
                .zip(&self.field)
                .map(|(g, m)| g.dot(&(r * m)) + s),
        )
    }

    fn jacobian(&self, p: &DVector<f64>) -> DMatrix<f64> {
        // A change dw of the rotation vector turns Rm̂ by J_l(w)·dw, so ∂(ĝᵀRm̂)/∂w = J_l(w)ᵀ(Rm̂ × ĝ).
        let r = self.rotation(p);
        let c = p[3].cos();
        let mut j = DMatrix::zeros(self.gravity.len(), 4);
        for (i, (g, m)) in self.gravity.iter().zip(&self.field).enumerate() {
            let d = (r * m).cross(g);
            let jr = left_jacobian_transpose(&Vec3::new(p[0], p[1], p[2])) * d;
            j[(i, 0)] = jr.x;
            j[(i, 1)] = jr.y;
            j[(i, 2)] = jr.z;
            j[(i, 3)] = c;
        }
        j
    }
}

/// `J_l(w)ᵀ`, with `J_l` the left Jacobian of SO(3): `d exp([w]) = [J_l(w) dw]× exp([w])`.
fn left_jacobian_transpose(w: &Vec3) -> Mat3 {
    let theta = w.norm();
    let k = w.cross_matrix();
    let jl = if theta < 1e-8 {
        Mat3::identity() + k * 0.5
    } else {
        let t2 = theta * theta;
        Mat3::identity()
            + k * ((1.0 - theta.cos()) / t2)
            + k * k * ((theta - theta.sin()) / (t2 * theta))
    };
    jl.transpose()
}

/// The 24 proper rotations that permute and flip axes.
fn axis_permutations() -> Vec<Rotation3<f64>> {
    let perms = [
        [0, 1, 2],
        [0, 2, 1],
        [1, 0, 2],
        [1, 2, 0],
        [2, 0, 1],
        [2, 1, 0],
    ];
    let mut out = Vec::with_capacity(24);
    for p in perms {
        for signs in 0..8u8 {
            let mut m = Mat3::zeros();
            for (row, &col) in p.iter().enumerate() {
                m[(row, col)] = if signs & (1 << row) != 0 { -1.0 } else { 1.0 };
            }
            if m.determinant() > 0.0 {
                out.push(Rotation3::from_matrix_unchecked(m));
            }
        }
    }
    out
}

/// Fit the rotation of the magnetometer frame relative to the accelerometer frame and the dip.
///
/// `accel[i]` and `mag[i]` are calibrated readings from the same still pose.
pub fn fit_alignment(accel: &[Vec3], mag: &[Vec3]) -> Result<Alignment, FitError> {
    if accel.len() != mag.len() {
        return Err(FitError::Underdetermined(format!(
            "{} accelerometer poses but {} magnetometer poses; give both readings of every pose",
            accel.len(),
            mag.len()
        )));
    }
    if let Some(i) = accel
        .iter()
        .chain(mag)
        .position(|v| v.iter().any(|x| !x.is_finite()))
    {
        return Err(FitError::NonFinite(format!(
            "pose {}",
            i % accel.len().max(1)
        )));
    }
    let unit = |v: &Vec3| v.try_normalize(0.0);
    let gravity: Option<Vec<Vec3>> = accel.iter().map(unit).collect();
    let field: Option<Vec<Vec3>> = mag.iter().map(unit).collect();
    let (Some(gravity), Some(field)) = (gravity, field) else {
        return Err(FitError::Underdetermined(
            "a pose has a zero reading; check the sensor output".into(),
        ));
    };
    if gravity.len() < 6 {
        return Err(FitError::Underdetermined(format!(
            "only {} poses for the rotation and the dip; hold the board still in at least 6 orientations",
            gravity.len()
        )));
    }
    // Spread of the gravity directions: with all of them near one plane, a rotation about that
    // plane's normal barely changes any dot product.
    let scatter = gravity.iter().map(|g| g * g.transpose()).sum::<Mat3>() / gravity.len() as f64;
    let smallest = scatter.symmetric_eigenvalues().min();
    if smallest < 0.02 {
        return Err(FitError::Underdetermined(format!(
            "the poses do not span enough orientations (the gravity directions lie within about {:.0}° of a plane); \
             add poses with each face of the board up",
            (smallest.max(0.0).sqrt()).asin().to_degrees()
        )));
    }

    let opts = LmOptions::default();
    let mut best: Option<(f64, Rotation3<f64>, super::lm::LmSolution)> = None;
    for base in axis_permutations() {
        let problem = DipProblem {
            gravity: gravity.clone(),
            field: field.clone(),
            base,
        };
        let dots: f64 = gravity
            .iter()
            .zip(&field)
            .map(|(g, m)| g.dot(&(base * m)))
            .sum::<f64>()
            / gravity.len() as f64;
        let start = DVector::from_vec(vec![0.0, 0.0, 0.0, (-dots).clamp(-1.0, 1.0).asin()]);
        if let Ok(sol) = levenberg_marquardt(&problem, start, &opts) {
            if best.as_ref().is_none_or(|(c, _, _)| sol.cost < *c) {
                best = Some((sol.cost, base, sol));
            }
        }
    }
    let Some((cost, base, sol)) = best else {
        return Err(FitError::NotConverged {
            method: "alignment",
            iterations: opts.max_iterations,
            detail: "no starting orientation converged".into(),
        });
    };
    let n = gravity.len();
    let p = &sol.params;
    let rotation = (Rotation3::new(Vec3::new(p[0], p[1], p[2])) * base).into_inner();
    // Wrap the dip into [−90°, 90°]: sin is what the data determine.
    let dip = p[3].sin().clamp(-1.0, 1.0).asin();
    // The covariance of the rotation itself, `exp([δ]×)·R` about the accelerometer's axes: the
    // normal matrix again at the solution with `R` as the base (`w = 0`, where the left Jacobian
    // is the identity). The solver's own matrix is that of `w` about the winning start, which
    // differs by `J_l(w)` and so would depend on which start won.
    let at_solution = DipProblem {
        gravity,
        field,
        base: Rotation3::from_matrix_unchecked(rotation),
    };
    let jacobian = at_solution.jacobian(&DVector::from_vec(vec![0.0, 0.0, 0.0, p[3]]));
    let unit_covariance = normal_covariance(&(jacobian.transpose() * &jacobian));
    if unit_covariance.is_none() {
        return Err(FitError::Underdetermined(
            "the poses do not determine the rotation about every axis; add poses with each face of the board up".into(),
        ));
    }
    // One policy (`uncertainty`): the angle noise is estimated from the residual; a noise-free
    // (exact) fit has no estimate, and its σ are NaN rather than a false zero.
    let covariance =
        scaled_covariance(unit_covariance, cost, n, 4, NoiseLevel::Unknown).map(|s| s.covariance);
    let sd = |k: usize| {
        covariance
            .as_ref()
            .map_or(f64::NAN, |c| c[(k, k)].max(0.0).sqrt())
    };
    Ok(Alignment {
        rotation,
        dip,
        rotation_std: Vec3::new(sd(0), sd(1), sd(2)),
        dip_std: sd(3),
        rms: (cost / n as f64).sqrt(),
        covariance,
        iterations: sol.iterations,
    })
}
