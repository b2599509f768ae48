//! Input checks shared by the fits: finite values, a usable reference magnitude, and whether a
//! pose set or sample cloud can determine the parameters at all (faces present, directions not
//! all near one plane, enough distinct orientations). Each refusal is a sentence naming what to add.
//! Whether a cloud covers enough orientations for an ellipsoid is the coverage rule of
//! [`super::coverage`].

use super::{FitError, Mat3, Pose, Vec3};
use crate::stats::descriptive::median;

/// Names of the six faces, in the order `+X, −X, +Y, −Y, +Z, −Z`.
pub const FACE_NAMES: [&str; 6] = ["+X", "−X", "+Y", "−Y", "+Z", "−Z"];

/// The unit direction of each face's axis, in [`FACE_NAMES`] order (the index [`face_of`]
/// returns).
pub fn face_directions() -> [Vec3; 6] {
    [
        Vec3::x(),
        -Vec3::x(),
        Vec3::y(),
        -Vec3::y(),
        Vec3::z(),
        -Vec3::z(),
    ]
}

/// A pose counts as a face when its direction is within this angle of the face's axis.
pub const FACE_TOLERANCE_DEG: f64 = 30.0;

/// Default minimum RMS out-of-plane angle of a pose set before it is refused as near-planar.
pub const MIN_SPREAD_DEG: f64 = 20.0;

/// Refuse NaN or infinite pose means or variances.
pub fn check_finite_poses(poses: &[Pose]) -> Result<(), FitError> {
    for (i, p) in poses.iter().enumerate() {
        if !p.mean.iter().all(|v| v.is_finite()) {
            return Err(FitError::NonFinite(format!(
                "mean of pose {}",
                pose_name(p, i)
            )));
        }
        if !p.var.iter().all(|v| v.is_finite() && *v >= 0.0) {
            return Err(FitError::NonFinite(format!(
                "variance of pose {} (must be finite and non-negative)",
                pose_name(p, i)
            )));
        }
    }
    Ok(())
}

/// Refuse NaN or infinite samples.
pub fn check_finite_points(points: &[Vec3]) -> Result<(), FitError> {
    match points.iter().position(|p| !p.iter().all(|v| v.is_finite())) {
        Some(i) => Err(FitError::NonFinite(format!("sample {i}"))),
        None => Ok(()),
    }
}

/// Require a positive finite reference magnitude.
pub fn check_reference(reference: f64) -> Result<(), FitError> {
    if !reference.is_finite() {
        return Err(FitError::NonFinite("reference magnitude".into()));
    }
    if reference <= 0.0 {
        return Err(FitError::Underdetermined(format!(
            "a reference magnitude of {reference} cannot scale the fit; pass the local gravity, \
             the field strength or 1 (a positive number)"
        )));
    }
    Ok(())
}

/// Rough centre of a set of readings: the per-axis median. For face and tilt sets most poses
/// read near zero on any one axis, so the median sits near the offset even when a face is
/// missing (where the min/max midpoint would be pulled half a reference towards the present face).
pub fn median_centre(points: &[Vec3]) -> Vec3 {
    Vec3::from_fn(|axis, _| median(&mut points.iter().map(|p| p[axis]).collect::<Vec<_>>()))
}

/// Which face (index into [`FACE_NAMES`]) a direction points along, if within `tolerance_deg`.
pub fn face_of(direction: &Vec3, tolerance_deg: f64) -> Option<usize> {
    let norm = direction.norm();
    if norm.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let axis = direction.iamax();
    let component = direction[axis];
    (component.abs() / norm >= tolerance_deg.to_radians().cos())
        .then_some(2 * axis + usize::from(component < 0.0))
}

/// For each of the six faces, the index of the pose best aligned with it (direction taken from
/// the median centre). Refuses with "no pose with −Z up" (etc.) when a face is missing.
pub fn find_faces(poses: &[Pose]) -> Result<[usize; 6], FitError> {
    let best = best_face_poses(poses);
    let missing: Vec<&str> = (0..6)
        .filter(|&f| best[f].is_none())
        .map(|f| FACE_NAMES[f])
        .collect();
    if !missing.is_empty() {
        let list = missing
            .iter()
            .map(|f| format!("{f} up"))
            .collect::<Vec<_>>()
            .join(", ");
        return Err(FitError::Underdetermined(format!(
            "no pose with {list} (within {FACE_TOLERANCE_DEG}°); the six-face method needs every \
             face of the board up once"
        )));
    }
    let mut out = [0usize; 6];
    for (slot, b) in out.iter_mut().zip(best.iter()) {
        *slot = b.unwrap_or_default();
    }
    Ok(out)
}

/// The faces (names as in [`FACE_NAMES`]) no pose points along, within [`FACE_TOLERANCE_DEG`]
/// of the median centre: empty when [`find_faces`] succeeds.
pub fn missing_faces(poses: &[Pose]) -> Vec<&'static str> {
    let best = best_face_poses(poses);
    (0..6)
        .filter(|&f| best[f].is_none())
        .map(|f| FACE_NAMES[f])
        .collect()
}

/// Per face, the best-aligned pose seen from the median centre, if any.
fn best_face_poses(poses: &[Pose]) -> [Option<usize>; 6] {
    let means: Vec<Vec3> = poses.iter().map(|p| p.mean).collect();
    let centre = median_centre(&means);
    let mut best: [Option<(usize, f64)>; 6] = [None; 6];
    for (i, m) in means.iter().enumerate() {
        let d = m - centre;
        if let Some(face) = face_of(&d, FACE_TOLERANCE_DEG) {
            let alignment = d[face / 2].abs() / d.norm();
            if best[face].is_none_or(|(_, a)| alignment > a) {
                best[face] = Some((i, alignment));
            }
        }
    }
    best.map(|b| b.map(|(i, _)| i))
}

/// Unit directions of `points` as seen from their mean (zero-length ones are skipped).
pub fn directions_from_mean(points: &[Vec3]) -> Vec<Vec3> {
    if points.is_empty() {
        return Vec::new();
    }
    let mean = points.iter().sum::<Vec3>() / points.len() as f64;
    points
        .iter()
        .filter_map(|p| (p - mean).try_normalize(1e-300))
        .collect()
}

/// Refuse directions that all lie near one plane through the origin: the smallest singular value
/// of the `N×3` matrix of unit directions, divided by `√N`, is the RMS sine of the angle out of
/// the worst plane. Below `sin(min_angle_deg)` the fit cannot separate the axis normal to it.
pub fn check_spread(directions: &[Vec3], min_angle_deg: f64) -> Result<(), FitError> {
    check_spread_of(directions.iter().copied(), min_angle_deg)
}

/// [`check_spread`] of directions taken one at a time: one pass, so directions computed on
/// the way (one per magnetometer sample) need not be stored.
pub fn check_spread_of(
    directions: impl IntoIterator<Item = Vec3>,
    min_angle_deg: f64,
) -> Result<(), FitError> {
    let (count, scatter) = scatter(directions);
    if count < 3 {
        return Err(FitError::Underdetermined(format!(
            "only {count} distinct directions; at least three not in one plane are needed"
        )));
    }
    let (rms_sine, normal) = out_of_plane(count, scatter);
    if rms_sine < min_angle_deg.to_radians().sin() {
        let axis = ["X", "Y", "Z"][normal.iamax()];
        return Err(FitError::Underdetermined(format!(
            "all poses lie within {min_angle_deg}° of a plane (RMS out-of-plane angle {:.1}°); \
             add orientations with the {axis} axis pointing up or down",
            rms_sine.clamp(-1.0, 1.0).asin().to_degrees()
        )));
    }
    Ok(())
}

/// The number of directions and their 3×3 scatter `Σ dᵢdᵢᵀ`, in one pass.
fn scatter(directions: impl IntoIterator<Item = Vec3>) -> (usize, Mat3) {
    directions
        .into_iter()
        .fold((0, Mat3::zeros()), |(n, sum), d| {
            (n + 1, sum + d * d.transpose())
        })
}

/// The RMS sine of the angles of `count` directions out of their best plane through the
/// origin, and that plane's normal: the smallest singular value of the N×3 matrix of directions
/// over `√N`, and its right singular vector. Taken from their 3×3 `scatter` (whose eigenvalues
/// are the squared singular values): one pass, where an SVD of the N×3 matrix copies and sweeps
/// a million rows several times. Squaring costs precision only for planes within ~10⁻⁸ rad, far
/// below any threshold this is compared with.
fn out_of_plane(count: usize, scatter: Mat3) -> (f64, Vec3) {
    let eigen = scatter.symmetric_eigen();
    let k = eigen.eigenvalues.imin();
    let rms_sine = (eigen.eigenvalues[k].max(0.0) / count.max(1) as f64).sqrt();
    (rms_sine, eigen.eigenvectors.column(k).into_owned())
}

/// Number of distinct orientations: directions further apart than `tolerance_deg` from every
/// earlier representative.
pub fn count_distinct(directions: &[Vec3], tolerance_deg: f64) -> usize {
    let cos_tol = tolerance_deg.to_radians().cos();
    let mut reps: Vec<Vec3> = Vec::new();
    for d in directions {
        if !reps.iter().any(|r| r.dot(d) >= cos_tol) {
            reps.push(*d);
        }
    }
    reps.len()
}

/// Orientations closer than this (degrees) count as one: for a norm model they give the same
/// equation, however often repeated.
pub const DISTINCT_DEG: f64 = 5.0;

/// Refuse when fewer than `needed` distinct orientations ([`DISTINCT_DEG`] apart) are present.
pub fn check_distinct(directions: &[Vec3], needed: usize) -> Result<(), FitError> {
    let distinct = count_distinct(directions, DISTINCT_DEG);
    if distinct < needed {
        return Err(FitError::Underdetermined(format!(
            "only {distinct} distinct orientations; at least {needed} are needed"
        )));
    }
    Ok(())
}

fn pose_name(p: &Pose, index: usize) -> String {
    match p.label {
        Some(l) => format!("{index} (label {l})"),
        None => index.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::{rng, sphere_directions};
    use nalgebra::DMatrix;

    /// The out-of-plane measure as the smallest singular value of the N×3 matrix.
    fn out_of_plane_by_svd(directions: &[Vec3]) -> f64 {
        let m = DMatrix::from_fn(directions.len(), 3, |i, j| directions[i][j]);
        let smallest = m.singular_values().min();
        smallest / (directions.len() as f64).sqrt()
    }

    #[test]
    fn out_of_plane_from_the_scatter_equals_the_singular_value_of_the_directions() {
        // Directions squeezed towards the x–y plane by factors from 1 (the whole sphere) to
        // 10⁻⁴ (all within ≈ 0.01° of the plane), tilted so the plane is not a coordinate one.
        let tilt = nalgebra::Rotation3::new(Vec3::new(0.3, -0.2, 0.5));
        let mut r = rng(11);
        for squeeze in [1.0, 0.3, 0.1, 0.03, 1e-2, 1e-3, 1e-4] {
            let directions: Vec<Vec3> = sphere_directions(&mut r, 5000)
                .into_iter()
                .map(|d| tilt * Vec3::new(d.x, d.y, d.z * squeeze).normalize())
                .collect();
            let (count, sum) = scatter(directions.iter().copied());
            let (rms_sine, normal) = out_of_plane(count, sum);
            let by_svd = out_of_plane_by_svd(&directions);
            // Squaring in the scatter loses about ε/(rms sine)² relative: 10⁻⁸ at 10⁻⁴.
            assert!(
                (rms_sine - by_svd).abs() <= 1e-7 * by_svd,
                "squeeze {squeeze}: {rms_sine:.10e} against {by_svd:.10e}"
            );
            if squeeze < 0.5 {
                let expected = tilt * Vec3::z();
                assert!(
                    normal.dot(&expected).abs() > 0.999,
                    "squeeze {squeeze}: normal {normal:?}"
                );
            }
        }
    }
}
