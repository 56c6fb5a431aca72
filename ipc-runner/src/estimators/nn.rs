//! `nn`, `kf`, `ekf`, `ekf-std`: the estimators of seed 003 on the `nn-token-bucket` scenario
//! (any composed scenario whose plant is channel-sim's `Seed003Plant`).
//!
//! * **`nn`** — the paper's recursive NN-based estimator (5)-(6) with the Theorem 1 bounds and
//!   the Theorem 2 gain (Kronecker solve of (35)), section IV's scalars (`α = 0.1`, `β = 0.9`,
//!   `θ = 0.001`, `H̄ = 8`, `φ̄ = 1`, `ε̄ = 0.1`), `tanh` activation, `Ĥ₀` of section IV,
//!   `P̄₀ = Q̄₀ = 10 I`. Diagnostics: `bound_trace` = tr P̄_k, `bound_q_trace` = tr Q̄_k,
//!   `phi_norm` = ‖φ(x̂_k)‖ and `phi_exceeds` = 1{‖φ(x̂_k)‖ > φ̄} (its mean over runs is the
//!   fraction of runs violating the paper's `‖φ‖ ≤ φ̄` at k). `eval` adds
//!   `empirical_trace` = tr E[e_k e_kᵀ] = MSE(k) (`ipc_runner::eval::nn_bound`).
//! * **`kf`** — the paper's KF: `A_k` only, `f` ignored.
//! * **`ekf`** — the paper's EKF: `A_k + ∂f/∂x|_{x̂_{k|k−1}}` as the linear transition.
//! * **`ekf-std`** — a standard EKF (mean `A_k x̂ + f(x̂)`), the product's option beside the
//!   paper's.
//!
//! * **`kf-indep`**, **`ekf-indep`** — the textbook KF (`A_k`, `f` ignored) and EKF (`f`
//!   known, linearised at the filtered estimate) a practitioner would try first: they take
//!   `B_k w_k` and `D_k w_k` as independent noises (`Q = B w̄² Bᵀ`, `R = D w̄² Dᵀ`, no
//!   cross-covariance), estimator-core's `IndependentNoiseKf`.
//! * **`pf`** — a particle filter on the true nonlinear model, the reference of what is
//!   achievable (`--particles`, 0 disables it; [`pf_coupled`]).
//!
//! The paper's three baselines are estimator-core's `CoupledNoiseKf`: the exact one-step
//! predictor for noise that drives state and measurement (cross-covariance `B_k w̄² D_kᵀ`),
//! prediction only when the bucket withheld the packet, and a spectral pseudo-inverse of the
//! innovation covariance, which becomes singular because `D w̄² Dᵀ` has rank 1 in two
//! dimensions. All of them produce `x̂_k` from `y_0 … y_{k−1}` (the paper's `x̂_k` is a one-step
//! prediction).
//!
//! **`y₀`.** The paper's bucket takes its first decision at k = 0 and (5) uses `y₀` for `x̂₁`;
//! the stream's slots start at k = 1. The scenario's run carries `y₀` and its delivery as
//! its instant-0 observation (`channel_sim::Simulation::initial_observations`), and every
//! estimator here is built with it ([`initial_measurement`]): re-simulating instant 0 of
//! `(scenario, seed, run)` gives exactly what the publisher of that run drew, so `eval`,
//! `run`, `demo` and `replay` initialise identically. A log recorded elsewhere carries no
//! `y₀`; a replay of it gets the simulated one of `--seed`/`--run` (docs/design.md, "Seed 003").
//!
//! This scenario's plant has no linear description, so the framework's `kf`/`ikf` do not
//! apply to it and the name `kf` means the paper's KF here.

pub mod pf_coupled;

use channel_sim::channel::token_bucket::TokenBucketStage;
use channel_sim::plant::nn::Seed003Plant;
use channel_sim::scenario::ComposedScenario;
use channel_sim::Scenario;
use estimator_core::filter::coupled_kf::{CoupledNoiseKf, Linearisation, NoNonlinearity};
use estimator_core::filter::independent_kf::{IndependentMode, IndependentNoiseKf};
use estimator_core::filter::nn::{
    check_before_run, BucketParams, NnBoundConfig, NnTbcpEstimator, PreRunVerdict, Tanh,
};
use estimator_core::papers::{Seed003Example, Seed003Nn};
use estimator_core::OnModel;
use nalgebra::{matrix, SMatrix, SVector};

use super::adapter::Adapted;
use super::fed::Fed;
use super::EvalOptions;
use crate::Estimator;

/// The seed 003 scenario's parts, if `scenario` is one.
fn seed003(scenario: &dyn Scenario) -> Option<(&ComposedScenario, &Seed003Plant)> {
    let composed = scenario.as_any().downcast_ref::<ComposedScenario>()?;
    let plant = composed.plant().as_any().downcast_ref::<Seed003Plant>()?;
    Some((composed, plant))
}

/// Section IV's configuration with the scenario's `w̄²`.
pub fn config(w_var: f64) -> anyhow::Result<NnBoundConfig<f64>> {
    Ok(NnBoundConfig::new(
        [0.1; 4], [0.9; 12], [0.001; 2], 8.0, 1.0, 0.1, w_var,
    )?)
}

/// `ε̄` of section IV.
pub const EPS_BAR: f64 = 0.1;

/// `y₀` of run `run` when the bucket sent it (`None` when it was withheld or the scenario has
/// no instant-0 observation): the run's instant 0 simulated again, which is what the run's
/// publisher drew (same scenario, seed and run, same streams).
pub fn initial_measurement(
    scenario: &dyn Scenario,
    seed: u64,
    run: u64,
) -> Option<SVector<f64, 2>> {
    let sim = scenario.start(seed, run);
    let o = sim.initial_observations()?.first()?;
    o.measurement().map(SVector::from_column_slice)
}

/// Builds the seed 003 estimators (none for other scenarios), each initialised with `y₀`
/// when it was sent.
pub fn build(
    scenario: &dyn Scenario,
    options: &EvalOptions,
    seed: u64,
    run: u64,
) -> anyhow::Result<Vec<Box<dyn Estimator>>> {
    let Some((composed, plant)) = seed003(scenario) else {
        return Ok(Vec::new());
    };
    let init = composed.initial();
    let x0 = SVector::<f64, 3>::from_column_slice(init.estimator_mean.as_slice());
    let p0 = SMatrix::<f64, 3, 3>::from_fn(|i, j| init.estimator_cov[(i, j)]);
    let w = plant.w_var();
    let y0 = initial_measurement(scenario, seed, run);
    let named = |name: &'static str| move |e: estimator_core::Error| anyhow::anyhow!("{name}: {e}");
    let mut nn = NnTbcpEstimator::new(
        config(w)?,
        Tanh,
        x0,
        Seed003Example::h0(),
        p0,
        Seed003Example::p0(),
    )
    .map_err(named("nn"))?;
    if let Some(y0) = y0 {
        nn = nn.with_initial_measurement(y0).map_err(named("nn"))?;
    }
    let base = |name: &'static str, mode| {
        let kf = CoupledNoiseKf::new(x0, p0, matrix![w], mode).map_err(named(name))?;
        match y0 {
            Some(y0) => kf.with_initial_measurement(y0).map_err(named(name)),
            None => Ok(kf),
        }
    };
    let indep = |name: &'static str, mode| {
        let kf = IndependentNoiseKf::new(x0, p0, matrix![w], mode).map_err(named(name))?;
        match y0 {
            Some(y0) => kf.with_initial_measurement(y0).map_err(named(name)),
            None => Ok(kf),
        }
    };
    let kf = base("kf", Linearisation::None)?;
    let mut all: Vec<Box<dyn Estimator>> = vec![
        Box::new(
            Adapted::<_, 3>::new("nn", Fed::fixed(OnModel::new(Seed003Example, nn)))
                .with_diagnostics(nn_diagnostics)
                .with_covariance_bound(),
        ),
        Box::new(
            Adapted::<_, 3>::new(
                "kf",
                Fed::fixed(OnModel::new((Seed003Example, NoNonlinearity), kf)),
            )
            .with_gate(options.gate)?,
        ),
        Box::new(
            Adapted::<_, 3>::new(
                "ekf",
                Fed::fixed(OnModel::new(
                    (Seed003Example, Seed003Example),
                    base("ekf", Linearisation::PaperJacobian)?,
                )),
            )
            .with_gate(options.gate)?,
        ),
        Box::new(
            Adapted::<_, 3>::new(
                "ekf-std",
                Fed::fixed(OnModel::new(
                    (Seed003Example, Seed003Example),
                    base("ekf-std", Linearisation::Ekf)?,
                )),
            )
            .with_gate(options.gate)?,
        ),
        Box::new(
            Adapted::<_, 3>::new(
                "kf-indep",
                Fed::fixed(OnModel::new(
                    (Seed003Example, NoNonlinearity),
                    indep("kf-indep", IndependentMode::Kf)?,
                )),
            )
            .with_gate(options.gate)?,
        ),
        Box::new(
            Adapted::<_, 3>::new(
                "ekf-indep",
                Fed::fixed(OnModel::new(
                    (Seed003Example, Seed003Example),
                    indep("ekf-indep", IndependentMode::Ekf)?,
                )),
            )
            .with_gate(options.gate)?,
        ),
    ];
    if options.particles > 0 {
        all.push(Box::new(pf_coupled::CoupledPf::new(
            x0,
            p0,
            w,
            y0,
            options.particles,
            seed,
            run,
        )?));
    }
    Ok(all)
}

/// The NN estimator's diagnostics: its bounds' traces and `‖φ(x̂_k)‖` against `φ̄`.
fn nn_diagnostics(
    on: &OnModel<Seed003Example, Seed003Nn<f64>, 2>,
    sink: &mut dyn FnMut(&'static str, f64),
) {
    let nn = &on.filter;
    sink("bound_trace", nn.estimate().covariance().trace());
    sink("bound_q_trace", nn.bound_q().trace());
    let phi = nn.phi_norm();
    sink("phi_norm", phi);
    sink(
        "phi_exceeds",
        f64::from(u8::from(phi > nn.config().phi_bar())),
    );
}

/// The assumption checker's pre-run verdict for a seed 003 scenario (`None` otherwise).
pub fn verdict(scenario: &dyn Scenario) -> anyhow::Result<Option<PreRunVerdict<f64>>> {
    let Some((composed, plant)) = seed003(scenario) else {
        return Ok(None);
    };
    let init = composed.initial();
    let e0 = SVector::<f64, 3>::from_column_slice(init.mean.as_slice())
        - SVector::<f64, 3>::from_column_slice(init.estimator_mean.as_slice());
    let cov = SMatrix::<f64, 3, 3>::from_fn(|i, j| init.cov[(i, j)]);
    let p0_true = cov + e0 * e0.transpose();
    let p0_bar = SMatrix::<f64, 3, 3>::from_fn(|i, j| init.estimator_cov[(i, j)]);
    let bucket = composed
        .stage::<TokenBucketStage>()
        .map(|b| BucketParams {
            a: b.a,
            b: b.b,
            s: b.s,
            z0: b.z0,
        })
        .ok_or_else(|| anyhow::anyhow!("seed 003 scenario without a token-bucket stage"))?;
    // sup ‖f‖ of section IV's f: x₂ = π/2, |cos x₃| = 1, |sin x₁| = 1 give 8√3.
    let f_sup = 8.0 * 3f64.sqrt();
    Ok(Some(check_before_run::<f64, 3, 3, _>(
        &config(plant.w_var())?,
        &Tanh,
        EPS_BAR,
        &p0_true,
        &p0_bar,
        Some(f_sup),
        bucket,
    )?))
}
