//! Seed 003's part of an evaluation (`nn-token-bucket`, any scenario with channel-sim's
//! `Seed003Plant`): the assumption checker's verdict before the run, Theorem 1's bound against
//! the empirical covariance trace after it, and the bound plot (the paper's Fig. 3).

use std::path::Path;

use channel_sim::channel::token_bucket::TokenBucketStage;
use channel_sim::plant::nn::Seed003Plant;
use channel_sim::scenario::ComposedScenario;
use channel_sim::Scenario;
use estimator_core::filter::nn::{check_before_run, BucketParams, PreRunVerdict, Tanh};
use nalgebra::{SMatrix, SVector};

use super::report::EvalResult;
use crate::estimators::nn;

/// How the empirical covariance trace compares with the bound, per k.
#[derive(Clone, Debug, PartialEq)]
pub struct BoundCheck {
    /// Instants k = 0..=T where tr E[e eᵀ] > tr P̄_k (a necessary condition of P_k ≤ P̄_k
    /// failing).
    pub exceeded_at: Vec<usize>,
    /// Instants k ≥ 1 where the bound is not finite.
    pub non_finite_at: Vec<usize>,
    /// Smallest tr P̄_k / tr E[e eᵀ] over k ≥ 1.
    pub min_ratio_after_0: f64,
}

/// The assumption checker's pre-run verdict for a seed 003 scenario (`None` otherwise).
pub fn verdict(scenario: &dyn Scenario) -> anyhow::Result<Option<PreRunVerdict<f64>>> {
    let Some(composed) = scenario.as_any().downcast_ref::<ComposedScenario>() else {
        return Ok(None);
    };
    let Some(plant) = composed.plant().as_any().downcast_ref::<Seed003Plant>() else {
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
        &nn::config(plant.w_var())?,
        &Tanh,
        nn::EPS_BAR,
        &p0_true,
        &p0_bar,
        Some(f_sup),
        bucket,
    )?))
}

/// Adds `empirical_trace` (= MSE(k) = tr E[e_k e_kᵀ]) to the `nn` entry, prints the assumption
/// checker's verdict and the bound check, and writes the bound plot beside `plot` (as
/// `<stem>-bound.png`/`.svg`). Does nothing for other scenarios.
pub fn after_eval(
    result: &mut EvalResult,
    scenario: &dyn Scenario,
    plot: Option<&Path>,
) -> anyhow::Result<()> {
    let Some(v) = verdict(scenario)? else {
        return Ok(());
    };
    estpipe_process::outln!("seed 003 assumption checker (before the run):\n{v}");
    let Some(check) = add_empirical_trace(result) else {
        return Ok(());
    };
    estpipe_process::outln!(
        "bound check: tr E[e eᵀ] > tr P̄_k at {} of {} instants {:?}; min tr P̄/tr E[eeᵀ] over k ≥ 1: {:.3e}",
        check.exceeded_at.len(),
        result.horizon as usize + 1,
        check.exceeded_at,
        check.min_ratio_after_0
    );
    if let Some((_, r)) = result.estimators.iter().find(|(n, _)| n == "nn") {
        if let Some((_, phi)) = r.diagnostics.iter().find(|(n, _)| n == "phi_exceeds") {
            let mean = phi.iter().skip(1).sum::<f64>() / (phi.len().max(2) - 1) as f64;
            estpipe_process::outln!(
                "during the run: ||phi(x_hat_k)|| > phi_bar in {:.1} % of (run, k) pairs, k ≥ 1",
                100.0 * mean
            );
        }
    }
    for (name, r) in &result.estimators {
        let per_state: Vec<String> = r
            .mse_per_state
            .iter()
            .map(|m| {
                let v: Vec<f64> = m.iter().skip(1).copied().collect();
                format!("{:.4e}", v.iter().sum::<f64>() / v.len().max(1) as f64)
            })
            .collect();
        estpipe_process::outln!(
            "{name}: per-state MSE (mean over k = 1..T) [{}]",
            per_state.join(", ")
        );
    }
    if let Some(path) = plot {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().into_owned())
            .unwrap_or_else(|| "png".into());
        let stem = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "plot".into());
        let out = path.with_file_name(format!("{stem}-bound.{ext}"));
        crate::plot::bound::plot_bound(result, &out)?;
        estpipe_process::outln!("wrote {}", out.display());
    }
    Ok(())
}

/// Adds `empirical_trace` to the `nn` entry and compares it with `bound_trace`.
pub fn add_empirical_trace(result: &mut EvalResult) -> Option<BoundCheck> {
    let (_, r) = result.estimators.iter_mut().find(|(n, _)| n == "nn")?;
    let empirical = r.mse.clone();
    let bound = r
        .diagnostics
        .iter()
        .find(|(n, _)| n == "bound_trace")?
        .1
        .clone();
    if !r.diagnostics.iter().any(|(n, _)| n == "empirical_trace") {
        r.diagnostics
            .push(("empirical_trace".to_owned(), empirical.clone()));
    }
    let mut check = BoundCheck {
        exceeded_at: Vec::new(),
        non_finite_at: Vec::new(),
        min_ratio_after_0: f64::INFINITY,
    };
    for (k, (&e, &b)) in empirical.iter().zip(&bound).enumerate() {
        if !b.is_finite() {
            if k > 0 {
                check.non_finite_at.push(k);
            }
            continue;
        }
        if e > b {
            check.exceeded_at.push(k);
        }
        if k > 0 && e > 0.0 {
            check.min_ratio_after_0 = check.min_ratio_after_0.min(b / e);
        }
    }
    Some(check)
}
