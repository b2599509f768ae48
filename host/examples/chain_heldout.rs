//! Held-out norm error of every accelerometer model imucal offers and of the default chain on
//! the real 6-face and multi-pose recordings: the still holds (found and screened as `imucal fit`
//! does) are split by hold, every 4th hold held out; each model is fitted on the rest and scored
//! by the RMS of `(|A(x − b)| − g)/g` over the held-out holds. A second table pools the four
//! rotations of that split (holds `i % 4 == k` held out, k = 0…3), so every hold is held out once
//! and the figure rests on all holds rather than a quarter. Prints markdown tables and the ratio
//! of the default chain's error to the best model's.
//!
//! `cargo run --release -p imucal --example chain_heldout -- [DIR]`; DIR defaults to
//! `/work/shared/data/real` if present, else the repository's `data/real`.

use std::path::{Path, PathBuf};

use imucal::fit::{Calibration, Method, Pose};
use imucal::pipeline::methods::{fit_accel, ACCEL_METHODS};
use imucal::pipeline::{check_input, default_accel_chain, InputOptions};
use imucal::recording::{
    AccelUnit, GyroUnit, LoadOptions, MagUnit, Recording, Sensor, Units, STANDARD_GRAVITY,
};

/// The sets measured and their units (from each set's provenance note).
const SETS: [(&str, AccelUnit, GyroUnit); 5] = [
    (
        "imucal_nilspod_ferraris.csv",
        AccelUnit::Mps2,
        GyroUnit::Dps,
    ),
    (
        "imucal_ferraris_raw_annotated.csv",
        AccelUnit::Counts,
        GyroUnit::Counts,
    ),
    (
        "tsi_mpu6050_multipos.csv",
        AccelUnit::Counts,
        GyroUnit::Counts,
    ),
    (
        "imutk_xsens_multipos.csv",
        AccelUnit::Counts,
        GyroUnit::Counts,
    ),
    (
        "sf_mpu6050_hmc5883l_static_poses.csv",
        AccelUnit::G,
        GyroUnit::Dps,
    ),
];

/// Every `HOLD_OUT_EVERY`-th hold (the 4th, 8th, …) is held out.
const HOLD_OUT_EVERY: usize = 4;

/// Squared held-out residuals `((|A(x − b)| − g)/g)²` of `test`.
fn squared_errors(cal: &Calibration, test: &[Pose], g: f64) -> Vec<f64> {
    test.iter()
        .map(|p| ((cal.apply(&p.mean).norm() - g) / g).powi(2))
        .collect()
}

/// One model's pooled held-out errors over the splits asked for, or `None` when it was refused
/// in some split.
fn pooled(
    splits: &[(Vec<Pose>, Vec<Pose>)],
    fit: impl Fn(&[Pose]) -> Option<(Calibration, Method)>,
) -> Option<(f64, Vec<Method>)> {
    let mut squares = Vec::new();
    let mut chosen = Vec::new();
    for (train, test) in splits {
        let (cal, method) = fit(train)?;
        squares.extend(squared_errors(&cal, test, STANDARD_GRAVITY));
        chosen.push(method);
    }
    (!squares.is_empty()).then(|| {
        (
            (squares.iter().sum::<f64>() / squares.len() as f64).sqrt(),
            chosen,
        )
    })
}

/// The still holds of a set, found and screened as `imucal fit` does.
fn holds(dir: &Path, name: &str, accel: AccelUnit, gyro: GyroUnit) -> Result<Vec<Pose>, String> {
    let units = Units {
        accel,
        gyro,
        mag: MagUnit::Ut,
    };
    let options = LoadOptions {
        units,
        no_mag_sibling: true,
        ..Default::default()
    };
    let recording = Recording::load(&dir.join(name), &options).map_err(|e| e.to_string())?;
    let input = check_input(recording, &[Sensor::Accel], &InputOptions::default(), None);
    match &input.still {
        Some(still) => Ok(still.poses(Sensor::Accel)),
        None => Err(format!("no usable holds ({:?})", input.refusals)),
    }
}

/// Train/test splits: holds `i` with `i % HOLD_OUT_EVERY == offset` held out.
fn split(poses: &[Pose], offset: usize) -> (Vec<Pose>, Vec<Pose>) {
    let held_out = |i: &usize| i % HOLD_OUT_EVERY == offset;
    let pick = |keep: bool| -> Vec<Pose> {
        (0..poses.len())
            .filter(|i| held_out(i) != keep)
            .map(|i| poses[i].clone())
            .collect()
    };
    (pick(true), pick(false))
}

/// One table row: every method's pooled held-out RMS, the chain's, and the ratio to the best.
fn row(name: &str, splits: &[(Vec<Pose>, Vec<Pose>)]) -> Option<f64> {
    let g = STANDARD_GRAVITY;
    let mut cells = Vec::new();
    let mut best: Option<(f64, Method)> = None;
    for method in ACCEL_METHODS {
        match pooled(splits, |train| {
            fit_accel(method, train, g).ok().map(|f| (f.cal, method))
        }) {
            Some((e, _)) => {
                cells.push(format!("{e:.2e}"));
                if best.is_none_or(|(b, _)| e < b) {
                    best = Some((e, method));
                }
            }
            None => cells.push("refused".to_string()),
        }
    }
    let chain = pooled(splits, |train| {
        default_accel_chain(train, g)
            .ok()
            .map(|c| (c.fit.cal, c.fit.method))
    });
    let ratio = chain.as_ref().zip(best).map(|((e, _), (b, _))| e / b);
    let chain_cell = chain.map_or("refused".to_string(), |(e, chosen)| {
        let mut names: Vec<&str> = chosen.iter().map(|m| m.name()).collect();
        names.dedup();
        format!("{e:.2e} ({})", names.join(", "))
    });
    let sizes: Vec<String> = splits
        .iter()
        .map(|(train, test)| format!("{}/{}", train.len(), test.len()))
        .collect();
    println!(
        "| `{name}` | {} | {} | {chain_cell} | {} | {} |",
        sizes.join(", "),
        cells.join(" | "),
        best.map_or("—".to_string(), |(_, m)| m.name().to_string()),
        ratio.map_or("—".to_string(), |r| format!("{r:.2}")),
    );
    ratio
}

fn table(dir: &Path, title: &str, offsets: &[usize]) {
    let names: Vec<&str> = ACCEL_METHODS.iter().map(|m| m.name()).collect();
    println!("\n{title}\n");
    println!(
        "| set | holds train/test | {} | default chain | best | chain/best |",
        names.join(" | ")
    );
    println!("|---|---|{}---|---|---|", "---|".repeat(names.len()));
    let mut worst: f64 = 0.0;
    for (name, accel, gyro) in SETS {
        match holds(dir, name, accel, gyro) {
            Err(e) => println!("| `{name}` | {e} |"),
            Ok(poses) => {
                let splits: Vec<_> = offsets.iter().map(|&k| split(&poses, k)).collect();
                if let Some(r) = row(name, &splits) {
                    worst = worst.max(r);
                }
            }
        }
    }
    println!("\nlargest chain/best ratio: {worst:.2} (target ≤ 1.5)");
}

/// The shared collection when present, else the repository's copies.
fn default_dir() -> PathBuf {
    let shared = PathBuf::from("/work/shared/data/real");
    let repo = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data/real");
    if shared.is_dir() {
        shared
    } else {
        repo
    }
}

fn main() {
    let dir = std::env::args()
        .nth(1)
        .map_or_else(default_dir, PathBuf::from);
    table(
        &dir,
        "Every 4th hold (the 4th, 8th, …) held out, held-out RMS of |a|/g − 1:",
        &[HOLD_OUT_EVERY - 1],
    );
    let all: Vec<usize> = (0..HOLD_OUT_EVERY).collect();
    table(
        &dir,
        "The four rotations of that split (each hold held out once), pooled RMS:",
        &all,
    );
}
