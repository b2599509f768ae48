//! Which fitting method applies to which sensor, and how its input is formed from a
//! recording: accelerometer methods take still-interval poses (point methods take the pose
//! means), magnetometer methods take samples over many orientations, the gyroscope takes the
//! still poses. The default accelerometer method is not one of these but the evidence-based
//! choice of [`super::chain`].

use crate::fit::{self, Fit, FitError, Method, Pose, Vec3};
use crate::stats::distributions::chi2_quantile_per_dof;
use crate::stats::robust::stream_noise;

/// Methods offered for the accelerometer (`--method`; the default is [`super::chain`]).
pub const ACCEL_METHODS: [Method; 8] = [
    Method::Lm,
    Method::SixPosition,
    Method::Chen,
    Method::MinMax,
    Method::AxisAligned,
    Method::Li,
    Method::Frosio,
    Method::Merayo,
];

/// Methods offered for the magnetometer, the default first.
pub const MAG_METHODS: [Method; 6] = [
    Method::Lm,
    Method::Li,
    Method::Frosio,
    Method::Merayo,
    Method::AxisAligned,
    Method::MinMax,
];

/// Methods offered for the gyroscope.
/// `gyro-scale` needs the whole recording (motions between holds), see [`super::gyro`].
pub const GYRO_METHODS: [Method; 2] = [Method::GyroBias, Method::GyroScale];

/// Every method, for parsing names.
pub const ALL_METHODS: [Method; 10] = [
    Method::GyroScale,
    Method::GyroBias,
    Method::MinMax,
    Method::AxisAligned,
    Method::SixPosition,
    Method::Chen,
    Method::Li,
    Method::Lm,
    Method::Frosio,
    Method::Merayo,
];

/// The methods offered for `sensor`, the default first for the gyroscope and magnetometer.
pub fn offered(sensor: crate::recording::Sensor) -> &'static [Method] {
    use crate::recording::Sensor;
    match sensor {
        Sensor::Accel => &ACCEL_METHODS,
        Sensor::Gyro => &GYRO_METHODS,
        Sensor::Mag => &MAG_METHODS,
    }
}

/// The method named `name` if it applies to `sensor`, else a sentence listing the choices.
pub fn method_for_sensor(name: &str, sensor: crate::recording::Sensor) -> Result<Method, String> {
    let Some(method) = method_by_name(name) else {
        let all: Vec<&str> = ALL_METHODS.iter().map(|m| m.name()).collect();
        return Err(format!(
            "unknown method `{name}`; choose one of {}",
            all.join(", ")
        ));
    };
    let offered = offered(sensor);
    if !offered.contains(&method) {
        let names: Vec<&str> = offered.iter().map(|m| m.name()).collect();
        return Err(format!(
            "method `{name}` does not apply to the {sensor}; for the {sensor} choose one of {}",
            names.join(", ")
        ));
    }
    Ok(method)
}

/// Look a method up by its command-line name.
pub fn method_by_name(name: &str) -> Option<Method> {
    ALL_METHODS.into_iter().find(|m| m.name() == name)
}

/// Frosio (and Merayo, by its `true` flag) start at the data mean: raw counts can have offsets
/// as large as the signal, where a start at zero offset does not converge (seed 000, Table 2
/// uses the same preconditioning for all methods).
const FROSIO: fit::frosio::FrosioOptions = fit::frosio::FrosioOptions {
    subtract_mean: true,
    max_iterations: 50,
    step_tolerance: 1e-10,
};

fn means(poses: &[Pose]) -> Vec<Vec3> {
    poses.iter().map(|p| p.mean).collect()
}

/// Single samples as poses of one sample each, for pose-based methods run on points.
fn as_poses(points: &[Vec3]) -> Vec<Pose> {
    points.iter().map(|p| Pose::single(*p)).collect()
}

fn not_for(method: Method, sensor: &str) -> FitError {
    FitError::Underdetermined(format!(
        "method `{}` is not offered for the {sensor}",
        method.name()
    ))
}

/// Fit the accelerometer from still poses to the gravity magnitude `reference`.
pub fn fit_accel(method: Method, poses: &[Pose], reference: f64) -> Result<Fit, FitError> {
    match method {
        Method::Lm => fit::norm_lm::fit_accel_lm(poses, reference),
        Method::SixPosition => fit::six_position::fit_six_position(poses, None, reference),
        Method::Chen => fit::chen::fit_chen(poses, reference),
        Method::MinMax => fit::minmax::fit_minmax(poses, reference),
        Method::AxisAligned => fit::axis_aligned::fit_axis_aligned_poses(poses, reference),
        Method::Li => {
            let means = means(poses);
            fit::li::fit_li(
                &means,
                reference,
                fit::li::LiOptions {
                    subtract_mean: true,
                },
            )
            .map(|mut fit| {
                // Exact leave-one-pose-out by downdating the moment sums (`fit::li_loo`).
                fit.loo_rms = fit::li_loo::li_leave_one_out_rms(&means, reference);
                fit
            })
        }
        Method::Frosio => fit::frosio::fit_frosio(&means(poses), reference, &FROSIO),
        Method::Merayo => fit::merayo::fit_merayo(&means(poses), reference, true),
        Method::GyroBias | Method::GyroScale | Method::MinMaxAxisAlignedMean => {
            Err(not_for(method, "accelerometer"))
        }
    }
}

/// The held-out error of an accelerometer model the user chose whose fit gives none (every
/// pose's refit must succeed for it): each pose predicted by `method` refit on the others, over
/// the poses it can be refit without, as the default chain scores its candidates. Returns the
/// RMS and the poses it is over; `None` with fewer than two such poses.
pub fn leave_one_out_where_refittable(
    method: Method,
    poses: &[Pose],
    reference: f64,
) -> Option<(f64, Vec<usize>)> {
    let errors = fit::loo::held_out_errors_threaded(poses, reference, |i| {
        fit_accel(method, &fit::loo::without(poses, i), reference).map(|f| f.cal)
    })?;
    let (kept, values): (Vec<usize>, Vec<f64>) = errors
        .iter()
        .enumerate()
        .filter_map(|(i, e)| e.map(|e| (i, e)))
        .unzip();
    (values.len() >= 2).then(|| (fit::linalg::rms(&values), kept))
}

/// Fit the magnetometer from samples over many orientations to the field magnitude `reference`.
pub fn fit_mag(method: Method, points: &[Vec3], reference: f64) -> Result<Fit, FitError> {
    match method {
        Method::Lm => fit::norm_lm::fit_mag_lm(points, reference),
        Method::Li => fit::li::fit_li(
            points,
            reference,
            fit::li::LiOptions {
                subtract_mean: true,
            },
        )
        .map(|mut fit| {
            fit.loo_rms = li_sample_loo_rms(points, reference);
            fit
        }),
        Method::Frosio => fit::frosio::fit_frosio(points, reference, &FROSIO),
        Method::Merayo => fit::merayo::fit_merayo(points, reference, true),
        Method::AxisAligned => fit::axis_aligned::fit_axis_aligned(points, reference),
        Method::MinMax => {
            let poses = as_poses(points);
            // The face search runs again only on a refusal, to word it for the field.
            let refused = match fit::minmax::fit_minmax(&poses, reference) {
                Err(FitError::Underdetermined(why)) => why,
                other => return other,
            };
            let missing = fit::validate::missing_faces(&poses);
            if !missing.is_empty() {
                return Err(FitError::Underdetermined(format!(
                    "no sample has the field along {} (within {}° of the axis, seen from the \
                     median centre); min/max needs the field along each axis both ways: turn \
                     the board through every direction, or use the default method, which fits \
                     the ellipsoid from any directions",
                    missing.join(", "),
                    fit::validate::FACE_TOLERANCE_DEG
                )));
            }
            Err(FitError::Underdetermined(refused))
        }
        Method::SixPosition
        | Method::Chen
        | Method::GyroBias
        | Method::GyroScale
        | Method::MinMaxAxisAlignedMean => Err(not_for(method, "magnetometer")),
    }
}

/// Most samples for which the magnetometer's Li fit gets its exact leave-one-out
/// (`fit::li_loo`, one 10×10 eigenproblem per sample: ≈ 60 µs each, so ≤ 55 ms here) rather
/// than the first-order one (`fit::li_loo_first_order`, one pass). The rule is `100·p` with
/// `p = 9` unknowns: above it the first order's error bound `(p/N)²` of the RMS is below 1e-4,
/// finer than the four digits the RMS is reported with.
pub const LI_EXACT_LOO_MAX_SAMPLES: usize = 900;

/// Leave-one-out RMS of Li's fit on magnetometer samples: exact up to
/// [`LI_EXACT_LOO_MAX_SAMPLES`], first order above.
fn li_sample_loo_rms(points: &[Vec3], reference: f64) -> Option<f64> {
    if points.len() <= LI_EXACT_LOO_MAX_SAMPLES {
        fit::li_loo::li_leave_one_out_rms(points, reference)
    } else {
        fit::li_loo_first_order::li_first_order_loo_rms(points, reference)
    }
}

/// Fit the gyroscope bias from still poses; `scale` converts the file's unit to rad/s.
pub fn fit_gyro(method: Method, poses: &[Pose], scale: f64) -> Result<Fit, FitError> {
    match method {
        Method::GyroBias => fit::gyro_bias::fit_gyro_bias(poses, scale),
        _ => Err(not_for(method, "gyroscope")),
    }
}

/// `max` points evenly spaced through `points` (all of them when `max` is 0 or larger).
pub fn thin(points: &[Vec3], max: usize) -> Vec<Vec3> {
    thin_indices(points.len(), max)
        .into_iter()
        .filter_map(|i| points.get(i).copied())
        .collect()
}

/// Tail probability at which a stream sample counts as having left the reading its run began
/// with ([`thin_redundant_indices`]): a board held still breaks its run about once per
/// thousand samples.
const REDUNDANT_RUN_BREAK: f64 = 1e-3;

/// The indices of at most `max` of the stream `points` (all when `max` is 0 or larger), thinned
/// where the samples are redundant and only as much as `max` needs.
///
/// The stream is cut into runs of consecutive samples that stay within the noise of the run's
/// first one (the board held still, or turning slower than the noise shows): a sample leaves
/// the run when `Σₖ((xₖ − x₀ₖ)/σₖ)²`, which for two noisy readings of one field is `2·χ²(3)`,
/// passes its `1 − `[`REDUNDANT_RUN_BREAK`] quantile (σ the stream's noise, [`stream_noise`]).
/// Every run then keeps at most `c` of its samples, evenly spaced within it, with `c` the
/// largest cap that keeps `max` or fewer in all: short runs (the turning) are kept whole and
/// only the long ones (pauses) give up samples. With more runs than `max`, one sample per run
/// is kept and those are evenly spaced. Evenly spacing the raw stream instead lets a long pause
/// crowd out the turning: minutes still in one position leave thousands of copies of one
/// direction and few of the others.
pub fn thin_redundant_indices(points: &[Vec3], max: usize) -> Vec<usize> {
    if max == 0 || points.len() <= max {
        return (0..points.len()).collect();
    }
    let Some(sigma) = stream_noise(points).filter(|s| s.iter().all(|v| *v > 0.0 && v.is_finite()))
    else {
        return thin_indices(points.len(), max);
    };
    let limit = 2.0 * 3.0 * chi2_quantile_per_dof(1.0 - REDUNDANT_RUN_BREAK, 3.0);
    // Runs as (start, length).
    let mut runs: Vec<(usize, usize)> = Vec::new();
    let mut start = 0;
    for i in 1..=points.len() {
        let leaves = i == points.len() || {
            let d = (points[i] - points[start]).component_div(&sigma);
            d.norm_squared() > limit
        };
        if leaves {
            runs.push((start, i - start));
            start = i;
        }
    }
    if runs.len() >= max {
        return thin_indices(runs.len(), max)
            .into_iter()
            .map(|r| runs[r].0 + runs[r].1 / 2)
            .collect();
    }
    // The largest cap whose total fits: the total grows with the cap, so bisect.
    let kept_with = |cap: usize| runs.iter().map(|(_, len)| (*len).min(cap)).sum::<usize>();
    let (mut low, mut high) = (1, runs.iter().map(|(_, len)| *len).max().unwrap_or(1));
    while low < high {
        let mid = low + (high - low).div_ceil(2);
        if kept_with(mid) <= max {
            low = mid;
        } else {
            high = mid - 1;
        }
    }
    let cap = low;
    runs.iter()
        .flat_map(|&(start, len)| {
            let keep = len.min(cap);
            // Centred in `keep` equal parts of the run.
            (0..keep).map(move |k| start + (2 * k + 1) * len / (2 * keep))
        })
        .collect()
}

/// The points of [`thin_redundant_indices`].
pub fn thin_redundant(points: &[Vec3], max: usize) -> Vec<Vec3> {
    thin_redundant_indices(points, max)
        .into_iter()
        .filter_map(|i| points.get(i).copied())
        .collect()
}

/// The indices [`thin`] keeps out of `len` items.
pub fn thin_indices(len: usize, max: usize) -> Vec<usize> {
    if max == 0 || len <= max {
        return (0..len).collect();
    }
    // Evenly spaced indices i·len/max keep exactly `max` points spread over the whole recording.
    (0..max).map(|i| i * len / max).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::hard_and_soft_iron_cloud;

    /// Deterministic standard normal draws (sum of twelve uniforms, SplitMix64).
    fn normals(seed: u64) -> impl FnMut() -> f64 {
        let mut state = seed;
        move || {
            let mut sum = 0.0;
            for _ in 0..12 {
                state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
                let mut z = state;
                z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
                z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
                z ^= z >> 31;
                sum += (z >> 11) as f64 / (1u64 << 53) as f64;
            }
            sum - 6.0
        }
    }

    /// The point at `polar`, `azimuth` (radians) on the sphere of `radius` about the origin.
    fn on_sphere(polar: f64, azimuth: f64, radius: f64) -> Vec3 {
        Vec3::new(
            polar.sin() * azimuth.cos(),
            polar.sin() * azimuth.sin(),
            polar.cos(),
        ) * radius
    }

    #[test]
    fn thinning_keeps_the_requested_count_in_order() {
        let points: Vec<Vec3> = (0..1000).map(|i| Vec3::new(i as f64, 0.0, 0.0)).collect();
        let thinned = thin(&points, 300);
        assert_eq!(thinned.len(), 300);
        assert!(thinned.windows(2).all(|w| w[1].x > w[0].x));
        assert_eq!(thin(&points, 0).len(), 1000);
        assert_eq!(thin_redundant(&points, 0).len(), 1000);
        assert_eq!(thin_redundant(&points, 5000).len(), 1000);
    }

    #[test]
    fn a_long_pause_does_not_crowd_out_the_turning_when_the_stream_is_thinned() {
        // 2000 samples turning along a spiral over a 50 µT sphere (about 2 µT apart), then
        // 100 000 samples held still in one direction, all with 0.3 µT of noise per axis.
        let mut noise = normals(7);
        let sigma = 0.3;
        let mut stream: Vec<Vec3> = (0..2000)
            .map(|i| {
                let t = i as f64 / 2000.0;
                let polar = std::f64::consts::PI * t;
                on_sphere(polar, 40.0 * polar, 50.0)
            })
            .collect();
        stream.extend(std::iter::repeat_n(Vec3::new(0.0, 0.0, 50.0), 100_000));
        for p in &mut stream {
            *p += Vec3::new(noise(), noise(), noise()) * sigma;
        }
        let turning = |kept: &[usize]| kept.iter().filter(|&&i| i < 2000).count();
        // Evenly spaced, the pause takes 98 % of the 3000 samples kept.
        assert!(turning(&thin_indices(stream.len(), 3000)) < 60);
        let kept = thin_redundant_indices(&stream, 3000);
        assert!(kept.len() <= 3000);
        // The turning is kept whole; only the pause gives up samples, down to what is left.
        assert_eq!(
            turning(&kept),
            2000,
            "{} of {} kept samples turn",
            turning(&kept),
            kept.len()
        );
        let still = kept.len() - turning(&kept);
        assert!((900..=1000).contains(&still), "{still} still samples kept");
    }

    #[test]
    fn magnetometer_minmax_without_the_field_along_an_axis_names_the_field_not_a_face_up() {
        // A cap within 45° of +Z: the field never points along −Z (nor along ±X, ±Y).
        let points: Vec<Vec3> = (0..400)
            .map(|i| {
                let polar = 0.5 * std::f64::consts::FRAC_PI_2 * (i % 20) as f64 / 20.0;
                on_sphere(polar, i as f64 * 0.7, 50.0)
            })
            .collect();
        let Err(FitError::Underdetermined(why)) = fit_mag(Method::MinMax, &points, 50.0) else {
            panic!("min/max on a cap of directions must be refused");
        };
        assert!(why.contains("field along"), "{why}");
        assert!(!why.contains(" up"), "accelerometer wording: {why}");
        // The full sphere fits.
        assert!(fit_mag(Method::MinMax, &hard_and_soft_iron_cloud(400, 3), 50.0).is_ok());
    }

    #[test]
    fn a_chosen_model_is_held_out_over_the_poses_it_can_be_refit_without() {
        // Each face once, +X twice: min/max can be refit without a +X pose only.
        let mut dirs: Vec<Vec3> = crate::fit::validate::face_directions().to_vec();
        dirs.push(Vec3::new(1.0, 0.02, 0.0));
        let mut noise = normals(11);
        let poses: Vec<Pose> = dirs
            .iter()
            .map(|d| {
                let raw = d.normalize() * 9.81 * 1.01
                    + Vec3::new(0.1, -0.05, 0.02)
                    + Vec3::new(noise(), noise(), noise()) * 1e-3;
                Pose {
                    mean: raw,
                    var: Vec3::repeat(1e-6),
                    n: 100,
                    label: None,
                }
            })
            .collect();
        assert!(fit_accel(Method::MinMax, &poses, 9.81)
            .expect("six faces fit")
            .loo_rms
            .is_none());
        let (rms, kept) =
            leave_one_out_where_refittable(Method::MinMax, &poses, 9.81).expect("two poses");
        assert_eq!(kept, vec![0, 6]);
        assert!(rms.is_finite() && rms > 0.0 && rms < 1e-2, "{rms}");
    }

    #[test]
    fn li_on_magnetometer_samples_reports_a_held_out_rms_on_either_side_of_the_size_rule() {
        let points = hard_and_soft_iron_cloud(LI_EXACT_LOO_MAX_SAMPLES + 1, 51);
        let small = &points[..LI_EXACT_LOO_MAX_SAMPLES];
        for set in [small, &points[..]] {
            let fit = fit_mag(Method::Li, set, 50.0).expect("a full sphere fits");
            let loo = fit.loo_rms.expect("a held-out RMS");
            assert!(loo > fit.rms, "N = {}: {loo:e} ≤ {:e}", set.len(), fit.rms);
        }
        // At the rule, the exact form (used there) and first order agree to the printed digits.
        let exact = fit_mag(Method::Li, small, 50.0)
            .ok()
            .and_then(|f| f.loo_rms);
        let first = fit::li_loo_first_order::li_first_order_loo_rms(small, 50.0);
        let (exact, first) = (exact.expect("exact"), first.expect("first order"));
        assert!(
            (exact - first).abs() <= 1e-4 * exact,
            "{exact:e} against {first:e}"
        );
    }
}
