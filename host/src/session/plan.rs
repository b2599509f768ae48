//! Which orientation to ask for next: the one that most reduces the worst-direction error of
//! `|a|` after the accelerometer's norm fit (a minimax experimental design).
//!
//! The norm model's nine parameters (upper-triangular `A`, `b`) are linearised at the nominal
//! calibration (`A = I`, `b = 0`): a pose with up direction `d` adds `g gᵀ/σ²` to the
//! information, with `g` the gradient of `|A(x − b)|` at `x = G·d` (as in [`super::solve`]).
//! A weak prior (scale and cross-axis within 5 %, offset within 50 mg: the range of a consumer
//! MEMS part) keeps the information invertible before nine poses are in. The expected error
//! along a direction `û` is `√(gᵤᵀ Σ gᵤ)`; the worst over the 26 cube directions is compared per
//! candidate, and the candidate with the smallest is prompted.

use nalgebra::{DMatrix, DVector};

use super::coverage::region_directions;
use super::solve::CapturedPose;
use super::targets::Target;
use crate::fit::Vec3;

/// Prior σ of each entry of `A` (relative).
const PRIOR_SCALE: f64 = 0.05;

/// Prior σ of each offset, in units of `g`.
const PRIOR_OFFSET_G: f64 = 0.05;

/// Gradient of `|A(x − b)|` over `A11 A12 A13 A22 A23 A33 b1 b2 b3` at `A = I`, `b = 0`, for
/// the reading `gravity·d` (unit `d`).
fn nominal_gradient(d: &Vec3, gravity: f64) -> DVector<f64> {
    let u = d * gravity;
    DVector::from_vec(vec![
        d[0] * u[0],
        d[0] * u[1],
        d[0] * u[2],
        d[1] * u[1],
        d[1] * u[2],
        d[2] * u[2],
        -d[0],
        -d[1],
        -d[2],
    ])
}

/// Largest `gᵤᵀ Σ gᵤ` over the 26 cube directions for the information `info`, in units of the
/// pose noise variance; `None` if `info` is singular.
fn worst_variance(info: &DMatrix<f64>, gravity: f64) -> Option<f64> {
    let cov = info.clone().try_inverse()?;
    region_directions()
        .iter()
        .map(|d| {
            let g = nominal_gradient(d, gravity);
            (g.transpose() * &cov * &g)[(0, 0)]
        })
        .reduce(f64::max)
}

/// The target of `needed` whose pose would leave the smallest worst-direction error of `|a|`
/// given the poses in `captured` (all of equal noise); `None` when `needed` is empty.
pub fn most_informative<'t>(
    captured: &[CapturedPose],
    needed: &[&'t Target],
    gravity: f64,
) -> Option<&'t Target> {
    // Information in units of 1/σ² of one pose: the prior relative to the pose noise, which is
    // about an eighth of a 2 mg budget (see `super::hold`).
    let pose_sigma = 0.25e-3 * gravity;
    let mut info = DMatrix::zeros(9, 9);
    for i in 0..6 {
        info[(i, i)] = (pose_sigma / (PRIOR_SCALE * gravity)).powi(2);
    }
    for i in 6..9 {
        info[(i, i)] = (pose_sigma / (PRIOR_OFFSET_G * gravity)).powi(2);
    }
    for pose in captured {
        let up = Vec3::from(pose.stats.accel_mean.map(f64::from));
        if let Some(d) = up.try_normalize(0.0) {
            let g = nominal_gradient(&d, gravity);
            info += &g * g.transpose();
        }
    }
    needed
        .iter()
        .map(|t| {
            let g = nominal_gradient(&t.up, gravity);
            let after = &info + &g * g.transpose();
            (*t, worst_variance(&after, gravity).unwrap_or(f64::INFINITY))
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(t, _)| t)
}

#[cfg(test)]
pub(in crate::session) mod tests {
    use super::*;
    use crate::session::targets::twelve_positions;
    use imucal_protocol::PoseStats;

    /// A noise-free pose with `target`'s up direction.
    pub(in crate::session) fn pose(target: &Target, gravity: f64) -> CapturedPose {
        let up = target.up * gravity;
        CapturedPose {
            target: target.clone(),
            stats: PoseStats {
                n: 100,
                accel_mean: [up.x as f32, up.y as f32, up.z as f32],
                accel_var: [1e-4; 3],
                gyro_mean: [0.0; 3],
                gyro_var: [1e-6; 3],
                mag_mean: [20.0, 0.0, 40.0],
                mag_var: [0.1; 3],
                temp_mean_c: 25.0,
                temp_min_c: 25.0,
                temp_max_c: 25.0,
                duration_ms: 1000,
            },
            t_s: 0.0,
        }
    }

    #[test]
    fn the_missing_direction_is_asked_for_before_a_repeat_of_a_captured_one() {
        let g = 9.8;
        let twelve = twelve_positions();
        // Eleven of the twelve in; the candidates are +Z up again and the missing −X+Z tilt.
        let captured: Vec<CapturedPose> = twelve[..11].iter().map(|t| pose(t, g)).collect();
        let needed = vec![&twelve[0], &twelve[11]];
        let next = most_informative(&captured, &needed, g).expect("a candidate");
        assert_eq!(next.name, twelve[11].name);
    }

    #[test]
    fn nothing_needed_gives_no_prompt() {
        assert!(most_informative(&[], &[], 9.8).is_none());
    }
}
