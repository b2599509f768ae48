//! Leave-one-out of the norm-model fit ([`super::norm_lm`]) over samples, to first order, from
//! the leverages of its final Gauss–Newton system instead of one refit per sample.
//!
//! For weighted least squares with Jacobian `J` (rows `gᵢ`) and residual `r`, removing sample
//! `i` moves the parameters by `δθ ≈ (JᵀJ − gᵢgᵢᵀ)⁻¹gᵢrᵢ`, and its residual becomes
//! `rᵢ/(1 − hᵢᵢ)` with the leverage `hᵢᵢ = gᵢᵀ(JᵀJ)⁻¹gᵢ` (Sherman–Morrison; Cook & Weisberg,
//! "Residuals and Influence in Regression", 1982, §2.2). This is exact for a linear model and
//! first-order for the nonlinear norm model: the neglected terms are the change of `J` over
//! `δθ`, of relative size `|δθ|`, i.e. of order `hᵢᵢ ≈ p/N`. The held-out norm residual in
//! units of the reference is `eᵢ + (rᵢ/w'ᵢ)·hᵢᵢ/(1 − hᵢᵢ)`, `eᵢ = |R(x̃ᵢ − b̃)| − 1` the plain
//! norm residual and `w'ᵢ = ∂rᵢ/∂n` its weight. One pass, `O(N·p²)`.
//!
//! [`FoldUpdate`] gives the calibration itself without one point: the same Gauss–Newton
//! downdate `θ₋ᵢ = θ + (JᵀJ)⁻¹gᵢrᵢ/(1 − hᵢᵢ)` (the step that returns the gradient of the other
//! points, `−gᵢrᵢ`, to zero), after which the held-out point's residual is evaluated on the
//! nonlinear model. Its error is second order in the step, `O(hᵢᵢ²)`. The fit's root is that of
//! the corrected score, whose per-point term differs from `gᵢrᵢ` by the noise correction, of
//! relative size the noise itself (≈ 10⁻⁴ for pose means): neglected here.

use nalgebra::{DMatrix, DVector, SMatrix, SVector};

use super::corrected_score::upper_from_params;
use super::linalg::RANK_TOLERANCE;
use super::norm_jacobian::{
    for_each_block, in_two_halves, jacobian_row, norm_residual, NormSamples, LANES,
};
use super::{Calibration, FitError, Mat3, Vec3};

/// RMS over the samples of the first-order held-out relative norm residual (see the module
/// comment), at the solution `(r, b)` of the problem `samples` (centred, scaled units, where
/// the reference is 1) whose Gauss–Newton normal matrix there is `jtj`.
///
/// `None` when `jtj` is singular, there are not more samples than parameters, or a sample has
/// leverage 1 (the others cannot predict it).
pub(super) fn first_order_loo_rms(
    r: &Mat3,
    b: &Vec3,
    samples: NormSamples<'_>,
    jtj: &DMatrix<f64>,
) -> Option<f64> {
    let n = samples.len();
    if n <= 9 || jtj.shape() != (9, 9) {
        return None;
    }
    let inverse: SMatrix<f64, 9, 9> = jtj
        .clone()
        .cholesky()?
        .inverse()
        .fixed_view::<9, 9>(0, 0)
        .into_owned();
    let total = in_two_halves(
        n,
        &mut [],
        |range, _| held_out_sum_of_squares(r, b, samples.range(range), &inverse),
        |a, b| Some(a? + b?),
    )?;
    Some((total / n as f64).sqrt())
}

/// Sum of the squared first-order held-out norm residuals; `None` when a sample has leverage 1
/// or above, sits at the centre, or gives a non-finite residual.
fn held_out_sum_of_squares(
    r: &Mat3,
    b: &Vec3,
    samples: NormSamples<'_>,
    inverse: &SMatrix<f64, 9, 9>,
) -> Option<f64> {
    let mut total = 0.0;
    let mut all_predicted = true;
    for_each_block(r, b, samples, |_, valid, block| {
        // Leverage hᵢᵢ = gᵢᵀ(JᵀJ)⁻¹gᵢ, lane by lane.
        let mut leverage = [0.0; LANES];
        for i in 0..9 {
            let mut m_row = [0.0; LANES];
            for (j, row) in block.rows.iter().enumerate() {
                for (m, g) in m_row.iter_mut().zip(row) {
                    *m += inverse[(i, j)] * g;
                }
            }
            for lane in 0..LANES {
                leverage[lane] += block.rows[i][lane] * m_row[lane];
            }
        }
        for (lane, &h) in leverage.iter().enumerate().take(valid) {
            let norm = block.norm[lane];
            if h.is_nan() || h >= 1.0 || norm == 0.0 {
                all_predicted = false;
                continue;
            }
            // The fitted residual moves by rᵢhᵢᵢ/(1 − hᵢᵢ); the norm by that over ∂r/∂n.
            let e = norm - 1.0 + block.res[lane] / block.slope[lane] * h / (1.0 - h);
            if e.is_finite() {
                total += e * e;
            } else {
                all_predicted = false;
            }
        }
    });
    all_predicted.then_some(total)
}

/// Samples up to which a fit of a cloud keeps what [`FoldUpdate`] needs (its scaled points,
/// weights and corrections); fits of pose means always keep it.
pub(super) const FOLD_UPDATE_MAX_POINTS: usize = 10_000;

/// A norm-model fit that can give its calibration without any one of its points, to first
/// order (see the module comment), instead of a refit per point.
#[derive(Debug, Clone)]
pub struct FoldUpdate {
    /// `(JᵀJ)⁻¹` at the solution (centred, scaled units).
    inverse: SMatrix<f64, 9, 9>,
    /// The solution: upper-triangular `R̃` (6) and `b̃` (3).
    params: SVector<f64, 9>,
    /// The problem's points, weights and norm corrections.
    points: Vec<Vec3>,
    weights: Vec<f64>,
    tangential: Vec<f64>,
    /// Centre and scale of the data units: `x̃ = (x − centre)/scale`.
    centre: Vec3,
    scale: f64,
    /// The reference magnitude: `A = reference·R̃/scale`.
    reference: f64,
}

impl FoldUpdate {
    /// The update for the solution `params` of the problem `samples` (taken over), whose normal
    /// matrix there is `jtj`; `None` when `jtj` is singular or not 9×9.
    pub(super) fn new(
        params: &DVector<f64>,
        samples: (Vec<Vec3>, Vec<f64>, Vec<f64>),
        jtj: &DMatrix<f64>,
        centre: Vec3,
        scale: f64,
        reference: f64,
    ) -> Option<Self> {
        if jtj.shape() != (9, 9) || params.len() != 9 {
            return None;
        }
        let inverse: SMatrix<f64, 9, 9> = jtj
            .clone()
            .cholesky()?
            .inverse()
            .fixed_view::<9, 9>(0, 0)
            .into_owned();
        let (points, weights, tangential) = samples;
        Some(Self {
            inverse,
            params: SVector::from_iterator(params.iter().copied()),
            points,
            weights,
            tangential,
            centre,
            scale,
            reference,
        })
    }

    /// Number of points of the fit.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Whether the fit had no points.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// The calibration fitted without point `i`, to first order. Refused when point `i` does
    /// not exist or carries all the leverage (the others cannot determine the fit without it),
    /// and when the result is degenerate.
    pub fn calibration_without(&self, i: usize) -> Result<Calibration, FitError> {
        self.without(i).map(|(cal, _)| cal)
    }

    /// As [`Self::calibration_without`], with point `i`'s leverage `hᵢᵢ` (the update's error
    /// grows with it: a caller may refit where it is high).
    pub fn without(&self, i: usize) -> Result<(Calibration, f64), FitError> {
        let (Some(x), Some(&w), Some(&k)) = (
            self.points.get(i),
            self.weights.get(i),
            self.tangential.get(i),
        ) else {
            return Err(FitError::Underdetermined(format!(
                "point {i} does not exist ({} points)",
                self.points.len()
            )));
        };
        let p = DVector::from_iterator(9, self.params.iter().copied());
        let r = upper_from_params(&p);
        let b = Vec3::new(p[6], p[7], p[8]);
        let g = SVector::<f64, 9>::from(jacobian_row(&r, &b, x, w, k));
        let residual = norm_residual((r * (x - b)).norm(), w, k);
        let mg = self.inverse * g;
        let leverage = g.dot(&mg);
        // NaN leverage (a degenerate row) is refused with the rest.
        if (1.0 - leverage).partial_cmp(&RANK_TOLERANCE.sqrt()) != Some(std::cmp::Ordering::Greater)
        {
            return Err(FitError::Underdetermined(
                "a point determines the fit alone".into(),
            ));
        }
        let fold = self.params + mg * (residual / (1.0 - leverage));
        let mut r = Mat3::new(
            fold[0], fold[1], fold[2], 0.0, fold[3], fold[4], 0.0, 0.0, fold[5],
        );
        // Positive diagonal, as the fit reports it (a row's sign leaves every norm unchanged).
        for row in 0..3 {
            if r[(row, row)] < 0.0 {
                r.row_mut(row).neg_mut();
            }
        }
        let cal = Calibration {
            a: r * (self.reference / self.scale),
            b: self.centre + Vec3::new(fold[6], fold[7], fold[8]) * self.scale,
        };
        if !cal.is_finite() || r.determinant() == 0.0 {
            return Err(FitError::Underdetermined(
                "the fit without this point is degenerate".into(),
            ));
        }
        Ok((cal, leverage))
    }
}

#[cfg(test)]
mod tests {
    use crate::fit::loo::without;
    use crate::fit::norm_lm::{fit_accel_lm_detailed, fit_mag_lm, refit_accel_lm_from};
    use crate::fit::Vec3;
    use crate::synthetic::hard_and_soft_iron_cloud as cloud;
    use crate::synthetic::{accel_poses, random_calibration, rng, sphere_directions, TruthSpec};

    #[test]
    fn the_fit_without_each_pose_by_the_update_matches_refitting_without_it() {
        let g = 9.81;
        for (n, seed) in [(40, 5), (150, 6)] {
            let mut rng = rng(seed);
            let spec = TruthSpec {
                reference: g,
                ..TruthSpec::default()
            };
            let truth = random_calibration(&mut rng, &spec);
            let dirs = sphere_directions(&mut rng, n);
            // 0.02 m/s² per sample, 100 samples a pose: a typical MEMS accelerometer's hold.
            let poses = accel_poses(&mut rng, &truth, &dirs, g, 0.02, 100);
            let outcome = fit_accel_lm_detailed(&poses, g).expect("a full sphere fits");
            let all = outcome.fit.cal;
            let update = outcome.fold_update.expect("a pose fit keeps its update");
            assert_eq!(update.len(), n);
            let error = |cal: &crate::fit::Calibration, i: usize| {
                (cal.apply(&poses[i].mean).norm() - g) / g
            };
            let (mut fast2, mut brute2, mut shift2) = (0.0, 0.0, 0.0);
            for i in 0..n {
                let refit = refit_accel_lm_from(&without(&poses, i), g, &all)
                    .expect("one pose fewer still fits")
                    .fit
                    .cal;
                let fold = update.calibration_without(i).expect("the update exists");
                let (e_fast, e_brute) = (error(&fold, i), error(&refit, i));
                fast2 += e_fast * e_fast;
                brute2 += e_brute * e_brute;
                // How far leaving the pose out moves its own residual: what the update predicts.
                shift2 += (e_brute - error(&all, i)).powi(2);
                // The update is exact to first order in the leverage h ≈ p/N (p = 9): what it
                // misses of that move is of order h times the move.
                let h = 9.0 / n as f64;
                assert!(
                    (e_fast - e_brute).abs() <= h * (e_brute - error(&all, i)).abs() + 1e-12,
                    "N = {n}, pose {i}: update {e_fast:.6e}, refit {e_brute:.6e}, in-sample {:.6e}",
                    error(&all, i)
                );
            }
            let (fast, brute) = ((fast2 / n as f64).sqrt(), (brute2 / n as f64).sqrt());
            // Over the RMS that is (p/N)² of it at most, as for the samples' leverage form.
            let h = 9.0 / n as f64;
            assert!(
                (fast - brute).abs() <= h * h * brute,
                "N = {n}: update {fast:.6e}, refits {brute:.6e}"
            );
            assert!(shift2 > 0.0, "leaving a pose out moves its residual");
        }
    }

    #[test]
    fn a_fold_update_refuses_a_pose_that_does_not_exist() {
        let mut rng = rng(7);
        let truth = random_calibration(&mut rng, &TruthSpec::default());
        let dirs = sphere_directions(&mut rng, 20);
        let poses = accel_poses(&mut rng, &truth, &dirs, 1.0, 0.002, 50);
        let update = fit_accel_lm_detailed(&poses, 1.0)
            .expect("fits")
            .fold_update
            .expect("kept");
        let err = update.calibration_without(20).unwrap_err();
        assert!(err.to_string().contains("point 20 does not exist"), "{err}");
    }

    #[test]
    fn a_cloud_of_samples_keeps_no_fold_update() {
        let points = cloud(super::FOLD_UPDATE_MAX_POINTS + 1, 3);
        let outcome = crate::fit::norm_lm::fit_mag_lm_detailed(&points, 50.0).expect("fits");
        assert!(outcome.fold_update.is_none());
    }

    #[test]
    fn first_order_leave_one_out_matches_refitting_without_each_sample() {
        for (n, seed) in [(60, 11), (200, 21)] {
            let points = cloud(n, seed);
            let fit = fit_mag_lm(&points, 50.0).expect("a full sphere fits");
            let fast = fit.loo_rms.expect("every sample can be left out");
            let errors: Vec<f64> = (0..n)
                .map(|i| {
                    let rest: Vec<Vec3> = points
                        .iter()
                        .enumerate()
                        .filter(|&(j, _)| j != i)
                        .map(|(_, p)| *p)
                        .collect();
                    let cal = fit_mag_lm(&rest, 50.0).expect("refit").cal;
                    (cal.apply(&points[i]).norm() - 50.0) / 50.0
                })
                .collect();
            let brute = (errors.iter().map(|e| e * e).sum::<f64>() / n as f64).sqrt();
            // Leaving a sample out raises the RMS by a relative O(p/N) (p = 9 unknowns); the
            // leverage form gets that rise to first order, so what it misses is O((p/N)²) of the
            // RMS. Allowed: (p/N)², i.e. 2.3 % at N = 60 and 0.2 % at N = 200.
            let h = 9.0 / n as f64;
            assert!(
                (fast - brute).abs() <= h * h * brute,
                "N = {n}: first order {fast:.6e}, refits {brute:.6e}, in-sample {:.6e}",
                fit.rms
            );
            // And it is a held-out figure: above the in-sample RMS.
            assert!(fast > fit.rms, "N = {n}: {fast} ≤ {}", fit.rms);
        }
    }
}
