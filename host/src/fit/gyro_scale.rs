//! Gyroscope scale and misalignment after Tedaldi, Pretto & Menegatti (2014), "A robust and easy
//! to implement method for IMU calibration without external equipments", ICRA 2014, section IV-B.
//!
//! Between two consecutive still poses the board is turned; the calibrated rate `ω = A·ω_raw`
//! (`ω_raw` bias-corrected, in the gyroscope's nominal units) is integrated as a quaternion with
//! fourth-order Runge–Kutta, `q̇ = ½·q ⊗ (0, ω)`, giving the rotation `R` from the start pose to
//! the end pose. Gravity is fixed in the world, so the start pose's calibrated gravity direction
//! rotated into the end pose, `Rᵀ·ĝ_before`, must equal the measured `ĝ_after`. The 9 entries of
//! a full `A` (scale, cross-axis, and the gyro-to-accelerometer misalignment) minimise the
//! mismatch by Levenberg–Marquardt, Jacobian by central differences. The residual of a motion is
//! the mismatch's two components perpendicular to `ĝ_after` (≈ angle errors in radians), each
//! divided by the motion's own angle σ when every motion gives one (generalised least squares:
//! a motion with short or noisy still ends counts less), scaled by the σs' RMS. A
//! rotation about gravity leaves gravity unchanged, so motions must turn about varied axes.
//!
//! The motions of a recording are cut between its still holds by [`crate::still::motions`].

use nalgebra::{DMatrix, DVector, Quaternion, UnitQuaternion};

use super::covariance::{calibration_std, normal_covariance, param_names, FULL_MATRIX_LAYOUT};
use super::linalg::{equilibrated_condition_from_normal_matrix, rms};
use super::lm::{levenberg_marquardt, LeastSquaresProblem, LmOptions, LmSolution};
use super::uncertainty::{scaled_covariance, NoiseLevel, Z_95};
use super::{Calibration, Fit, FitError, Mat3, Method, Vec3};

/// Longest step between two time stamps, in sample periods, of a stream still integrated:
/// one read the board skipped (two periods) with room for the sensor's rate error.
const MAX_STEP_PERIODS: f64 = 2.5;

/// Least-squares slope of the stamps `times` against the sample count, s per sample, whatever
/// the steps between them; `None` for fewer than two stamps or a slope that is not a positive
/// finite number.
pub fn stamp_slope_s(times: impl Iterator<Item = f64> + Clone) -> Option<f64> {
    let n = times.clone().count();
    if n < 2 {
        return None;
    }
    let mean_k = (n - 1) as f64 / 2.0;
    let t0 = times.clone().next()?;
    let mean_t = times.clone().map(|t| t - t0).sum::<f64>() / n as f64;
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for (k, t) in times.enumerate() {
        let dk = k as f64 - mean_k;
        sxy += dk * (t - t0 - mean_t);
        sxx += dk * dk;
    }
    let dt = sxy / sxx;
    (dt.is_finite() && dt > 0.0).then_some(dt)
}

/// Time step of a stream of stamps `times`: the least-squares slope of the stamps against the
/// sample count.
///
/// A sensor converts on its own oscillator, a few per cent off the board's read timer, and the
/// firmware leaves out a read that finds no new conversion: a stream from a sensor slower than
/// the timer jumps by two read periods now and then, while its samples are evenly spaced on the
/// sensor's clock. The slope is that clock's period (each stamp lags its conversion by less than
/// a read period, which averages out over the stream); the mean interval of the two ends would
/// carry the lag of both, up to a period per motion. `None` when there are fewer than two
/// stamps, they do not increase, or a step exceeds [`MAX_STEP_PERIODS`] periods (samples lost:
/// the rotation over the gap is unknown).
pub fn sample_step_s(times: impl Iterator<Item = f64> + Clone) -> Option<f64> {
    let dt = stamp_slope_s(times.clone())?;
    let mut previous = times.clone().next()?;
    let even = times.skip(1).all(|t| {
        let step = t - previous;
        previous = t;
        step > 0.0 && step <= MAX_STEP_PERIODS * dt
    });
    even.then_some(dt)
}

/// One motion between two still poses.
#[derive(Debug, Clone, PartialEq)]
pub struct GyroMotion {
    /// Calibrated accelerometer reading (mean) in the still pose before the motion.
    pub gravity_before: Vec3,
    /// Calibrated accelerometer reading (mean) in the still pose after the motion.
    pub gravity_after: Vec3,
    /// Bias-corrected gyroscope samples, evenly spaced, from the end of the first pose to the
    /// start of the second.
    pub rates: Vec<Vec3>,
    /// Sample interval, in seconds.
    pub dt: f64,
    /// One-sigma of each component of the motion's angle mismatch from its own noise
    /// (gravity directions at the still ends, gyroscope noise over the turn), radians. When every
    /// motion has one, the fit weighs each by its inverse (generalised least squares); `None`
    /// weighs all motions alike.
    pub angle_sigma: Option<f64>,
}

/// Rotation (body at the end → body at the start) from integrating `A·rates` with RK4 on the
/// quaternion, the rate interpolated linearly between samples.
pub fn integrate_rotation(a: &Mat3, rates: &[Vec3], dt: f64) -> UnitQuaternion<f64> {
    let deriv = |q: &Quaternion<f64>, w: &Vec3| q * Quaternion::new(0.0, w.x, w.y, w.z) * 0.5;
    let mut q = Quaternion::identity();
    for pair in rates.windows(2) {
        let (w0, w1) = (a * pair[0], a * pair[1]);
        let wm = (w0 + w1) * 0.5;
        let k1 = deriv(&q, &w0);
        let k2 = deriv(&(q + k1 * (dt / 2.0)), &wm);
        let k3 = deriv(&(q + k2 * (dt / 2.0)), &wm);
        let k4 = deriv(&(q + k3 * dt), &w1);
        q += (k1 + k2 * 2.0 + k3 * 2.0 + k4) * (dt / 6.0);
        // Renormalise each step so that round-off does not accumulate as a scale.
        q = q.normalize();
    }
    UnitQuaternion::new_normalize(q)
}

struct GyroProblem {
    /// Per motion: unit gravity before, and an orthonormal basis perpendicular to gravity after.
    motions: Vec<(Vec3, Vec3, Vec3, Vec3)>,
    rates: Vec<Vec<Vec3>>,
    dt: Vec<f64>,
    /// Per motion: the factor its two angle errors are multiplied by in the least squares.
    weights: Vec<f64>,
}

impl GyroProblem {
    /// The two angle errors (radians) of every motion, unweighted.
    fn angle_errors(&self, p: &DVector<f64>) -> DVector<f64> {
        let a = matrix_from(p);
        let mut r = DVector::zeros(2 * self.motions.len());
        for (k, ((before, _after, e1, e2), (rates, dt))) in self
            .motions
            .iter()
            .zip(self.rates.iter().zip(&self.dt))
            .enumerate()
        {
            let predicted = integrate_rotation(&a, rates, *dt).inverse() * before;
            r[2 * k] = e1.dot(&predicted);
            r[2 * k + 1] = e2.dot(&predicted);
        }
        r
    }
}

/// Relative weight of each motion: `σ̄/σₖ` when every motion states its angle σ (positive and
/// finite), `σ̄` their RMS so that a weighted residual reads as an angle; all 1 otherwise.
fn motion_weights(motions: &[GyroMotion]) -> Vec<f64> {
    let sigmas: Option<Vec<f64>> = motions
        .iter()
        .map(|m| m.angle_sigma.filter(|s| s.is_finite() && *s > 0.0))
        .collect();
    match sigmas {
        Some(sigmas) if !sigmas.is_empty() => {
            let mean_square = sigmas.iter().map(|s| s * s).sum::<f64>() / sigmas.len() as f64;
            sigmas.iter().map(|s| mean_square.sqrt() / s).collect()
        }
        _ => vec![1.0; motions.len()],
    }
}

fn matrix_from(p: &DVector<f64>) -> Mat3 {
    Mat3::from_row_slice(p.as_slice())
}

impl LeastSquaresProblem for GyroProblem {
    fn residuals(&self, p: &DVector<f64>) -> DVector<f64> {
        let mut r = self.angle_errors(p);
        for (k, w) in self.weights.iter().enumerate() {
            r[2 * k] *= w;
            r[2 * k + 1] *= w;
        }
        r
    }

    fn jacobian(&self, p: &DVector<f64>) -> DMatrix<f64> {
        let mut j = DMatrix::zeros(2 * self.motions.len(), 9);
        for k in 0..9 {
            // Entries of A are O(1); 1e-6 balances truncation against round-off.
            let h = 1e-6;
            let mut plus = p.clone();
            let mut minus = p.clone();
            plus[k] += h;
            minus[k] -= h;
            let d = (self.residuals(&plus) - self.residuals(&minus)) / (2.0 * h);
            j.set_column(k, &d);
        }
        j
    }
}

/// Fewest motions the scale fit takes: each gives three angle components for the nine unknowns
/// of `A`, and a few more than three keep it from passing through them exactly.
pub const MIN_MOTIONS: usize = 5;

/// Fit the full gyroscope matrix `A` (bias already removed) from motions between still poses;
/// `start` defaults to the identity (nominal scale). Residuals are the per-motion angle errors in
/// radians; `reference` of the result is 1.
pub fn fit_gyro_scale(motions: &[GyroMotion], start: Option<&Mat3>) -> Result<Fit, FitError> {
    if motions.len() < MIN_MOTIONS {
        return Err(FitError::Underdetermined(format!(
            "only {} motions between still poses for 9 unknowns; turn the board between at least 5 poses (9+ recommended)",
            motions.len()
        )));
    }
    let mut prepared = Vec::with_capacity(motions.len());
    for (i, m) in motions.iter().enumerate() {
        if !(m.dt.is_finite() && m.dt > 0.0) {
            return Err(FitError::Underdetermined(format!(
                "motion {i} has sample interval {} s; give the gyroscope's sample period",
                m.dt
            )));
        }
        if m.rates
            .iter()
            .chain([&m.gravity_before, &m.gravity_after])
            .any(|v| v.iter().any(|x| !x.is_finite()))
        {
            return Err(FitError::NonFinite(format!("motion {i}")));
        }
        if m.rates.len() < 2 {
            return Err(FitError::Underdetermined(format!(
                "motion {i} has fewer than 2 gyroscope samples; record the rotation between the poses"
            )));
        }
        let (Some(before), Some(after)) = (
            m.gravity_before.try_normalize(0.0),
            m.gravity_after.try_normalize(0.0),
        ) else {
            return Err(FitError::Underdetermined(format!(
                "motion {i} has a zero gravity reading; use calibrated accelerometer pose means"
            )));
        };
        // Any orthonormal pair perpendicular to gravity-after spans the angle error.
        let not_parallel = if after.x.abs() < 0.9 {
            Vec3::x()
        } else {
            Vec3::y()
        };
        let e1 = after.cross(&not_parallel).normalize();
        let e2 = after.cross(&e1);
        prepared.push((before, after, e1, e2));
    }
    let problem = GyroProblem {
        motions: prepared,
        rates: motions.iter().map(|m| m.rates.clone()).collect(),
        dt: motions.iter().map(|m| m.dt).collect(),
        weights: motion_weights(motions),
    };
    let a0 = start.copied().unwrap_or_else(Mat3::identity);
    if a0.iter().any(|v| !v.is_finite()) {
        return Err(FitError::NonFinite("the starting gyroscope matrix".into()));
    }
    let p0 = DVector::from_row_slice(a0.transpose().as_slice());
    let sol = levenberg_marquardt(&problem, p0, &LmOptions::default())
        .map_err(|e| e.into_fit_error("gyroscope scale (Tedaldi)"))?;
    let refusal = || lacking_rotation(least_turned_axis(&matrix_from(&sol.params), motions));
    if !check_observability(&sol.jtj) {
        return Err(refusal());
    }
    // One policy (`uncertainty`): the angle noise is unknown and estimated from the residual;
    // without scatter to estimate it from (ν = 0 or an exact fit) there is no covariance.
    let scaled = scaled_covariance(
        normal_covariance(&sol.jtj),
        sol.cost,
        sol.residuals.len(),
        9,
        NoiseLevel::Unknown,
    );
    let coverage_factor = scaled.as_ref().map_or(Z_95, |s| s.coverage_factor);
    let covariance = scaled.map(|s| s.covariance);
    if covariance.as_ref().is_some_and(|c| !check_precision(c)) {
        return Err(refusal());
    }
    // Reported in angle, unweighted.
    let residuals: Vec<f64> = problem
        .angle_errors(&sol.params)
        .as_slice()
        .chunks(2)
        .map(|c| c.iter().map(|v| v * v).sum::<f64>().sqrt())
        .collect();
    Ok(gyro_matrix_fit(
        matrix_from(&sol.params),
        residuals,
        covariance,
        &sol,
        coverage_factor,
    ))
}

/// The [`Fit`] of a full gyroscope matrix `a` (bias zero: it comes from the holds) with its
/// angle residuals and the covariance of its 9 entries, from the solver's outcome `sol`.
pub(super) fn gyro_matrix_fit(
    a: Mat3,
    residuals: Vec<f64>,
    covariance: Option<DMatrix<f64>>,
    sol: &LmSolution,
    coverage_factor: f64,
) -> Fit {
    let std = covariance
        .as_ref()
        .map(|c| calibration_std(c, &FULL_MATRIX_LAYOUT));
    Fit {
        method: Method::GyroScale,
        cal: Calibration {
            a,
            b: Vec3::zeros(),
        },
        rms: rms(&residuals),
        residuals,
        loo_rms: None,
        covariance,
        param_names: param_names(&FULL_MATRIX_LAYOUT),
        std,
        condition_number: equilibrated_condition_from_normal_matrix(&sol.jtj),
        iterations: sol.iterations,
        termination: Some(sol.termination),
        coverage_factor,
        reference: 1.0,
    }
}

/// Largest condition number of the equilibrated information matrix accepted: beyond
/// `1/√ε_mach` the covariance has lost half its digits to round-off, so the worst-determined
/// combination of entries is fixed by the start, not by the data.
const MAX_INFORMATION_CONDITION: f64 = 6.7e7;

/// Largest one-sigma uncertainty accepted on an entry of `A` (nominally 1): beyond 0.1 a gain
/// or cross-axis term is not known to 10 %, i.e. the data do not determine it.
const MAX_ENTRY_STD: f64 = 0.1;

const AXES: [&str; 3] = ["x", "y", "z"];

/// The calibrated axis about which the motions turn the least: `Σ ∫|(A·ω_raw)_k| dt`.
fn least_turned_axis(a: &Mat3, motions: &[GyroMotion]) -> &'static str {
    let mut turned = Vec3::zeros();
    for m in motions {
        for w in &m.rates {
            turned += (a * w).abs() * m.dt;
        }
    }
    AXES[turned.imin()]
}

fn lacking_rotation(axis: &str) -> FitError {
    FitError::Underdetermined(format!(
        "the motions barely turn the board about its gyroscope {axis} axis, so the terms of that \
         axis are not determined; add turns of at least 90° about {axis} (not about the vertical)"
    ))
}

/// Refuse a nearly unobservable direction: condition number of the equilibrated information.
fn check_observability(jtj: &DMatrix<f64>) -> bool {
    let d: Vec<f64> = (0..9).map(|i| jtj[(i, i)].max(0.0).sqrt()).collect();
    if d.iter().any(|v| *v == 0.0 || !v.is_finite()) {
        return false;
    }
    let scaled = DMatrix::from_fn(9, 9, |i, j| jtj[(i, j)] / (d[i] * d[j]));
    let eig = scaled.symmetric_eigenvalues();
    let (min, max) = (eig.min(), eig.max());
    min > 0.0 && max / min <= MAX_INFORMATION_CONDITION
}

/// Refuse when an entry's uncertainty shows the motions do not determine it.
fn check_precision(cov: &DMatrix<f64>) -> bool {
    (0..9).all(|i| cov[(i, i)].max(0.0).sqrt() <= MAX_ENTRY_STD)
}

#[cfg(test)]
mod tests {
    use super::sample_step_s;

    /// Stamps of a sensor converting every `period` read on a timer of `read` (> period is
    /// slower): each conversion is stamped at the first read after it.
    fn read_stamps(period: f64, read: f64, count: usize) -> Vec<f64> {
        let mut stamps: Vec<f64> = Vec::new();
        for k in 0..count {
            let t = ((k as f64 * period) / read).ceil() * read;
            if stamps.last().is_none_or(|last| t > *last) {
                stamps.push(t);
            }
        }
        stamps
    }

    #[test]
    fn the_step_of_a_sensor_slower_than_the_read_timer_is_its_own_period() {
        let (period, read) = (1.0 / 119.0 * 1.02, 1.0 / 119.0);
        let stamps = read_stamps(period, read, 300);
        let step = sample_step_s(stamps.iter().copied()).expect("a step");
        // The stamps lag by less than a read period, spread over ~300 samples.
        assert!(
            (step / period - 1.0).abs() < 1e-3,
            "{step} against {period}"
        );
    }

    #[test]
    fn a_stream_with_a_gap_of_samples_has_no_step() {
        let mut stamps: Vec<f64> = (0..100).map(|k| k as f64 * 0.01).collect();
        stamps.drain(40..43);
        assert!(sample_step_s(stamps.iter().copied()).is_none());
        assert!(sample_step_s([0.0].into_iter()).is_none());
        assert!(sample_step_s([0.0, 0.0, 0.0].into_iter()).is_none());
    }
}
