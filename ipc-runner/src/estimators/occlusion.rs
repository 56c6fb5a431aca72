//! The seed 001 estimators for occlusion dropouts: `cce` (the paper's cross-coupled estimator,
//! Algorithms 1-2), `kf-io` (the paper's linear MMSE baseline, built as `docs/design.md`
//! "Seed 001" states) and `adf` (the product's exact-likelihood assumed-density filter). The
//! paper's third curve, `ikf`, is the generic [`super::ikf`] family (prediction only on a
//! dropout).
//!
//! Applies to composed scenarios with one sensor node, a linear plant and an occlusion stage
//! ([`OcclusionSpec`] with 1 to 4 intervals), for `n_x ≤ 4` and `n_y ≤ 2`. `cce` uses the
//! KL-optimal 15-component Gaussian sum (`gsum`, σ = 0.0617 r). Diagnostics: `trace_p`.
//!
//! A packet lost in transport ([`Packet::Lost`]: lost inside the IPC, missed before join,
//! marked lost in a slot log or by `eval --transport-loss`) is a prediction-only step for all
//! three: a loss says nothing about the state. With `--loss-rate P` (a positive
//! `EvalOptions::loss_rate`) the family also builds `cce-mix`, `kf-io-mix` and `adf-mix`, the
//! same filters with `with_loss_rate(P)`: for a receiver that cannot tell a loss from a
//! dropout, every dropout is "occluded, or lost with probability P" (docs/occlusion.md,
//! "Losses").

use std::sync::Arc;

use channel_sim::channel::occlusion::OcclusionSpec;
use channel_sim::plant::Plant;
use channel_sim::scenario::ComposedScenario;
use channel_sim::Scenario;
use estimator_core::filter::{AssumedDensityFilter, CrossCoupledEstimator, KfIo};
use estimator_core::gsum::GaussSum;
use estimator_core::protocol::occlusion::Occlusion;
use estimator_core::{OnModel, Packet};
use nalgebra::{SMatrix, SVector};

use super::adapter::Adapted;
use super::fed::Fed;
use super::snapshot::{fixed, Snapshot};
use super::EvalOptions;
use crate::Estimator;

/// Gaussian components per region used by `cce` (the paper's N = 15).
pub const CCE_COMPONENTS: usize = 15;

/// Builds `cce`, `kf-io` and `adf` for an occlusion scenario (empty list otherwise).
pub fn build(
    scenario: &dyn Scenario,
    options: &EvalOptions,
    _seed: u64,
    _run: u64,
) -> anyhow::Result<Vec<Box<dyn Estimator>>> {
    let Some(composed) = scenario.as_any().downcast_ref::<ComposedScenario>() else {
        return Ok(Vec::new());
    };
    if composed.plant().linear().is_none() || scenario.nodes() != 1 {
        return Ok(Vec::new());
    }
    macro_rules! by_s {
        ($s:literal) => {
            if let Some(spec) = composed.stage::<OcclusionSpec<$s>>() {
                return by_dims::<$s>(composed, spec, options.loss_rate, options.gate);
            }
        };
    }
    by_s!(1);
    by_s!(2);
    by_s!(3);
    by_s!(4);
    Ok(Vec::new())
}

fn by_dims<const S: usize>(
    composed: &ComposedScenario,
    spec: &OcclusionSpec<S>,
    loss_rate: f64,
    gate: Option<f64>,
) -> anyhow::Result<Vec<Box<dyn Estimator>>> {
    let (nx, ny) = (composed.plant().nx(), composed.plant().ny());
    macro_rules! go {
        ($nx:literal, $ny:literal) => {
            family::<$nx, $ny, S>(composed, spec, loss_rate, gate)
        };
    }
    match (nx, ny) {
        (1, 1) => go!(1, 1),
        (2, 1) => go!(2, 1),
        (3, 1) => go!(3, 1),
        (4, 1) => go!(4, 1),
        (1, 2) => go!(1, 2),
        (2, 2) => go!(2, 2),
        (3, 2) => go!(3, 2),
        (4, 2) => go!(4, 2),
        _ => anyhow::bail!("occlusion estimators support n_x ≤ 4 and n_y ≤ 2, got {nx}, {ny}"),
    }
}

fn family<const NX: usize, const NY: usize, const S: usize>(
    composed: &ComposedScenario,
    spec: &OcclusionSpec<S>,
    loss_rate: f64,
    gate: Option<f64>,
) -> anyhow::Result<Vec<Box<dyn Estimator>>> {
    let occ: Occlusion<f64, NX, 1, S> = spec.occlusion::<NX>().ok_or_else(|| {
        anyhow::anyhow!(
            "the occlusion stage (e of {} entries, psi {}) does not fit the {NX}-state plant",
            spec.e.len(),
            spec.psi
        )
    })?;
    let init = composed.initial();
    let x0 = SVector::<f64, NX>::from_column_slice(init.estimator_mean.as_slice());
    let p0: SMatrix<f64, NX, NX> = fixed(&init.estimator_cov);
    let plant = composed.plant_arc();
    let gsum = GaussSum::<f64, 1, CCE_COMPONENTS>::uniform()?;
    let cce =
        CrossCoupledEstimator::new(x0, p0, occ, &gsum).map_err(|e| anyhow::anyhow!("cce: {e}"))?;
    let kfio = KfIo::new(x0, p0, occ).map_err(|e| anyhow::anyhow!("kf-io: {e}"))?;
    let adf = AssumedDensityFilter::new(x0, p0, occ).map_err(|e| anyhow::anyhow!("adf: {e}"))?;
    let model = Snapshot::<NX, NY>::at(super::linear_of(&*plant)?, 1);
    let mut out = vec![
        adapted("cce", &plant, OnModel::new(model, cce), gate)?,
        adapted("kf-io", &plant, OnModel::new(model, kfio), gate)?,
        adapted("adf", &plant, OnModel::new(model, adf), gate)?,
    ];
    if loss_rate > 0.0 {
        let bad = |name: &str, e: estimator_core::Error| anyhow::anyhow!("{name}: {e}");
        let cce = cce
            .with_loss_rate(loss_rate)
            .map_err(|e| bad("cce-mix", e))?;
        let kfio = kfio
            .with_loss_rate(loss_rate)
            .map_err(|e| bad("kf-io-mix", e))?;
        let adf = adf
            .with_loss_rate(loss_rate)
            .map_err(|e| bad("adf-mix", e))?;
        out.extend([
            adapted("cce-mix", &plant, OnModel::new(model, cce), gate)?,
            adapted("kf-io-mix", &plant, OnModel::new(model, kfio), gate)?,
            adapted("adf-mix", &plant, OnModel::new(model, adf), gate)?,
        ]);
    }
    Ok(out)
}

/// `on` (a filter on node 0's model) under `name`.
fn adapted<const NX: usize, const NY: usize, F>(
    name: &'static str,
    plant: &Arc<dyn Plant>,
    on: OnModel<Snapshot<NX, NY>, F, NY>,
    gate: Option<f64>,
) -> anyhow::Result<Box<dyn Estimator>>
where
    OnModel<Snapshot<NX, NY>, F, NY>: estimator_core::filter::GatedStep<f64, NX, Measurement = Packet<f64, NY>>
        + Clone
        + Send
        + 'static,
{
    let fed = Fed::on_plant(on, Arc::clone(plant), |on, model, k| {
        on.model = Snapshot::at(model, k);
    });
    let a = Adapted::<_, NX>::new(name, fed)
        .with_gate(gate)
        .map_err(|e| anyhow::anyhow!("{name}: {e}"))?;
    Ok(Box::new(a))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimators::{build_all, FACTORIES};
    use channel_sim::sim::FLAG_OCCLUDED;
    use estpipe_wire::FLAG_IPC_LOST;

    /// A slot lost in the IPC is a prediction for every occlusion estimator (the same as
    /// `ikf`'s), a dropout is not: from the same prior, after one instant.
    #[test]
    fn a_lost_slot_is_a_prediction_and_a_dropout_is_not() {
        let s = channel_sim::scenario::preset("occlusion").unwrap();
        let options = EvalOptions {
            particles: 0,
            loss_rate: 0.2,
            ..EvalOptions::default()
        };
        let after = |flags: u32| {
            let mut ests = build_all(FACTORIES, &*s, &options, 0, 0).unwrap();
            let obs = [channel_sim::Observation::dropped(1, 0, 2, flags)];
            ests.iter_mut()
                .filter(|e| !e.full_information())
                .map(|e| {
                    e.step(1, &obs).unwrap();
                    let mut x = [0.0; 3];
                    e.estimate(&mut x);
                    (e.name(), x)
                })
                .collect::<Vec<_>>()
        };
        let (lost, dropped) = (after(FLAG_IPC_LOST), after(FLAG_OCCLUDED));
        let ikf = lost.iter().find(|(n, _)| *n == "ikf").unwrap().1;
        assert_eq!(lost.len(), 7, "{lost:?}");
        for ((name, x), (_, y)) in lost.iter().zip(&dropped) {
            assert_eq!(*x, ikf, "{name} on a loss");
            match *name {
                "ikf" => {}
                // The prior (x₁ ≈ 5) is far below every region (15..85): for cce-mix the
                // "lost" hypothesis wins the label scoring and the update is the prediction.
                "cce-mix" => assert_eq!(*y, ikf),
                _ => assert_ne!(x, y, "{name}: a dropout is not a loss"),
            }
        }
    }
}
