//! Coverage of the reported uncertainties (see `imucal::coverage`): prints the RESULTS.md table.
//!
//! `cargo run --release --example uncertainty_coverage -p imucal -- [trials] [seed]`

use imucal::coverage::coverage;

fn main() {
    let mut args = std::env::args().skip(1);
    let trials: usize = args.next().and_then(|a| a.parse().ok()).unwrap_or(1000);
    let seed: u64 = args.next().and_then(|a| a.parse().ok()).unwrap_or(2026);
    println!("Coverage of the 95 % intervals over {trials} simulated recordings (seed {seed})\n");
    println!("| sensor | method | recordings with σ | refused / no σ | parameters | covered |");
    println!("|---|---|---:|---:|---:|---:|");
    for row in coverage(trials, seed) {
        println!(
            "| {} | {} | {} | {} | {} | {:.1} % |",
            row.sensor,
            row.method,
            row.trials,
            row.without_interval,
            row.total,
            100.0 * row.fraction()
        );
    }
}
