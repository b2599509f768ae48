//! The residual analysis (`imucal analyze`) on every real recording in a folder: one markdown row
//! per analysed sensor with the observations, the noise floor, the base model's χ²/dof, the
//! accepted effects and the fit and held-out RMS before and after (docs/RESULTS.md, "Residual
//! analysis on real recordings"). Gyroscope counts are converted with the documented
//! sensitivities; accelerometer and magnetometer residuals are relative.
//!
//! `cargo run --release -p imucal --example analysis_table -- [DIR]`; DIR defaults to the
//! repository's `data/real`.

use std::path::{Path, PathBuf};

use imucal::analysis::{analyse_recording, AnalysisOptions, EffectStatus};
use imucal::recording::{LoadOptions, Recording};
use imucal::still::{find_still, StillOptions};

#[path = "common/real_units.rs"]
mod real_units;
use real_units::units_of;

/// Gyroscope counts to rad/s for the sets stored in counts (documented sensitivities: Xsens
/// 1/6258 rad/s per count, MPU-6050 at ±250 °/s (π/180)/131, MaD-Lab raw (π/180)/16.4).
fn gyro_counts_to_rads(name: &str) -> Option<f64> {
    let dps = std::f64::consts::PI / 180.0;
    if name.starts_with("imutk_") {
        Some(1.0 / 6258.0)
    } else if name.starts_with("tsi_") {
        Some(dps / 131.0)
    } else if name.starts_with("imucal_ferraris_raw") {
        Some(dps / 16.4)
    } else {
        None
    }
}

fn run(path: &Path) -> Result<(), Box<dyn std::error::Error>> {
    let name = path
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or_default()
        .to_string();
    let recording = Recording::load(
        path,
        &LoadOptions {
            units: units_of(&name),
            ..Default::default()
        },
    )?;
    if recording.time_is_index {
        println!("| `{name}` | — | — | — | — | no time column | | |");
        return Ok(());
    }
    let still = find_still(&recording, &StillOptions::default())?;
    let counts = gyro_counts_to_rads(&name);
    let options = AnalysisOptions {
        gyro_scale: counts
            .or(recording.units.to_si(imucal::recording::Sensor::Gyro))
            .unwrap_or(1.0),
        gyro_scale_known: true,
        ..AnalysisOptions::default()
    };
    for (sensor, result) in analyse_recording(&recording, &still, &options).sensors {
        let a = match result {
            Ok(a) => a,
            Err(e) => {
                println!("| `{name}` | {sensor} | — | — | — | not analysed: {e} | | |");
                continue;
            }
        };
        let accepted: Vec<String> = a
            .effects
            .iter()
            .filter(|e| e.status == EffectStatus::Accepted)
            .map(|e| {
                format!(
                    "**{}** (score {:.0} %, p = {:.1e}, gain {:.1})",
                    e.kind.name(),
                    100.0 * e.score,
                    e.p_value,
                    e.gain
                )
            })
            .collect();
        let best_rejected = a
            .effects
            .iter()
            .filter(|e| e.status == EffectStatus::Rejected)
            .max_by(|x, y| x.score.total_cmp(&y.score))
            .map(|e| {
                format!(
                    "; best rejected {} (gain {:.2}, p = {:.2})",
                    e.kind.name(),
                    e.gain,
                    e.p_value
                )
            })
            .unwrap_or_default();
        let found = format!(
            "{}{}{}{}",
            if accepted.is_empty() {
                "nothing".to_string()
            } else {
                accepted.join(", ")
            },
            if a.unexplained {
                format!("; **unexplained** (χ²/dof {:.1})", a.test_after.reduced())
            } else {
                "; consistent with noise".to_string()
            },
            a.best_correlate
                .as_ref()
                .map(|(v, r)| format!(", correlate {v} (r = {r:.2})"))
                .unwrap_or_default(),
            best_rejected
        );
        println!(
            "| `{name}` | {sensor} | {} | {:.2e} | {:.1} ({:.0e}) | {found} | {:.2e} → {:.2e} | {:.2e} → {:.2e} |",
            a.observations.len(),
            a.noise_floor,
            a.test_before.reduced(),
            a.test_before.p_value,
            a.rms_before,
            a.rms_after,
            a.heldout_rms_before,
            a.heldout_rms_after
        );
    }
    Ok(())
}

fn main() {
    let dir = std::env::args()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data/real"));
    let mut files: Vec<PathBuf> = match std::fs::read_dir(&dir) {
        Ok(entries) => entries.filter_map(|e| e.ok().map(|e| e.path())).collect(),
        Err(e) => {
            eprintln!("cannot list `{}`: {e}", dir.display());
            std::process::exit(1);
        }
    };
    files.retain(|p| p.extension().is_some_and(|e| e == "csv"));
    files.sort();
    println!("| recording | sensor | obs | floor | base χ²/dof (p) | found | RMS fit before → after | held-out before → after |");
    println!("|---|---|---|---|---|---|---|---|");
    for path in &files {
        if let Err(e) = run(path) {
            println!("| `{}` | — | — | — | — | error: {e} | | |", path.display());
        }
    }
}
