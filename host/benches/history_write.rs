//! Time to record one calibration in the history: SQLite (WAL, synchronous commit) always,
//! PostgreSQL when `IMUCAL_TEST_PG_URL` names a server (`scripts/ci-postgres.sh` starts one).
//! Each write is one committed insert on an open store, as a station does per board; opening
//! the store (connection and schema check) is timed separately.
//! Run: `cargo bench -p imucal --bench history_write`.

#[path = "../tests/history_support/mod.rs"]
mod history_support;

use std::time::Instant;

use imucal::history::HistoryStore;

/// Records written per database.
const RECORDS: u64 = 300;

fn main() {
    // `cargo bench` passes `--bench`; a filter argument would name other benches.
    for location in history_support::databases("bench") {
        let opened = Instant::now();
        let mut store = HistoryStore::open(&location).expect("open");
        let open_ms = opened.elapsed().as_secs_f64() * 1e3;
        let records: Vec<_> = (0..RECORDS).map(history_support::board_record).collect();
        let mut times_ms: Vec<f64> = records
            .iter()
            .map(|record| {
                let start = Instant::now();
                store.record(record).expect("write");
                start.elapsed().as_secs_f64() * 1e3
            })
            .collect();
        let read = Instant::now();
        let back = store.records(None).expect("read").len();
        let read_ms = read.elapsed().as_secs_f64() * 1e3;
        times_ms.sort_by(f64::total_cmp);
        let mean = times_ms.iter().sum::<f64>() / times_ms.len() as f64;
        let pick = |q: f64| times_ms[((times_ms.len() - 1) as f64 * q).round() as usize];
        println!(
            "history write, {}: open {open_ms:.1} ms; per record mean {mean:.3} ms, median {:.3} ms, \
             p95 {:.3} ms ({RECORDS} records); reading all {back} back {read_ms:.1} ms",
            match location {
                imucal::history::DbLocation::Sqlite(_) => "SQLite",
                imucal::history::DbLocation::Postgres(_) => "PostgreSQL",
            },
            pick(0.5),
            pick(0.95),
        );
    }
}
