//! Seed 003 on its section IV example: the bounds and gain of Theorems 1-2 and the NN
//! estimator (5)-(6). (Integration tests: the example lives in `papers`, which is built on
//! the estimator, so the example-driven tests are here rather than in the modules.)

use estimator_core::filter::nn::bound::{
    optimal_gain, propagate_bounds, GainSolver, NnBoundConfig, StepMatrices,
};
use estimator_core::filter::nn::{CoupledNoiseSystem, NnTbcpEstimator, Tanh};
use estimator_core::papers::{Seed003Example, Seed003Nn};
use estimator_core::protocol::token_bucket::{TokenBucket, TokenBucketConfig};
use estimator_core::{Error, Real};
use nalgebra::{matrix, vector, SMatrix, SVector};

// ---- Theorems 1-2: bounds and gain (filter::nn::bound).

fn step_mats(k: usize, gamma_next: bool) -> StepMatrices<f64, 3, 1, 2> {
    let s = Seed003Example;
    StepMatrices {
        a: s.a(k),
        b: s.b(k),
        c: s.c(k),
        d: s.d(k),
        c_next: s.c(k + 1),
        d_next: s.d(k + 1),
        gamma: true,
        gamma_next,
    }
}

fn objective(
    cfg: &NnBoundConfig<f64>,
    p: &SMatrix<f64, 3, 3>,
    q: &SMatrix<f64, 3, 3>,
    l: &SMatrix<f64, 3, 2>,
    s: &StepMatrices<f64, 3, 1, 2>,
) -> f64 {
    let (pn, qn) = propagate_bounds(cfg, p, q, l, s).unwrap();
    (pn + qn).trace()
}

#[test]
fn gain_minimises_trace_of_the_bound() {
    // The objective tr(P̄_{k+1} + Q̄_{k+1}) is quadratic in L, so a central difference is
    // exact up to rounding: |∂/∂L_ij| at the optimum is ~ eps·|objective|/h. With h = 1e-3
    // and objective ~1e3 that is ~1e-10; we allow 1e-6 relative to the gradient's scale at
    // L = 0 (which is O(10²)). A convexity check (objective grows in every direction)
    // guards against a saddle point.
    // A benign config (θ large enough that the Q̄ terms matter) and the paper's own one.
    let cfgs = [
        NnBoundConfig::<f64>::seed003_example(),
        NnBoundConfig::new([0.3; 4], [0.5; 12], [0.2, 0.5], 2.0, 1.0, 0.1, 0.1).unwrap(),
    ];
    let p = matrix![10.0, 1.0, -2.0; 1.0, 8.0, 0.5; -2.0, 0.5, 12.0];
    let q = matrix![4.0, 0.2, 0.0; 0.2, 5.0, 0.3; 0.0, 0.3, 6.0];
    for cfg in &cfgs {
        for k in [0usize, 1, 7, 42] {
            for gamma_next in [true, false] {
                let s = step_mats(k, gamma_next);
                for solver in [GainSolver::Kronecker, GainSolver::TwoSided] {
                    let l = optimal_gain::<f64, 3, 1, 2, 6>(cfg, &p, &s, solver).unwrap();
                    let f0 = objective(cfg, &p, &q, &l, &s);
                    let h = 1e-3;
                    let zero = SMatrix::<f64, 3, 2>::zeros();
                    let mut gscale = 0.0f64;
                    let mut gmax = 0.0f64;
                    for i in 0..3 {
                        for j in 0..2 {
                            let mut e = zero;
                            e[(i, j)] = h;
                            let fp = objective(cfg, &p, &q, &(l + e), &s);
                            let fm = objective(cfg, &p, &q, &(l - e), &s);
                            gmax = gmax.max(((fp - fm) / (2.0 * h)).abs());
                            assert!(fp > f0 && fm > f0, "not a minimum along L[{i},{j}]");
                            let fz = objective(cfg, &p, &q, &e, &s);
                            let fz0 = objective(cfg, &p, &q, &(-e), &s);
                            gscale = gscale.max(((fz - fz0) / (2.0 * h)).abs());
                        }
                    }
                    assert!(
                        gmax < 1e-6 * gscale.max(1.0),
                        "k={k}: grad {gmax} vs {gscale}"
                    );
                }
            }
        }
    }
}

#[test]
fn bound_without_transmission_ignores_the_gain() {
    let cfg = NnBoundConfig::<f64>::seed003_example();
    let mut s = step_mats(3, false);
    s.gamma = false;
    let p = SMatrix::<f64, 3, 3>::identity() * 10.0;
    let l1 = SMatrix::<f64, 3, 2>::zeros();
    let l2 = SMatrix::<f64, 3, 2>::repeat(5.0);
    let a = propagate_bounds(&cfg, &p, &p, &l1, &s).unwrap();
    let b = propagate_bounds(&cfg, &p, &p, &l2, &s).unwrap();
    assert_eq!(a, b);
    // γ_{k+1} = 0: (15) reduces to δ₁ Q̄ + δ̄₇ I.
    let d = cfg.deltas(false, 1.0);
    let expect = p * d.d1 + SMatrix::<f64, 3, 3>::identity() * d.d7;
    assert!((a.1 - expect).amax() < 1e-12);
}

#[test]
fn example_deltas_by_hand() {
    // α = 0.1, β = 0.9, θ = 0.001: δ₁ = (1 + 5·0.9)(1 − 1e-6)² = 5.5·(1 − 1e-6)².
    let cfg = NnBoundConfig::<f64>::seed003_example();
    assert!((cfg.delta1() - 5.5 * (1.0f64 - 1e-6).powi(2)).abs() < 1e-12);
    let d = cfg.deltas(true, 2.0);
    // δ₂ = (1 + 1/0.9 + 3·0.9)·1e-6; δ̄₂ = δ₂/4.
    assert!((d.d2 - (1.0 + 1.0 / 0.9 + 2.7) * 1e-6 / 4.0).abs() < 1e-18);
    // δ̄₅ = (1 + 3/0.9 + 0.9)·1e-6·(2·1·8 + 0.1)².
    assert!((d.d5 - (1.9 + 3.0 / 0.9) * 1e-6 * 16.1 * 16.1).abs() < 1e-15);
}

// ---- The estimator (filter::nn::estimator).

fn example_f64() -> Seed003Nn<f64> {
    Seed003Nn::seed003(NnBoundConfig::seed003_example()).unwrap()
}

#[test]
fn first_step_by_hand() {
    // No y₀ (γ₀ = 0): x̂₁ = A₀ x̂₀ + Ĥ₀ tanh(x̂₀) = 0 for x̂₀ = 0, and with y₁ transmitted
    // Ĥ₁ = (1 − θ₁θ₂) Ĥ₀ + θ₁ C₁ᵀ y₁ φ̄ᵀ(x̂₀) = (1 − 1e-6) Ĥ₀ since φ(0) = 0.
    let mut nn = example_f64();
    nn.step(&Seed003Example, Some(&vector![1.0, 2.0])).unwrap();
    assert_eq!(nn.estimate().state(), &SVector::<f64, 3>::zeros());
    assert!((nn.weights() - Seed003Example::h0::<f64>() * (1.0 - 1e-6)).amax() < 1e-15);
    // P̄₁ = 1.2 A₀ P̄₀ A₀ᵀ + (1 + 10 + 0.2) Q̄₀ + 11 w̄² B₀B₀ᵀ + 21 (16.1)² I.
    let a0: SMatrix<f64, 3, 3> = Seed003Example.a(0);
    let b0: SMatrix<f64, 3, 1> = Seed003Example.b(0);
    let p1 = a0 * a0.transpose() * 12.0
        + SMatrix::<f64, 3, 3>::identity() * (11.2 * 10.0 + 21.0 * 16.1 * 16.1)
        + b0 * b0.transpose() * 1.1;
    assert!((nn.estimate().covariance() - p1).amax() < 1e-10);
    assert_eq!(nn.instant(), 1);
}

#[test]
fn transmitted_step_uses_the_gain_and_tunes_weights() {
    let mut nn = example_f64();
    let y1 = vector![0.7, -0.3];
    nn.step(&Seed003Example, Some(&y1)).unwrap();
    let before = nn;
    let y2 = vector![1.1, 0.4];
    nn.step(&Seed003Example, Some(&y2)).unwrap();
    // Independent recomputation of (5) and (6) for this step.
    let sys = Seed003Example;
    let x1 = *before.estimate().state();
    let phi = x1.map(|v| v.tanh());
    let l = *nn.last_gain();
    let x2 = sys.a(1) * x1 + before.weights() * phi + l * (y1 - sys.c(1) * x1);
    assert!((nn.estimate().state() - x2).amax() < 1e-12);
    let c2: SMatrix<f64, 2, 3> = sys.c(2);
    let mnorm = (c2.transpose() * c2).symmetric_eigenvalues().max();
    let phib = phi / ((1.0 + phi.dot(&phi)) * mnorm);
    let h2 = before.weights()
        + (c2.transpose() * (y2 - c2 * x2) * phib.transpose() - before.weights() * 0.001) * 0.001;
    assert!((nn.weights() - h2).amax() < 1e-14);
    // A non-zero gain was used.
    assert!(l.amax() > 0.0);
}

#[test]
fn nan_is_an_error_and_state_is_unchanged() {
    let mut nn = example_f64();
    nn.step(&Seed003Example, Some(&vector![0.7, -0.3])).unwrap();
    let before = nn;
    assert_eq!(
        nn.step(&Seed003Example, Some(&vector![f64::NAN, 0.0])),
        Err(Error::NonFinite {
            what: "measurement"
        })
    );
    assert_eq!(nn, before);
    assert!(NnTbcpEstimator::<f64, 3, 1, 2, 3, 6, Tanh>::new(
        NnBoundConfig::seed003_example(),
        Tanh,
        Seed003Example::xhat0(),
        Seed003Example::h0(),
        matrix![1.0, 0.0, 0.0; 0.0, 1.0, 0.0; 0.0, 0.0, -1.0],
        Seed003Example::p0(),
    )
    .is_err());
}

/// Runs the section IV example on a noise-free plant (w = 0) under the token bucket.
fn run<T: Real>(
    cfg: NnBoundConfig<T>,
    solver: GainSolver,
    steps: usize,
) -> Result<Seed003Nn<T>, (usize, Error)> {
    use estimator_core::filter::nn::DifferentiableMap;
    let sys = Seed003Example;
    let mut nn = Seed003Nn::seed003(cfg).unwrap().with_gain_solver(solver);
    let mut tb = TokenBucket::new(TokenBucketConfig::new(2, 3, 10, 6).unwrap());
    let mut x = Seed003Example::x0::<T>();
    for k in 0..steps {
        x = CoupledNoiseSystem::<T, 3, 1, 2>::a(&sys, k) * x + sys.eval(&x);
        let y = CoupledNoiseSystem::<T, 3, 1, 2>::c(&sys, k + 1) * x;
        let sent = tb.step().transmit;
        nn.step(&sys, sent.then_some(&y)).map_err(|e| (k, e))?;
    }
    Ok(nn)
}

#[test]
fn kronecker_and_two_sided_runs_agree() {
    let cfg = NnBoundConfig::<f64>::seed003_example();
    let a = run(cfg, GainSolver::Kronecker, 40).unwrap();
    let b = run(cfg, GainSolver::TwoSided, 40).unwrap();
    let scale = a.estimate().state().amax().max(1.0);
    assert!((a.estimate().state() - b.estimate().state()).amax() < 1e-9 * scale);
}

#[test]
fn f32_and_f64_both_run() {
    // A configuration whose bound does not grow geometrically (δ₁ < 1), so f32's range
    // suffices; the paper's own configuration overflows f32 (see the assumption checker).
    let cfg64 =
        NnBoundConfig::<f64>::new([0.5; 4], [0.5; 12], [0.05, 10.0], 8.0, 1.8, 0.1, 0.1).unwrap();
    assert!(cfg64.delta1() < 1.0);
    let cfg32 =
        NnBoundConfig::<f32>::new([0.5; 4], [0.5; 12], [0.05, 10.0], 8.0, 1.8, 0.1, 0.1).unwrap();
    // 40 steps: at k = 44 (cos 44 ≈ 0.99984) the two rows of C_k nearly coincide and
    // κ(Θ̄) ≈ 1e7 exceeds what f32 resolves; the Cholesky solve then refuses (tested below).
    let a = run(cfg64, GainSolver::Kronecker, 40).unwrap();
    let b = run(cfg32, GainSolver::Kronecker, 40).unwrap();
    assert!(a.estimate().covariance().trace().is_finite());
    assert!(b.estimate().covariance().trace().is_finite());
    // Bounds are deterministic functions of the configuration and transmission pattern:
    // f32 tracks f64 to single precision.
    let rel = (a.estimate().covariance().trace() - b.estimate().covariance().trace() as f64).abs()
        / a.estimate().covariance().trace();
    assert!(rel < 1e-4, "{rel}");
    // f64 runs the whole horizon; f32 reports the ill-conditioned gain system instead of
    // returning a meaningless gain.
    assert!(run(cfg64, GainSolver::Kronecker, 300).is_ok());
    let err = run(cfg32, GainSolver::Kronecker, 300).unwrap_err();
    assert!(
        matches!(err.1, Error::NotPositiveDefinite { .. }),
        "{err:?}"
    );
}
