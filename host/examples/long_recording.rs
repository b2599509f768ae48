//! Writes a long seeded 11-column recording for measuring `imucal fit` at scale (see
//! [`imucal::synthetic::write_long_recording`]).
//!
//! Run: `cargo run --release -p imucal --example long_recording -- ROWS OUT.csv`.

use std::io::Write;

fn main() -> std::io::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let (Some(rows), Some(out)) = (
        args.get(1).and_then(|s| s.parse::<usize>().ok()),
        args.get(2),
    ) else {
        eprintln!("usage: long_recording ROWS OUT.csv");
        std::process::exit(2);
    };
    let mut w = std::io::BufWriter::new(std::fs::File::create(out)?);
    imucal::synthetic::write_long_recording(rows, &mut w)?;
    w.flush()
}
