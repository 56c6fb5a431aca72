//! One dropout step of the cross-coupled estimator (seed 001: S = 4 regions, N = 15
//! Gaussians, n_x = 3), f64 and f32, beside the `adf` and `kf-io` steps. Target ≤ 1 µs.

use criterion::{criterion_group, criterion_main, Criterion};
use estimator_core::filter::{AssumedDensityFilter, CrossCoupledEstimator, KfIo};
use estimator_core::gsum::GaussSum;
use estimator_core::model::LinearModel;
use estimator_core::protocol::occlusion::{Occlusion, OcclusionRegions};
use estimator_core::Real;
use nalgebra::{matrix, vector, SMatrix, SVector};
use std::hint::black_box;

fn paper<T: Real>() -> (LinearModel<T, 3, 3, 2, 2>, Occlusion<T, 3, 1, 4>) {
    let l = T::lit;
    let m = LinearModel::<f64, 3, 3, 2, 2>::new(
        matrix![1.01, 0.1, 0.0; 0.0, 1.01, 0.1; 0.0, 0.0, -1.02],
        SMatrix::identity(),
        matrix![2.0, 3.0, 1.0; 1.0, 0.0, 0.98],
        SMatrix::identity(),
        SMatrix::identity() * 0.3,
        SMatrix::identity() * 0.2,
    )
    .expect("valid model")
    .cast::<T>()
    .expect("valid model");
    let occ = Occlusion::new(
        matrix![T::one(), T::zero(), T::zero()],
        matrix![l(0.1)],
        OcclusionRegions::new(
            [
                vector![l(20.0)],
                vector![l(40.0)],
                vector![l(60.0)],
                vector![l(80.0)],
            ],
            [l(5.0); 4],
        )
        .expect("valid regions"),
    )
    .expect("valid occlusion");
    (m, occ)
}

fn bench_scalar<T: Real>(c: &mut Criterion, tag: &str) {
    let (m, occ) = paper::<T>();
    // A state whose prediction sits on the edge of region 2, the typical dropout.
    let x0: SVector<T, 3> = vector![T::lit(35.0), T::lit(1.0), T::lit(0.5)];
    let p0 = SMatrix::<T, 3, 3>::identity() * T::lit(0.5);
    let cce = CrossCoupledEstimator::<T, 3, 1, 4, 15>::new(
        x0,
        p0,
        occ,
        &GaussSum::uniform().expect("table"),
    )
    .expect("valid");
    c.bench_function(&format!("cce_dropout_step_s4_n15_nx3_{tag}"), |b| {
        b.iter(|| {
            let mut f = black_box(cce);
            f.step::<2, _>(black_box(&m), 1, None).expect("step")
        })
    });
    let adf = AssumedDensityFilter::new(x0, p0, occ).expect("valid");
    c.bench_function(&format!("adf_dropout_step_s4_nx3_{tag}"), |b| {
        b.iter(|| {
            let mut f = black_box(adf);
            f.step::<2, _>(black_box(&m), 1, None).expect("step")
        })
    });
    let y: SVector<T, 2> = vector![T::lit(100.0), T::lit(35.0)];
    c.bench_function(&format!("adf_arrival_step_s4_nx3_{tag}"), |b| {
        b.iter(|| {
            let mut f = black_box(adf);
            f.step(black_box(&m), 1, Some(black_box(&y))).expect("step")
        })
    });
    let kfio = KfIo::new(x0, p0, occ).expect("valid");
    c.bench_function(&format!("kfio_dropout_step_s4_nx3_{tag}"), |b| {
        b.iter(|| {
            let mut f = black_box(kfio);
            f.step::<2, _>(black_box(&m), 1, None).expect("step")
        })
    });
}

fn occlusion_steps(c: &mut Criterion) {
    bench_scalar::<f64>(c, "f64");
    bench_scalar::<f32>(c, "f32");
}

criterion_group!(benches, occlusion_steps);
criterion_main!(benches);
