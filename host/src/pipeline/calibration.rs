//! What the pipeline produces from a recording: per sensor a fit (or the reason there is none)
//! with its units and findings, the references used, and the provenance (tool version,
//! recording, methods, time). The parameter file ([`super::params_file`]) and every command's
//! output are views of this.

use crate::device::params_json::Provenance;
use crate::fit::alignment::Alignment;
use crate::fit::{Fit, Pose, Vec3};
use crate::geomag::{LocalField, RadiusCheck};
use crate::recording::Sensor;
use crate::stats::autocorrelation::MAX_NOISE_CORRELATION;
use crate::stats::chi_square::ChiSquareTest;

use super::chain::ChainChoice;

/// One sensor's outcome.
#[derive(Debug, Clone)]
pub struct SensorOutcome {
    /// The sensor.
    pub sensor: Sensor,
    /// The fit, or the sentence saying why there is none.
    pub fit: Result<Fit, String>,
    /// Still poses used (accelerometer, gyroscope).
    pub n_poses: usize,
    /// Samples used.
    pub n_samples: usize,
    /// Unit of the data (`counts` when no scale is known).
    pub input_unit: &'static str,
    /// Unit of the calibrated output (`counts` or `field = 1` when no scale or reference is known).
    pub output_unit: String,
    /// Factor from the data's unit to the board's nominal unit (m/s², rad/s, µT), when known.
    pub to_nominal: Option<f64>,
    /// Relative residual a perfect model would leave: from the pose noise (accelerometer,
    /// gyroscope), or from the noise of single samples (magnetometer).
    pub noise_floor: Option<f64>,
    /// The χ² test of the residual against the noise of the means it rests on, the residual
    /// analysis's test: each pose's ([`norm_noise_test`], [`bias_noise_test`]), or for the
    /// magnetometer the means of its residual over windows of its stream
    /// ([`stream_noise_test`]). `None` for models with as many unknowns as observations, and
    /// when an observation has too few samples for its noise.
    pub noise_test: Option<ChiSquareTest>,
    /// What the noise test's observations are, when not the poses ("noise of its 20-sample
    /// windows").
    pub noise_test_of: Option<String>,
    /// Findings worth a line (e.g. which model the default chain chose and why).
    pub notes: Vec<String>,
    /// Accelerometer with the default chain: every candidate model and why it was chosen or not.
    pub chain: Option<ChainChoice>,
    /// Magnetometer only: the rotation into the accelerometer frame (already applied to the
    /// fit's `A`), or why there is none.
    pub alignment: Option<Result<Alignment, String>>,
    /// Magnetometer only: the modelled field used as reference or for the radius check.
    pub field_model: Option<LocalField>,
    /// Magnetometer only: the fitted raw radius against the modelled field.
    pub radius_check: Option<RadiusCheck>,
}

impl SensorOutcome {
    /// A sensor with no fit yet (or refused with `reason`).
    pub fn without_fit(sensor: Sensor, input_unit: &'static str, reason: String) -> Self {
        Self {
            sensor,
            fit: Err(reason),
            n_poses: 0,
            n_samples: 0,
            input_unit,
            output_unit: String::new(),
            to_nominal: None,
            noise_floor: None,
            noise_test: None,
            noise_test_of: None,
            notes: Vec::new(),
            chain: None,
            alignment: None,
            field_model: None,
            radius_check: None,
        }
    }

    /// Why a magnetometer fitted together with the accelerometer is not in the accelerometer's
    /// frame, with the fix; `None` when it is aligned or was fitted alone.
    pub fn alignment_failure(&self) -> Option<String> {
        let Some(Err(error)) = &self.alignment else {
            return None;
        };
        Some(format!(
            "not aligned to the accelerometer ({error}), so its output would be in its own \
             frame; hold more orientations with both sensors recording, or fit it alone with \
             --sensor mag to keep its own frame deliberately"
        ))
    }

    /// Whether `A`'s per-entry uncertainties still apply (a rotated `A` carries the rotation's
    /// uncertainty instead, reported with the alignment).
    pub fn a_std_applies(&self) -> bool {
        !matches!(self.alignment, Some(Ok(_)))
    }

    /// A short judgement of the fit: residual against the noise floor, held-out error against
    /// fit error. `None` without a fit.
    pub fn verdict(&self) -> Option<String> {
        let (parts, _) = self.judgement()?;
        Some(if parts.is_empty() {
            "fitted".to_string()
        } else {
            parts.join("; ")
        })
    }

    /// Whether the verdict finds something to act on: a residual above the noise, holds that
    /// disagree, a held-out error far above the fit's, a fit that passes through every pose.
    pub fn has_findings(&self) -> bool {
        self.judgement().is_some_and(|(_, found)| found)
    }

    /// The verdict's phrases and whether any is a finding to act on.
    fn judgement(&self) -> Option<(Vec<String>, bool)> {
        let fit = self.fit.as_ref().ok()?;
        let mut parts = Vec::new();
        let mut found = false;
        let (noise, misses) = if self.sensor == Sensor::Mag {
            (
                "sample noise",
                "a field that changed during the recording (iron nearby, the board carried \
                 elsewhere, parts recorded apart) or a sensor that moved on its mount",
            )
        } else {
            (
                "pose noise",
                "temperature, non-linearity, motion during holds",
            )
        };
        let noise = self.noise_test_of.as_deref().unwrap_or(noise);
        if let Some(test) = &self.noise_test {
            // √(χ²/dof): the residual in units of what the poses' own noise leaves.
            let ratio = test.reduced().sqrt();
            let figures = format!(
                "χ² = {:.1} on {} dof, {}",
                test.chi2,
                test.dof,
                test.p_text()
            );
            found |= !test.consistent();
            parts.push(match (self.sensor, test.consistent()) {
                (Sensor::Gyro, true) => {
                    format!("the holds agree on one bias within their noise ({figures})")
                }
                (Sensor::Gyro, false) => format!(
                    "the holds' means scatter {ratio:.1}× their noise ({figures}): the bias \
                     moved between holds (temperature, drift) or the board turned during one"
                ),
                (_, true) => {
                    format!("residual is at the noise floor ({ratio:.1}× the {noise}: {figures})")
                }
                (_, false) => format!(
                    "residual is {ratio:.1}× the {noise} ({figures}): the model misses \
                     something ({misses})"
                ),
            });
        } else if let Some(floor) = self.noise_floor.filter(|f| *f > 0.0) {
            let ratio = fit.rms / floor;
            // Noise never leaves a residual a millionth of its floor: the fit has as many
            // unknowns as equations and passes through every pose. An iterative fit stops
            // short of exact, so the count decides where it is known.
            let determined = self.sensor == Sensor::Accel
                && self.n_poses > 0
                && self.n_poses <= super::chain::unknowns(fit.method);
            let exact = ratio < 1e-6 || determined;
            found |= exact || ratio > 3.0;
            if exact {
                parts.push(
                    "the fit passes through every pose exactly (as many unknowns as poses), so \
                     its residual says nothing of its accuracy; add poses"
                        .to_string(),
                );
            } else if ratio <= 3.0 {
                parts.push(format!(
                    "residual is at the noise floor ({ratio:.1}× the {noise})"
                ));
            } else {
                parts.push(format!(
                    "residual is {ratio:.1}× the {noise}: the model misses something ({misses})"
                ));
            }
        }
        if self.sensor == Sensor::Gyro && self.n_poses == 1 && fit.loo_rms.is_none() {
            // A single hold's mean is its own fit: the residual is zero by construction and
            // there is no other hold to test it on.
            parts.push(
                "one hold: the bias is its mean (± the standard error of that mean); with no \
                 second hold nothing is held out, so drift between holds (temperature, time) is \
                 not seen: record two or more holds apart in time to check it"
                    .to_string(),
            );
        }
        if let Some(loo) = fit.loo_rms {
            if fit.rms > 0.0 && loo > 3.0 * fit.rms {
                found = true;
                parts.push(format!(
                    "held-out error is {:.1}× the fit error: more poses are needed",
                    loo / fit.rms
                ));
            } else {
                parts.push("held-out error agrees with the fit error".to_string());
            }
        }
        if self.sensor == Sensor::Mag {
            parts.push(format!("{} samples over the sphere", self.n_samples));
            if self.noise_floor.is_none() {
                parts.push("too few samples to estimate their noise".to_string());
            }
        }
        Some((parts, found))
    }
}

/// Expected relative residual of a norm fit from the pose noise: the standard error of each
/// pose mean divided by its distance from the offset, as an RMS over the poses.
pub fn pose_noise_floor(poses: &[Pose], fit: &Fit) -> Option<f64> {
    let values: Vec<f64> = poses
        .iter()
        .map(|p| {
            let se = (p.var_of_mean().sum() / 3.0).sqrt();
            se / (p.mean - fit.cal.b).norm()
        })
        .filter(|v| v.is_finite())
        .collect();
    (!values.is_empty())
        .then(|| (values.iter().map(|v| v * v).sum::<f64>() / values.len() as f64).sqrt())
}

/// The χ² test of a norm fit's residual against its poses' own noise, as the residual analysis
/// tests it ([`crate::stats::chi_square`]): each pose's relative residual `|A(x−b)|/ref − 1`
/// weighed by the standard error of its mean carried to the norm, `σ'ᵢ = |(Aᵀŷᵢ)∘σᵢ|/ref`
/// (`ŷ` the calibrated direction), on `N − unknowns` degrees of freedom; with the RMS of the
/// `σ'ᵢ`, the floor printed beside it. `sigmas` are the poses' standard errors
/// ([`crate::still::StillReport::pose_sigmas`]); `None` when one is missing or the model has
/// as many unknowns as there are poses.
pub fn norm_noise_test(
    poses: &[Pose],
    sigmas: &[Option<Vec3>],
    fit: &Fit,
    unknowns: usize,
) -> Option<(ChiSquareTest, f64)> {
    if poses.len() != sigmas.len() || poses.len() <= unknowns || fit.reference <= 0.0 {
        return None;
    }
    let (mut chi2, mut floor2) = (0.0, 0.0);
    for (pose, sigma) in poses.iter().zip(sigmas) {
        let y = fit.cal.a * (pose.mean - fit.cal.b);
        let norm = y.norm();
        let spread = (fit.cal.a.transpose() * (y / norm))
            .component_mul(&(*sigma)?)
            .norm()
            / fit.reference;
        let residual = norm / fit.reference - 1.0;
        if !(spread > 0.0 && spread.is_finite() && residual.is_finite()) {
            return None;
        }
        chi2 += (residual / spread).powi(2);
        floor2 += spread * spread;
    }
    Some((
        ChiSquareTest::new(chi2, poses.len(), unknowns),
        (floor2 / poses.len() as f64).sqrt(),
    ))
}

/// The χ² test of a norm fit of a stream of samples (the magnetometer's): the relative residual
/// `|A(x−b)|/ref − 1` of every sample, averaged over consecutive windows of `window` samples
/// (at most `max_windows`, evenly spread), each mean against the standard error of such a mean,
/// on `windows − unknowns` degrees of freedom.
///
/// The norm is taken per sample before averaging, so a board turning within a window does not
/// pull the mean inward (a mean of raw readings over a turn lies inside the ellipsoid). The
/// standard error comes from the residual's first differences, as
/// [`crate::stats::autocorrelation`] takes it (slow variation, which is what the test looks
/// for, hardly enters them; correlated noise is corrected by the AR(1) `n_eff`), pooled over all
/// windows: the noise variance and its lag-1 correlation estimated from one window's 19
/// differences would scatter by tens of per cent and bias χ² (its correlation is clipped at
/// zero, its variance enters inverted). `None` with fewer windows than `unknowns + 1`.
pub fn stream_noise_test(
    samples: &[Vec3],
    fit: &Fit,
    window: usize,
    max_windows: usize,
    unknowns: usize,
) -> Option<ChiSquareTest> {
    let window = window.max(4);
    let count = samples.len() / window;
    if count <= unknowns || max_windows == 0 || fit.reference <= 0.0 {
        return None;
    }
    let residual = |x: &Vec3| (fit.cal.a * (x - fit.cal.b)).norm() / fit.reference - 1.0;
    let stride = count.div_ceil(max_windows).max(1);
    let mut means = Vec::with_capacity(count.div_ceil(stride));
    // Per window: differences centred on the window's own mean difference (a steady trend
    // within the window is not noise); pooled sums of their squares and lag-1 products.
    let (mut d_var, mut d_cov, mut d_count) = (0.0, 0.0, 0usize);
    let mut r = Vec::with_capacity(window);
    for w in (0..count).step_by(stride) {
        r.clear();
        r.extend(samples[w * window..(w + 1) * window].iter().map(residual));
        if r.iter().any(|v| !v.is_finite()) {
            return None;
        }
        means.push(r.iter().sum::<f64>() / window as f64);
        let d_mean = (r[window - 1] - r[0]) / (window - 1) as f64;
        let mut previous: Option<f64> = None;
        for pair in r.windows(2) {
            let d = pair[1] - pair[0] - d_mean;
            d_var += d * d;
            if let Some(p) = previous {
                d_cov += p * d;
            }
            previous = Some(d);
            d_count += 1;
        }
    }
    if d_var.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) || means.len() <= unknowns {
        return None;
    }
    let rho = (1.0 + 2.0 * d_cov / d_var).clamp(0.0, MAX_NOISE_CORRELATION);
    let white_var = d_var / d_count as f64 / (2.0 * (1.0 - rho));
    let n_eff = (window as f64 * (1.0 - rho) / (1.0 + rho)).max(1.0);
    let var_of_mean = white_var / n_eff;
    let chi2 = means.iter().map(|m| m * m / var_of_mean).sum();
    Some(ChiSquareTest::new(chi2, means.len(), unknowns))
}

/// The χ² test of a gyroscope bias against its holds' own noise: every hold's mean less the
/// bias, per axis, weighed by the hold's standard error, on `3N − 3` degrees of freedom; with
/// the RMS standard error in the data's units. `None` for fewer than two holds or when one has
/// no standard error.
pub fn bias_noise_test(
    poses: &[Pose],
    sigmas: &[Option<Vec3>],
    fit: &Fit,
) -> Option<ChiSquareTest> {
    if poses.len() < 2 || poses.len() != sigmas.len() {
        return None;
    }
    let mut chi2 = 0.0;
    for (pose, sigma) in poses.iter().zip(sigmas) {
        let sigma = (*sigma)?;
        for k in 0..3 {
            let weighted = (pose.mean[k] - fit.cal.b[k]) / sigma[k];
            if !(sigma[k] > 0.0 && weighted.is_finite()) {
                return None;
            }
            chi2 += weighted * weighted;
        }
    }
    Some(ChiSquareTest::new(chi2, 3 * poses.len(), 3))
}

/// Most samples the sample noise floor is averaged over: evenly spaced, they give its RMS to
/// about 1 % (a mean of squares over 10⁴ values), at a fixed cost on a long recording.
const NOISE_FLOOR_SAMPLES: usize = 10_000;

/// Expected relative residual of a norm fit of single samples (the magnetometer's) from their
/// noise per axis `noise` (file units): each sample's noise carried to the norm
/// `|A·(x − b)|` to first order, `σ_r² = Σ_k (Aᵀn̂)_k² σ_k²` with `n̂` the calibrated
/// direction, divided by that norm, as an RMS over (at most [`NOISE_FLOOR_SAMPLES`] of) the
/// samples.
pub fn sample_noise_floor(points: &[Vec3], fit: &Fit, noise: &Vec3) -> Option<f64> {
    let step = points.len().div_ceil(NOISE_FLOOR_SAMPLES).max(1);
    let (sum, count) = points
        .iter()
        .step_by(step)
        .filter_map(|x| {
            let y = fit.cal.a * (x - fit.cal.b);
            let norm = y.norm();
            let gradient = fit.cal.a.transpose() * (y / norm);
            let radial = gradient.component_mul(noise).norm();
            let relative = radial / norm;
            relative.is_finite().then_some(relative * relative)
        })
        .fold((0.0, 0_usize), |(s, n), v| (s + v, n + 1));
    (count > 0).then(|| (sum / count as f64).sqrt())
}

/// The calibration of a recording: every requested sensor's outcome and what it rests on.
#[derive(Debug, Clone)]
pub struct RecordingCalibration {
    /// Per sensor, in the order asked for.
    pub sensors: Vec<SensorOutcome>,
    /// Local gravity used, m/s².
    pub gravity_mps2: f64,
    /// Field magnitude used as the magnetometer's reference, µT (`None`: normalised to 1).
    pub field_ut: Option<f64>,
    /// One line on the still intervals found, when any were looked for.
    pub still_summary: Option<String>,
    /// Warnings from the input checks.
    pub warnings: Vec<String>,
    /// Where it came from.
    pub provenance: Provenance,
}

impl RecordingCalibration {
    /// The outcome of `sensor`, if it was asked for.
    pub fn sensor(&self, sensor: Sensor) -> Option<&SensorOutcome> {
        self.sensors.iter().find(|s| s.sensor == sensor)
    }

    /// What went wrong, one sentence per distinct reason naming every sensor it stopped
    /// (`"accel and gyro not fitted: …"`, `"mag not aligned to the accelerometer …"`): the
    /// sensors that were not fitted, and a magnetometer that could not be aligned to the
    /// accelerometer fitted with it (left out of the parameter file). Empty when all is well.
    pub fn failures(&self) -> Vec<String> {
        let reasons: Vec<(&str, String)> = self
            .sensors
            .iter()
            .filter_map(|r| {
                let reason = match &r.fit {
                    Err(e) => format!("not fitted: {e}"),
                    Ok(_) => r.alignment_failure()?,
                };
                Some((r.sensor.name(), reason))
            })
            .collect();
        once_per_reason(&reasons)
    }
}

/// `"{names} {reason}"` once per distinct reason, the names of every item with that reason
/// joined by "and", in order of first appearance (the accelerometer and the gyroscope share
/// the still intervals, so they often fail for the same reason, which is then said once).
pub fn once_per_reason(reasons: &[(&str, String)]) -> Vec<String> {
    let mut sentences: Vec<(Vec<&str>, &str)> = Vec::new();
    for (name, reason) in reasons {
        match sentences.iter_mut().find(|(_, r)| r == reason) {
            Some((names, _)) => names.push(name),
            None => sentences.push((vec![name], reason)),
        }
    }
    sentences
        .into_iter()
        .map(|(names, reason)| format!("{} {reason}", names.join(" and ")))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::{Calibration, Mat3, Method, Vec3};

    /// An accelerometer outcome of `method` on `poses` poses with residual `rms` over a noise
    /// floor of 1e-4 (no χ² test: the verdict reads the floor).
    fn outcome(method: Method, poses: usize, rms: f64) -> SensorOutcome {
        let cal = Calibration {
            a: Mat3::identity(),
            b: Vec3::zeros(),
        };
        let mut fit = crate::fit::Fit::closed_form(method, cal, &[], 9.81, 1.0);
        fit.rms = rms;
        let mut out = SensorOutcome::without_fit(Sensor::Accel, "m/s²", String::new());
        out.fit = Ok(fit);
        out.n_poses = poses;
        out.noise_floor = Some(1e-4);
        out
    }

    #[test]
    fn a_fit_with_as_many_unknowns_as_poses_is_called_exact_whatever_its_solver_left() {
        // lm stops at its tolerance, a few percent of the floor, where Chen's closed form is
        // exact to rounding: both pass through nine poses with nine unknowns.
        for (method, rms) in [(Method::Lm, 9e-7), (Method::Chen, 1e-14)] {
            let verdict = outcome(method, 9, rms).verdict().unwrap_or_default();
            assert!(
                verdict.contains("passes through every pose exactly"),
                "{verdict}"
            );
        }
        // With a pose more the same residual is at the floor.
        let verdict = outcome(Method::Lm, 10, 9e-7).verdict().unwrap_or_default();
        assert!(verdict.contains("at the noise floor"), "{verdict}");
    }
}
