//! One Kalman step at the papers' dimensions: our `KalmanFilter` side by side with
//! `adskalman` on identical problems (same model, prior and measurement, converted once at
//! setup), and the KF/IKF steps in f32 and f64.
//!
//! Every iteration computes one step from the same converged prior (see `benches::problems`).
//! `benches/run.sh` turns the medians into the ratios of `BENCHMARKS.md`.

use benches::ads::AdsProblem;
use benches::compare as cmp;
use benches::problems::{
    occlusion_3x2_f32, occlusion_3x2_f64, tracking_4x2_f32, tracking_4x2_f64, KfProblem,
};
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use estimator_core::Real;
use std::hint::black_box;
use std::time::Duration;

fn versus_adskalman(c: &mut Criterion) {
    let mut g = c.benchmark_group("kf_vs_adskalman");
    g.warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(3));
    // The steps are `benches::compare`'s non-inlined functions, the same machine code that
    // `icount` and `kf_interleaved` run.
    let p = occlusion_3x2_f64();
    let a = AdsProblem::from_core(&p);
    g.bench_function(BenchmarkId::new("ours", p.name), |b| {
        b.iter(|| cmp::ours_joseph_3x2_f64(black_box(&p)))
    });
    g.bench_function(BenchmarkId::new("adskalman", p.name), |b| {
        b.iter(|| cmp::ads_joseph_3x2_f64(black_box(&a)))
    });
    g.bench_function(BenchmarkId::new("ours_standard", p.name), |b| {
        b.iter(|| cmp::ours_standard_3x2_f64(black_box(&p)))
    });
    g.bench_function(BenchmarkId::new("adskalman_symmetric", p.name), |b| {
        b.iter(|| cmp::ads_symmetric_3x2_f64(black_box(&a)))
    });
    let p = tracking_4x2_f32();
    let a = AdsProblem::from_core(&p);
    g.bench_function(BenchmarkId::new("ours", p.name), |b| {
        b.iter(|| cmp::ours_joseph_4x2_f32(black_box(&p)))
    });
    g.bench_function(BenchmarkId::new("adskalman", p.name), |b| {
        b.iter(|| cmp::ads_joseph_4x2_f32(black_box(&a)))
    });
    g.bench_function(BenchmarkId::new("ours_standard", p.name), |b| {
        b.iter(|| cmp::ours_standard_4x2_f32(black_box(&p)))
    });
    g.bench_function(BenchmarkId::new("adskalman_symmetric", p.name), |b| {
        b.iter(|| cmp::ads_symmetric_4x2_f32(black_box(&a)))
    });
    g.finish();
}

fn steps<T: Real, const NX: usize, const NY: usize>(c: &mut Criterion, p: &KfProblem<T, NX, NY>) {
    let mut g = c.benchmark_group("kalman");
    g.warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(2));
    g.bench_function(BenchmarkId::new("kf", p.name), |b| {
        b.iter(|| black_box(black_box(p).kf_step()))
    });
    g.bench_function(BenchmarkId::new("ikf_arrival", p.name), |b| {
        b.iter(|| black_box(black_box(p).ikf_arrival_step()))
    });
    g.bench_function(BenchmarkId::new("ikf_dropout", p.name), |b| {
        b.iter(|| black_box(black_box(p).ikf_dropout_step()))
    });
    g.finish();
}

fn kf_ikf(c: &mut Criterion) {
    steps(c, &occlusion_3x2_f64());
    steps(c, &occlusion_3x2_f32());
    steps(c, &tracking_4x2_f64());
    steps(c, &tracking_4x2_f32());
}

criterion_group!(benches, versus_adskalman, kf_ikf);
criterion_main!(benches);
