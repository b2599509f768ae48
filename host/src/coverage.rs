//! Coverage of the reported uncertainties: over many simulated recordings with a known truth,
//! the fraction of parameters whose 95 % interval `±k·σ` (σ from [`Fit::std`], `k` from
//! [`Fit::coverage_factor`]) contains the truth, per fit method and sensor.
//!
//! Each trial draws its own conditions: a random calibration, a per-sample noise level spanning
//! a factor of 16, a pose set (twelve positions, or 18 or 30 random orientations), and, at
//! random, the two errors the within-hold variance cannot see: placement error (the board held
//! 1° off the labelled orientation, which only the label-using six-position fit feels) and
//! tremor (a per-hold offset of the mean twice its white-noise standard error, as from slow
//! sway or correlated samples). Norm-model fits are compared in their gauge: the truth is drawn
//! upper-triangular. A well-calibrated method covers 95 %; `n` trials of `P` parameters are not
//! independent within a trial, so tolerances should be set on the number of trials.

use rand::Rng;

use crate::fit::chen::fit_chen;
use crate::fit::gyro_bias::fit_gyro_bias;
use crate::fit::merayo::fit_merayo;
use crate::fit::norm_lm::{fit_accel_lm_detailed, fit_mag_lm};
use crate::fit::six_position::fit_six_position;
use crate::fit::{Calibration, Fit, FitError, Pose, Vec3};
use crate::synthetic::{
    accel_poses, directions, mag_samples, perturb_directions, random_calibration, rng, PoseSet,
    TruthSpec,
};

/// Standard gravity, m/s².
const G: f64 = 9.806_65;
/// Earth-like field strength, µT.
const FIELD: f64 = 50.0;

/// Interval hits of one method on one sensor.
#[derive(Debug, Clone, PartialEq)]
pub struct CoverageCount {
    /// Method name ([`crate::fit::Method::name`]).
    pub method: &'static str,
    /// Sensor name.
    pub sensor: &'static str,
    /// Parameters whose interval contained the truth.
    pub covered: usize,
    /// Parameters compared.
    pub total: usize,
    /// Trials where the method refused the data or reported no σ.
    pub without_interval: usize,
    /// Trials compared.
    pub trials: usize,
}

impl CoverageCount {
    fn new(method: &'static str, sensor: &'static str) -> Self {
        Self {
            method,
            sensor,
            covered: 0,
            total: 0,
            without_interval: 0,
            trials: 0,
        }
    }

    /// Fraction of parameters covered (NaN before any comparison).
    pub fn fraction(&self) -> f64 {
        self.covered as f64 / self.total as f64
    }

    /// Count the parameters of `fit` that are fixed by its layout: entries of `A` with a
    /// non-zero σ, and `b`.
    fn add(&mut self, fit: Result<Fit, FitError>, truth: &Calibration, compare_a: bool) {
        let Some((fit, std)) = fit.ok().and_then(|f| f.std.map(|s| (f, s))) else {
            self.without_interval += 1;
            return;
        };
        self.trials += 1;
        let k = fit.coverage_factor;
        let mut check = |est: f64, truth: f64, sd: f64| {
            self.total += 1;
            if (est - truth).abs() <= k * sd {
                self.covered += 1;
            }
        };
        if compare_a {
            for (i, sd) in std.a.iter().enumerate() {
                if *sd > 0.0 {
                    check(fit.cal.a[i], truth.a[i], *sd);
                }
            }
        }
        for i in 0..3 {
            check(fit.cal.b[i], truth.b[i], std.b[i]);
        }
    }
}

/// Conditions of one simulated recording.
struct Conditions {
    dirs: Vec<Vec3>,
    sigma: f64,
    samples: usize,
    placement_deg: f64,
    tremor: f64,
}

fn draw_conditions<R: Rng + ?Sized>(r: &mut R) -> Conditions {
    let set = match r.gen_range(0..3) {
        0 => PoseSet::TwelvePositions,
        1 => PoseSet::Random(18),
        _ => PoseSet::Random(30),
    };
    Conditions {
        dirs: directions(r, set),
        sigma: [0.005, 0.02, 0.08][r.gen_range(0..3)],
        samples: [50, 200][r.gen_range(0..2)],
        placement_deg: if r.gen_bool(0.5) { 1.0 } else { 0.0 },
        tremor: if r.gen_bool(0.5) { 2.0 } else { 0.0 },
    }
}

/// Static holds at the true directions `true_dirs`, with each mean shifted by tremor of
/// `tremor` times its white-noise standard error (the within-hold variance does not show it).
fn holds<R: Rng + ?Sized>(
    r: &mut R,
    truth: &Calibration,
    true_dirs: &[Vec3],
    reference: f64,
    c: &Conditions,
) -> Vec<Pose> {
    let mut poses = accel_poses(r, truth, true_dirs, reference, c.sigma, c.samples);
    let se = c.sigma / (c.samples as f64).sqrt();
    for p in &mut poses {
        let shift = Vec3::from_fn(|_, _| gaussian(r)) * (c.tremor * se);
        p.mean += shift;
    }
    poses
}

fn gaussian<R: Rng + ?Sized>(r: &mut R) -> f64 {
    // Box–Muller; the uniform is kept away from 0 so the logarithm is finite.
    let u: f64 = r.gen_range(f64::MIN_POSITIVE..1.0);
    let v: f64 = r.gen_range(0.0..std::f64::consts::TAU);
    (-2.0 * u.ln()).sqrt() * v.cos()
}

/// Run `trials` simulated recordings from `seed` and count interval hits per method and sensor:
/// accelerometer (default LM, Chen, six-position), gyroscope bias, magnetometer (default LM,
/// Merayo).
pub fn coverage(trials: usize, seed: u64) -> Vec<CoverageCount> {
    let mut r = rng(seed);
    let mut lm = CoverageCount::new("lm", "accelerometer");
    let mut chen = CoverageCount::new("chen", "accelerometer");
    let mut six = CoverageCount::new("six-position", "accelerometer");
    let mut bias = CoverageCount::new("gyro-bias", "gyroscope");
    let mut mag_lm = CoverageCount::new("lm", "magnetometer");
    let mut merayo = CoverageCount::new("merayo", "magnetometer");
    for _ in 0..trials {
        let c = draw_conditions(&mut r);
        let accel_spec = TruthSpec {
            reference: G,
            upper_triangular: true,
            ..TruthSpec::default()
        };
        let truth = random_calibration(&mut r, &accel_spec);
        // The norm model does not care where the board points, so placement error is only
        // applied to the labelled six-position fit.
        let poses = holds(&mut r, &truth, &c.dirs, G, &c);
        lm.add(
            fit_accel_lm_detailed(&poses, G).map(|o| o.fit),
            &truth,
            true,
        );
        if c.dirs.len() == 12 {
            chen.add(fit_chen(&poses, G), &truth, true);
        }
        let placed = perturb_directions(&mut r, &c.dirs, c.placement_deg / 3f64.sqrt());
        let six_truth = random_calibration(
            &mut r,
            &TruthSpec {
                upper_triangular: false,
                ..accel_spec
            },
        );
        let labelled = holds(&mut r, &six_truth, &placed, G, &c);
        six.add(
            fit_six_position(&labelled, Some(&c.dirs), G),
            &six_truth,
            true,
        );

        // Gyroscope at rest: bias only, in rad/s (scale 1); tremor as sway between holds.
        let gyro_truth = Calibration {
            a: crate::fit::Mat3::identity(),
            b: Vec3::from_fn(|_, _| gaussian(&mut r) * 0.01),
        };
        let rest = vec![Vec3::zeros(); c.dirs.len().min(12)];
        let gyro_c = Conditions {
            sigma: c.sigma * 0.01,
            ..c
        };
        let still = holds(&mut r, &gyro_truth, &rest, 1.0, &gyro_c);
        bias.add(fit_gyro_bias(&still, 1.0), &gyro_truth, false);

        let mag_truth = random_calibration(
            &mut r,
            &TruthSpec {
                scale_error: 0.2,
                cross_axis: 0.05,
                offset_ratio: 1.0,
                reference: FIELD,
                upper_triangular: true,
            },
        );
        let tumble = directions(&mut r, PoseSet::Random(200));
        let points = mag_samples(&mut r, &mag_truth, &tumble, FIELD, gyro_c.sigma * 2000.0);
        mag_lm.add(fit_mag_lm(&points, FIELD), &mag_truth, true);
        merayo.add(fit_merayo(&points, FIELD, true), &mag_truth, true);
    }
    vec![lm, chen, six, bias, mag_lm, merayo]
}
