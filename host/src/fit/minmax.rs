//! Min/max six-face calibration (seed 004 §1.2.1): with each face of the board up once, the axis
//! reads its maximum and minimum at ±ref, so per axis `b = (max + min)/2` and
//! `scale = ref / ((max − min)/2)`; `A = diag(scale)` (no cross-axis terms).
//!
//! Leave-one-out without refits: a fold's calibration depends only on its six face poses, which
//! [`find_faces`] picks as the best-aligned pose per face seen from the median centre. Removing
//! one pose moves each axis's median to one of at most two neighbouring order statistics, and
//! changes a face's pose only when it removes that pose (then the runner-up takes its place). So
//! the best and runner-up per face for each of the few distinct fold centres give every fold
//! exactly as a refit would, in O(N log N) instead of O(N²).

use nalgebra::DMatrix;

use super::linalg::rms;
use super::loo::held_out_rms;
use super::validate::{
    check_finite_poses, check_reference, face_of, find_faces, FACE_TOLERANCE_DEG,
};
use super::{Calibration, CalibrationStd, Fit, FitError, Mat3, Method, Pose, Vec3};

/// Fit per-axis bias and scale from the six face poses.
///
/// The face poses are found by direction (see [`find_faces`]); the extremes of axis `k` are the
/// `k` readings of the `+k` and `−k` poses. Refused when a face is missing ("no pose with −Z up").
/// The covariance (order `A11 A22 A33 b1 b2 b3`) follows from the variance of the two pose means
/// used per axis.
pub fn fit_minmax(poses: &[Pose], reference: f64) -> Result<Fit, FitError> {
    let cal = minmax_calibration(poses, reference)?;
    let faces = find_faces(poses)?;

    let residuals: Vec<f64> = poses
        .iter()
        .map(|p| (cal.apply(&p.mean).norm() - reference) / reference)
        .collect();
    let loo_rms = leave_one_out_minmax(poses, reference);

    // Per axis: b = (M + m)/2, s = 2r/(M − m); first-order propagation of the two means' variances.
    let mut cov = DMatrix::zeros(6, 6);
    let mut has_noise = true;
    for k in 0..3 {
        let (hi, lo) = (&poses[faces[2 * k]], &poses[faces[2 * k + 1]]);
        let (v_hi, v_lo) = (hi.var_of_mean()[k], lo.var_of_mean()[k]);
        has_noise &= v_hi > 0.0 || v_lo > 0.0;
        let d = hi.mean[k] - lo.mean[k];
        let ds = 2.0 * reference / (d * d);
        cov[(k, k)] = ds * ds * (v_hi + v_lo);
        cov[(k + 3, k + 3)] = 0.25 * (v_hi + v_lo);
        let cross = 0.5 * ds * (v_lo - v_hi);
        cov[(k, k + 3)] = cross;
        cov[(k + 3, k)] = cross;
    }
    let (covariance, std) = if has_noise {
        let std = CalibrationStd {
            a: Mat3::from_diagonal(
                &Vec3::new(cov[(0, 0)], cov[(1, 1)], cov[(2, 2)]).map(f64::sqrt),
            ),
            b: Vec3::new(cov[(3, 3)], cov[(4, 4)], cov[(5, 5)]).map(f64::sqrt),
        };
        (Some(cov), Some(std))
    } else {
        (None, None)
    };

    Ok(Fit {
        method: Method::MinMax,
        cal,
        rms: rms(&residuals),
        residuals,
        loo_rms,
        covariance,
        param_names: ["A11", "A22", "A33", "b1", "b2", "b3"]
            .map(String::from)
            .to_vec(),
        std,
        condition_number: 1.0,
        iterations: 0,
        termination: None,
        coverage_factor: crate::fit::uncertainty::Z_95,
        reference,
    })
}

/// The min/max calibration alone (no residuals or statistics).
pub fn minmax_calibration(poses: &[Pose], reference: f64) -> Result<Calibration, FitError> {
    check_reference(reference)?;
    check_finite_poses(poses)?;
    let faces = find_faces(poses)?;
    calibration_from_faces(poses, &faces, reference)
}

/// Per-axis bias and scale from the poses chosen for the six faces.
fn calibration_from_faces(
    poses: &[Pose],
    faces: &[usize; 6],
    reference: f64,
) -> Result<Calibration, FitError> {
    let mut scale = Vec3::zeros();
    let mut b = Vec3::zeros();
    for k in 0..3 {
        let hi = poses[faces[2 * k]].mean[k];
        let lo = poses[faces[2 * k + 1]].mean[k];
        let half_span = 0.5 * (hi - lo);
        if half_span.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            return Err(FitError::Underdetermined(format!(
                "axis {} reads no higher with its face up than down; check the pose labels",
                ["X", "Y", "Z"][k]
            )));
        }
        b[k] = 0.5 * (hi + lo);
        scale[k] = reference / half_span;
    }
    Ok(Calibration {
        a: Mat3::from_diagonal(&scale),
        b,
    })
}

/// Best and runner-up pose per face seen from one centre, with [`find_faces`]' tie-breaking
/// (the earlier pose wins a tie).
struct FaceRanking {
    centre: Vec3,
    best: [Option<(usize, f64)>; 6],
    second: [Option<(usize, f64)>; 6],
}

impl FaceRanking {
    fn new(means: &[Vec3], centre: Vec3) -> Self {
        let mut best: [Option<(usize, f64)>; 6] = [None; 6];
        let mut second: [Option<(usize, f64)>; 6] = [None; 6];
        for (i, m) in means.iter().enumerate() {
            let d = m - centre;
            let Some(face) = face_of(&d, FACE_TOLERANCE_DEG) else {
                continue;
            };
            let alignment = d[face / 2].abs() / d.norm();
            if best[face].is_none_or(|(_, a)| alignment > a) {
                second[face] = best[face];
                best[face] = Some((i, alignment));
            } else if second[face].is_none_or(|(_, a)| alignment > a) {
                second[face] = Some((i, alignment));
            }
        }
        Self {
            centre,
            best,
            second,
        }
    }

    /// The face poses when pose `removed` is left out, or `None` when a face has no pose then.
    fn faces_without(&self, removed: usize) -> Option<[usize; 6]> {
        let mut faces = [0; 6];
        for (f, slot) in faces.iter_mut().enumerate() {
            let pick = match self.best[f] {
                Some((i, _)) if i == removed => self.second[f],
                other => other,
            };
            *slot = pick?.0;
        }
        Some(faces)
    }
}

/// Per axis, the median of the pose means with one pose left out (as `median_centre` of the rest).
struct MediansWithoutOne {
    sorted: [Vec<f64>; 3],
    rank: [Vec<usize>; 3],
}

impl MediansWithoutOne {
    fn new(means: &[Vec3]) -> Self {
        let per_axis = |axis: usize| {
            let mut order: Vec<usize> = (0..means.len()).collect();
            order.sort_by(|&a, &b| means[a][axis].total_cmp(&means[b][axis]));
            let mut rank = vec![0; means.len()];
            for (r, &i) in order.iter().enumerate() {
                rank[i] = r;
            }
            (order.iter().map(|&i| means[i][axis]).collect(), rank)
        };
        let [(s0, r0), (s1, r1), (s2, r2)] = [0, 1, 2].map(per_axis);
        Self {
            sorted: [s0, s1, s2],
            rank: [r0, r1, r2],
        }
    }

    fn centre_without(&self, removed: usize) -> Vec3 {
        Vec3::from_fn(|axis, _| {
            let (sorted, rho) = (&self.sorted[axis], self.rank[axis][removed]);
            let at = |k: usize| sorted[if k < rho { k } else { k + 1 }];
            match sorted.len() - 1 {
                0 => 0.0,
                m if m % 2 == 1 => at(m / 2),
                m => 0.5 * (at(m / 2 - 1) + at(m / 2)),
            }
        })
    }
}

/// Leave-one-pose-out RMS of the min/max fit, equal to refitting without each pose (see the
/// module comment).
fn leave_one_out_minmax(poses: &[Pose], reference: f64) -> Option<f64> {
    held_out_rms(poses, reference, calibrations_without(poses, reference))
}

/// The min/max calibration of `poses` without pose `i`, for any `i`: equal to
/// [`minmax_calibration`] of the other poses (see the module comment), at the cost of one fit
/// for all of them.
pub fn calibrations_without(
    poses: &[Pose],
    reference: f64,
) -> impl FnMut(usize) -> Result<Calibration, FitError> + '_ {
    let means: Vec<Vec3> = poses.iter().map(|p| p.mean).collect();
    let medians = MediansWithoutOne::new(&means);
    let mut rankings: Vec<FaceRanking> = Vec::new();
    move |i| {
        check_reference(reference)?;
        if i >= poses.len() {
            return Err(FitError::Underdetermined(format!(
                "pose {i} does not exist ({} poses)",
                poses.len()
            )));
        }
        let centre = medians.centre_without(i);
        let k = match rankings.iter().position(|r| r.centre == centre) {
            Some(k) => k,
            None => {
                rankings.push(FaceRanking::new(&means, centre));
                rankings.len() - 1
            }
        };
        let faces = rankings[k]
            .faces_without(i)
            .ok_or_else(|| FitError::Underdetermined("a face has no pose left".into()))?;
        calibration_from_faces(poses, &faces, reference)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::loo::leave_one_out_rms;

    /// Pose means on a scaled, offset sphere: `n` directions, several near each face, with
    /// deterministic pseudo-noise; repeated directions make ties in the face ranking.
    fn poses(n: usize) -> Vec<Pose> {
        (0..n)
            .map(|i| {
                let t = i as f64;
                let z = 1.0 - 2.0 * (t + 0.5) / n as f64;
                let phi = t * 2.399_963_229_728_653;
                let r = (1.0 - z * z).sqrt();
                let u = Vec3::new(r * phi.cos(), r * phi.sin(), z);
                let face = Vec3::from_fn(|k, _| if k == i % 3 { 1.0 } else { 0.0 })
                    * if i % 2 == 0 { 1.0 } else { -1.0 };
                let dir = if i % 4 == 0 {
                    face
                } else {
                    (u + face).normalize()
                };
                Pose {
                    mean: Vec3::new(1.02 * dir.x + 0.05, 0.97 * dir.y - 0.03, 1.01 * dir.z) * 9.81
                        + Vec3::repeat(1e-3 * (3.7 * t).sin()),
                    var: Vec3::repeat(1e-4),
                    n: 100,
                    label: None,
                }
            })
            .collect()
    }

    #[test]
    fn leave_one_out_without_refits_equals_refitting_without_each_pose() {
        for n in [6, 7, 12, 13, 40, 41] {
            let poses = poses(n);
            let fast = leave_one_out_minmax(&poses, 9.81);
            let brute = leave_one_out_rms(&poses, 9.81, |rest| minmax_calibration(rest, 9.81));
            // Same face poses and the same arithmetic per fold: equal to the last bit.
            assert_eq!(fast, brute, "{n} poses");
        }
    }
}
