//! One step of the seed 003 NN estimator (n_x = 3, n_y = 2) including the gain solve of
//! Theorem 2, in f64 and f32, with the paper's Kronecker solve and the two-sided solve; and
//! one step of the correlated-noise KF baseline for scale.

use criterion::{criterion_group, criterion_main, Criterion};
use estimator_core::filter::coupled_kf::{CoupledNoiseKf, Linearisation};
use estimator_core::filter::nn_bound::{GainSolver, NnBoundConfig};
use estimator_core::filter::nn_system::{Seed003Example, Tanh};
use estimator_core::filter::nn_tbcp::{NnTbcpEstimator, Seed003Nn};
use estimator_core::Real;
use nalgebra::{matrix, vector, SVector};
use std::hint::black_box;

fn estimator<T: Real>(solver: GainSolver) -> Seed003Nn<T> {
    // δ₁ < 1 so the bound stays finite however long criterion iterates; the step's cost
    // does not depend on the scalars.
    let cfg = NnBoundConfig::new(
        [T::lit(0.5); 4],
        [T::lit(0.5); 12],
        [T::lit(0.05), T::lit(10.0)],
        T::lit(8.0),
        T::lit(1.8),
        T::lit(0.1),
        T::lit(0.1),
    )
    .expect("valid config");
    NnTbcpEstimator::new(
        cfg,
        Tanh,
        Seed003Example::xhat0(),
        Seed003Example::h0(),
        Seed003Example::p0(),
        Seed003Example::p0(),
    )
    .expect("valid")
    .with_initial_measurement(SVector::<T, 2>::new(T::lit(0.3), T::lit(-0.2)))
    .expect("finite")
    .with_gain_solver(solver)
}

fn nn_step(c: &mut Criterion) {
    let sys = Seed003Example;
    for (name, solver) in [
        ("kron", GainSolver::Kronecker),
        ("two_sided", GainSolver::TwoSided),
    ] {
        // Each iteration restarts from the same state so every call does the full
        // transmitted-measurement step (gain solve included) at k = 1.
        let e64 = estimator::<f64>(solver);
        let y64 = vector![0.3, -0.2];
        c.bench_function(&format!("nn_step_3x2_f64_{name}"), |b| {
            b.iter(|| {
                let mut e = e64;
                e.step(black_box(&sys), Some(black_box(&y64)))
                    .expect("step");
                e
            })
        });
        let e32 = estimator::<f32>(solver);
        let y32 = vector![0.3f32, -0.2];
        c.bench_function(&format!("nn_step_3x2_f32_{name}"), |b| {
            b.iter(|| {
                let mut e = e32;
                e.step(black_box(&sys), Some(black_box(&y32)))
                    .expect("step");
                e
            })
        });
    }
    let kf = CoupledNoiseKf::<f64, 3, 1, 2>::new(
        Seed003Example::xhat0(),
        Seed003Example::p0(),
        matrix![0.1],
        Linearisation::PaperJacobian,
    )
    .expect("valid")
    .with_initial_measurement(vector![0.3, -0.2])
    .expect("finite");
    let y = vector![0.3, -0.2];
    c.bench_function("coupled_ekf_step_3x2_f64", |b| {
        b.iter(|| {
            let mut e = kf;
            e.step(black_box(&sys), &sys, Some(black_box(&y)))
                .expect("step");
            e
        })
    });
}

criterion_group!(benches, nn_step);
criterion_main!(benches);
