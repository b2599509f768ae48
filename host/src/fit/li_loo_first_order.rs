//! Leave-one-out of Li's ellipsoid fit ([`super::li`]) over samples, to first order in the
//! removed sample, from one 11×11 solve instead of one constrained eigenproblem per sample
//! ([`super::li_loo`], exact, ≈ 60 µs a sample).
//!
//! Li & Griffiths (2004) minimise `vᵀSv` subject to `vᵀCv = 1` (`C = diag(C₁, 0)`, the
//! constraint on the quadratic part), so the solution is stationary for the Lagrangian:
//! `(S − λC)v = 0`, `vᵀCv = 1`, `λ = vᵀSv`. Removing sample `i` changes `S` by `−φᵢφᵢᵀ` (`φᵢ` its
//! design row). Keeping every term of the perturbed equations except `δλ·Cδv` (second order):
//!
//! ```text
//! (S − λC − φᵢφᵢᵀ) δv − δλ·Cv = φᵢ rᵢ,   vᵀC δv = 0,   rᵢ = φᵢᵀv (the algebraic residual).
//! ```
//!
//! Its matrix is the bordered `K = [[S − λC, −Cv], [−vᵀC, 0]]`, independent of `i`, less the
//! rank one `eeᵀ` (`e = [φᵢ; 0]`); by Sherman–Morrison `δv = rᵢ/(1 − hᵢ)·Pφᵢ` with `P` the leading
//! 10×10 block of `K⁻¹` and `hᵢ = φᵢᵀPφᵢ`, the analogue of a leverage (`P` is `S − λC` inverted
//! on the constraint's tangent space, positive semi-definite at the minimum; cf. the leverage
//! form of [`super::norm_loo`] and Cook & Weisberg 1982, §2.2). What is neglected, `δλ·Cδv` with
//! `δλ = −rᵢ²/(1 − hᵢ)`, is second order in the removed sample.
//!
//! The held-out residual needs no square root of a matrix: with `M`, `n`, `d` the parts of `v`
//! (`qᵀMq + 2nᵀq + d`, seed 000 eq. 19–23), `c = −M⁻¹n` and `C₀ = cᵀMc − d`,
//! `|A(x − b)|²/ref² = (q − c)ᵀM(q − c)/C₀ = 1 + φ(q)ᵀv/C₀` (`q` the centred, scaled sample). For
//! `v' = v + δv`, `φᵢᵀv' = rᵢ/(1 − hᵢ)` exactly, and since `c` is where the quadric is stationary,
//! `C₀' = C₀ − φ(c)ᵀδv` to first order (`∇ᵥC₀ = −φ(c)`). So the held-out relative residual is
//!
//! ```text
//! eᵢ = √(1 + sᵢ/(C₀ − sᵢtᵢ)) − 1,   sᵢ = rᵢ/(1 − hᵢ),   tᵢ = φᵢᵀPφ(c).
//! ```
//!
//! `rᵢ`, `tᵢ` and `hᵢ` are polynomials of degree ≤ 4 in `q`, so each is a dot product of fixed
//! coefficients with the 35 monomials the fit already accumulates ([`super::li_moments`]): one
//! pass of about 80 multiply-adds, three divisions and a square root a sample, after one 11×11
//! inversion (≈ 2× the fit's moment pass; figures in docs/RESULTS.md).
//!
//! Accuracy: the neglected terms are of relative order `hᵢ ≈ p/N` (`p = 9`) against the change
//! `δv` they correct, which is itself of relative order `p/N` of the fit, so the held-out RMS is
//! off by `O((p/N)²)` of itself, as for [`super::norm_loo`]. The dropped `δλ·Cδv` carries
//! `rᵢ²`, so in practice the difference is smaller still by about the squared relative noise
//! (tests below: 1e-6 of the RMS at N = 200, 1e-8 at 2000). Which form runs where: the
//! magnetometer's `fit_mag` uses the exact downdate up to
//! [`crate::pipeline::methods::LI_EXACT_LOO_MAX_SAMPLES`] samples and this one above; pose
//! fits (a few to a few hundred means) keep the exact one.

use nalgebra::{DMatrix, DVector};

use super::li::{constrained_quadric, constraint_matrix, quadric_centre};
use super::li_moments::{linear_form, quadratic_form, scaled_monomials, Moments, LINEAR_TERMS};
use super::norm_jacobian::in_two_halves;
use super::Vec3;

/// The per-sample coefficients of the first-order leave-one-out of one Li fit (module comment).
struct Influence {
    centre: Vec3,
    scale: f64,
    /// `C₀`, positive.
    c0: f64,
    /// `rᵢ = φᵢᵀv`, `hᵢ = φᵢᵀPφᵢ` and `tᵢ = φᵢᵀPφ(c)` over the 35 monomials.
    residual: [f64; 35],
    leverage: [f64; 35],
    centre_shift: [f64; 35],
}

impl Influence {
    /// Li's fit about the sample mean and the bordered system's inverse; `None` with fewer than
    /// eleven points, no spread, no ellipsoid or a singular `K`.
    fn of(points: &[Vec3]) -> Option<Self> {
        if points.len() < 11 || !points.iter().all(|p| p.iter().all(|x| x.is_finite())) {
            return None;
        }
        let (moments, centre, scale) = Moments::about_mean(points)?;
        let s = moments.scatter(scale);
        let mut v = constrained_quadric(&s).ok()?;
        // Sign as the fit takes it (M positive definite), length so that vᵀCv = 1.
        if v[0] + v[1] + v[2] < 0.0 {
            v = -v;
        }
        let mut c = DMatrix::zeros(10, 10);
        c.view_mut((0, 0), (6, 6)).copy_from(&constraint_matrix());
        let kappa = (v.transpose() * &c * &v)[(0, 0)];
        if kappa.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            return None;
        }
        let v = v / kappa.sqrt();
        let lambda = (v.transpose() * &s * &v)[(0, 0)];
        let cv = &c * &v;
        let mut k = DMatrix::zeros(11, 11);
        k.view_mut((0, 0), (10, 10)).copy_from(&(&s - &c * lambda));
        for j in 0..10 {
            k[(j, 10)] = -cv[j];
            k[(10, j)] = -cv[j];
        }
        let k_inv = k.try_inverse()?;
        let p = k_inv.view((0, 0), (10, 10)).into_owned();
        let p = (&p + p.transpose()) * 0.5;

        let (_, q, c0) = quadric_centre(v.as_slice()).ok()?;
        let phi_c = DVector::from_row_slice(&[
            q.x * q.x,
            q.y * q.y,
            q.z * q.z,
            2.0 * q.y * q.z,
            2.0 * q.x * q.z,
            2.0 * q.x * q.y,
            2.0 * q.x,
            2.0 * q.y,
            2.0 * q.z,
            1.0,
        ]);
        let p_phi_c = &p * phi_c;
        let as_array = |w: &DVector<f64>| std::array::from_fn::<f64, 10, _>(|j| w[j]);
        let influence = Self {
            centre,
            scale,
            c0,
            residual: linear_form(&as_array(&v)),
            leverage: quadratic_form(&p),
            centre_shift: linear_form(&as_array(&p_phi_c)),
        };
        let all_finite = influence
            .residual
            .iter()
            .chain(&influence.leverage)
            .chain(&influence.centre_shift)
            .all(|x| x.is_finite());
        all_finite.then_some(influence)
    }

    /// `(rᵢ, hᵢ, tᵢ)` of `point` (module comment).
    #[inline]
    fn terms(&self, point: &Vec3) -> (f64, f64, f64) {
        let m = scaled_monomials(point, &self.centre, 1.0 / self.scale);
        let (mut r, mut h, mut t) = (0.0, 0.0, 0.0);
        for ((x, a), b) in m
            .iter()
            .zip(&self.residual)
            .zip(&self.centre_shift)
            .take(LINEAR_TERMS)
        {
            r += a * x;
            t += b * x;
        }
        for (c, x) in self.leverage.iter().zip(&m) {
            h += c * x;
        }
        (r, h, t)
    }

    /// Sum over `points` of the squared first-order held-out residuals, four samples at a time
    /// (one vector lane each); `None` when any cannot be predicted ([`Self::error_from`]).
    fn sum_of_squares(&self, points: &[Vec3]) -> Option<f64> {
        const LANES: usize = 4;
        let inverse_scale = 1.0 / self.scale;
        let mut total = [0.0; LANES];
        let mut all_predicted = true;
        for chunk in points.chunks(LANES) {
            // Monomials lane by lane; lanes past the end stay 0 and give a residual of 0.
            let mut m = [[0.0; LANES]; 35];
            for (lane, p) in chunk.iter().enumerate() {
                for (j, x) in scaled_monomials(p, &self.centre, inverse_scale)
                    .into_iter()
                    .enumerate()
                {
                    m[j][lane] = x;
                }
            }
            let (mut r, mut h, mut t) = ([0.0; LANES], [0.0; LANES], [0.0; LANES]);
            for ((row, a), b) in m
                .iter()
                .zip(&self.residual)
                .zip(&self.centre_shift)
                .take(LINEAR_TERMS)
            {
                for lane in 0..LANES {
                    r[lane] += a * row[lane];
                    t[lane] += b * row[lane];
                }
            }
            for (c, row) in self.leverage.iter().zip(&m) {
                for lane in 0..LANES {
                    h[lane] += c * row[lane];
                }
            }
            for lane in 0..LANES {
                let (e, predicted) = self.error_from(r[lane], h[lane], t[lane]);
                all_predicted &= predicted;
                total[lane] += e * e;
            }
        }
        all_predicted.then_some(total.iter().sum())
    }

    /// The held-out residual from `(rᵢ, hᵢ, tᵢ)` and whether it is defined: the leverage is
    /// below 1 (else the others cannot predict the sample), the fit without the sample encloses
    /// a volume (`C₀' > 0`), the squared norm is not negative (first order can make it so for a
    /// sample at the fitted centre) and the value is finite. Branch-free, for the lanes.
    #[inline(always)]
    fn error_from(&self, r: f64, h: f64, t: f64) -> (f64, bool) {
        let s = r / (1.0 - h);
        let c0 = self.c0 - s * t;
        let ratio = 1.0 + s / c0;
        let e = ratio.max(0.0).sqrt() - 1.0;
        let predicted = h < 1.0 && c0 > 0.0 && ratio >= 0.0 && e.is_finite();
        (if predicted { e } else { 0.0 }, predicted)
    }

    /// The first-order held-out relative norm residual of `point`, `None` where undefined
    /// ([`Self::error_from`]).
    fn held_out_error(&self, point: &Vec3) -> Option<f64> {
        let (r, h, t) = self.terms(point);
        let (e, predicted) = self.error_from(r, h, t);
        predicted.then_some(e)
    }
}

/// The first-order held-out relative norm residual `(|A₋ᵢ(xᵢ − b₋ᵢ)| − ref)/ref` of every point
/// under Li's fit about the sample mean (module comment), in order; `None` for a point that
/// cannot be predicted. `None` overall with fewer than eleven points, no spread, no ellipsoid,
/// a singular bordered system or a reference that is not positive.
pub fn li_first_order_loo_errors(points: &[Vec3], reference: f64) -> Option<Vec<Option<f64>>> {
    if reference.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let influence = Influence::of(points)?;
    Some(points.iter().map(|p| influence.held_out_error(p)).collect())
}

/// RMS of [`li_first_order_loo_errors`] over all points, in one pass (on two threads for large
/// sets) without storing them; `None` when any point cannot be predicted.
pub fn li_first_order_loo_rms(points: &[Vec3], reference: f64) -> Option<f64> {
    if reference.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let influence = Influence::of(points)?;
    let total = in_two_halves(
        points.len(),
        &mut [],
        |range, _| influence.sum_of_squares(&points[range]),
        |a, b| Some(a? + b?),
    )?;
    Some((total / points.len() as f64).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::li::{fit_li, LiOptions};
    use crate::fit::li_loo::{li_leave_one_out_errors, li_leave_one_out_rms};
    use crate::synthetic::hard_and_soft_iron_cloud as cloud;

    /// Unknowns of the general ellipsoid.
    const P: f64 = 9.0;

    /// The magnetometer columns (`mx,my,mz`) of a recording under `data/real/`.
    fn real_mag(name: &str) -> Vec<Vec3> {
        let path = format!("{}/../data/real/{name}", env!("CARGO_MANIFEST_DIR"));
        let text = std::fs::read_to_string(&path).expect("the recording is in the repository");
        text.lines()
            .skip(1)
            .map(|line| {
                let v: Vec<f64> = line
                    .split(',')
                    .map(|x| x.trim().parse().expect("a number"))
                    .collect();
                Vec3::new(v[1], v[2], v[3])
            })
            .collect()
    }

    fn li(points: &[Vec3], reference: f64) -> crate::fit::Fit {
        fit_li(
            points,
            reference,
            LiOptions {
                subtract_mean: true,
            },
        )
        .expect("the cloud fits")
    }

    #[test]
    fn first_order_leave_one_out_rms_matches_the_exact_downdate() {
        for (n, seed) in [(200, 31), (2000, 41)] {
            let points = cloud(n, seed);
            let fast = li_first_order_loo_rms(&points, 50.0).expect("first order");
            let exact = li_leave_one_out_rms(&points, 50.0).expect("exact");
            let fit = li(&points, 50.0);
            let h = P / n as f64;
            println!(
                "N = {n}: first order {fast:.9e}, exact {exact:.9e}, relative {:.2e}, \
                 in-sample {:.9e}",
                (fast - exact).abs() / exact,
                fit.rms
            );
            assert!(
                (fast - exact).abs() <= h * h * exact,
                "N = {n}: first order {fast:e}, exact {exact:e}"
            );
            assert!(fast > fit.rms, "N = {n}: held out {fast:e} ≤ {:e}", fit.rms);
        }
    }

    #[test]
    fn first_order_held_out_residuals_match_the_exact_ones_sample_by_sample() {
        for (n, seed) in [(200, 31), (2000, 41)] {
            let points = cloud(n, seed);
            let fast = li_first_order_loo_errors(&points, 50.0).expect("first order");
            let exact = li_leave_one_out_errors(&points, 50.0).expect("exact");
            let fit = li(&points, 50.0);
            let (mut worst, mut worst_shift) = (0.0_f64, 0.0_f64);
            for ((f, e), r) in fast.iter().zip(&exact).zip(&fit.residuals) {
                let (f, e) = (f.expect("predicted"), e.expect("refitted"));
                worst = worst.max((f - e).abs());
                worst_shift = worst_shift.max((e - r).abs());
            }
            let h = P / n as f64;
            println!(
                "N = {n}: worst difference {worst:.2e}, worst held-out shift {worst_shift:.2e}"
            );
            // Each held-out residual moves from the in-sample one by O(p/N) of it; first order
            // gets that move up to a relative O(p/N).
            assert!(
                worst <= h * worst_shift,
                "N = {n}: {worst:e} against {worst_shift:e}"
            );
        }
    }

    #[test]
    fn too_few_flat_or_empty_clouds_give_no_leave_one_out() {
        let ten = cloud(10, 5);
        assert_eq!(li_first_order_loo_rms(&ten, 50.0), None);
        assert_eq!(li_first_order_loo_errors(&ten, 50.0), None);
        let flat: Vec<Vec3> = cloud(100, 6)
            .iter()
            .map(|p| Vec3::new(p.x, p.y, 3.0))
            .collect();
        assert_eq!(li_first_order_loo_rms(&flat, 50.0), None);
        let still = vec![Vec3::new(1.0, 2.0, 3.0); 50];
        assert_eq!(li_first_order_loo_rms(&still, 50.0), None);
        let mut with_nan = cloud(100, 7);
        with_nan[3].y = f64::NAN;
        assert_eq!(li_first_order_loo_rms(&with_nan, 50.0), None);
        assert_eq!(li_first_order_loo_rms(&cloud(100, 8), 0.0), None);
    }

    #[test]
    fn first_order_leave_one_out_matches_the_exact_one_on_a_real_full_sphere() {
        // 8190 HMC5883L samples in gauss over a full sphere; the relative residual does not
        // depend on the reference.
        let points = real_mag("sf_mpu6050_hmc5883l_full_sphere_mag.csv");
        assert_eq!(points.len(), 8190);
        let fast = li_first_order_loo_rms(&points, 0.5).expect("first order");
        let exact = li_leave_one_out_rms(&points, 0.5).expect("exact");
        let fit = li(&points, 0.5);
        let h = P / points.len() as f64;
        println!(
            "real: first order {fast:.9e}, exact {exact:.9e}, relative {:.2e}, in-sample {:.9e}",
            (fast - exact).abs() / exact,
            fit.rms
        );
        assert!(
            (fast - exact).abs() <= h * h * exact,
            "{fast:e} against {exact:e}"
        );
        assert!(fast > fit.rms);
    }
}
