//! Leave-one-out of Li's ellipsoid fit ([`super::li`]) without refitting: removing point `i`
//! removes its monomials from the 35 moment sums ([`Moments::without`]), so the scatter matrix
//! `S₋ᵢ = S − φᵢφᵢᵀ` of the other points is exact at the cost of one 35-term subtraction, and only
//! the 10×10 constrained eigenproblem is solved again — no pass over the other points.
//!
//! The centre and scale of the normalisation stay those of the full cloud: the constraint
//! `kJ − I² = 1` acts on the quadratic part alone, which a translation leaves unchanged and a
//! uniform scaling multiplies by a constant that the constraint normalises away, so the fit of
//! the other points does not depend on them (up to rounding).

use super::li::calibration_from_scatter;
use super::li_moments::Moments;
use super::loo::{held_out_errors, rms_of_all};
use super::{Pose, Vec3};

/// RMS over all points of the held-out relative norm residual `(|A₋ᵢ(xᵢ − b₋ᵢ)| − ref)/ref` of
/// Li's fit about the sample mean, each `(A, b)₋ᵢ` fitted without point `i`. Costs one solve of
/// the 10×10 problem per point, independent of the number of points. `None` with fewer than
/// eleven points (a fit without one needs ten), or when a fit without some point is refused.
pub fn li_leave_one_out_rms(points: &[Vec3], reference: f64) -> Option<f64> {
    rms_of_all(li_leave_one_out_errors(points, reference)?)
}

/// The held-out relative norm residual of every point, in order, as in
/// [`li_leave_one_out_rms`]; `None` for a point whose fit without it is refused. `None` overall
/// with fewer than eleven points or all of them at their mean.
pub fn li_leave_one_out_errors(points: &[Vec3], reference: f64) -> Option<Vec<Option<f64>>> {
    if points.len() < 11 {
        return None;
    }
    let (moments, centre, scale) = Moments::about_mean(points)?;
    let as_poses: Vec<Pose> = points.iter().map(|p| Pose::single(*p)).collect();
    held_out_errors(&as_poses, reference, |i| {
        let without = moments.without(&points[i], &centre);
        calibration_from_scatter(&without.scatter(scale), &centre, scale, reference)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::li::{fit_li, LiOptions};
    use crate::fit::loo::leave_one_out_rms;
    use crate::fit::Mat3;

    #[test]
    fn moment_downdate_leave_one_out_equals_refitting_without_each_point() {
        // 40 noisy points on a tilted, offset ellipsoid (deterministic pseudo-noise, 1 %).
        let a_true = Mat3::new(1.08, 0.04, -0.02, 0.0, 0.95, 0.03, 0.0, 0.0, 1.01);
        let inverse = a_true.try_inverse().expect("invertible");
        let b_true = Vec3::new(0.3, -0.2, 0.5);
        let points: Vec<Vec3> = (0..40)
            .map(|i| {
                let t = f64::from(i);
                let z = 1.0 - 2.0 * (t + 0.5) / 40.0;
                let phi = t * 2.399_963_229_728_653;
                let r = (1.0 - z * z).sqrt();
                let u = Vec3::new(r * phi.cos(), r * phi.sin(), z) * (1.0 + 0.01 * (5.1 * t).sin());
                inverse * (u * 9.81) + b_true
            })
            .collect();
        let fast = li_leave_one_out_rms(&points, 9.81).expect("every point can be left out");
        let as_poses: Vec<Pose> = points
            .iter()
            .map(|p| Pose {
                mean: *p,
                var: Vec3::zeros(),
                n: 1,
                label: None,
            })
            .collect();
        let brute = leave_one_out_rms(&as_poses, 9.81, |rest| {
            let means: Vec<Vec3> = rest.iter().map(|p| p.mean).collect();
            fit_li(
                &means,
                9.81,
                LiOptions {
                    subtract_mean: true,
                },
            )
            .map(|f| f.cal)
        })
        .expect("every refit succeeds");
        // Same 10×10 problems; they differ only in the rounding of the moment sums and in the
        // normalisation's centre and scale, to which the fit is invariant.
        assert!(
            (fast - brute).abs() <= 1e-8 * brute,
            "downdate {fast:e} against refits {brute:e}"
        );
        // Held out, the error exceeds the in-sample one (the fit cannot absorb the point).
        let fit = fit_li(
            &points,
            9.81,
            LiOptions {
                subtract_mean: true,
            },
        )
        .expect("fit");
        assert!(
            fast > fit.rms,
            "held-out {fast:e} vs in-sample {:e}",
            fit.rms
        );
    }

    #[test]
    fn too_few_points_for_a_fit_without_one_give_no_leave_one_out() {
        let points: Vec<Vec3> = (0..10).map(|i| Vec3::new(f64::from(i), 1.0, 2.0)).collect();
        assert_eq!(li_leave_one_out_rms(&points, 1.0), None);
    }
}
