//! `kf`: the full-information Kalman filter, an oracle lower bound.
//!
//! **Definition.** `kf` is estimator-core's [`KalmanFilter`] on the plant's linear description
//! fed with *every* sensor measurement, as if the channel were perfect: it reads the
//! observations before the channel ([`Estimator::full_information`]), so it exists only in
//! offline evaluation. Under a lossy channel it is therefore not a competitor but the bound
//! that no channel-aware estimator can beat (for a linear-Gaussian plant it is the MMSE
//! estimator given all measurements, and its MSE converges to the trace of the Riccati
//! covariance). The meaningful channel-aware baseline is [`super::ikf`]. A "KF" that treats
//! a dropped packet as y = 0 is deliberately not offered: it is neither optimal nor a bound.
//!
//! Applies to every spec with a linear model. Multi-node models
//! update node by node (sequential updates are exact because nodes' noises are independent),
//! nodes of different ny included (each padded to the largest, see `snapshot`). A known
//! control input enters the prediction (`B_u u_{k−1}`).
//! Diagnostics: `trace_p`, the trace of the filter's covariance P_k.

use std::sync::Arc;

use estimator_core::filter::{KalmanFilter, SequentialKf};
use estpipe_spec::{EstimatorSpec, LinearModel};
use estpipe_wire::MAX_NODES;
use nalgebra::SVector;

use super::adapter::{name, Adapted, Name};
use super::fed::{linear, on_model};
use super::snapshot::{fixed, Snapshot};
use super::{BuildOptions, RunStart};
use crate::Estimator;

/// Builds `kf` for a spec with a linear model.
pub fn build(
    spec: &Arc<EstimatorSpec>,
    options: &BuildOptions,
    _start: &RunStart<'_>,
) -> anyhow::Result<Vec<Box<dyn Estimator>>> {
    Ok(linear_kf(spec, name!("kf"), true, options.gate)?
        .into_iter()
        .collect())
}

/// A Kalman filter on `spec`'s linear model named `name`, or `None` when the spec has none.
/// `full_information` selects the oracle (`kf`) or the channel-fed filter; `gate`, the
/// innovation gate's probability (`--gate`, docs/gate.md).
pub(crate) fn linear_kf(
    spec: &Arc<EstimatorSpec>,
    name: Name,
    full_information: bool,
    gate: Option<f64>,
) -> anyhow::Result<Option<Box<dyn Estimator>>> {
    if spec.linear().is_none() {
        return Ok(None);
    }
    let spec = Spec {
        name,
        full_information,
        gate,
        spec,
    };
    let (nx, ny) = (spec.spec.nx(), spec.spec.ny());
    macro_rules! by_ny {
        ($nx:literal) => {
            match ny {
                1 => boxed::<$nx, 1>(spec),
                2 => boxed::<$nx, 2>(spec),
                3 => boxed::<$nx, 3>(spec),
                4 => boxed::<$nx, 4>(spec),
                _ => anyhow::bail!("{}: measurement dimension {ny} not supported", name.plain),
            }
        };
    }
    let kf = match nx {
        1 => by_ny!(1),
        2 => by_ny!(2),
        3 => by_ny!(3),
        4 => by_ny!(4),
        5 => by_ny!(5),
        6 => by_ny!(6),
        7 => by_ny!(7),
        8 => by_ny!(8),
        _ => anyhow::bail!("{}: state dimension {nx} not supported", name.plain),
    }?;
    Ok(Some(kf))
}

struct Spec<'a> {
    name: Name,
    full_information: bool,
    gate: Option<f64>,
    spec: &'a Arc<EstimatorSpec>,
}

/// The core's sequential Kalman filter on every node's packet of an instant (one prediction,
/// then an update with each delivered measurement, node by node), on the spec's model per node.
type NodeByNode<const NX: usize, const NY: usize> =
    SequentialKf<f64, NX, NY, MAX_NODES, Snapshot<NX, NY>>;

/// `NodeByNode`'s model at instant `k`: its input term (the matrices are constant).
fn remodel<const NX: usize, const NY: usize>(
    e: &mut NodeByNode<NX, NY>,
    model: &LinearModel,
    k: usize,
) {
    let nodes = e.nodes();
    for m in &mut e.models_mut()[..nodes] {
        m.set_input(model, k);
    }
}

/// The filter of `spec` at `NX`, `NY`.
fn boxed<const NX: usize, const NY: usize>(spec: Spec<'_>) -> anyhow::Result<Box<dyn Estimator>> {
    let prior = &spec.spec.prior;
    let kf = KalmanFilter::new(
        SVector::from_column_slice(prior.mean.as_slice()),
        fixed(&prior.cov),
    )
    .map_err(|e| anyhow::anyhow!("{}: prior.cov: {e}", spec.name.plain))?;
    let nodes = spec.spec.nodes();
    let model = Snapshot::nodes(linear(spec.spec)?, nodes, 1);
    let est = NodeByNode::<NX, NY>::new(model, nodes, kf)
        .map_err(|e| anyhow::anyhow!("{}: {e}", spec.name.plain))?;
    Ok(Box::new(
        Adapted::<_, NX>::new(spec.name, on_model(est, spec.spec, remodel))
            .with_full_information(spec.full_information)
            .with_gate(spec.gate)?,
    ))
}
