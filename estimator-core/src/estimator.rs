//! One interface to every estimator: [`Estimator`], a step per instant and the
//! [`Estimate`] it holds.
//!
//! # Configuration apart from running state
//!
//! The filters of [`crate::filter`] hold only their running state (estimate, counters, held
//! measurement, ...) and take the model at every call: `kf.step(&model, k, &y)`. That "split"
//! form lets one model serve many filters and a time-varying model be evaluated at `k`, and
//! keeps the filters' state small and `Copy`. [`Estimator::step`] takes only the instant and
//! the measurement, so [`OnModel`] pairs a filter with its model — the idea of the `Split`
//! type of quartiq's `idsp` (`dsp-process`), which pairs a configuration with a state. The
//! model is owned or borrowed: [`LinearSystem`](crate::model::LinearSystem) and
//! [`CoupledNoiseSystem`](crate::filter::nn::CoupledNoiseSystem) are implemented for
//! references, so `OnModel::new(&model, kf)` borrows. The measurement dimension `NY` is a
//! parameter of [`OnModel`] because the filters take it per call (and a trait impl must fix
//! it).
//!
//! The trait needs no allocation and no dynamic dispatch: code written against it is generic
//! and runs on the MCU as it does on a host.
//!
//! | Filter (inner type of `OnModel`) | model `M` | [`Estimator::Measurement`] |
//! |---|---|---|
//! | [`KalmanFilter`](crate::filter::KalmanFilter) | `LinearSystem` | `SVector<T, NY>` |
//! | [`IntermittentKalmanFilter`](crate::filter::IntermittentKalmanFilter), [`CrossCoupledEstimator`](crate::filter::CrossCoupledEstimator), [`AssumedDensityFilter`](crate::filter::AssumedDensityFilter), [`KfIo`](crate::filter::KfIo), [`TobitFilter`](crate::filter::TobitFilter) | `LinearSystem` | [`Packet<T, NY>`](crate::Packet) |
//! | [`NnTbcpEstimator`](crate::filter::NnTbcpEstimator) | `CoupledNoiseSystem` | [`Packet<T, NY>`](crate::Packet) |
//! | [`CoupledNoiseKf`](crate::filter::CoupledNoiseKf) | `(CoupledNoiseSystem, DifferentiableMap)` | [`Packet<T, NY>`](crate::Packet) |
//! | [`IndependentNoiseKf`](crate::filter::IndependentNoiseKf) | `(CoupledNoiseSystem, DifferentiableMap)` | [`Packet<T, NY>`](crate::Packet) |
//! | [`TobitFusion`](crate::filter::TobitFusion) | `[LinearSystem; L]` | `[Packet<T, NY>; L]` |
//!
//! # What each estimator makes of a [`Packet`](crate::Packet)
//!
//! * IKF: delivered → Kalman step; dropped or lost → prediction only.
//! * CCE, ADF: delivered → their arrival update; dropped → their dropout update (the dropout
//!   says the state is in an occlusion region); lost → prediction only, the label and the
//!   region weights keep the values of the last update.
//! * KF-IO: delivered or dropped → its linear MMSE update (`ỹ = z` or `0`); lost →
//!   prediction only, the arrival probability keeps its last value.
//! * CCE, ADF, KF-IO with a known loss rate (`with_loss_rate(p_loss)`, default 0): for a
//!   receiver that cannot tell a loss from a dropout, "dropped" means "occluded, or lost with
//!   probability `p_loss`": `P(no packet | x) = p_occ(x) + (1 − p_occ(x)) p_loss` (CCE: a
//!   "lost" hypothesis in the label scoring; ADF: the exact moments of the two-component
//!   posterior; KF-IO: arrival probability `p_k (1 − p_loss)`). Lost is still prediction only.
//! * NN estimator, coupled-noise and independent-noise KF/EKF: delivered → `γ = 1`; dropped
//!   (withheld by the token bucket) or lost → `γ = 0`, as the papers treat a withheld packet.
//!   They count their own instant: a step for any `k` but the next one is refused
//!   ([`Error::OutOfOrder`]).
//! * Tobit filter and fusion: delivered → `θ = 0`; dropped → `θ = 1` (the trigger did not
//!   fire or the bucket withheld: the held measurement ȳ and the trigger's bound enter (30)).
//!   Lost is treated like dropped. This is provisional: the estimator cannot tell whether the
//!   trigger fired, and a lost packet that did fire carries no event-trigger information.
//! * Behind an innovation gate ([`crate::filter::gate`], docs/gate.md), a delivered packet the
//!   gate rejects is what that estimator makes of a lost one (the Tobit filters: a dropped
//!   one; the seed 003 baselines: a withheld one).
//!
//! [`Error::OutOfOrder`]: crate::Error::OutOfOrder

use crate::estimate::Estimate;
use crate::{Real, Result};

/// A recursive estimator on `NX` states driven one instant at a time.
pub trait Estimator<T: Real, const NX: usize> {
    /// What one instant delivers: a vector, a [`Packet`](crate::Packet), per-node packets, ...
    type Measurement;

    /// Processes instant `k` with its measurement. On error nothing changes.
    fn step(&mut self, k: usize, y: &Self::Measurement) -> Result<()>;

    /// The current estimate.
    fn estimate(&self) -> &Estimate<T, NX>;
}

/// A filter `F` with the model `M` it runs on (owned, or a reference), for measurements of
/// dimension `NY`: the [`Estimator`] form of the filters' `step(model, k, y)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OnModel<M, F, const NY: usize> {
    /// The model (the configuration the filter runs on).
    pub model: M,
    /// The filter (the running state).
    pub filter: F,
}

impl<M, F, const NY: usize> OnModel<M, F, NY> {
    /// Pairs `filter` with `model`.
    #[inline]
    pub const fn new(model: M, filter: F) -> Self {
        Self { model, filter }
    }

    /// The model and the filter, apart again.
    #[inline]
    pub fn into_parts(self) -> (M, F) {
        (self.model, self.filter)
    }
}
