//! Runs every fitting method on every real recording in a folder and prints markdown tables of
//! fit RMS and leave-one-pose-out RMS (and, for magnetometers, the fitted field magnitude).
//!
//! `cargo run --release -p imucal --example real_data_table -- [DIR]`; DIR defaults to
//! `/work/shared/data/real` if present, else the repository's `data/real`.

use std::path::{Path, PathBuf};

use imucal::pipeline::methods;

use imucal::fit::{Fit, FitError, Method};
use imucal::recording::{LoadOptions, Recording, Sensor};
use imucal::still::{find_still, StillOptions};

#[path = "common/real_units.rs"]
mod real_units;
use real_units::units_of;

fn short(error: &FitError) -> String {
    let text = error.to_string();
    let text = text
        .strip_prefix("the data cannot determine the calibration: ")
        .unwrap_or(&text)
        .to_string();
    let cut: String = text.chars().take(70).collect();
    if cut.len() < text.len() {
        format!("refused: {cut}…")
    } else {
        format!("refused: {cut}")
    }
}

fn row(method: Method, result: &Result<Fit, FitError>, extra: impl Fn(&Fit) -> String) -> String {
    match result {
        Ok(fit) => format!(
            "| {} | {:.3e} | {} | {} |",
            method.name(),
            fit.rms,
            fit.loo_rms.map_or("—".to_string(), |l| format!("{l:.3e}")),
            extra(fit)
        ),
        Err(e) => format!("| {} | — | — | {} |", method.name(), short(e)),
    }
}

fn run(path: &Path) -> Result<(), Box<dyn std::error::Error>> {
    let name = path
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or_default()
        .to_string();
    let units = units_of(&name);
    let recording = Recording::load(
        path,
        &LoadOptions {
            units,
            ..Default::default()
        },
    )?;
    println!("\n### `{name}`\n");
    let still = if recording.time_is_index {
        None
    } else {
        find_still(&recording, &StillOptions::default()).ok()
    };
    match &still {
        Some(s) => println!("{}.\n", s.summary()),
        None => println!("No time column: still intervals not detected.\n"),
    }
    if let Some(still) = &still {
        let poses = still.poses(Sensor::Accel);
        if recording.has(Sensor::Accel) && !poses.is_empty() {
            println!(
                "Accelerometer ({} poses, relative RMS of |a|/g − 1):\n",
                poses.len()
            );
            println!("| method | fit RMS | leave-one-out RMS | note |\n|---|---|---|---|");
            for method in methods::ACCEL_METHODS {
                let result =
                    methods::fit_accel(method, &poses, imucal::recording::STANDARD_GRAVITY);
                println!("{}", row(method, &result, |_| String::new()));
            }
            println!();
        }
        let gyro = still.poses(Sensor::Gyro);
        if recording.has(Sensor::Gyro) && !gyro.is_empty() {
            let scale = recording.units.to_si(Sensor::Gyro).unwrap_or(1.0);
            let unit = if recording.units.to_si(Sensor::Gyro).is_some() {
                "rad/s"
            } else {
                "counts"
            };
            println!(
                "Gyroscope bias ({} poses, RMS of pose bias about the common bias, {unit}):\n",
                gyro.len()
            );
            println!("| method | fit RMS | leave-one-out RMS | note |\n|---|---|---|---|");
            println!(
                "{}\n",
                row(
                    Method::GyroBias,
                    &methods::fit_gyro(Method::GyroBias, &gyro, scale),
                    |_| String::new()
                )
            );
        }
    }
    if let Some(mag) = recording.samples(Sensor::Mag) {
        let points = methods::thin(mag, 2000);
        let factor = recording.units.to_si(Sensor::Mag);
        let unit = recording.units.symbol(Sensor::Mag);
        println!(
            "Magnetometer ({} of {} samples, field normalised to 1; relative RMS of |m| − 1; fitted field = 1/∛det A):\n",
            points.len(),
            mag.len()
        );
        println!("| method | fit RMS | leave-one-out RMS | fitted field |\n|---|---|---|---|");
        for method in methods::MAG_METHODS {
            let result = methods::fit_mag(method, &points, 1.0);
            println!(
                "{}",
                row(method, &result, |fit| {
                    let field = 1.0 / fit.cal.a.determinant().abs().cbrt();
                    match factor {
                        Some(f) => format!("{field:.4} {unit} = {:.2} µT", field * f),
                        None => format!("{field:.1} {unit}"),
                    }
                })
            );
        }
        println!();
    }
    Ok(())
}

fn main() {
    let dir = std::env::args()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            let shared = PathBuf::from("/work/shared/data/real");
            if shared.is_dir() {
                shared
            } else {
                PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data/real")
            }
        });
    let mut files: Vec<PathBuf> = match std::fs::read_dir(&dir) {
        Ok(entries) => entries.filter_map(|e| e.ok().map(|e| e.path())).collect(),
        Err(e) => {
            eprintln!("cannot list `{}`: {e}", dir.display());
            std::process::exit(1);
        }
    };
    files.retain(|p| {
        p.extension().is_some_and(|e| e == "csv")
            && !p
                .file_stem()
                .and_then(|s| s.to_str())
                .is_some_and(|s| s.ends_with("_mag"))
    });
    files.sort();
    println!(
        "Real recordings in `{}`: every method on every set.",
        dir.display()
    );
    for file in files {
        if let Err(e) = run(&file) {
            println!("\n### `{}`\n\nnot read: {e}\n", file.display());
        }
    }
}
