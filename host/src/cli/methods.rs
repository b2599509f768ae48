//! Which fitting method applies to which sensor, and how its input is formed from a
//! recording: accelerometer methods take still-interval poses (point methods take the pose
//! means), magnetometer methods take samples over many orientations, the gyroscope takes the
//! still poses. Shared by the command line and the real-data example.

use imucal::fit::coverage::{measure_coverage, EllipsoidModel, MAX_RELATIVE_SIGMA};
use imucal::fit::norm_lm::{refine_lm, NormLmOptions, NormObservations};
use imucal::fit::{self, Fit, FitError, Method, Pose, Vec3};

/// Methods offered for the accelerometer, the default first.
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
/// `gyro-scale` needs the whole recording (motions between holds), see `cli/fit.rs`.
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
    points
        .iter()
        .map(|p| Pose {
            mean: *p,
            var: Vec3::zeros(),
            n: 1,
            label: None,
        })
        .collect()
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
        Method::Li => fit::li::fit_li(
            &means(poses),
            reference,
            fit::li::LiOptions {
                subtract_mean: true,
            },
        ),
        Method::Frosio => fit::frosio::fit_frosio(&means(poses), reference, &FROSIO),
        Method::Merayo => fit::merayo::fit_merayo(&means(poses), reference, true),
        Method::GyroBias | Method::GyroScale => Err(not_for(method, "accelerometer")),
    }
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
        ),
        Method::Frosio => fit::frosio::fit_frosio(points, reference, &FROSIO),
        Method::Merayo => fit::merayo::fit_merayo(points, reference, true),
        Method::AxisAligned => fit::axis_aligned::fit_axis_aligned(points, reference),
        Method::MinMax => fit::minmax::fit_minmax(&as_poses(points), reference),
        Method::SixPosition | Method::Chen | Method::GyroBias | Method::GyroScale => {
            Err(not_for(method, "magnetometer"))
        }
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
    if max == 0 || points.len() <= max {
        return points.to_vec();
    }
    // Evenly spaced indices i·len/max keep exactly `max` points spread over the whole recording.
    (0..max)
        .filter_map(|i| points.get(i * points.len() / max).copied())
        .collect()
}

/// Unknowns of the norm model with the upper-triangular gauge: it needs this many distinct
/// directions.
pub const NORM_MODEL_UNKNOWNS: usize = 9;

/// Per-axis one-sigma noise of each pose mean, in data units (for the coverage measure).
pub fn pose_mean_noise(poses: &[Pose]) -> Vec<f64> {
    poses
        .iter()
        .map(|p| (p.var_of_mean().sum() / 3.0).sqrt())
        .collect()
}

/// The default accelerometer fit and, when it is not `lm`, why: the six-position method when
/// there are fewer distinct directions than the norm model's unknowns, and the axis-aligned
/// model (6 unknowns) when `lm` is refused because the poses cannot determine the cross-axis
/// terms.
pub fn default_accel_fit(
    poses: &[Pose],
    gravity: f64,
    directions: usize,
) -> (Result<Fit, FitError>, Option<String>) {
    if directions < NORM_MODEL_UNKNOWNS {
        return (
            fit_accel(Method::SixPosition, poses, gravity),
            Some(format!(
                "lm needs at least {NORM_MODEL_UNKNOWNS} distinct directions and {directions} were found, so the six-position method was used"
            )),
        );
    }
    let reason = match fit_accel(Method::Lm, poses, gravity) {
        Err(FitError::Underdetermined(reason)) => reason,
        other => return (other, None),
    };
    let refusal = FitError::Underdetermined(reason.clone());
    let Ok(axis_aligned) = fit_accel(Method::AxisAligned, poses, gravity) else {
        return (Err(refusal), None);
    };
    // Judge the general model as lm did, through its own (unchecked) solution where it converges.
    let observations = NormObservations::from_poses(poses, &axis_aligned.cal.b);
    let general = refine_lm(
        &observations,
        &axis_aligned.cal,
        gravity,
        &NormLmOptions::default(),
    )
    .map_or(axis_aligned.cal, |f| f.cal);
    let coverage = measure_coverage(
        &observations.points,
        Some(&pose_mean_noise(poses)),
        &general,
        gravity,
        EllipsoidModel::General,
    );
    let why = if coverage.max_relative_sigma.is_finite()
        && coverage.max_relative_sigma > MAX_RELATIVE_SIGMA
    {
        format!(
            "the {} orientations cannot determine the cross-axis terms to {:.1} % (they leave them uncertain by {:.1} %)",
            coverage.distinct,
            100.0 * MAX_RELATIVE_SIGMA,
            100.0 * coverage.max_relative_sigma
        )
    } else if !coverage.max_relative_sigma.is_finite() {
        format!(
            "the {} orientations cannot determine the cross-axis terms at all",
            coverage.distinct
        )
    } else {
        format!("lm was refused ({reason})")
    };
    (
        Ok(axis_aligned),
        Some(format!(
            "{why}; fitted the axis-aligned model (scales and offsets, 6 unknowns) instead; record more tilted poses for a full fit"
        )),
    )
}
