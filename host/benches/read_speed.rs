//! Speed of reading an 11-column recording (`t_s,ax,ay,az,gx,gy,gz,mx,my,mz,temp_c`) of 10⁶ rows,
//! generated here (seeded) into a temporary file; criterion's wall time, then the CPU time per
//! load. Run: `cargo bench -p imucal --bench read_speed`.

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
    // CPU time per load, independent of other work sharing the machine.
    const LOADS: usize = 5;
    if let Some(before) = common::cpu_seconds() {
        for _ in 0..LOADS {
            std::hint::black_box(Recording::load(&path, &LoadOptions::default()).map(|r| r.len()))
                .expect("the generated recording reads");
        }
        if let Some(after) = common::cpu_seconds() {
            let per_load = (after - before) / LOADS as f64;
            println!(
                "read/csv_11_columns_1e6_rows: {per_load:.3} CPU s per load, {:.2e} rows per CPU s",
                ROWS as f64 / per_load
            );
        }
    }
    let _ = std::fs::remove_file(&path);
}

criterion_group!(benches, bench_read);
criterion_main!(benches);
