//! Clustering of the holds' gravity directions by angle, on plain accelerometer means.

use crate::fit::Vec3;

/// Holds whose means spread less than this many per-sample standard deviations show one
/// orientation: hand sway and noise move a mean by a few, a turn by tens to hundreds.
const ONE_ORIENTATION_SIGMAS: f64 = 6.0;

/// Centre used to turn accelerometer means into directions: zero for data in physical units
/// (offsets are small next to g), the per-axis midrange of the hold means for raw counts
/// (whose offset can be as large as the signal, e.g. unsigned 16-bit data). `counts` is the
/// holds' per-sample standard deviation when the data are raw counts. Holds that spread less
/// than [`ONE_ORIENTATION_SIGMAS`] of it show one orientation, and their midrange is the holds
/// themselves (a single hold's direction would be the zero vector): zero is the centre then too.
fn direction_centre(means: &[Option<Vec3>], counts: Option<f64>) -> Vec3 {
    let present: Vec<&Vec3> = means.iter().flatten().collect();
    let Some(sigma) = counts.filter(|_| !present.is_empty()) else {
        return Vec3::zeros();
    };
    let lo = present
        .iter()
        .fold(Vec3::repeat(f64::INFINITY), |a, m| a.inf(m));
    let hi = present
        .iter()
        .fold(Vec3::repeat(f64::NEG_INFINITY), |a, m| a.sup(m));
    if (hi - lo).norm() <= ONE_ORIENTATION_SIGMAS * sigma {
        return Vec3::zeros();
    }
    (lo + hi) / 2.0
}

/// Greedy clustering of hold directions: each hold's accelerometer mean (about the centre of
/// [`direction_centre`]; `counts`, the holds' per-sample standard deviation, when the data are
/// raw counts) joins the first direction
/// within `angle_deg`, whose representative is the normalised sum of its members, or starts a
/// new one. Returns each hold's direction index (`None` without a usable mean) and the
/// directions as unit vectors.
pub fn cluster_directions(
    means: &[Option<Vec3>],
    counts: Option<f64>,
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_hold_of_raw_counts_has_one_direction_not_none() {
        let means = [Some(Vec3::new(-438.0, 142.0, 16_400.0))];
        let (members, directions) = cluster_directions(&means, Some(3.0), 10.0);
        assert_eq!(members, vec![Some(0)]);
        assert_eq!(directions.len(), 1);
        assert!(directions[0].z > 0.99, "{directions:?}");
    }

    #[test]
    fn unsigned_counts_over_several_faces_are_centred_on_their_midrange() {
        // Unsigned 16-bit data: offset 32768 per axis, 16384 counts per g; the six faces.
        let offset = Vec3::repeat(32_768.0);
        let faces = crate::fit::validate::face_directions();
        let means: Vec<Option<Vec3>> = faces.iter().map(|f| Some(offset + f * 16_384.0)).collect();
        let (_, directions) = cluster_directions(&means, Some(3.0), 10.0);
        assert_eq!(directions.len(), 6);
        // Three holds of one face, differing by noise: one orientation, not noise directions.
        let same = [
            Some(offset + Vec3::new(1.0, -2.0, 16_384.0)),
            Some(offset + Vec3::new(-3.0, 1.0, 16_385.0)),
            Some(offset + Vec3::new(0.0, 2.0, 16_382.0)),
        ];
        let (_, directions) = cluster_directions(&same, Some(3.0), 10.0);
        assert_eq!(directions.len(), 1);
    }
}
