//! Speed of the whole fit of a 10⁶-row, 11-column recording (what `imucal fit` does short of
//! printing): reading, still detection and the input checks, then every sensor's default fit
//! (the accelerometer chain with its leave-one-pose-out, the gyroscope bias, the magnetometer LM
//! on every sample). Each stage is timed alone as well, and the CPU time of whole fits printed.
//! The recording is [`imucal::synthetic::write_long_recording`] in a temporary file. The
//! `stages` group times the parts of the checks changed for speed on the same recording: the
//! magnetometer stream's outlier screen and the windowed variances of still detection.
//! Run: `cargo bench -p imucal --bench fit_pipeline`.

mod common;

use std::io::Write;

use criterion::{criterion_group, criterion_main, BatchSize, Criterion};
use imucal::pipeline::{calibrate, check_and_calibrate, check_input, FitOptions, InputOptions};
use imucal::recording::{LoadOptions, Recording, Sensor};
use imucal::stats::descriptive::window_variances;
use imucal::stats::robust::screen_stream;

const ROWS: usize = 1_000_000;

fn load(path: &std::path::Path) -> Recording {
    Recording::load(path, &LoadOptions::default()).expect("the generated recording reads")
}

fn bench_pipeline(c: &mut Criterion) {
    let path = std::env::temp_dir().join(format!("imucal-fit-pipeline-{}.csv", std::process::id()));
    let mut out = std::io::BufWriter::new(std::fs::File::create(&path).expect("temporary file"));
    imucal::synthetic::write_long_recording(ROWS, &mut out).expect("write");
    out.flush().expect("write");
    drop(out);
    let recording = load(&path);
    let sensors = recording.sensors();
    let input_options = InputOptions::default();
    let fit_options = FitOptions::default();
    // As `imucal fit` does it: the magnetometer's fit beside still detection.
    let whole = || {
        check_and_calibrate(load(&path), &sensors, &input_options, None, &fit_options)
            .map(|(_, c)| c.sensors.len())
    };

    let mut group = c.benchmark_group("pipeline");
    group.sample_size(10);
    group.bench_function("read_1e6_rows", |b| b.iter(|| load(&path).len()));
    group.bench_function("check_input_1e6_rows", |b| {
        b.iter_batched(
            || recording.clone(),
            |r| {
                check_input(r, &sensors, &input_options, None)
                    .mag_points()
                    .len()
            },
            BatchSize::LargeInput,
        )
    });
    let input = check_input(recording.clone(), &sensors, &input_options, None);
    group.bench_function("calibrate_1e6_rows", |b| {
        b.iter(|| calibrate(&input, &fit_options).map(|c| c.sensors.len()))
    });
    group.bench_function("check_and_calibrate_1e6_rows", |b| {
        b.iter_batched(
            || recording.clone(),
            |r| {
                let input = check_input(r, &sensors, &input_options, None);
                calibrate(&input, &fit_options).map(|c| c.sensors.len())
            },
            BatchSize::LargeInput,
        )
    });
    group.bench_function("whole_fit_1e6_rows", |b| b.iter(whole));
    group.finish();

    let mut stages = c.benchmark_group("stages");
    stages.sample_size(10);
    let mag = recording
        .samples(Sensor::Mag)
        .expect("the recording has a magnetometer");
    stages.bench_function("screen_stream_1e6_mag_samples", |b| {
        b.iter(|| screen_stream(mag).dropped)
    });
    let accel = recording
        .samples(Sensor::Accel)
        .expect("the recording has an accelerometer");
    stages.bench_function("window_variances_1e6_rows", |b| {
        b.iter(|| window_variances(accel, 50).len())
    });
    stages.finish();

    // CPU time per whole fit (both threads), beside criterion's wall time.
    const FITS: usize = 3;
    if let Some(before) = common::cpu_seconds() {
        for _ in 0..FITS {
            std::hint::black_box(whole()).expect("the generated recording fits");
        }
        if let Some(after) = common::cpu_seconds() {
            println!(
                "pipeline/whole_fit_1e6_rows: {:.3} CPU s per fit",
                (after - before) / FITS as f64
            );
        }
    }
    let _ = std::fs::remove_file(&path);
}

criterion_group!(benches, bench_pipeline);
criterion_main!(benches);
