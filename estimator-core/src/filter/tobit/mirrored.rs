//! The fusion filter with silence-reading local filters and the receiver's bucket mirror
//! (docs/tobit-fusion.md, "Silence that speaks"): Algorithm 1's estimator side, where an
//! instant's silences are first classified by the mirror of the shared bucket
//! ([`crate::protocol::bucket_mirror`]) — held trigger, or no token / unknown — and then every
//! local filter steps on its node's [`Arrival`].

use nalgebra::{SMatrix, SVector};

use super::config::diagonal_variances;
use super::fusion::TobitFusion;
use crate::estimate::Estimate;
use crate::estimator::{Estimator, OnModel};
use crate::filter::gate::{GateCounts, GatedStep, InnovationGate};
use crate::filter::silence::{Arrival, SilenceCounts, TriggeredPackets};
use crate::model::LinearSystem;
use crate::protocol::bucket_mirror::BucketMirror;
use crate::protocol::shared_token_bucket::SharedTokenBucket;
use crate::{Real, Result};

/// [`TobitFusion`] behind the bucket mirror.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MirroredFusion<T: Real, const NX: usize, const NY: usize, const L: usize> {
    fusion: TobitFusion<T, NX, NY, L>,
    mirror: BucketMirror<L>,
    counts: SilenceCounts,
}

impl<T: Real, const NX: usize, const NY: usize, const L: usize> MirroredFusion<T, NX, NY, L> {
    /// `fusion` (its local filters configured with a silence-reading
    /// [`super::Silence`], or any other) and the shared bucket at ξ₀.
    pub fn new(fusion: TobitFusion<T, NX, NY, L>, bucket: SharedTokenBucket<L>) -> Self {
        Self {
            fusion,
            mirror: BucketMirror::new(bucket),
            counts: SilenceCounts::default(),
        }
    }

    /// The fusion filter.
    #[inline]
    pub fn fusion(&self) -> &TobitFusion<T, NX, NY, L> {
        &self.fusion
    }

    /// The bucket mirror.
    #[inline]
    pub fn mirror(&self) -> &BucketMirror<L> {
        &self.mirror
    }

    /// Silences held / without a token so far, over all nodes.
    #[inline]
    pub fn counts(&self) -> SilenceCounts {
        self.counts
    }

    /// One instant `k ≥ 1`: the mirror, then [`TobitFusion::step_arrivals_models`].
    /// All-or-nothing (the mirror included).
    pub fn step<M: LinearSystem<T, NX, NY>>(
        &mut self,
        models: &[M; L],
        k: usize,
        y: &TriggeredPackets<T, NY, L>,
    ) -> Result<()> {
        self.step_admitted(models, k, y, &[true; L])
    }

    /// [`MirroredFusion::step`] with explicit matrices (as [`TobitFusion::step`] takes them:
    /// `a` = A, `bqb` = B Q Bᵀ, per node `C_m` and the variances `r_m`), for a caller that
    /// stores a time-invariant model once (the firmware). All-or-nothing.
    pub fn step_matrices(
        &mut self,
        a: &SMatrix<T, NX, NX>,
        bqb: &SMatrix<T, NX, NX>,
        c: &[SMatrix<T, NY, NX>; L],
        r: &[SVector<T, NY>; L],
        y: &TriggeredPackets<T, NY, L>,
    ) -> Result<()> {
        let mut mirror = self.mirror;
        let held = mirror.step(&y.sent(), y.level);
        let arrivals = y.arrivals(&held);
        let mut fusion = self.fusion;
        fusion.step_arrivals(a, bqb, None, c, r, &arrivals)?;
        self.counts = tally(self.counts, &arrivals);
        self.fusion = fusion;
        self.mirror = mirror;
        Ok(())
    }

    /// [`MirroredFusion::step`] where node m's delivered packet is used only if
    /// `admitted[m]` (the gate's verdict): a rejected one still counts as a send for the
    /// mirror, and its local filter reads it as lost (no information, reference unknown).
    pub fn step_admitted<M: LinearSystem<T, NX, NY>>(
        &mut self,
        models: &[M; L],
        k: usize,
        y: &TriggeredPackets<T, NY, L>,
        admitted: &[bool; L],
    ) -> Result<()> {
        let mut mirror = self.mirror;
        let held = mirror.step(&y.sent(), y.level);
        let mut arrivals = y.arrivals(&held);
        for m in 0..L {
            if !admitted[m] && matches!(arrivals[m], Arrival::Received(_)) {
                arrivals[m] = Arrival::Lost;
            }
        }
        let mut fusion = self.fusion;
        fusion.step_arrivals_models(models, k, &arrivals)?;
        self.counts = tally(self.counts, &arrivals);
        self.fusion = fusion;
        self.mirror = mirror;
        Ok(())
    }
}

/// `counts` plus the instant's held and blocked silences.
fn tally<T: Real, const NY: usize>(
    mut counts: SilenceCounts,
    arrivals: &[Arrival<'_, T, NY>],
) -> SilenceCounts {
    for a in arrivals {
        match a {
            Arrival::Held => counts.held += 1,
            Arrival::Blocked => counts.blocked += 1,
            _ => {}
        }
    }
    counts
}

/// Behind a gate: each delivered measurement is tested by its local filter
/// ([`super::TobitFilter::admits`]); see [`MirroredFusion::step_admitted`].
impl<T: Real, const NX: usize, const NY: usize, const L: usize, M: LinearSystem<T, NX, NY>>
    GatedStep<T, NX> for OnModel<[M; L], MirroredFusion<T, NX, NY, L>, NY>
{
    fn step_gated(
        &mut self,
        k: usize,
        y: &TriggeredPackets<T, NY, L>,
        gate: &InnovationGate<T>,
    ) -> Result<GateCounts> {
        let (models, prev) = (&self.model, k.saturating_sub(1));
        let (a, bqb) = (models[0].a(prev), models[0].process_cov(prev));
        let mut counts = GateCounts::NONE;
        let mut admitted = [true; L];
        for m in 0..L {
            if let (Some(z), Some(local)) = (y.packets[m].delivered(), self.filter.fusion.local(m))
            {
                let r = diagonal_variances(&models[m].measurement_cov(k))?;
                let q_m = bqb / self.filter.fusion.weights()[m];
                let used = local.admits(&a, &q_m, &models[m].c(k), &r, z, gate)?;
                counts.add(GateCounts::one(used));
                admitted[m] = used;
            }
        }
        self.filter.step_admitted(models, k, y, &admitted)?;
        Ok(counts)
    }
}

impl<T: Real, const NX: usize, const NY: usize, const L: usize, M: LinearSystem<T, NX, NY>>
    Estimator<T, NX> for OnModel<[M; L], MirroredFusion<T, NX, NY, L>, NY>
{
    type Measurement = TriggeredPackets<T, NY, L>;

    #[inline]
    fn step(&mut self, k: usize, y: &TriggeredPackets<T, NY, L>) -> Result<()> {
        self.filter.step(&self.model, k, y)
    }

    #[inline]
    fn estimate(&self) -> &Estimate<T, NX> {
        self.filter.fusion.estimate()
    }
}
