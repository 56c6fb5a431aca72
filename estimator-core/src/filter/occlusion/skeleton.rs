//! The step every occlusion filter of seed 001 shares, written once: predict (eq. 11), then
//! the filter's own arrival or dropout update, or nothing more for a packet lost in
//! transport; the [`Estimator`] and [`GatedStep`] forms; the known loss rate.
//!
//! A member of the family is its configuration (occlusion regions, Gaussian-sum table,
//! covariance form, loss rate: [`CceConfig`](super::CceConfig),
//! [`AdfConfig`](super::AdfConfig), [`KfIoConfig`](super::KfIoConfig)) implementing
//! [`OcclusionUpdate`]: the two updates and the running state they write beside the estimate
//! (the region label and weights, the arrival probability). [`OcclusionFilter`] holds the
//! configuration apart from that state (docs/design.md, "Configuration apart from state").

use core::fmt::Debug;

use nalgebra::{SMatrix, SVector};

use crate::estimate::Estimate;
use crate::estimator::{Estimator, OnModel};
use crate::filter::gate::{admits_linear, GateCounts, GatedStep, InnovationGate};
use crate::filter::time_update::predict;
use crate::linalg::check_finite;
use crate::model::LinearSystem;
use crate::packet::Packet;
use crate::{Real, Result};

/// What a member of the occlusion family adds to [`OcclusionFilter`]: its updates of the
/// prediction `(x̂⁻, P⁻)` of instant `k` on an arrival and on a dropout. Implemented by the
/// member's configuration.
pub trait OcclusionUpdate<T: Real, const NX: usize>: Sized {
    /// The running state the updates write beside the estimate. A packet lost in transport
    /// leaves it as it is.
    type State: Copy + Debug + PartialEq;
    /// What [`OcclusionFilter::step`] returns: the region label, or nothing.
    type Output;

    /// The state before the first update.
    fn initial_state(&self) -> Self::State;

    /// The step's result from the state after the update.
    fn output(state: &Self::State) -> Self::Output;

    /// This configuration with the known loss rate `p_loss` (docs/design.md, "A loss is not a
    /// dropout"). Refuses a `p_loss` that is not finite or not in `[0, 1)`.
    fn with_loss_rate(self, p_loss: T) -> Result<Self>;

    /// `p_loss` (0 unless set).
    fn loss_rate(&self) -> T;

    /// The update on a delivered `y_k` (finite: the skeleton checked it before predicting).
    /// Returns `(x̂_k, P_k)` and the new state; on error the filter keeps its old ones.
    #[allow(clippy::type_complexity)]
    fn arrival_update<const NY: usize, M: LinearSystem<T, NX, NY>>(
        &self,
        model: &M,
        k: usize,
        xp: &SVector<T, NX>,
        pp: &SMatrix<T, NX, NX>,
        y: &SVector<T, NY>,
        state: &Self::State,
    ) -> Result<(SVector<T, NX>, SMatrix<T, NX, NX>, Self::State)>;

    /// The update on a dropout (the channel dropped the packet: the state may be in a
    /// region). Returns as [`OcclusionUpdate::arrival_update`].
    #[allow(clippy::type_complexity)]
    fn dropout_update<const NY: usize, M: LinearSystem<T, NX, NY>>(
        &self,
        model: &M,
        k: usize,
        xp: &SVector<T, NX>,
        pp: &SMatrix<T, NX, NX>,
        state: &Self::State,
    ) -> Result<(SVector<T, NX>, SMatrix<T, NX, NX>, Self::State)>;

    /// Whether `gate` admits the delivered `y_k` of the filter at `est` (docs/gate.md).
    /// Default: the Kalman innovation of the linear prediction ([`admits_linear`]), the one of
    /// the filters whose arrival update is the Kalman update (18).
    fn admits<const NY: usize, M: LinearSystem<T, NX, NY>>(
        &self,
        est: &Estimate<T, NX>,
        _state: &Self::State,
        model: &M,
        k: usize,
        y: &SVector<T, NY>,
        gate: &InnovationGate<T>,
    ) -> Result<bool> {
        admits_linear(gate, model, k, est.state(), est.covariance(), y)
    }
}

/// An occlusion filter on `NX` states: the estimate, the member's configuration `C` and the
/// running state its updates write. `CrossCoupledEstimator`, `AssumedDensityFilter` and `KfIo`
/// are this type with their configurations.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OcclusionFilter<T: Real, const NX: usize, C: OcclusionUpdate<T, NX>> {
    est: Estimate<T, NX>,
    config: C,
    state: C::State,
}

impl<T: Real, const NX: usize, C: OcclusionUpdate<T, NX>> OcclusionFilter<T, NX, C> {
    /// Starts from `x̂_0 = x0`, `P_0 = p0` with `config`.
    pub fn from_config(x0: SVector<T, NX>, p0: SMatrix<T, NX, NX>, config: C) -> Result<Self> {
        let est = Estimate::new(x0, p0)?;
        Ok(Self {
            est,
            state: config.initial_state(),
            config,
        })
    }

    /// The configuration.
    #[inline]
    pub fn config(&self) -> &C {
        &self.config
    }

    /// The running state beside the estimate.
    #[inline]
    pub fn state(&self) -> &C::State {
        &self.state
    }

    /// The configuration, changed by `f` (the builders of the members).
    #[inline]
    pub(super) fn map_config(mut self, f: impl FnOnce(C) -> C) -> Self {
        self.config = f(self.config);
        self
    }

    /// A dropout may also be a packet lost in transport with the known probability `p_loss`
    /// (independent of the state), which the receiver cannot tell from an occlusion dropout:
    /// `P(no packet | x) = p_occ(x) + (1 − p_occ(x)) p_loss` (each member's module docs, "A
    /// known loss rate"). `p_loss = 0` (the default) is the filter without it. Refuses a
    /// `p_loss` that is not finite or not in `[0, 1)`.
    pub fn with_loss_rate(mut self, p_loss: T) -> Result<Self> {
        self.config = self.config.with_loss_rate(p_loss)?;
        Ok(self)
    }

    /// `p_loss` (0 unless set by [`Self::with_loss_rate`]).
    #[inline]
    pub fn loss_rate(&self) -> T {
        self.config.loss_rate()
    }

    /// Current estimate `x̂_k` and covariance `P_k`.
    #[inline]
    pub fn estimate(&self) -> &Estimate<T, NX> {
        &self.est
    }

    /// One instant `k ≥ 1`: predict from `k − 1` (eq. 11), then the arrival update for
    /// `y = Some(z_k)` or the dropout update for `None`. Returns the member's output (the
    /// region label of the CCE and the ADF). On error nothing changes.
    pub fn step<const NY: usize, M: LinearSystem<T, NX, NY>>(
        &mut self,
        model: &M,
        k: usize,
        y: Option<&SVector<T, NY>>,
    ) -> Result<C::Output> {
        self.advance(model, k, Some(y))?;
        Ok(C::output(&self.state))
    }

    /// Instant `k ≥ 1` without information (a packet lost in transport,
    /// [`Packet::Lost`]): the prediction (11) only; the running state beside the estimate
    /// (label, region weights, arrival probability) keeps the values of the last update. On
    /// error nothing changes.
    pub fn predict_to<const NY: usize, M: LinearSystem<T, NX, NY>>(
        &mut self,
        model: &M,
        k: usize,
    ) -> Result<()> {
        self.advance(model, k, None)
    }

    /// Instant `k`: `y` is `Some(Some(z_k))` on arrival, `Some(None)` on a dropout, `None`
    /// for a loss (prediction only). The one place that predicts (eq. 11), so that the
    /// prediction is inlined once into every step.
    #[inline(always)]
    fn advance<const NY: usize, M: LinearSystem<T, NX, NY>>(
        &mut self,
        model: &M,
        k: usize,
        y: Option<Option<&SVector<T, NY>>>,
    ) -> Result<()> {
        if let Some(Some(y)) = y {
            check_finite(y, "measurement")?;
        }
        let (xp, pp) = predict(model, k, self.est.state(), self.est.covariance())?;
        let (x, p, state) = match y {
            Some(Some(y)) => self
                .config
                .arrival_update(model, k, &xp, &pp, y, &self.state)?,
            Some(None) => self
                .config
                .dropout_update(model, k, &xp, &pp, &self.state)?,
            None => {
                self.est = Estimate::trusted(xp, pp);
                return Ok(());
            }
        };
        self.est = Estimate::trusted(x, p);
        self.state = state;
        Ok(())
    }

    /// Whether `gate` admits the delivered `y_k` ([`OcclusionUpdate::admits`]). The off gate
    /// admits without a test.
    pub fn admits<const NY: usize, M: LinearSystem<T, NX, NY>>(
        &self,
        model: &M,
        k: usize,
        y: &SVector<T, NY>,
        gate: &InnovationGate<T>,
    ) -> Result<bool> {
        self.config
            .admits(&self.est, &self.state, model, k, y, gate)
    }
}

/// Delivered: the arrival update; dropped: the dropout update; lost: prediction only.
impl<
        T: Real,
        const NX: usize,
        const NY: usize,
        M: LinearSystem<T, NX, NY>,
        C: OcclusionUpdate<T, NX>,
    > Estimator<T, NX> for OnModel<M, OcclusionFilter<T, NX, C>, NY>
{
    type Measurement = Packet<T, NY>;

    fn step(&mut self, k: usize, y: &Packet<T, NY>) -> Result<()> {
        let y = match y {
            Packet::Delivered(y) => Some(Some(y)),
            Packet::Dropped => Some(None),
            Packet::Lost => None,
        };
        self.filter.advance(&self.model, k, y)
    }

    #[inline]
    fn estimate(&self) -> &Estimate<T, NX> {
        self.filter.estimate()
    }
}

/// Behind a gate (docs/gate.md): a delivered packet the gate rejects is stepped as
/// [`Packet::Lost`] (prediction only; never as a dropout, which would say the state is in a
/// region).
impl<
        T: Real,
        const NX: usize,
        const NY: usize,
        M: LinearSystem<T, NX, NY>,
        C: OcclusionUpdate<T, NX>,
    > GatedStep<T, NX> for OnModel<M, OcclusionFilter<T, NX, C>, NY>
{
    fn step_gated(
        &mut self,
        k: usize,
        y: &Packet<T, NY>,
        gate: &InnovationGate<T>,
    ) -> Result<GateCounts> {
        let Packet::Delivered(z) = y else {
            return self.step(k, y).map(|()| GateCounts::NONE);
        };
        let used = self.filter.admits(&self.model, k, z, gate)?;
        if used {
            self.step(k, y)?;
        } else {
            self.filter.predict_to(&self.model, k)?;
        }
        Ok(GateCounts::one(used))
    }
}
