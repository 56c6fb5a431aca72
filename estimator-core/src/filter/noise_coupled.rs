//! The one-step predictor shared by seed 003's Kalman baselines on the noise-coupled system
//! `x_{k+1} = A_k x_k + f(x_k) + B_k w_k`, `y_k = C_k x_k + D_k w_k` under the token bucket.
//!
//! [`NoiseCoupledKf`] holds what every such baseline holds — the instant `k`, the prediction
//! `x̂_{k|k−1}` with the filter's own `P_{k|k−1}`, the noise covariance `W = E[w wᵀ]` and the
//! stored `y_k` the next step uses — and does what they all do: take the observation of
//! instant `k + 1`, gate the held measurement, count its instants through the [`Estimator`]
//! trait. The step's algebra is the mode's ([`NoiseCoupledStep`]):
//!
//! * [`Linearisation`](super::coupled_kf::Linearisation): the paper's baselines, the exact
//!   correlated-noise predictor ([`CoupledNoiseKf`](super::CoupledNoiseKf)).
//! * [`IndependentMode`](super::independent_kf::IndependentMode): the textbook KF/EKF that take
//!   `B w` and `D w` as independent ([`IndependentNoiseKf`](super::IndependentNoiseKf)).
//!
//! # Timing
//! [`NoiseCoupledKf::step`] is driven by the observation of instant `k + 1`; it processes the
//! stored `y_k` and yields `x̂_{k+1|k}`, so every estimator of the comparison uses the same
//! information (`y_0 … y_k`) for `x̂_{k+1}`.

use core::fmt::Debug;

use nalgebra::{SMatrix, SVector};

use crate::estimate::Estimate;
use crate::estimator::{Estimator, OnModel};
use crate::filter::gate::{GateCounts, GatedStep, InnovationGate};
use crate::filter::nn::system::{CoupledNoiseSystem, DifferentiableMap};
use crate::linalg::{check_finite, check_spd, symmetrize};
use crate::packet::Packet;
use crate::{Error, Real, Result};

/// One step of a noise-coupled baseline: from `x̂_{k|k−1}`, `P_{k|k−1}` and the stored `y_k`
/// (`None`: withheld) to `x̂_{k+1|k}`, `P_{k+1|k}`, checked finite, and the number of
/// innovation directions the update used (0 without a measurement).
pub trait NoiseCoupledStep<T: Real, const NX: usize, const NW: usize, const NY: usize>:
    Copy + Debug + PartialEq
{
    /// The step at instant `k` on `sys` (and `f` where the mode uses it).
    fn advance<S, F>(
        &self,
        sys: &S,
        f: &F,
        k: usize,
        est: &Estimate<T, NX>,
        w: &SMatrix<T, NW, NW>,
        y: Option<&SVector<T, NY>>,
    ) -> Result<(SVector<T, NX>, SMatrix<T, NX, NX>, u8)>
    where
        S: CoupledNoiseSystem<T, NX, NW, NY>,
        F: DifferentiableMap<T, NX>;
}

/// A one-step predictor on the noise-coupled system; the mode `M` is its algebra.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NoiseCoupledKf<T: Real, const NX: usize, const NW: usize, const NY: usize, M> {
    k: usize,
    /// `x̂_{k|k−1}` with `P_{k|k−1}`.
    est: Estimate<T, NX>,
    w: SMatrix<T, NW, NW>,
    y: Option<SVector<T, NY>>,
    mode: M,
    rank_used: u8,
}

impl<T: Real, const NX: usize, const NW: usize, const NY: usize, M> NoiseCoupledKf<T, NX, NW, NY, M>
where
    M: NoiseCoupledStep<T, NX, NW, NY>,
{
    /// Starts at instant 0 from `x̂₀`, `P₀` (SPD) with noise covariance `W = E[w wᵀ]` (SPD).
    pub fn new(
        x0: SVector<T, NX>,
        p0: SMatrix<T, NX, NX>,
        w: SMatrix<T, NW, NW>,
        mode: M,
    ) -> Result<Self> {
        let est = Estimate::named(x0, p0, "x̂₀", "P₀")?;
        check_spd(&w, "W")?;
        Ok(Self {
            k: 0,
            est,
            w: symmetrize(&w),
            y: None,
            mode,
            rank_used: 0,
        })
    }

    /// Uses `y₀` (transmitted at instant 0) in the first step.
    pub fn with_initial_measurement(mut self, y0: SVector<T, NY>) -> Result<Self> {
        check_finite(&y0, "y₀")?;
        self.y = Some(y0);
        Ok(self)
    }

    /// Estimate `x̂_{k|k−1}` with the filter's own covariance `P_{k|k−1}`.
    #[inline]
    pub fn estimate(&self) -> &Estimate<T, NX> {
        &self.est
    }
    /// Instant `k`.
    #[inline]
    pub fn instant(&self) -> usize {
        self.k
    }
    /// The mode.
    #[inline]
    pub fn mode(&self) -> M {
        self.mode
    }
    /// Number of innovation directions used by the last update (0 without a measurement).
    #[inline]
    pub fn last_rank(&self) -> u8 {
        self.rank_used
    }

    /// Advances from `k` to `k + 1` given the observation of `k + 1` (`None`: withheld). `f`
    /// is used only in the EKF modes. On error nothing changes.
    pub fn step<S, F>(&mut self, sys: &S, f: &F, y_next: Option<&SVector<T, NY>>) -> Result<()>
    where
        S: CoupledNoiseSystem<T, NX, NW, NY>,
        F: DifferentiableMap<T, NX>,
    {
        if let Some(y) = y_next {
            check_finite(y, "measurement")?;
        }
        let k = self.k;
        let (x_next, p_next, rank) =
            self.mode
                .advance(sys, f, k, &self.est, &self.w, self.y.as_ref())?;
        self.k = k + 1;
        self.est = Estimate::trusted(x_next, p_next);
        self.y = y_next.copied();
        self.rank_used = rank;
        Ok(())
    }

    /// Tests the held measurement `y_{k+1}` (stored by the last step) against the
    /// prediction `x̂_{k+1|k}`, `P_{k+1|k}` the filter now holds: `ν = y − C x̂`,
    /// `S = C P Cᵀ + D W Dᵀ` of instant `k + 1`, the innovation the next step's update uses. A
    /// rejected one is dropped (the next step predicts only, as for a withheld packet).
    /// Returns whether it is kept (`false` when none is held). A singular `S` (noise-free,
    /// certain directions; the update uses its pseudo-inverse) cannot be tested and is kept.
    pub fn gate_held<S: CoupledNoiseSystem<T, NX, NW, NY>>(
        &mut self,
        sys: &S,
        gate: &InnovationGate<T>,
    ) -> bool {
        let Some(y) = self.y else {
            return false;
        };
        if gate.is_off() {
            return true;
        }
        let k = self.k;
        let (c, d) = (sys.c(k), sys.d(k));
        let (x, p) = (self.est.state(), self.est.covariance());
        let s = symmetrize(&(c * p * c.transpose() + d * self.w * d.transpose()));
        let keep = gate.admits(&(y - c * x), &s).unwrap_or(true);
        if !keep {
            self.y = None;
        }
        keep
    }
}

/// The model is the system and the nonlinearity `(sys, f)`. Delivered: the update with
/// `y_{k+1}` at the next step; dropped (withheld by the token bucket) or lost: prediction only.
/// The filter counts its instants: `k` must be [`NoiseCoupledKf::instant`] + 1.
impl<T: Real, const NX: usize, const NW: usize, const NY: usize, M, S, F> Estimator<T, NX>
    for OnModel<(S, F), NoiseCoupledKf<T, NX, NW, NY, M>, NY>
where
    M: NoiseCoupledStep<T, NX, NW, NY>,
    S: CoupledNoiseSystem<T, NX, NW, NY>,
    F: DifferentiableMap<T, NX>,
{
    type Measurement = Packet<T, NY>;

    /// [`NoiseCoupledKf::step`] with the observation of instant `k`; refused with
    /// [`Error::OutOfOrder`] unless `k` is the next instant.
    fn step(&mut self, k: usize, y: &Packet<T, NY>) -> Result<()> {
        let expected = self.filter.instant() + 1;
        if k != expected {
            return Err(Error::OutOfOrder { expected, got: k });
        }
        let (sys, f) = &self.model;
        self.filter.step(sys, f, y.delivered())
    }

    #[inline]
    fn estimate(&self) -> &Estimate<T, NX> {
        self.filter.estimate()
    }
}

/// Behind a gate (docs/gate.md): a delivered `y_k` is tested against `x̂_{k|k−1}` once the
/// step has formed it; a rejected one is not used by the next step (as if withheld).
impl<T: Real, const NX: usize, const NW: usize, const NY: usize, M, S, F> GatedStep<T, NX>
    for OnModel<(S, F), NoiseCoupledKf<T, NX, NW, NY, M>, NY>
where
    M: NoiseCoupledStep<T, NX, NW, NY>,
    S: CoupledNoiseSystem<T, NX, NW, NY>,
    F: DifferentiableMap<T, NX>,
{
    fn step_gated(
        &mut self,
        k: usize,
        y: &Packet<T, NY>,
        gate: &InnovationGate<T>,
    ) -> Result<GateCounts> {
        self.step(k, y)?;
        if y.delivered().is_none() {
            return Ok(GateCounts::NONE);
        }
        Ok(GateCounts::one(self.filter.gate_held(&self.model.0, gate)))
    }
}
