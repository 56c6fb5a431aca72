//! The Kalman filter on every node's packet of an instant: one prediction, then the update
//! (18) with each delivered measurement, node by node.
//!
//! The nodes' measurement noises are independent, so updating with one node's measurement
//! after the other's is the update with the stacked measurement (the sequential form of the
//! Kalman update). Nodes of different `n_y` share one `NY`: a node that measures fewer
//! components has a model padded with zero rows of `C` and unit variances in `D R Dᵀ`, and
//! zeros in its measurement, so that the padded components carry no information.
//!
//! The prediction is node 0's (`A`, `B Q Bᵀ` and the known input are the plant's, the same
//! for every node). An instant on which only node 0 delivers, on a one-node model whose
//! covariances are their own symmetric parts, takes [`KalmanFilter::step`]'s fused predict
//! and update: the same bits as the prediction and the update apart.

use nalgebra::{SMatrix, SVector};

use crate::estimate::Estimate;
use crate::estimator::Estimator;
use crate::filter::gate::{GateCounts, GatedStep, InnovationGate};
use crate::filter::kalman::KalmanFilter;
use crate::linalg::symmetrize;
use crate::model::LinearSystem;
use crate::packet::Packet;
use crate::{CovarianceForm, CovarianceUpdate, Error, Real, Result};

/// A Kalman filter on `NX` states fed by up to `L` nodes of `NY` measurements each: node
/// `m`'s model is `models[m]` (its `C_k` and `D R Dᵀ`; node 0's `A`, `B Q Bᵀ` and input term
/// are the prediction's), the first `nodes` of them in use. The models are the
/// configuration, the filter the running state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SequentialKf<
    T: Real,
    const NX: usize,
    const NY: usize,
    const L: usize,
    M,
    F: CovarianceForm = CovarianceUpdate,
> {
    models: [M; L],
    nodes: usize,
    kf: KalmanFilter<T, NX, F>,
}

/// The error of a measurement from a node past the model's `nodes`.
const UNKNOWN_NODE: Error = Error::InvalidConfig {
    field: "node",
    reason: "observation from a node the model does not have",
};

impl<T: Real, const NX: usize, const NY: usize, const L: usize, M, F: CovarianceForm>
    SequentialKf<T, NX, NY, L, M, F>
where
    M: LinearSystem<T, NX, NY>,
{
    /// `kf` on the first `nodes` of `models` (`1 ≤ nodes ≤ L`).
    pub fn new(models: [M; L], nodes: usize, kf: KalmanFilter<T, NX, F>) -> Result<Self> {
        if nodes == 0 || nodes > L {
            return Err(Error::InvalidConfig {
                field: "nodes",
                reason: "must be at least 1 and at most the model's nodes",
            });
        }
        Ok(Self { models, nodes, kf })
    }

    /// The per-node models.
    #[inline]
    pub fn models(&self) -> &[M; L] {
        &self.models
    }

    /// The per-node models, to be brought to another instant (a time-varying plant).
    #[inline]
    pub fn models_mut(&mut self) -> &mut [M; L] {
        &mut self.models
    }

    /// The number of nodes in use.
    #[inline]
    pub fn nodes(&self) -> usize {
        self.nodes
    }

    /// The Kalman filter (the running state).
    #[inline]
    pub fn filter(&self) -> &KalmanFilter<T, NX, F> {
        &self.kf
    }

    /// Current estimate `x̂_k` and covariance `P_k`.
    #[inline]
    pub fn estimate(&self) -> &Estimate<T, NX> {
        self.kf.estimate()
    }

    /// Node 0's model, the one that predicts.
    #[inline]
    fn first(&self) -> Result<&M> {
        self.models.first().ok_or(UNKNOWN_NODE)
    }

    /// The prediction of instant `k` from node 0's model into `kf`.
    #[inline]
    fn predict_into(&self, kf: &mut KalmanFilter<T, NX, F>, k: usize) -> Result<()> {
        let m0 = self.first()?;
        let j = k.saturating_sub(1);
        match m0.input(j) {
            None => kf.predict_with(&m0.a(j), &m0.process_cov(j)),
            Some(gu) => kf.predict_with_input(&m0.a(j), &m0.process_cov(j), &gu),
        }
    }

    /// The one-node instant's finite measurement when [`KalmanFilter::step`] on node 0 gives
    /// the bits of [`KalmanFilter::predict_with`] and [`KalmanFilter::update_with`] (which
    /// symmetrise `B Q Bᵀ` and `D R Dᵀ`, the step trusts them): `None` otherwise. A
    /// non-finite measurement takes the sequential path, which reports the prediction's
    /// error first.
    #[inline]
    fn fused<'y>(&self, k: usize, y: &'y [Packet<T, NY>; L]) -> Option<&'y SVector<T, NY>> {
        if self.nodes != 1 || y.iter().skip(1).any(|p| p.delivered().is_some()) {
            return None;
        }
        let y0 = y
            .first()?
            .delivered()
            .filter(|v| v.iter().all(|e| e.finite()))?;
        let m0 = self.models.first()?;
        let q = m0.process_cov(k.saturating_sub(1));
        (own_symmetric_part(&q) && own_symmetric_part(&m0.measurement_cov(k))).then_some(y0)
    }
}

/// Whether `symmetrize(m)` is `m`, bit for bit.
#[inline]
fn own_symmetric_part<T: Real, const N: usize>(m: &SMatrix<T, N, N>) -> bool {
    symmetrize(m) == *m
}

/// One prediction, then an update with each delivered measurement in node order; dropped and
/// lost packets are no information. A delivered measurement from a node past `nodes` is an
/// error. On error nothing changes.
impl<T: Real, const NX: usize, const NY: usize, const L: usize, M, F: CovarianceForm>
    Estimator<T, NX> for SequentialKf<T, NX, NY, L, M, F>
where
    M: LinearSystem<T, NX, NY>,
{
    type Measurement = [Packet<T, NY>; L];

    fn step(&mut self, k: usize, y: &[Packet<T, NY>; L]) -> Result<()> {
        if let Some(y0) = self.fused(k, y) {
            let Self { models, kf, .. } = self;
            let m0 = models.first().ok_or(UNKNOWN_NODE)?;
            return kf.step(m0, k, y0);
        }
        // On a copy, committed at the end: an error leaves the filter untouched.
        let mut kf = self.kf;
        self.predict_into(&mut kf, k)?;
        for (node, y) in y.iter().enumerate() {
            if let Some(y) = y.delivered() {
                let m = self.models.get(node).filter(|_| node < self.nodes);
                let m = m.ok_or(UNKNOWN_NODE)?;
                kf.update_with::<NY>(&m.c(k), &m.measurement_cov(k), y)?;
            }
        }
        self.kf = kf;
        Ok(())
    }

    #[inline]
    fn estimate(&self) -> &Estimate<T, NX> {
        self.kf.estimate()
    }
}

/// Behind a gate (docs/gate.md): each delivered measurement is tested against the estimate it
/// would update (after the prediction and the earlier nodes' updates); a rejected one is
/// skipped. With [`InnovationGate::off`] it is [`Estimator::step`], bit for bit.
impl<T: Real, const NX: usize, const NY: usize, const L: usize, M, F: CovarianceForm>
    GatedStep<T, NX> for SequentialKf<T, NX, NY, L, M, F>
where
    M: LinearSystem<T, NX, NY>,
{
    fn step_gated(
        &mut self,
        k: usize,
        y: &[Packet<T, NY>; L],
        gate: &InnovationGate<T>,
    ) -> Result<GateCounts> {
        let mut kf = self.kf;
        self.predict_into(&mut kf, k)?;
        let mut counts = GateCounts::NONE;
        for (node, y) in y.iter().enumerate() {
            if let Some(y) = y.delivered() {
                let m = self.models.get(node).filter(|_| node < self.nodes);
                let m = m.ok_or(UNKNOWN_NODE)?;
                let used = kf.update_gated_with::<NY>(&m.c(k), &m.measurement_cov(k), y, gate)?;
                counts.add(GateCounts::one(used));
            }
        }
        self.kf = kf;
        Ok(counts)
    }
}

#[cfg(test)]
mod tests;
