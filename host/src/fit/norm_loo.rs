//! Leave-one-out of the norm-model fit ([`super::norm_lm`]) over samples, to first order, from
//! the leverages of its final Gauss–Newton system instead of one refit per sample.
//!
//! For weighted least squares with Jacobian `J` (rows `gᵢ`) and residual `r`, removing sample
//! `i` moves the parameters by `δθ ≈ −(JᵀJ − gᵢgᵢᵀ)⁻¹gᵢrᵢ`, and its residual becomes
//! `rᵢ/(1 − hᵢᵢ)` with the leverage `hᵢᵢ = gᵢᵀ(JᵀJ)⁻¹gᵢ` (Sherman–Morrison; Cook & Weisberg,
//! "Residuals and Influence in Regression", 1982, §2.2). This is exact for a linear model and
//! first-order for the nonlinear norm model: the neglected terms are the change of `J` over
//! `δθ`, of relative size `|δθ|`, i.e. of order `hᵢᵢ ≈ p/N`. The held-out norm residual in
//! units of the reference is `eᵢ + (rᵢ/w'ᵢ)·hᵢᵢ/(1 − hᵢᵢ)`, `eᵢ = |R(x̃ᵢ − b̃)| − 1` the plain
//! norm residual and `w'ᵢ = ∂rᵢ/∂n` its weight. One pass, `O(N·p²)`.

use nalgebra::{DMatrix, SMatrix};

use super::norm_jacobian::{for_each_block, in_two_halves, NormSamples, LANES};
use super::{Mat3, Vec3};

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

#[cfg(test)]
mod tests {
    use crate::fit::norm_lm::fit_mag_lm;
    use crate::fit::Vec3;
    use crate::synthetic::hard_and_soft_iron_cloud as cloud;

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
