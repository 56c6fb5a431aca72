//! One step of every estimator of the papers, from a fixed state, f64 and f32: the kernels of
//! `benches::estimators` (the same ones `icount` counts instructions of, under the same
//! names). Seed 001's target: one CCE dropout step (S = 4, N = 15, n_x = 3) ≤ 1 µs.

use criterion::{criterion_group, criterion_main, Criterion};
use std::hint::black_box;

fn steps(c: &mut Criterion) {
    for (name, mut f) in benches::estimators::all_kernels() {
        c.bench_function(&name, |b| b.iter(|| black_box(f()).expect("step")));
    }
}

criterion_group!(benches, steps);
criterion_main!(benches);
