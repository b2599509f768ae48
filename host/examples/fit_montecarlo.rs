//! Monte Carlo efficiency of the LM norm-model fit against the Cramér–Rao bound, and the bias of
//! the algebraic fits, on a 12-pose accelerometer set and 300-sample magnetometer clouds.
//!
//! For each scenario the truth and the orientations are fixed and only the noise is redrawn. Per
//! parameter (`A11 A12 A13 A22 A23 A33 b1 b2 b3`, upper-triangular gauge) it prints the CRB
//! standard deviation from the true Jacobian (`norm_lm::cramer_rao_bound`), the LM RMSE, the
//! efficiency `CRB/MSE` (1 is optimal; target ≥ 0.9), and the bias of each method in units of
//! the CRB standard deviation (|bias| above ~3/√trials·√(MSE/CRB) is significant), and the
//! efficiency of the other methods too. The six-position fit is given the poses' labelled
//! directions (it cannot use the 45° tilts otherwise).
//!
//! Run: `cargo run --release -p imucal --example fit_montecarlo`.

use imucal::fit::axis_aligned::{fit_axis_aligned, fit_axis_aligned_poses};
use imucal::fit::li::{fit_li, LiOptions};
use imucal::fit::linalg::upper_triangular_gauge;
use imucal::fit::merayo::fit_merayo;
use imucal::fit::norm_lm::{cramer_rao_bound, fit_accel_lm_detailed, fit_mag_lm};
use imucal::fit::six_position::fit_six_position;
use imucal::fit::{Calibration, Fit, FitError, Mat3, Vec3};
use imucal::synthetic::{
    accel_poses, cap_directions, directions, mag_samples, random_calibration, rng,
    sphere_directions, PoseSet, TruthSpec,
};

const NAMES: [&str; 9] = ["A11", "A12", "A13", "A22", "A23", "A33", "b1", "b2", "b3"];

fn upper_params(cal: &Calibration) -> [f64; 9] {
    let r = upper_triangular_gauge(&cal.a);
    [
        r[(0, 0)],
        r[(0, 1)],
        r[(0, 2)],
        r[(1, 1)],
        r[(1, 2)],
        r[(2, 2)],
        cal.b.x,
        cal.b.y,
        cal.b.z,
    ]
}

/// Running sums of the error of one method.
struct Tally {
    name: &'static str,
    sum: [f64; 9],
    sum_sq: [f64; 9],
    count: usize,
    failures: usize,
}

impl Tally {
    fn new(name: &'static str) -> Self {
        Self {
            name,
            sum: [0.0; 9],
            sum_sq: [0.0; 9],
            count: 0,
            failures: 0,
        }
    }

    fn add(&mut self, fit: Result<Fit, FitError>, truth: &[f64; 9]) {
        match fit {
            Ok(f) if f.cal.a.iter().chain(f.cal.b.iter()).all(|v| v.is_finite()) => {
                let est = upper_params(&f.cal);
                for k in 0..9 {
                    let e = est[k] - truth[k];
                    self.sum[k] += e;
                    self.sum_sq[k] += e * e;
                }
                self.count += 1;
            }
            _ => self.failures += 1,
        }
    }

    fn bias(&self, k: usize) -> f64 {
        self.sum[k] / self.count.max(1) as f64
    }

    fn mse(&self, k: usize) -> f64 {
        self.sum_sq[k] / self.count.max(1) as f64
    }
}

fn print_table(title: &str, truth: &[f64; 9], crb: &[f64; 9], lm: &Tally, others: &[Tally]) {
    println!("\n### {title}\n");
    print!("| param | truth | CRB σ | LM RMSE | efficiency CRB/MSE | LM bias/σ_CRB |");
    for o in others {
        print!(" {} bias/σ_CRB, eff. |", o.name);
    }
    println!();
    print!("|---|---:|---:|---:|---:|---:|");
    for _ in others {
        print!("---:|");
    }
    println!();
    for k in 0..9 {
        let sd = crb[k];
        print!(
            "| {} | {:.5} | {:.3e} | {:.3e} | {:.3} | {:+.2} |",
            NAMES[k],
            truth[k],
            sd,
            lm.mse(k).sqrt(),
            sd * sd / lm.mse(k),
            lm.bias(k) / sd
        );
        for o in others {
            print!(" {:+.1}, {:.2} |", o.bias(k) / sd, sd * sd / o.mse(k));
        }
        println!();
    }
    print!("\nTrials used: LM {} (failed {})", lm.count, lm.failures);
    for o in others {
        print!(", {} {} (failed {})", o.name, o.count, o.failures);
    }
    println!(".");
}

fn accelerometer(trials: usize) {
    let g = 9.81;
    let sigma = 0.02; // m/s² per sample
    let samples = 100;
    let spec = TruthSpec {
        scale_error: 0.05,
        cross_axis: 0.02,
        offset_ratio: 0.05,
        reference: g,
        upper_triangular: true,
    };
    let truth = random_calibration(&mut rng(1), &spec);
    let mut r = rng(2);
    let dirs = directions(&mut r, PoseSet::TwelvePositions);
    let ainv = truth.a.try_inverse().unwrap_or_else(Mat3::identity);
    let clean: Vec<Vec3> = dirs.iter().map(|u| ainv * (u * g) + truth.b).collect();
    let sigma_mean = sigma / (samples as f64).sqrt();
    let Some(crb) = cramer_rao_bound(&clean, &vec![sigma_mean; clean.len()], &truth) else {
        println!("the 12-pose set does not determine the parameters");
        return;
    };
    let crb_sd: [f64; 9] = std::array::from_fn(|k| crb[(k, k)].sqrt());
    let t = upper_params(&truth);
    let mut lm = Tally::new("LM");
    let mut others = [
        Tally::new("six-position"),
        Tally::new("Li"),
        Tally::new("axis-aligned"),
    ];
    for _ in 0..trials {
        let poses = accel_poses(&mut r, &truth, &dirs, g, sigma, samples);
        lm.add(fit_accel_lm_detailed(&poses, g).map(|o| o.fit), &t);
        others[0].add(fit_six_position(&poses, Some(&dirs), g), &t);
        let means: Vec<Vec3> = poses.iter().map(|p| p.mean).collect();
        others[1].add(
            fit_li(
                &means,
                g,
                LiOptions {
                    subtract_mean: true,
                },
            ),
            &t,
        );
        others[2].add(fit_axis_aligned_poses(&poses, g), &t);
    }
    print_table(
        &format!(
            "Accelerometer: 12 positions, σ = {sigma} m/s² per sample × {samples} samples, {trials} trials"
        ),
        &t,
        &crb_sd,
        &lm,
        &others,
    );
}

fn magnetometer(trials: usize, sigma: f64, cap_deg: f64, seed: u64) {
    let field = 50.0;
    let spec = TruthSpec {
        scale_error: 0.2,
        cross_axis: 0.05,
        offset_ratio: 2.0,
        reference: field,
        upper_triangular: true,
    };
    let truth = random_calibration(&mut rng(seed), &spec);
    let mut r = rng(seed + 1);
    let dirs = if cap_deg >= 180.0 {
        sphere_directions(&mut r, 300)
    } else {
        cap_directions(&mut r, 300, Vec3::new(0.3, -0.5, 0.8), cap_deg)
    };
    let ainv = truth.a.try_inverse().unwrap_or_else(Mat3::identity);
    let clean: Vec<Vec3> = dirs.iter().map(|u| ainv * (u * field) + truth.b).collect();
    let Some(crb) = cramer_rao_bound(&clean, &vec![sigma; clean.len()], &truth) else {
        println!("the sample set does not determine the parameters");
        return;
    };
    let crb_sd: [f64; 9] = std::array::from_fn(|k| crb[(k, k)].sqrt());
    let t = upper_params(&truth);
    let mut lm = Tally::new("LM");
    let mut others = [
        Tally::new("Li"),
        Tally::new("Merayo"),
        Tally::new("axis-aligned"),
    ];
    for _ in 0..trials {
        let points = mag_samples(&mut r, &truth, &dirs, field, sigma);
        lm.add(fit_mag_lm(&points, field), &t);
        others[0].add(
            fit_li(
                &points,
                field,
                LiOptions {
                    subtract_mean: true,
                },
            ),
            &t,
        );
        others[1].add(fit_merayo(&points, field, true), &t);
        others[2].add(fit_axis_aligned(&points, field), &t);
    }
    let coverage = if cap_deg >= 180.0 {
        "full sphere".to_string()
    } else {
        format!("{cap_deg}° cap")
    };
    print_table(
        &format!("Magnetometer: 300 samples, {coverage}, σ = {sigma} µT per axis (field 50 µT), {trials} trials"),
        &t,
        &crb_sd,
        &lm,
        &others,
    );
}

fn main() {
    let trials = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(2000);
    println!("## Norm-model LM vs. the Cramér–Rao bound ({trials} noise draws per scenario)");
    accelerometer(trials);
    magnetometer(trials, 0.5, 180.0, 10);
    magnetometer(trials, 2.5, 180.0, 20);
    magnetometer(trials, 0.5, 90.0, 30);
}
