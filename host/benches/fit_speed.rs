//! Speed of the fits: Li's ellipsoid and the norm-model LM on 10⁶ magnetometer samples, the
//! 12-pose accelerometer LM, the 300-sample magnetometer LM, and the leave-one-out of the
//! sample-level min/max, the pose-level axis-aligned and Li fits, and Li's fit on magnetometer
//! samples (first order on 10⁶, first order against exact on 2000: group `li_loo`, which also
//! prints CPU times).
//! The LM on 10⁶ samples also prints its CPU time per fit (both threads), its residual
//! evaluations and the time of its parts, since criterion's wall time on a shared machine
//! includes waiting for a core.
//! Run: `cargo bench -p imucal --bench fit_speed`.

mod common;

use criterion::{criterion_group, criterion_main, Criterion};
use imucal::fit::axis_aligned::fit_axis_aligned_poses;
use imucal::fit::li::{fit_li, LiOptions};
use imucal::fit::li_loo::li_leave_one_out_rms;
use imucal::fit::li_loo_first_order::li_first_order_loo_rms;
use imucal::fit::minmax::fit_minmax;
use imucal::fit::norm_lm::{fit_accel_lm_detailed, fit_mag_lm};
use imucal::fit::Pose;
use imucal::synthetic::{
    accel_poses, directions, mag_samples, random_calibration, rng, sphere_directions, PoseSet,
    TruthSpec,
};

fn bench_fits(c: &mut Criterion) {
    let mag_spec = TruthSpec {
        scale_error: 0.2,
        cross_axis: 0.05,
        offset_ratio: 2.0,
        reference: 50.0,
        upper_triangular: false,
    };
    let mag_truth = random_calibration(&mut rng(1), &mag_spec);
    let mut r = rng(2);
    let million_dirs = sphere_directions(&mut r, 1_000_000);
    let million = mag_samples(&mut r, &mag_truth, &million_dirs, 50.0, 0.5);
    let dirs300 = sphere_directions(&mut r, 300);
    let cloud300 = mag_samples(&mut r, &mag_truth, &dirs300, 50.0, 0.5);

    let accel_spec = TruthSpec {
        scale_error: 0.05,
        cross_axis: 0.02,
        offset_ratio: 0.05,
        reference: 9.81,
        upper_triangular: false,
    };
    let accel_truth = random_calibration(&mut rng(3), &accel_spec);
    let dirs12 = directions(&mut r, PoseSet::TwelvePositions);
    let poses = accel_poses(&mut r, &accel_truth, &dirs12, 9.81, 0.02, 100);

    let mut group = c.benchmark_group("fit");
    group.sample_size(10);
    group.bench_function("li_1e6_mag_samples", |b| {
        b.iter(|| {
            fit_li(
                &million,
                50.0,
                LiOptions {
                    subtract_mean: true,
                },
            )
            .map(|f| f.cal)
        })
    });
    group.bench_function("lm_1e6_mag_samples", |b| {
        b.iter(|| fit_mag_lm(&million, 50.0).map(|f| f.cal))
    });
    group.finish();
    print_lm_cpu(&million);
    // Magnetometer samples as one-sample poses, as `fit --method minmax` passes them.
    let as_poses = |points: &[imucal::fit::Vec3]| -> Vec<Pose> {
        points.iter().map(|p| Pose::single(*p)).collect()
    };
    let samples2000 = as_poses(&million[..2000]);
    c.bench_function("minmax_2000_mag_samples_with_loo", |b| {
        b.iter(|| fit_minmax(&samples2000, 50.0).map(|f| f.loo_rms))
    });
    let dirs100 = sphere_directions(&mut r, 100);
    let poses100 = accel_poses(&mut r, &accel_truth, &dirs100, 9.81, 0.02, 100);
    c.bench_function("axis_aligned_100_poses_with_loo", |b| {
        b.iter(|| fit_axis_aligned_poses(&poses100, 9.81).map(|f| f.loo_rms))
    });
    // Li's leave-one-out by moment downdate: one 10×10 solve per point, none over the others.
    let means100: Vec<imucal::fit::Vec3> = poses100.iter().map(|p| p.mean).collect();
    c.bench_function("li_leave_one_out_100_poses", |b| {
        b.iter(|| li_leave_one_out_rms(&means100, 9.81))
    });
    bench_li_loo(c, &million);
    c.bench_function("lm_accel_12_poses", |b| {
        b.iter(|| fit_accel_lm_detailed(&poses, 9.81).map(|o| o.fit.cal))
    });
    c.bench_function("lm_mag_300_samples", |b| {
        b.iter(|| fit_mag_lm(&cloud300, 50.0).map(|f| f.cal))
    });
}

/// Li's fit on magnetometer samples with its leave-one-out: the fit alone and with the
/// first-order leave-one-out on 10⁶ samples, and the exact downdate against first order on 2000.
fn bench_li_loo(c: &mut Criterion, million: &[imucal::fit::Vec3]) {
    let li = li_about_mean;
    let li_with_loo =
        |points: &[imucal::fit::Vec3]| (li(points), li_first_order_loo_rms(points, 50.0));
    let first2000 = &million[..2000];
    let mut group = c.benchmark_group("li_loo");
    group.sample_size(10);
    group.bench_function("fit_only_1e6_mag_samples", |b| b.iter(|| li(million)));
    group.bench_function("fit_and_first_order_1e6_mag_samples", |b| {
        b.iter(|| li_with_loo(million))
    });
    group.bench_function("first_order_2000_mag_samples", |b| {
        b.iter(|| li_first_order_loo_rms(first2000, 50.0))
    });
    group.bench_function("exact_2000_mag_samples", |b| {
        b.iter(|| li_leave_one_out_rms(first2000, 50.0))
    });
    group.finish();
    const RUNS: usize = 11;
    let fit = cpu_per_call(RUNS, || li(million));
    let with_loo = cpu_per_call(RUNS, || li_with_loo(million));
    let first = li_first_order_loo_rms(million, 50.0).unwrap_or(f64::NAN);
    if let (Some(fit), Some(with_loo)) = (fit, with_loo) {
        println!(
            "li_loo/1e6: {:.1} ms CPU per fit, {:.1} ms CPU with the first-order leave-one-out \
             (both threads, {RUNS} runs); leave-one-out RMS {first:.6e}",
            fit * 1e3,
            with_loo * 1e3
        );
    }
    let exact = li_leave_one_out_rms(first2000, 50.0).unwrap_or(f64::NAN);
    let first = li_first_order_loo_rms(first2000, 50.0).unwrap_or(f64::NAN);
    println!(
        "li_loo/2000: first order {first:.9e}, exact {exact:.9e}, relative difference {:.1e}",
        (first - exact).abs() / exact
    );
}

/// CPU seconds per call of `f`, over `runs` calls; `None` without `/proc`.
/// Li's fit about the sample mean of magnetometer samples (field 50).
fn li_about_mean(
    points: &[imucal::fit::Vec3],
) -> Result<imucal::fit::Calibration, imucal::fit::FitError> {
    fit_li(
        points,
        50.0,
        LiOptions {
            subtract_mean: true,
        },
    )
    .map(|f| f.cal)
}

fn cpu_per_call<T>(runs: usize, mut f: impl FnMut() -> T) -> Option<f64> {
    let before = common::cpu_seconds()?;
    for _ in 0..runs {
        std::hint::black_box(f());
    }
    Some((common::cpu_seconds()? - before) / runs as f64)
}

/// CPU time of the LM on 10⁶ samples (both threads), of its Li start and of the whole fit, with
/// the number of residual evaluations and the first-order leave-one-out it reports.
fn print_lm_cpu(points: &[imucal::fit::Vec3]) {
    const RUNS: usize = 5;
    let Ok(fit) = fit_mag_lm(points, 50.0) else {
        println!("fit/lm_1e6_mag_samples: the fit failed");
        return;
    };
    let li = cpu_per_call(RUNS, || li_about_mean(points));
    let lm = cpu_per_call(RUNS, || fit_mag_lm(points, 50.0).map(|f| f.cal));
    if let (Some(li), Some(lm)) = (li, lm) {
        println!(
            "fit/lm_1e6_mag_samples: {lm:.3} CPU s per fit (Li start {li:.3} s), {} residual \
             evaluations, {}, leave-one-out RMS {:.4e} (in-sample {:.4e})",
            fit.iterations,
            fit.termination.map_or("-", |t| t.name()),
            fit.loo_rms.unwrap_or(f64::NAN),
            fit.rms
        );
    }
}

criterion_group!(benches, bench_fits);
criterion_main!(benches);
