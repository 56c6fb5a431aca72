//! The product's seed-004 estimator at the information bound: one centralised Gaussian filter
//! that carries a covariance, reads every delivered censored packet by exact moment matching
//! and, optionally, every held trigger's silence (docs/tobit-fusion.md, "At the information
//! bound"; the estimators `tobit-cmm` and `tobit-cmm-held`).
//!
//! Per instant `k ≥ 1`:
//!
//! 1. the Kalman prediction with A, B Q Bᵀ (and G u) of node 0's model, which all nodes share;
//! 2. (C1) with every observed component of every delivered packet;
//! 3. (C2)-(C3) with every censored component of every delivered packet ([`super::censored`]);
//! 4. with `reads_silence`: for every silence the receiver's mirror of the shared bucket calls
//!    held ([`crate::protocol::bucket_mirror`]), the truncated-Gaussian update (S4)-(S6) on the
//!    node's silence box (S2) — the ball `‖y − ȳ‖ < r̄` of
//!    [`crate::protocol::trigger_knowledge`] intersected with the censoring region — with the
//!    full prediction covariance;
//! 5. a silence without a token, or a lost packet: no information.
//!
//! Where the paper's federated filter (Theorems 1-5) propagates a bound `P̄` and fuses with it,
//! this filter propagates the (moment-matched) error covariance itself, so its `P` is an
//! estimate of the error covariance, not a bound: the ANEES and the 95 % ellipse test it.
//! Lost and late packets follow the same rules as the other estimators (a lost packet makes
//! the node's reference unknown until its next delivery, [`Revise`](crate::fixed_lag::Revise)
//! folds a late one in).

use nalgebra::{SMatrix, SVector};

use super::censored::{observe, truncate_censored};
use super::config::diagonal_variances;
use crate::estimate::Estimate;
use crate::estimator::{Estimator, OnModel};
use crate::filter::gate::{GateCounts, GatedStep, InnovationGate};
use crate::filter::silence::set::SilenceBox;
use crate::filter::silence::truncated::truncate_box;
use crate::filter::silence::{Arrival, SilenceCounts, TriggeredPackets};
use crate::filter::KalmanFilter;
use crate::linalg::{check_finite, check_spd, symmetrize};
use crate::model::LinearSystem;
use crate::protocol::bucket_mirror::BucketMirror;
use crate::protocol::shared_token_bucket::SharedTokenBucket;
use crate::protocol::trigger_knowledge::TriggerKnowledge;
use crate::{Real, Result};

/// The centralised moment-matched Tobit filter of `L` nodes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MomentMatchedTobit<T: Real, const NX: usize, const NY: usize, const L: usize> {
    kf: KalmanFilter<T, NX>,
    tau: [SVector<T, NY>; L],
    nodes: [TriggerKnowledge<T, NY>; L],
    mirror: BucketMirror<L>,
    reads_silence: bool,
    counts: SilenceCounts,
}

/// One node's model at an instant: C and the diagonal of R.
type NodeModel<T, const NX: usize, const NY: usize> = (SMatrix<T, NY, NX>, SVector<T, NY>);

impl<T: Real, const NX: usize, const NY: usize, const L: usize> MomentMatchedTobit<T, NX, NY, L> {
    /// The prior `(x̄₀, P₀)`, every node's censoring thresholds τ_m and trigger knowledge
    /// (η̄₀ and the initial reference), the shared bucket at ξ₀, and whether held silences are
    /// read (`tobit-cmm-held`) or ignored (`tobit-cmm`).
    pub fn new(
        prior: Estimate<T, NX>,
        tau: [SVector<T, NY>; L],
        nodes: [TriggerKnowledge<T, NY>; L],
        bucket: SharedTokenBucket<L>,
        reads_silence: bool,
    ) -> Result<Self> {
        for t in &tau {
            check_finite(t, "censoring threshold")?;
        }
        let (x, p) = prior.into_parts();
        Ok(Self {
            kf: KalmanFilter::new(x, p)?,
            tau,
            nodes,
            mirror: BucketMirror::new(bucket),
            reads_silence,
            counts: SilenceCounts::default(),
        })
    }

    /// x̂ and P (the moment-matched error covariance).
    #[inline]
    pub fn estimate(&self) -> &Estimate<T, NX> {
        self.kf.estimate()
    }

    /// The bucket mirror.
    #[inline]
    pub fn mirror(&self) -> &BucketMirror<L> {
        &self.mirror
    }

    /// Silences read as held, without a token, and held without a usable set, so far.
    #[inline]
    pub fn counts(&self) -> SilenceCounts {
        self.counts
    }

    /// Whether held silences are read.
    #[inline]
    pub fn reads_silence(&self) -> bool {
        self.reads_silence
    }

    /// One instant with explicit matrices (`a` = A, `bqb` = B Q Bᵀ, `gu` = G u, per node C and
    /// the variances of R) and the arrivals already classified; `gate` tests the observed part
    /// of each delivered packet (docs/gate.md; a rejected packet is read as lost). Nothing
    /// changes on error.
    #[allow(clippy::too_many_arguments)]
    pub fn step_arrivals(
        &mut self,
        a: &SMatrix<T, NX, NX>,
        bqb: &SMatrix<T, NX, NX>,
        gu: Option<&SVector<T, NX>>,
        nodes: &[NodeModel<T, NX, NY>; L],
        arrivals: &[Arrival<'_, T, NY>; L],
        gate: &InnovationGate<T>,
    ) -> Result<GateCounts> {
        let mut kf = self.kf;
        match gu {
            Some(gu) => kf.predict_with_input(a, bqb, gu)?,
            None => kf.predict_with(a, bqb)?,
        }
        let (mut x, mut p) = kf.estimate().into_parts();
        let mut used = [false; L];
        let mut gates = GateCounts::NONE;
        // (C4): every observed component first, then every censored one.
        for m in 0..L {
            if let Arrival::Received(y) = arrivals[m] {
                check_finite(y, "measurement")?;
                let (c, r) = &nodes[m];
                let (mut xm, mut pm) = (x, p);
                let (nis, dof) = observe(&mut xm, &mut pm, c, r, y, &self.tau[m])?;
                used[m] = dof == 0 || gate.is_off() || nis <= gate.threshold(dof)?;
                if !gate.is_off() && dof > 0 {
                    gates.add(GateCounts::one(used[m]));
                }
                if used[m] {
                    (x, p) = (xm, pm);
                }
            }
        }
        for m in 0..L {
            if let (Arrival::Received(y), true) = (arrivals[m], used[m]) {
                let (c, r) = &nodes[m];
                truncate_censored(&mut x, &mut p, c, r, y, &self.tau[m])?;
            }
        }
        let mut next = *self;
        for m in 0..L {
            next.read_node(m, &mut x, &mut p, &nodes[m], arrivals[m], used[m])?;
        }
        let p = symmetrize(&p);
        check_finite(&x, "estimate")?;
        check_spd(&p, "covariance")?;
        next.kf.reset(x, p)?;
        *self = next;
        Ok(gates)
    }

    /// Node `m`'s knowledge after its arrival, and the silence update (step 4) of a held one.
    fn read_node(
        &mut self,
        m: usize,
        x: &mut SVector<T, NX>,
        p: &mut SMatrix<T, NX, NX>,
        (c, r): &NodeModel<T, NX, NY>,
        arrival: Arrival<'_, T, NY>,
        used: bool,
    ) -> Result<()> {
        let node = &mut self.nodes[m];
        match arrival {
            Arrival::Received(y) if used => node.delivered(y)?,
            // Rejected by the gate: the node did send, so its reference is unknown.
            Arrival::Received(_) => node.lost(),
            Arrival::Held => {
                if self.reads_silence {
                    match node.silence_set() {
                        Some(ball) => {
                            let bx = SilenceBox::of_ball(&ball, Some(&self.tau[m]));
                            (*x, *p) = truncate_box(x, p, c, &SMatrix::from_diagonal(r), &bx)?;
                            self.counts.held += 1;
                        }
                        None => self.counts.unusable += 1,
                    }
                }
                node.silent();
            }
            Arrival::Blocked => {
                self.counts.blocked += 1;
                node.silent();
            }
            Arrival::Lost => node.lost(),
        }
        Ok(())
    }

    /// One instant on every node's model: the mirror classifies the silences, then
    /// [`MomentMatchedTobit::step_arrivals`]. Nothing changes on error (the mirror included).
    pub fn step_gated<M: LinearSystem<T, NX, NY>>(
        &mut self,
        models: &[M; L],
        k: usize,
        y: &TriggeredPackets<T, NY, L>,
        gate: &InnovationGate<T>,
    ) -> Result<GateCounts> {
        let prev = k.saturating_sub(1);
        let mut nodes = [(SMatrix::zeros(), SVector::zeros()); L];
        for m in 0..L {
            nodes[m] = (
                models[m].c(k),
                diagonal_variances(&models[m].measurement_cov(k))?,
            );
        }
        let mut next = *self;
        let held = next.mirror.step(&y.sent(), y.level);
        let counts = next.step_arrivals(
            &models[0].a(prev),
            &models[0].process_cov(prev),
            models[0].input(prev).as_ref(),
            &nodes,
            &y.arrivals(&held),
            gate,
        )?;
        *self = next;
        Ok(counts)
    }

    /// [`MomentMatchedTobit::step_gated`] for a caller that stores a time-invariant model once
    /// (the firmware): explicit A, B Q Bᵀ, per node C and variances; no gate.
    pub fn step_matrices(
        &mut self,
        a: &SMatrix<T, NX, NX>,
        bqb: &SMatrix<T, NX, NX>,
        nodes: &[NodeModel<T, NX, NY>; L],
        y: &TriggeredPackets<T, NY, L>,
    ) -> Result<()> {
        let mut next = *self;
        let held = next.mirror.step(&y.sent(), y.level);
        let off = InnovationGate::off();
        next.step_arrivals(a, bqb, None, nodes, &y.arrivals(&held), &off)?;
        *self = next;
        Ok(())
    }
}

/// Behind a gate: the mirror sees every delivered packet (a rejected one was still a send);
/// the filter reads a rejected one as lost.
impl<T: Real, const NX: usize, const NY: usize, const L: usize, M: LinearSystem<T, NX, NY>>
    GatedStep<T, NX> for OnModel<[M; L], MomentMatchedTobit<T, NX, NY, L>, NY>
{
    fn step_gated(
        &mut self,
        k: usize,
        y: &TriggeredPackets<T, NY, L>,
        gate: &InnovationGate<T>,
    ) -> Result<GateCounts> {
        self.filter.step_gated(&self.model, k, y, gate)
    }
}

impl<T: Real, const NX: usize, const NY: usize, const L: usize, M: LinearSystem<T, NX, NY>>
    Estimator<T, NX> for OnModel<[M; L], MomentMatchedTobit<T, NX, NY, L>, NY>
{
    type Measurement = TriggeredPackets<T, NY, L>;

    #[inline]
    fn step(&mut self, k: usize, y: &TriggeredPackets<T, NY, L>) -> Result<()> {
        self.filter
            .step_gated(&self.model, k, y, &InnovationGate::off())
            .map(|_| ())
    }

    #[inline]
    fn estimate(&self) -> &Estimate<T, NX> {
        self.filter.estimate()
    }
}

#[cfg(test)]
mod tests;
