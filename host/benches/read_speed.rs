//! Speed of reading an 11-column recording (`t_s,ax,ay,az,gx,gy,gz,mx,my,mz,temp_c`) of 10⁶ rows,
//! generated here (seeded) into a temporary file; criterion's wall time, then the median wall
//! time and the CPU time (both threads) per load. Run: `cargo bench -p imucal --bench read_speed`.

mod common;

use std::io::Write;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use imucal::recording::{LoadOptions, Recording};
use rand::{Rng, SeedableRng};

const ROWS: usize = 1_000_000;

/// A recording with the digits a logger writes: 100 Hz time, accelerometer and gyroscope to
/// five or six decimals, magnetometer to three, temperature to two.
fn write_recording(path: &std::path::Path) {
    let mut rng = rand::rngs::StdRng::seed_from_u64(17);
    let file = std::fs::File::create(path).expect("temporary file is writable");
    let mut out = std::io::BufWriter::new(file);
    writeln!(out, "t_s,ax,ay,az,gx,gy,gz,mx,my,mz,temp_c").expect("write");
    for i in 0..ROWS {
        let v: [f64; 9] = std::array::from_fn(|_| rng.gen_range(-1.0..1.0));
        writeln!(
            out,
            "{:.3},{:.5},{:.5},{:.5},{:.6},{:.6},{:.6},{:.3},{:.3},{:.3},{:.2}",
            i as f64 * 0.01,
            9.81 * v[0],
            9.81 * v[1],
            9.81 * v[2],
            0.1 * v[3],
            0.1 * v[4],
            0.1 * v[5],
            50.0 * v[6],
            50.0 * v[7],
            50.0 * v[8],
            25.0 + v[0]
        )
        .expect("write");
    }
    out.flush().expect("write");
}

fn bench_read(c: &mut Criterion) {
    let path = std::env::temp_dir().join(format!("imucal-read-speed-{}.csv", std::process::id()));
    write_recording(&path);
    let mut group = c.benchmark_group("read");
    group.sample_size(10);
    group.throughput(Throughput::Elements(ROWS as u64));
    group.bench_function("csv_11_columns_1e6_rows", |b| {
        b.iter(|| {
            Recording::load(&path, &LoadOptions::default())
                .map(|r| r.len())
                .expect("the generated recording reads")
        })
    });
    group.finish();
    // Wall time per load (median) and CPU time per load (both threads), outside criterion.
    const LOADS: usize = 5;
    let before = common::cpu_seconds();
    let mut walls: Vec<f64> = (0..LOADS)
        .map(|_| {
            let start = std::time::Instant::now();
            std::hint::black_box(Recording::load(&path, &LoadOptions::default()).map(|r| r.len()))
                .expect("the generated recording reads");
            start.elapsed().as_secs_f64()
        })
        .collect();
    walls.sort_by(f64::total_cmp);
    let wall = walls[LOADS / 2];
    println!(
        "read/csv_11_columns_1e6_rows: {wall:.3} s wall per load (median of {LOADS}), {:.2e} rows per s",
        ROWS as f64 / wall
    );
    if let (Some(before), Some(after)) = (before, common::cpu_seconds()) {
        let per_load = (after - before) / LOADS as f64;
        println!(
            "read/csv_11_columns_1e6_rows: {per_load:.3} CPU s per load, {:.2e} rows per CPU s",
            ROWS as f64 / per_load
        );
    }
    let _ = std::fs::remove_file(&path);
}

criterion_group!(benches, bench_read);
criterion_main!(benches);
