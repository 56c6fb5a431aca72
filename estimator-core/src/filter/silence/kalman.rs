//! The Kalman filter behind event-triggered nodes sharing a token bucket, reading every held
//! trigger's silence (docs/tobit-fusion.md, "The linear case").
//!
//! One prediction per instant (node 0's model, as [`crate::filter::SequentialKf`]), then node
//! by node: a delivered measurement is the Kalman update; a silence the bucket mirror calls
//! held ([`crate::protocol::bucket_mirror`]) is the silence update of the chosen
//! [`SilenceForm`] on the node's silence set ([`crate::protocol::trigger_knowledge`]); a
//! silence without a token, or a lost packet, is no information. Without the silence update
//! this is the intermittent Kalman filter.

use nalgebra::SMatrix;

use super::set::{uniform_moments, SilenceBox};
use super::truncated::truncate_box;
use super::{Arrival, SilenceCounts, SilenceForm, TriggeredPackets};
use crate::estimate::Estimate;
use crate::estimator::{Estimator, OnModel};
use crate::filter::gate::{GateCounts, GatedStep, InnovationGate};
use crate::filter::kalman::KalmanFilter;
use crate::model::LinearSystem;
use crate::protocol::bucket_mirror::BucketMirror;
use crate::protocol::shared_token_bucket::SharedTokenBucket;
use crate::protocol::trigger_knowledge::{SilenceBall, TriggerKnowledge};
use crate::{Real, Result};

/// The silence update of `form` on a Kalman filter: `kf` holds the prior, `c`, `r` the node's
/// `C` and `D R Dᵀ`, `ball` its silence set (no censoring).
pub fn silence_update<T: Real, const NX: usize, const NY: usize>(
    kf: &mut KalmanFilter<T, NX>,
    c: &SMatrix<T, NY, NX>,
    r: &SMatrix<T, NY, NY>,
    ball: &SilenceBall<T, NY>,
    form: SilenceForm,
) -> Result<()> {
    match form {
        SilenceForm::PseudoMeasurement => {
            let (mean, var) = uniform_moments(ball, None);
            kf.update_with(c, &(r + SMatrix::from_diagonal(&var)), &mean)
        }
        SilenceForm::TruncatedGaussian => {
            let (x, p) = kf.estimate().into_parts();
            let (x, p) = truncate_box(&x, &p, c, r, &SilenceBox::of_ball(ball, None))?;
            kf.reset(x, p)
        }
    }
}

/// The Kalman filter of `L` event-triggered nodes with the silence update `form`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SilenceKf<T: Real, const NX: usize, const NY: usize, const L: usize> {
    kf: KalmanFilter<T, NX>,
    nodes: [TriggerKnowledge<T, NY>; L],
    mirror: BucketMirror<L>,
    form: SilenceForm,
    counts: SilenceCounts,
}

impl<T: Real, const NX: usize, const NY: usize, const L: usize> SilenceKf<T, NX, NY, L> {
    /// `kf` with the nodes' trigger knowledge and the shared bucket (started at ξ₀).
    pub fn new(
        kf: KalmanFilter<T, NX>,
        nodes: [TriggerKnowledge<T, NY>; L],
        bucket: SharedTokenBucket<L>,
        form: SilenceForm,
    ) -> Self {
        Self {
            kf,
            nodes,
            mirror: BucketMirror::new(bucket),
            form,
            counts: SilenceCounts::default(),
        }
    }

    /// x̂ and P.
    #[inline]
    pub fn estimate(&self) -> &Estimate<T, NX> {
        self.kf.estimate()
    }

    /// The bucket mirror.
    #[inline]
    pub fn mirror(&self) -> &BucketMirror<L> {
        &self.mirror
    }

    /// The silences so far.
    #[inline]
    pub fn counts(&self) -> SilenceCounts {
        self.counts
    }

    /// One instant `k ≥ 1` with the arrivals already classified (the mirror is not
    /// consulted: a test can feed a mirror that lies). Nothing changes on error.
    pub fn step_arrivals<M: LinearSystem<T, NX, NY>>(
        &mut self,
        models: &[M; L],
        k: usize,
        arrivals: &[Arrival<'_, T, NY>; L],
    ) -> Result<()> {
        self.step_arrivals_gated(models, k, arrivals, &InnovationGate::off())
            .map(|_| ())
    }

    /// [`SilenceKf::step_arrivals`] behind an innovation gate (docs/gate.md): a delivered
    /// measurement the gate rejects is no information and its node's reference unknown (the
    /// node did send it), as a lost packet. Returns what the gate tested and rejected.
    pub fn step_arrivals_gated<M: LinearSystem<T, NX, NY>>(
        &mut self,
        models: &[M; L],
        k: usize,
        arrivals: &[Arrival<'_, T, NY>; L],
        gate: &InnovationGate<T>,
    ) -> Result<GateCounts> {
        let mut next = *self;
        let mut counts = GateCounts::NONE;
        next.kf.predict(&models[0], k.saturating_sub(1))?;
        for m in 0..L {
            let node = &mut next.nodes[m];
            match arrivals[m] {
                Arrival::Received(y) => {
                    let (c, r) = (models[m].c(k), models[m].measurement_cov(k));
                    let used = next.kf.update_gated_with(&c, &r, y, gate)?;
                    if gate.is_off() {
                        node.delivered(y)?;
                    } else {
                        counts.add(GateCounts::one(used));
                        if used {
                            node.delivered(y)?;
                        } else {
                            node.lost();
                        }
                    }
                }
                Arrival::Held => {
                    match node.silence_set() {
                        Some(ball) => {
                            let (c, r) = (models[m].c(k), models[m].measurement_cov(k));
                            silence_update(&mut next.kf, &c, &r, &ball, self.form)?;
                            next.counts.held += 1;
                        }
                        None => next.counts.unusable += 1,
                    }
                    node.silent();
                }
                Arrival::Blocked => {
                    next.counts.blocked += 1;
                    node.silent();
                }
                Arrival::Lost => node.lost(),
            }
        }
        *self = next;
        Ok(counts)
    }

    /// One instant: the mirror classifies the silences, then [`SilenceKf::step_arrivals`].
    /// Nothing changes on error (the mirror included).
    pub fn step<M: LinearSystem<T, NX, NY>>(
        &mut self,
        models: &[M; L],
        k: usize,
        y: &TriggeredPackets<T, NY, L>,
    ) -> Result<()> {
        let mut next = *self;
        let held = next.mirror.step(&y.sent(), y.level);
        next.step_arrivals(models, k, &y.arrivals(&held))?;
        *self = next;
        Ok(())
    }
}

/// Behind a gate: the mirror sees every delivered packet (a rejected one was still a send);
/// the filter reads a rejected one as lost.
impl<T: Real, const NX: usize, const NY: usize, const L: usize, M: LinearSystem<T, NX, NY>>
    GatedStep<T, NX> for OnModel<[M; L], SilenceKf<T, NX, NY, L>, NY>
{
    fn step_gated(
        &mut self,
        k: usize,
        y: &TriggeredPackets<T, NY, L>,
        gate: &InnovationGate<T>,
    ) -> Result<GateCounts> {
        let mut next = self.filter;
        let held = next.mirror.step(&y.sent(), y.level);
        let counts = next.step_arrivals_gated(&self.model, k, &y.arrivals(&held), gate)?;
        self.filter = next;
        Ok(counts)
    }
}

impl<T: Real, const NX: usize, const NY: usize, const L: usize, M: LinearSystem<T, NX, NY>>
    Estimator<T, NX> for OnModel<[M; L], SilenceKf<T, NX, NY, L>, NY>
{
    type Measurement = TriggeredPackets<T, NY, L>;

    #[inline]
    fn step(&mut self, k: usize, y: &TriggeredPackets<T, NY, L>) -> Result<()> {
        self.filter.step(&self.model, k, y)
    }

    #[inline]
    fn estimate(&self) -> &Estimate<T, NX> {
        self.filter.estimate()
    }
}

#[cfg(test)]
mod tests;
