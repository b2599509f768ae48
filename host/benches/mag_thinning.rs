//! Held-out accuracy of the default magnetometer fit with every sample against the same fit on
//! 2000 samples, evenly thinned or thinned where redundant first (the library's
//! `thin_redundant`, which `--max-mag-samples` and sessions use), on the real recordings in
//! `data/real/`.
//!
//! Blocked cross-validation: each recording is cut into 10 contiguous blocks of time; each block
//! in turn is held out, the fit is made on the other nine (all their samples, or 2000 of them
//! evenly spaced), and the held-out error is the RMS of `|A(x − b)| − 1` over the block's
//! samples (reference 1, so the figure is relative and unit-free). Contiguous blocks hold out
//! orientations the fit did not see nearby, unlike a random split where neighbours leak.
//! Prints one line per recording. Run: `cargo bench -p imucal --bench mag_thinning`.

use std::path::PathBuf;
use std::time::Instant;

use imucal::fit::norm_lm::fit_mag_lm;
use imucal::fit::Vec3;
use imucal::pipeline::methods::thin_redundant;
use imucal::recording::{LoadOptions, Recording, Sensor};

const FOLDS: usize = 10;
const THINNED: usize = 2000;

fn thin(points: &[Vec3], max: usize) -> Vec<Vec3> {
    if points.len() <= max {
        return points.to_vec();
    }
    (0..max).map(|i| points[i * points.len() / max]).collect()
}

/// Picks at most the given number of training samples.
type Thinning = fn(&[Vec3], usize) -> Vec<Vec3>;

/// RMS held-out error over the folds, and the total fitting time in seconds; `thinning` picks
/// the training samples.
fn held_out(points: &[Vec3], thinning: Option<Thinning>) -> (f64, f64) {
    let n = points.len();
    let (mut sum_sq, mut count, mut seconds) = (0.0, 0usize, 0.0);
    for k in 0..FOLDS {
        let (lo, hi) = (k * n / FOLDS, (k + 1) * n / FOLDS);
        let train: Vec<Vec3> = points[..lo].iter().chain(&points[hi..]).copied().collect();
        let train = match thinning {
            Some(pick) => pick(&train, THINNED),
            None => train,
        };
        let start = Instant::now();
        let Ok(fit) = fit_mag_lm(&train, 1.0) else {
            continue;
        };
        seconds += start.elapsed().as_secs_f64();
        for x in &points[lo..hi] {
            let e = fit.cal.apply(x).norm() - 1.0;
            sum_sq += e * e;
            count += 1;
        }
    }
    ((sum_sq / count.max(1) as f64).sqrt(), seconds)
}

fn main() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data/real");
    for name in [
        "sf_mpu6050_hmc5883l_full_sphere_mag.csv",
        "tsm_qmc5883l_mag_rotation.csv",
    ] {
        let recording = Recording::load(&dir.join(name), &LoadOptions::default())
            .expect("the real recording reads");
        let points = recording
            .samples(Sensor::Mag)
            .expect("a magnetometer recording")
            .to_vec();
        let (all, t_all) = held_out(&points, None);
        let (thinned, t_thin) = held_out(&points, Some(thin));
        let (redundant, t_redundant) = held_out(&points, Some(thin_redundant));
        println!(
            "{name}: {} samples; held-out RMS all {all:.5e} ({t_all:.2} s for {FOLDS} fits), \
             thinned evenly to {THINNED} {thinned:.5e} ({t_thin:.2} s, {:+.2} %), where \
             redundant first {redundant:.5e} ({t_redundant:.2} s, {:+.2} %)",
            points.len(),
            100.0 * (thinned - all) / all,
            100.0 * (redundant - all) / all
        );
    }
}
