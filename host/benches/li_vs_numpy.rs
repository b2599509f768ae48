//! Li's ellipsoid fit (fit only) on an array of points shared with `scripts/bench-vs-numpy.sh`,
//! which runs numpy's algebra for the same fit on the same array and prints the ratio.
//!
//! Reads `IMUCAL_LI_POINTS` (raw little-endian f64 triples `x y z`), fits it
//! `IMUCAL_LI_REPEATS` times (default 21) on one thread and prints the median wall time in
//! milliseconds as `rust_li_ms <value>`. Without the variable it fits 10⁶ seeded synthetic
//! samples instead, so `cargo bench` also runs it on its own.

mod common;

use std::time::Instant;

use imucal::fit::li::{fit_li, LiOptions};
use imucal::fit::Vec3;
use imucal::synthetic::hard_and_soft_iron_cloud;

fn points() -> Vec<Vec3> {
    if let Ok(path) = std::env::var("IMUCAL_LI_POINTS") {
        let bytes = std::fs::read(&path).expect("IMUCAL_LI_POINTS names a readable file");
        let values: Vec<f64> = bytes
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
            .collect();
        return values
            .chunks_exact(3)
            .map(|c| Vec3::new(c[0], c[1], c[2]))
            .collect();
    }
    hard_and_soft_iron_cloud(1_000_000, 1)
}

fn main() {
    // `cargo bench` passes `--bench`; this binary takes no arguments of its own.
    let points = points();
    let repeats: usize = std::env::var("IMUCAL_LI_REPEATS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(21);
    let mut times = Vec::with_capacity(repeats);
    let mut centre = Vec3::zeros();
    let cpu_before = common::cpu_seconds();
    for _ in 0..repeats.max(1) {
        let start = Instant::now();
        let fit = fit_li(
            &points,
            1.0,
            LiOptions {
                subtract_mean: true,
            },
        )
        .expect("Li fits");
        times.push(start.elapsed().as_secs_f64() * 1e3);
        centre = fit.cal.b;
    }
    if let (Some(before), Some(after)) = (cpu_before, common::cpu_seconds()) {
        println!(
            "rust_li_cpu_ms {:.2}",
            (after - before) * 1e3 / repeats.max(1) as f64
        );
    }
    times.sort_by(f64::total_cmp);
    println!("points {}", points.len());
    println!(
        "rust_li_centre {:.9} {:.9} {:.9}",
        centre.x, centre.y, centre.z
    );
    println!("rust_li_ms {:.2}", times[times.len() / 2]);
}
