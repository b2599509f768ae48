//! Loads a recording LOADS times and prints its row count: a driver for measuring the reader
//! with `/usr/bin/time` or `perf`.
//!
//! Run: `cargo run --release -p imucal --example load_recording -- FILE.csv [LOADS]`.

use imucal::recording::{LoadOptions, Recording};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let Some(path) = args.get(1) else {
        eprintln!("usage: load_recording FILE.csv [LOADS]");
        std::process::exit(2);
    };
    let loads = args
        .get(2)
        .and_then(|s| s.parse::<usize>().ok())
        .unwrap_or(1);
    for _ in 0..loads {
        match Recording::load(std::path::Path::new(path), &LoadOptions::default()) {
            Ok(r) => println!("{} rows", r.len()),
            Err(e) => {
                eprintln!("{e}");
                std::process::exit(1);
            }
        }
    }
}
