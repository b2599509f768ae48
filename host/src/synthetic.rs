//! Seeded synthetic truth data for testing the fits: random true calibrations, accelerometer
//! pose sets (six faces, the twelve positions of seed 003, random directions, half sphere) and
//! magnetometer sample clouds (full sphere or a partial cap), and long whole recordings as CSV
//! text for measuring the pipeline at scale.
//!
//! Compiled only with the `synthetic` feature: the library never needs it at run time; the
//! tests, examples and benches enable it through their dev-dependency on this crate.
//!
//! A raw reading is generated from a true calibrated vector `y` as `x = A_true⁻¹·y + b_true + e`
//! with white noise `e ~ N(0, σ²)` per axis, so that the true calibration in the library's
//! convention `y = A·(x − b)` is exactly `(A_true, b_true)`.

use nalgebra::{Rotation3, Unit, UnitQuaternion};
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};

use crate::fit::validate::face_directions;
use crate::fit::{Calibration, Mat3, Pose, Vec3};

pub use rand::rngs::StdRng;
pub use rand::SeedableRng;

/// A reproducible random generator for tests: `StdRng::seed_from_u64(seed)`.
pub fn rng(seed: u64) -> StdRng {
    StdRng::seed_from_u64(seed)
}

/// How to draw a random true calibration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthSpec {
    /// Each axis gain of the sensor is `1 + U(−scale_error, scale_error)` (e.g. 0.3 for ±30 %).
    pub scale_error: f64,
    /// Each off-diagonal (cross-axis) entry of the sensor response is `U(−cross_axis, cross_axis)`.
    pub cross_axis: f64,
    /// Offset magnitude as a multiple of the reference magnitude (e.g. 10 for a hard-iron offset
    /// ten times the field); the offset points in a uniformly random direction.
    pub offset_ratio: f64,
    /// Reference magnitude `|y|` (g, field strength, or 1).
    pub reference: f64,
    /// Express the truth in the norm-model gauge: `A` upper-triangular with positive diagonal
    /// (the same `|A·u|` for every `u`), so norm-model fits can be compared entry by entry.
    pub upper_triangular: bool,
}

impl Default for TruthSpec {
    fn default() -> Self {
        Self {
            scale_error: 0.1,
            cross_axis: 0.02,
            offset_ratio: 0.1,
            reference: 1.0,
            upper_triangular: false,
        }
    }
}

/// Draw a random true calibration `(A_true, b_true)`.
///
/// The sensor response `K = diag(gains) + cross-axis` is drawn first; `A_true = K⁻¹`. The gains
/// stay within ±`scale_error` < 1 and the cross-axis terms are small, so `K` is invertible for any
/// sensible spec; should it not be, the identity is used for `A`.
pub fn random_calibration<R: Rng + ?Sized>(rng: &mut R, spec: &TruthSpec) -> Calibration {
    let mut k = Mat3::zeros();
    for i in 0..3 {
        for j in 0..3 {
            k[(i, j)] = if i == j {
                1.0 + symmetric_uniform(rng, spec.scale_error)
            } else {
                symmetric_uniform(rng, spec.cross_axis)
            };
        }
    }
    let mut a = k.try_inverse().unwrap_or_else(Mat3::identity);
    if spec.upper_triangular {
        a = crate::fit::linalg::upper_triangular_gauge(&a);
    }
    let b = random_unit(rng).into_inner() * (spec.offset_ratio * spec.reference);
    Calibration { a, b }
}

/// Which orientations an accelerometer pose set visits (true directions of the specific force in
/// the calibrated frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PoseSet {
    /// ±X, ±Y, ±Z up (seed 000, seed 003 coarse step, seed 004).
    SixFaces,
    /// The six faces plus six 45° tilts in the XY, YZ and XZ planes (seed 003, section 3.2).
    TwelvePositions,
    /// `n` directions uniform on the sphere.
    Random(usize),
    /// `n` directions uniform on the upper half sphere (`z ≥ 0`).
    HalfSphere(usize),
}

/// Unit directions of the pose set, in the calibrated frame.
pub fn directions<R: Rng + ?Sized>(rng: &mut R, set: PoseSet) -> Vec<Vec3> {
    let h = std::f64::consts::FRAC_1_SQRT_2;
    match set {
        PoseSet::SixFaces => six_faces(),
        PoseSet::TwelvePositions => {
            let mut d = six_faces();
            d.extend([
                Vec3::new(h, h, 0.0),
                Vec3::new(-h, h, 0.0),
                Vec3::new(0.0, h, h),
                Vec3::new(0.0, -h, h),
                Vec3::new(h, 0.0, h),
                Vec3::new(-h, 0.0, h),
            ]);
            d
        }
        PoseSet::Random(n) => (0..n).map(|_| random_unit(rng).into_inner()).collect(),
        PoseSet::HalfSphere(n) => (0..n)
            .map(|_| {
                let u = random_unit(rng).into_inner();
                Vec3::new(u.x, u.y, u.z.abs())
            })
            .collect(),
    }
}

/// `n` directions uniform within `half_angle_deg` of `axis` (a spherical cap; 180° is the sphere).
pub fn cap_directions<R: Rng + ?Sized>(
    rng: &mut R,
    n: usize,
    axis: Vec3,
    half_angle_deg: f64,
) -> Vec<Vec3> {
    let axis = Unit::try_new(axis, 1e-12).unwrap_or(Vec3::z_axis());
    // Rotation taking +Z onto the cap axis (identity or a half turn when they are (anti)parallel).
    let to_axis = nalgebra::Rotation3::rotation_between(&Vec3::z(), &axis).unwrap_or_else(|| {
        nalgebra::Rotation3::from_axis_angle(&Vec3::x_axis(), std::f64::consts::PI)
    });
    let cos_min = half_angle_deg.clamp(0.0, 180.0).to_radians().cos();
    (0..n)
        .map(|_| {
            // Uniform in cos θ gives uniform area on the cap.
            let cos_t = rng.gen_range(cos_min..=1.0);
            let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
            let phi = rng.gen_range(0.0..std::f64::consts::TAU);
            to_axis * Vec3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t)
        })
        .collect()
}

/// `n` directions uniform on the full sphere.
pub fn sphere_directions<R: Rng + ?Sized>(rng: &mut R, n: usize) -> Vec<Vec3> {
    directions(rng, PoseSet::Random(n))
}

/// Tilt each direction by a random small rotation of standard deviation `sigma_deg` per axis,
/// modelling a table that is not level or a board placed slightly askew.
pub fn perturb_directions<R: Rng + ?Sized>(
    rng: &mut R,
    dirs: &[Vec3],
    sigma_deg: f64,
) -> Vec<Vec3> {
    let s = sigma_deg.to_radians();
    dirs.iter()
        .map(|d| {
            let w = Vec3::new(gauss(rng), gauss(rng), gauss(rng)) * s;
            nalgebra::Rotation3::new(w) * d
        })
        .collect()
}

/// The raw reading (noise-free) that the true calibration maps onto `y`: `A_true⁻¹·y + b_true`.
/// Returns `None` if `A_true` is singular.
pub fn raw_from_true(truth: &Calibration, y: &Vec3) -> Option<Vec3> {
    truth.a.try_inverse().map(|ainv| ainv * y + truth.b)
}

/// Accelerometer static poses: for each direction `u`, `samples` raw readings of
/// `A_true⁻¹·(reference·u) + b_true` with white noise of standard deviation `sigma` (raw units)
/// per axis, summarised as a [`Pose`] (mean, unbiased sample variance, count; label = index).
///
/// `samples` is raised to at least 1; with one sample the variance is reported as `sigma²`.
pub fn accel_poses<R: Rng + ?Sized>(
    rng: &mut R,
    truth: &Calibration,
    dirs: &[Vec3],
    reference: f64,
    sigma: f64,
    samples: usize,
) -> Vec<Pose> {
    let n = samples.max(1);
    let ainv = truth.a.try_inverse().unwrap_or_else(Mat3::identity);
    dirs.iter()
        .enumerate()
        .map(|(i, u)| {
            let clean = ainv * (u * reference) + truth.b;
            let mut sum = Vec3::zeros();
            let mut sum_sq = Vec3::zeros();
            for _ in 0..n {
                let e = Vec3::new(gauss(rng), gauss(rng), gauss(rng)) * sigma;
                sum += e;
                sum_sq += e.component_mul(&e);
            }
            let mean_e = sum / n as f64;
            let var = if n > 1 {
                // Unbiased variance of the noise around its own mean.
                (sum_sq - mean_e.component_mul(&mean_e) * n as f64) / (n - 1) as f64
            } else {
                Vec3::repeat(sigma * sigma)
            };
            Pose {
                mean: clean + mean_e,
                var: var.map(|v| v.max(0.0)),
                n,
                label: Some(i as i64),
            }
        })
        .collect()
}

/// Magnetometer samples: for each direction `u`, one raw reading of `A_true⁻¹·(field·u) + b_true`
/// with white noise of standard deviation `sigma` (raw units) per axis.
pub fn mag_samples<R: Rng + ?Sized>(
    rng: &mut R,
    truth: &Calibration,
    dirs: &[Vec3],
    field: f64,
    sigma: f64,
) -> Vec<Vec3> {
    let ainv = truth.a.try_inverse().unwrap_or_else(Mat3::identity);
    dirs.iter()
        .map(|u| {
            let e = Vec3::new(gauss(rng), gauss(rng), gauss(rng)) * sigma;
            ainv * (u * field) + truth.b + e
        })
        .collect()
}

/// `n` magnetometer samples over the whole sphere (field 50 µT, 0.5 µT noise per axis, i.e.
/// 1 %) of a sensor with random hard- and soft-iron errors (20 % scale, 5 % cross-axis, an
/// offset of twice the field), drawn from `seed`: the usual cloud of the sample-level tests.
pub fn hard_and_soft_iron_cloud(n: usize, seed: u64) -> Vec<Vec3> {
    let spec = TruthSpec {
        scale_error: 0.2,
        cross_axis: 0.05,
        offset_ratio: 2.0,
        reference: 50.0,
        upper_triangular: false,
    };
    let truth = random_calibration(&mut rng(seed), &spec);
    let mut r = rng(seed + 1);
    let dirs = sphere_directions(&mut r, n);
    mag_samples(&mut r, &truth, &dirs, 50.0, 0.5)
}

fn six_faces() -> Vec<Vec3> {
    face_directions().to_vec()
}

fn gauss<R: Rng + ?Sized>(rng: &mut R) -> f64 {
    StandardNormal.sample(rng)
}

fn symmetric_uniform<R: Rng + ?Sized>(rng: &mut R, half_width: f64) -> f64 {
    if half_width > 0.0 {
        rng.gen_range(-half_width..=half_width)
    } else {
        0.0
    }
}

fn random_unit<R: Rng + ?Sized>(rng: &mut R) -> Unit<Vec3> {
    loop {
        let v = Vec3::new(gauss(rng), gauss(rng), gauss(rng));
        if let Some(u) = Unit::try_new(v, 1e-9) {
            return u;
        }
    }
}

/// Seconds of each hold of [`write_long_recording`].
const LONG_HOLD_S: f64 = 20.0;
/// Seconds of each rotation between holds of [`write_long_recording`].
const LONG_MOVE_S: f64 = 5.0;
/// Row rate of [`write_long_recording`].
const LONG_RATE_HZ: f64 = 100.0;

/// Write a seeded 11-column recording (`t_s,ax,ay,az,gx,gy,gz,mx,my,mz,temp_c`) of `rows` rows
/// at 100 Hz, for measuring the whole fit at scale: 20 s holds in random orientations joined by
/// 5 s rotations; accelerometer in m/s² with a true scale, cross-axis and offset error, gyroscope
/// in rad/s with a bias, magnetometer in µT with hard- and soft-iron error, white noise on
/// every axis, printed with the digits a logger writes.
pub fn write_long_recording<W: std::io::Write>(rows: usize, w: &mut W) -> std::io::Result<()> {
    let mut rng = rng(2024);
    let accel_truth = Calibration {
        a: Mat3::new(1.02, 0.01, -0.005, 0.0, 0.98, 0.008, 0.0, 0.0, 1.01),
        b: Vec3::new(0.12, -0.08, 0.2),
    };
    let mag_truth = Calibration {
        a: Mat3::new(1.1, 0.05, 0.02, 0.05, 0.9, -0.03, 0.02, -0.03, 1.05),
        b: Vec3::new(12.0, -30.0, 8.0),
    };
    let gravity = Vec3::new(0.0, 0.0, 9.80665);
    let field = Vec3::new(20.0, 0.0, -40.0);
    let gyro_bias = Vec3::new(0.01, -0.02, 0.005);
    let random_orientation = |rng: &mut StdRng| {
        let axis = Vec3::new(gauss(rng), gauss(rng), gauss(rng));
        UnitQuaternion::from_scaled_axis(
            axis.normalize() * rng.gen_range(0.0..std::f64::consts::PI),
        )
    };
    let mut from = random_orientation(&mut rng);
    let mut to = random_orientation(&mut rng);
    let cycle = ((LONG_HOLD_S + LONG_MOVE_S) * LONG_RATE_HZ) as usize;
    let hold = (LONG_HOLD_S * LONG_RATE_HZ) as usize;
    let dt = 1.0 / LONG_RATE_HZ;
    writeln!(w, "t_s,ax,ay,az,gx,gy,gz,mx,my,mz,temp_c")?;
    for i in 0..rows {
        let phase = i % cycle;
        if phase == 0 && i > 0 {
            from = to;
            to = random_orientation(&mut rng);
        }
        // Body orientation (body → world) and body angular rate.
        let (q, rate) = if phase < hold {
            (from, Vec3::zeros())
        } else {
            let s = (phase - hold) as f64 / (cycle - hold) as f64;
            let q = from.slerp(&to, s);
            let delta = from.rotation_to(&to).scaled_axis() / LONG_MOVE_S;
            (q, q.inverse() * delta)
        };
        let r: Rotation3<f64> = q.to_rotation_matrix();
        let g_body = r.inverse() * gravity;
        let m_body = r.inverse() * field;
        let noise = |rng: &mut StdRng, s: f64| Vec3::new(gauss(rng), gauss(rng), gauss(rng)) * s;
        let a = raw_from_true(&accel_truth, &g_body).unwrap_or(g_body) + noise(&mut rng, 0.01);
        let g = rate + gyro_bias + noise(&mut rng, 0.002);
        let m = raw_from_true(&mag_truth, &m_body).unwrap_or(m_body) + noise(&mut rng, 0.3);
        writeln!(
            w,
            "{:.2},{:.5},{:.5},{:.5},{:.6},{:.6},{:.6},{:.3},{:.3},{:.3},{:.2}",
            i as f64 * dt,
            a.x,
            a.y,
            a.z,
            g.x,
            g.y,
            g.z,
            m.x,
            m.y,
            m.z,
            25.0 + 0.1 * gauss(&mut rng)
        )?;
    }
    Ok(())
}
