//! One Kalman step at the papers' dimensions.

use criterion::{criterion_group, criterion_main, Criterion};
use estimator_core::{filter::KalmanFilter, model::LinearModel};
use nalgebra::{matrix, vector, SMatrix};
use std::hint::black_box;

fn kf_step(c: &mut Criterion) {
    let m = LinearModel::<f64, 3, 3, 2, 2>::new(
        matrix![1.0, 0.1, 0.0; 0.0, 1.0, 0.1; 0.0, 0.0, 0.95],
        SMatrix::identity(),
        matrix![1.0, 0.0, 0.0; 0.0, 0.0, 1.0],
        SMatrix::identity(),
        SMatrix::identity() * 0.01,
        SMatrix::identity() * 0.5,
    )
    .expect("valid model");
    let mut kf = KalmanFilter::new(vector![0.0, 0.0, 0.0], SMatrix::identity()).expect("valid");
    let y = vector![0.3, -0.2];
    c.bench_function("kf_step_3x2_f64", |b| {
        b.iter(|| kf.step(black_box(&m), 1, black_box(&y)).expect("step"))
    });
}

criterion_group!(benches, kf_step);
criterion_main!(benches);
