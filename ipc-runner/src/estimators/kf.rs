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

use estimator_core::filter::{GateCounts, GatedStep, InnovationGate, KalmanFilter};
use estimator_core::linalg::symmetrize;
use estimator_core::{Error, Estimate, Packet};
use estpipe_spec::{EstimatorSpec, LinearModel};
use estpipe_wire::MAX_NODES;
use nalgebra::SVector;

use super::adapter::Adapted;
use super::fed::{linear, Fed};
use super::snapshot::{fixed, Snapshot};
use super::{EvalOptions, RunStart};
use crate::Estimator;

/// Builds `kf` for a spec with a linear model.
pub fn build(
    spec: &Arc<EstimatorSpec>,
    options: &EvalOptions,
    _start: &RunStart<'_>,
) -> anyhow::Result<Vec<Box<dyn Estimator>>> {
    Ok(linear_kf(spec, "kf", true, options.gate)?
        .into_iter()
        .collect())
}

/// A Kalman filter on `spec`'s linear model named `name`, or `None` when the spec has none.
/// `full_information` selects the oracle (`kf`) or the channel-fed filter; `gate`, the
/// innovation gate's probability (`--gate`, docs/gate.md).
pub fn linear_kf(
    spec: &Arc<EstimatorSpec>,
    name: &'static str,
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
                _ => anyhow::bail!("{name}: measurement dimension {ny} not supported"),
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
        _ => anyhow::bail!("{name}: state dimension {nx} not supported"),
    }?;
    Ok(Some(kf))
}

struct Spec<'a> {
    name: &'static str,
    full_information: bool,
    gate: Option<f64>,
    spec: &'a Arc<EstimatorSpec>,
}

/// The Kalman filter on every node's packet of an instant: one prediction, then an update
/// with each delivered measurement, node by node. A core [`estimator_core::Estimator`] of its
/// own because the core's Kalman filter takes one measurement per step.
#[derive(Clone, Copy)]
struct NodeByNode<const NX: usize, const NY: usize> {
    /// The plant's model per node (entries from `nodes` on unused).
    model: [Snapshot<NX, NY>; MAX_NODES],
    nodes: usize,
    kf: KalmanFilter<f64, NX>,
    /// Node 0's `B Q Bᵀ` and `D R Dᵀ` are their own symmetric parts, bit for bit (what
    /// `predict_with` and `update_with` would symmetrise): a one-node instant may then take
    /// the core's fused step, which computes the same bits ([`fused_ok`]).
    fused: bool,
}

/// Whether node 0's covariances are unchanged by `predict_with`'s and `update_with`'s
/// symmetrisation, so that `KalmanFilter::step` on them gives the same bits as the two calls.
fn fused_ok<const NX: usize, const NY: usize>(m: &Snapshot<NX, NY>) -> bool {
    symmetrize(&m.q) == m.q && symmetrize(&m.r) == m.r
}

impl<const NX: usize, const NY: usize> estimator_core::Estimator<f64, NX> for NodeByNode<NX, NY> {
    type Measurement = [Packet<f64, NY>; MAX_NODES];

    fn step(&mut self, k: usize, y: &Self::Measurement) -> Result<(), Error> {
        // One node delivering a finite measurement: the fused predict + update of the core
        // (the same arithmetic, one pass; on error it leaves the filter untouched). A
        // non-finite y takes the path below, which reports the prediction's error first.
        if self.fused && self.nodes == 1 && y[1..].iter().all(|p| p.delivered().is_none()) {
            if let Some(y0) = y[0].delivered().filter(|v| v.iter().all(|e| e.is_finite())) {
                return self.kf.step(&self.model[0], k, y0);
            }
        }
        // Work on a copy and commit at the end: an error leaves the filter untouched.
        let mut kf = self.kf;
        let m0 = &self.model[0];
        match &m0.u {
            None => kf.predict_with(&m0.a, &m0.q)?,
            Some(u) => kf.predict_with_input(&m0.a, &m0.q, u)?,
        }
        for (node, y) in y.iter().enumerate() {
            if let Some(y) = y.delivered() {
                if node >= self.nodes {
                    return Err(Error::InvalidConfig {
                        field: "node",
                        reason: "observation from a node the model does not have",
                    });
                }
                let m = &self.model[node];
                kf.update_with::<NY>(&m.c, &m.r, y)?;
            }
        }
        self.kf = kf;
        Ok(())
    }

    fn estimate(&self) -> &Estimate<f64, NX> {
        self.kf.estimate()
    }
}

/// Behind a gate: each delivered measurement is tested against the estimate it would update
/// (after the prediction and the earlier nodes' updates); a rejected one is skipped.
impl<const NX: usize, const NY: usize> GatedStep<f64, NX> for NodeByNode<NX, NY> {
    fn step_gated(
        &mut self,
        _k: usize,
        y: &Self::Measurement,
        gate: &InnovationGate<f64>,
    ) -> Result<GateCounts, Error> {
        let mut kf = self.kf;
        kf.predict_with(&self.model[0].a, &self.model[0].q)?;
        let mut counts = GateCounts::NONE;
        for (node, y) in y.iter().enumerate() {
            if let Some(y) = y.delivered() {
                if node >= self.nodes {
                    return Err(Error::InvalidConfig {
                        field: "node",
                        reason: "observation from a node the model does not have",
                    });
                }
                let m = &self.model[node];
                counts.add(GateCounts::one(
                    kf.update_gated_with::<NY>(&m.c, &m.r, y, gate)?,
                ));
            }
        }
        self.kf = kf;
        Ok(counts)
    }
}

/// `NodeByNode`'s model at instant `k`: its input term (the matrices are constant).
fn remodel<const NX: usize, const NY: usize>(
    e: &mut NodeByNode<NX, NY>,
    model: &LinearModel,
    k: usize,
) {
    for m in &mut e.model[..e.nodes] {
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
    .map_err(|e| anyhow::anyhow!("{}: prior.cov: {e}", spec.name))?;
    let nodes = spec.spec.nodes();
    let model = Snapshot::nodes(linear(spec.spec)?, nodes, 1);
    let est = NodeByNode::<NX, NY> {
        fused: fused_ok(&model[0]),
        model,
        nodes,
        kf,
    };
    Ok(Box::new(
        Adapted::<_, NX>::new(spec.name, Fed::on_model(est, spec.spec, remodel))
            .with_full_information(spec.full_information)
            .with_gate(spec.gate)?,
    ))
}
