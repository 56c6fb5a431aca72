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
//! the stream's slots start at k = 1. A simulated run carries `y₀` and its delivery as its
//! instant-0 observation, handed to the factory in [`RunStart::initial`], and every estimator
//! here is built with it ([`initial_measurement`]): the commands re-simulate instant 0 of
//! `(scenario, seed, run)`, exactly what the publisher of that run drew, so `eval`, `run`,
//! `demo` and `replay` initialise identically. A log recorded elsewhere, or a run configured
//! by a spec file, carries no `y₀` (docs/design.md, "Seed 003").
//!
//! This model has no linear description, so the framework's `kf`/`ikf` do not apply to it and
//! the name `kf` means the paper's KF here.

pub mod pf_coupled;

use std::sync::Arc;

use estimator_core::filter::coupled_kf::{CoupledNoiseKf, Linearisation, NoNonlinearity};
use estimator_core::filter::independent_kf::{IndependentMode, IndependentNoiseKf};
use estimator_core::filter::nn::{NnBoundConfig, NnTbcpEstimator, Tanh};
use estimator_core::papers::{Seed003Example, Seed003Nn};
use estimator_core::OnModel;
use nalgebra::{matrix, SMatrix, SVector};

use super::adapter::{name, Adapted};
use super::fed::fixed;
use super::{BuildOptions, RunStart};
use crate::Estimator;
use estpipe_spec::{EstimatorSpec, Model};

/// Section IV's configuration with the scenario's `w̄²`.
pub fn config(w_var: f64) -> anyhow::Result<NnBoundConfig<f64>> {
    Ok(NnBoundConfig::new(
        [0.1; 4], [0.9; 12], [0.001; 2], 8.0, 1.0, 0.1, w_var,
    )?)
}

/// `ε̄` of section IV.
pub const EPS_BAR: f64 = 0.1;

/// `y₀` when the bucket sent it: node 0's instant-0 observation of the run, if delivered
/// (`None` when it was withheld or the run has no instant-0 observation).
pub fn initial_measurement(start: &RunStart<'_>) -> Option<SVector<f64, 2>> {
    let o = start.initial?.first()?;
    o.measurement().map(SVector::from_column_slice)
}

/// What every seed 003 estimator starts from: the prior, the process noise variance and `y₀`
/// when it was sent.
#[derive(Clone, Copy)]
struct Start {
    x0: SVector<f64, 3>,
    p0: SMatrix<f64, 3, 3>,
    w: f64,
    y0: Option<SVector<f64, 2>>,
}

/// An estimator-core error as the factory's, naming the estimator.
fn named(name: &'static str) -> impl Fn(estimator_core::Error) -> anyhow::Error {
    move |e| anyhow::anyhow!("{name}: {e}")
}

/// Builds the seed 003 estimators (none for other specs), each initialised with `y₀` when it
/// was sent.
pub fn build(
    spec: &Arc<EstimatorSpec>,
    options: &BuildOptions,
    start: &RunStart<'_>,
) -> anyhow::Result<Vec<Box<dyn Estimator>>> {
    let Model::Seed003 { w_var: w } = spec.model else {
        return Ok(Vec::new());
    };
    let s = Start {
        x0: SVector::<f64, 3>::from_column_slice(spec.prior.mean.as_slice()),
        p0: SMatrix::<f64, 3, 3>::from_fn(|i, j| spec.prior.cov[(i, j)]),
        w,
        y0: initial_measurement(start),
    };
    let mut all = vec![nn_estimator(&s)?];
    all.extend(baselines(&s, options.gate)?);
    if options.particles > 0 {
        all.push(Box::new(pf_coupled::CoupledPf::new(
            s.x0,
            s.p0,
            s.w,
            s.y0,
            options.particles,
            start.seed,
            start.run,
        )?));
    }
    Ok(all)
}

/// The paper's NN estimator, reporting the covariance bound it propagates.
fn nn_estimator(s: &Start) -> anyhow::Result<Box<dyn Estimator>> {
    let mut nn = NnTbcpEstimator::new(
        config(s.w)?,
        Tanh,
        s.x0,
        Seed003Example::h0(),
        s.p0,
        Seed003Example::p0(),
    )
    .map_err(named("nn"))?;
    if let Some(y0) = s.y0 {
        nn = nn.with_initial_measurement(y0).map_err(named("nn"))?;
    }
    Ok(Box::new(
        Adapted::<_, 3>::new(name!("nn"), fixed(OnModel::new(Seed003Example, nn)))
            .with_diagnostics(nn_diagnostics)
            .with_covariance_bound(),
    ))
}

/// The baselines a practitioner would run, behind the gate when there is one: the Kalman
/// filters that know the noise coupling (`kf`, the paper's `ekf`, the textbook `ekf-std`)
/// and those that take the noises as independent (`kf-indep`, `ekf-indep`).
fn baselines(s: &Start, gate: Option<f64>) -> anyhow::Result<Vec<Box<dyn Estimator>>> {
    let coupled = |name: &'static str, mode| {
        let kf = CoupledNoiseKf::new(s.x0, s.p0, matrix![s.w], mode).map_err(named(name))?;
        match s.y0 {
            Some(y0) => kf.with_initial_measurement(y0).map_err(named(name)),
            None => Ok(kf),
        }
    };
    let indep = |name: &'static str, mode| {
        let kf = IndependentNoiseKf::new(s.x0, s.p0, matrix![s.w], mode).map_err(named(name))?;
        match s.y0 {
            Some(y0) => kf.with_initial_measurement(y0).map_err(named(name)),
            None => Ok(kf),
        }
    };
    macro_rules! gated {
        ($name:literal, $system:expr, $filter:expr) => {
            Box::new(
                Adapted::<_, 3>::new(name!($name), fixed(OnModel::new($system, $filter)))
                    .with_gate(gate)?,
            ) as Box<dyn Estimator>
        };
    }
    let (linear, jacobian) = (
        (Seed003Example, NoNonlinearity),
        (Seed003Example, Seed003Example),
    );
    Ok(vec![
        gated!("kf", linear, coupled("kf", Linearisation::None)?),
        gated!(
            "ekf",
            jacobian,
            coupled("ekf", Linearisation::PaperJacobian)?
        ),
        gated!("ekf-std", jacobian, coupled("ekf-std", Linearisation::Ekf)?),
        gated!("kf-indep", linear, indep("kf-indep", IndependentMode::Kf)?),
        gated!(
            "ekf-indep",
            jacobian,
            indep("ekf-indep", IndependentMode::Ekf)?
        ),
    ])
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
