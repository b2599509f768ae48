//! Clustering of the holds' gravity directions by angle, on plain accelerometer means.

use crate::fit::Vec3;

/// Centre used to turn accelerometer means into directions: zero for data in physical units
/// (offsets are small next to g), the per-axis midrange of the hold means for raw counts
/// (whose offset can be as large as the signal, e.g. unsigned 16-bit data).
fn direction_centre(means: &[Option<Vec3>], counts: bool) -> Vec3 {
    let present: Vec<&Vec3> = means.iter().flatten().collect();
    if !counts || present.is_empty() {
        return Vec3::zeros();
    }
    let lo = present
        .iter()
        .fold(Vec3::repeat(f64::INFINITY), |a, m| a.inf(m));
    let hi = present
        .iter()
        .fold(Vec3::repeat(f64::NEG_INFINITY), |a, m| a.sup(m));
    (lo + hi) / 2.0
}

/// Greedy clustering of hold directions: each hold's accelerometer mean (about the centre of
/// [`direction_centre`]; `counts` when the data are raw counts) joins the first direction
/// within `angle_deg`, whose representative is the normalised sum of its members, or starts a
/// new one. Returns each hold's direction index (`None` without a usable mean) and the
/// directions as unit vectors.
pub fn cluster_directions(
    means: &[Option<Vec3>],
    counts: bool,
    angle_deg: f64,
) -> (Vec<Option<usize>>, Vec<Vec3>) {
    let centre = direction_centre(means, counts);
    let cos_limit = angle_deg.to_radians().cos();
    let mut sums: Vec<Vec3> = Vec::new();
    let mut members = Vec::with_capacity(means.len());
    for mean in means {
        let Some(u) = mean
            .map(|m| m - centre)
            .filter(|d| d.norm() > 0.0 && d.norm().is_finite())
            .map(|d| d.normalize())
        else {
            members.push(None);
            continue;
        };
        let index = match sums.iter().position(|s| s.normalize().dot(&u) >= cos_limit) {
            Some(i) => {
                sums[i] += u;
                i
            }
            None => {
                sums.push(u);
                sums.len() - 1
            }
        };
        members.push(Some(index));
    }
    (members, sums.into_iter().map(|s| s.normalize()).collect())
}
