//! The seed 001 estimators for occlusion dropouts: `cce` (the paper's cross-coupled estimator,
//! Algorithms 1-2), `kf-io` (the paper's linear MMSE baseline, built as `docs/design.md`
//! "Seed 001" states) and `adf` (the product's exact-likelihood assumed-density filter). The
//! paper's third curve, `ikf`, is the generic [`super::ikf`] family (prediction only on a
//! dropout).
//!
//! Applies to specs with one sensor node, a linear model and known occlusion regions
//! ([`Occlusion`](estpipe_spec::channel::Occlusion) with 1 to 4 intervals), for `n_x ≤ 4` and `n_y ≤ 2`. `cce` uses the
//! KL-optimal 15-component Gaussian sum (`gsum`, σ = 0.0617 r). Diagnostics: `trace_p`.
//!
//! A packet lost in transport ([`Packet::Lost`]: lost inside the IPC, missed before join,
//! marked lost in a slot log or by `eval --transport-loss`) is a prediction-only step for all
//! three: a loss says nothing about the state. With `--loss-rate P` (a positive
//! `BuildOptions::loss_rate`) the family also builds `cce-mix`, `kf-io-mix` and `adf-mix`, the
//! same filters with `with_loss_rate(P)`: for a receiver that cannot tell a loss from a
//! dropout, every dropout is "occluded, or lost with probability P" (docs/occlusion.md,
//! "Losses").

use std::sync::Arc;

use estimator_core::filter::{AssumedDensityFilter, CrossCoupledEstimator, KfIo};
use estimator_core::gsum::GaussSum;
use estimator_core::protocol::occlusion::Occlusion;
use estimator_core::{OnModel, Packet};
use estpipe_spec::{EstimatorSpec, LinearModel};
use nalgebra::{SMatrix, SVector};

use super::adapter::{name, Adapted, Name};
use super::fed::{linear, on_model};
use super::snapshot::{fixed, Snapshot};
use super::{BuildOptions, RunStart};
use crate::Estimator;

/// Gaussian components per region used by `cce` (the paper's N = 15).
pub const CCE_COMPONENTS: usize = 15;

/// Builds `cce`, `kf-io` and `adf` for a spec with occlusion regions (empty list otherwise).
pub fn build(
    spec: &Arc<EstimatorSpec>,
    options: &BuildOptions,
    _start: &RunStart<'_>,
) -> anyhow::Result<Vec<Box<dyn Estimator>>> {
    let Some(occ) = &spec.channel.occlusion else {
        return Ok(Vec::new());
    };
    if spec.linear().is_none() || spec.nodes() != 1 {
        return Ok(Vec::new());
    }
    let (nx, ny) = (spec.nx(), spec.ny());
    macro_rules! go {
        ($nx:literal, $ny:literal) => {
            match occ.count() {
                1 => family::<$nx, $ny, 1>(spec, options.loss_rate, options.gate),
                2 => family::<$nx, $ny, 2>(spec, options.loss_rate, options.gate),
                3 => family::<$nx, $ny, 3>(spec, options.loss_rate, options.gate),
                4 => family::<$nx, $ny, 4>(spec, options.loss_rate, options.gate),
                _ => Ok(Vec::new()),
            }
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
    spec: &Arc<EstimatorSpec>,
    loss_rate: f64,
    gate: Option<f64>,
) -> anyhow::Result<Vec<Box<dyn Estimator>>> {
    let known = spec
        .channel
        .occlusion
        .as_ref()
        .ok_or_else(|| anyhow::anyhow!("the spec has no occlusion regions"))?;
    let occ: Occlusion<f64, NX, 1, S> = known.at::<NX, S>().ok_or_else(|| {
        anyhow::anyhow!(
            "the occlusion regions (e of {} entries, psi {}) do not fit the {NX}-state model",
            known.e().len(),
            known.psi()
        )
    })?;
    let x0 = SVector::<f64, NX>::from_column_slice(spec.prior.mean.as_slice());
    let p0: SMatrix<f64, NX, NX> = fixed(&spec.prior.cov);
    let gsum = GaussSum::<f64, 1, CCE_COMPONENTS>::uniform()?;
    let cce =
        CrossCoupledEstimator::new(x0, p0, occ, &gsum).map_err(|e| anyhow::anyhow!("cce: {e}"))?;
    let kfio = KfIo::new(x0, p0, occ).map_err(|e| anyhow::anyhow!("kf-io: {e}"))?;
    let adf = AssumedDensityFilter::new(x0, p0, occ).map_err(|e| anyhow::anyhow!("adf: {e}"))?;
    let model = Snapshot::<NX, NY>::at(linear(spec)?, 1);
    let mut out = vec![
        adapted(name!("cce"), spec, OnModel::new(model, cce), gate)?,
        adapted(name!("kf-io"), spec, OnModel::new(model, kfio), gate)?,
        adapted(name!("adf"), spec, OnModel::new(model, adf), gate)?,
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
            adapted(name!("cce-mix"), spec, OnModel::new(model, cce), gate)?,
            adapted(name!("kf-io-mix"), spec, OnModel::new(model, kfio), gate)?,
            adapted(name!("adf-mix"), spec, OnModel::new(model, adf), gate)?,
        ]);
    }
    Ok(out)
}

/// The input term of instant `k` in `on`'s model.
fn set_input<const NX: usize, const NY: usize, F>(
    on: &mut OnModel<Snapshot<NX, NY>, F, NY>,
    model: &LinearModel,
    k: usize,
) {
    on.model.set_input(model, k);
}

/// `on` (a filter on node 0's model) under `name`.
fn adapted<const NX: usize, const NY: usize, F>(
    name: Name,
    spec: &Arc<EstimatorSpec>,
    on: OnModel<Snapshot<NX, NY>, F, NY>,
    gate: Option<f64>,
) -> anyhow::Result<Box<dyn Estimator>>
where
    OnModel<Snapshot<NX, NY>, F, NY>: estimator_core::filter::GatedStep<f64, NX, Measurement = Packet<f64, NY>>
        + Clone
        + Send
        + 'static,
{
    let fed = on_model(on, spec, set_input);
    let a = Adapted::<_, NX>::new(name, fed)
        .with_gate(gate)
        .map_err(|e| anyhow::anyhow!("{}: {e}", name.plain))?;
    Ok(Box::new(a))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::RunStart;
    use crate::{build_all, FACTORIES};
    use estpipe_wire::{Observation, FLAG_IPC_LOST, FLAG_OCCLUDED};

    /// A slot lost in the IPC is a prediction for every occlusion estimator (the same as
    /// `ikf`'s), a dropout is not: from the same prior, after one instant.
    #[test]
    fn a_lost_slot_is_a_prediction_and_a_dropout_is_not() {
        let s = crate::presets::preset_spec("occlusion");
        let options = BuildOptions {
            particles: 0,
            loss_rate: 0.2,
            ..BuildOptions::default()
        };
        let after = |flags: u32| {
            let mut ests = build_all(FACTORIES, &s, &options, &RunStart::default()).unwrap();
            let obs = [Observation::dropped(1, 0, 2, flags)];
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
