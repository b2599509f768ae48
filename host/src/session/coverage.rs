//! Sphere coverage of the magnetometer phase: which directions of the field, seen in the sensor
//! frame, have been sampled.
//!
//! The sphere is split into 26 regions around the directions `(i, j, k)/|(i, j, k)|`,
//! `i, j, k ∈ {−1, 0, 1}` (six faces, twelve edges, eight corners of a cube; each region spans
//! roughly ±35°). A sample's direction is taken from the running centre of the raw readings
//! (hard iron), estimated by the linear sphere fit `|m|² = 2·c·m + k` (least squares in `c`, `k`);
//! soft iron and scale errors of a few percent move a direction by a few degrees only, which
//! does not matter at this resolution.

use nalgebra::{Matrix4, Vector4};

use crate::fit::Vec3;

/// Number of regions.
pub const REGIONS: usize = 26;

/// Unit direction of each region's centre.
pub fn region_directions() -> Vec<Vec3> {
    let mut out = Vec::with_capacity(REGIONS);
    for i in -1i32..=1 {
        for j in -1i32..=1 {
            for k in -1i32..=1 {
                if (i, j, k) != (0, 0, 0) {
                    out.push(Vec3::new(f64::from(i), f64::from(j), f64::from(k)).normalize());
                }
            }
        }
    }
    out
}

/// Name of a region, e.g. `+X`, `+X−Y`, `−X+Y+Z`.
pub fn region_name(direction: &Vec3) -> String {
    let mut name = String::new();
    for (axis, v) in ['X', 'Y', 'Z'].iter().zip(direction.iter()) {
        if v.abs() > 0.3 {
            name.push(if *v > 0.0 { '+' } else { '-' });
            name.push(*axis);
        }
    }
    name
}

/// Centre of a sphere through `points` by linear least squares; `None` when the points do not
/// determine it (fewer than four, or all near one plane).
pub fn sphere_centre(points: &[Vec3]) -> Option<Vec3> {
    if points.len() < 4 {
        return None;
    }
    // Centred for conditioning: |p|² = 2c·p + k with p relative to the mean.
    let mean = points.iter().sum::<Vec3>() / points.len() as f64;
    let mut normal = Matrix4::<f64>::zeros();
    let mut rhs = Vector4::<f64>::zeros();
    for p in points {
        let q = p - mean;
        let row = Vector4::new(2.0 * q.x, 2.0 * q.y, 2.0 * q.z, 1.0);
        normal += row * row.transpose();
        rhs += row * q.norm_squared();
    }
    let solution = normal.lu().solve(&rhs)?;
    let centre = mean + Vec3::new(solution[0], solution[1], solution[2]);
    centre.iter().all(|v| v.is_finite()).then_some(centre)
}

/// Sample counts per region.
#[derive(Debug, Clone, PartialEq)]
pub struct Coverage {
    /// Samples whose direction falls in each region (order of [`region_directions`]).
    pub counts: Vec<usize>,
    /// The centre the directions were taken from.
    pub centre: Vec3,
}

impl Coverage {
    /// Count `points` by direction from `centre`.
    pub fn of(points: &[Vec3], centre: &Vec3) -> Self {
        let regions = region_directions();
        let mut counts = vec![0usize; REGIONS];
        for p in points {
            let Some(d) = (p - centre).try_normalize(0.0) else {
                continue;
            };
            let best = regions
                .iter()
                .enumerate()
                .max_by(|a, b| a.1.dot(&d).total_cmp(&b.1.dot(&d)))
                .map(|(i, _)| i);
            if let Some(count) = best.and_then(|i| counts.get_mut(i)) {
                *count += 1;
            }
        }
        Self {
            counts,
            centre: *centre,
        }
    }

    /// Regions with at least `min_samples` samples.
    pub fn covered(&self, min_samples: usize) -> usize {
        self.counts.iter().filter(|&&c| c >= min_samples).count()
    }

    /// Names of the regions with fewer than `min_samples` samples.
    pub fn empty_regions(&self, min_samples: usize) -> Vec<String> {
        region_directions()
            .iter()
            .zip(&self.counts)
            .filter(|(_, &c)| c < min_samples)
            .map(|(d, _)| region_name(d))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points of a sphere of `radius` around `centre` along a Fibonacci spiral (even cover).
    fn spiral(count: usize, centre: Vec3, radius: f64) -> Vec<Vec3> {
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        (0..count)
            .map(|i| {
                let z = 1.0 - 2.0 * (i as f64 + 0.5) / count as f64;
                let r = (1.0 - z * z).sqrt();
                let phi = golden * i as f64;
                centre + radius * Vec3::new(r * phi.cos(), r * phi.sin(), z)
            })
            .collect()
    }

    #[test]
    fn the_sphere_fit_finds_an_offset_centre_exactly_without_noise() {
        let centre = Vec3::new(30.0, -45.0, 12.0);
        let found = sphere_centre(&spiral(200, centre, 48.0)).expect("a centre");
        // Exact data: only rounding of sums of ~10⁴-sized squares remains.
        assert!((found - centre).norm() < 1e-9, "{found}");
    }

    #[test]
    fn an_even_cover_reaches_every_region_and_a_hemisphere_about_half() {
        let centre = Vec3::new(30.0, -45.0, 12.0);
        let points = spiral(2000, centre, 48.0);
        let all = Coverage::of(&points, &centre);
        assert_eq!(all.covered(10), REGIONS);
        assert_eq!(all.counts.iter().sum::<usize>(), 2000);
        let upper: Vec<Vec3> = points.into_iter().filter(|p| p.z > centre.z).collect();
        let half = Coverage::of(&upper, &centre);
        // 9 regions lie above the equator, 8 on it (shared with the lower half), 9 below.
        assert!((9..=17).contains(&half.covered(10)), "{}", half.covered(10));
        assert!(half.empty_regions(10).contains(&"-Z".to_string()));
    }

    #[test]
    fn too_few_or_coplanar_points_give_no_centre() {
        assert!(sphere_centre(&[Vec3::x(), Vec3::y(), Vec3::z()]).is_none());
        let flat: Vec<Vec3> = (0..50)
            .map(|i| {
                let a = i as f64 * 0.3;
                Vec3::new(a.cos(), a.sin(), 0.0)
            })
            .collect();
        assert!(sphere_centre(&flat).is_none());
    }
}
