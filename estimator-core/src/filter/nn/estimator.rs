//! The recursive NN-based state estimator under the token-bucket protocol (seed 003):
//! estimator (5), weight tuning law (6), bounds of Theorem 1 and the gain of Theorem 2.
//!
//! ```text
//! x̂_{k+1} = A_k x̂_k + Ĥ_k φ(x̂_k) + γ_k L_k (y_k − C_k x̂_k)                        (5)
//! Ĥ_{k+1} = Ĥ_k + θ₁ (γ_{k+1} C_{k+1}ᵀ (y_{k+1} − C_{k+1} x̂_{k+1}) φ̄ᵀ(x̂_k) − θ₂ Ĥ_k)   (6)
//! ```
//! with `γ_k = 1{μ_k ≥ 0}` (the packet of instant `k` was transmitted).
//!
//! # Timing
//! `x̂_k` is a one-step *prediction*: it uses `y_0 … y_{k−1}`, and `P̄_k` bounds
//! `E[(x_k − x̂_k)(x_k − x̂_k)ᵀ]`. The gain `L_k` of (35) needs `1{μ_{k+1} ≥ 0}` (through `δ̄₂`,
//! `δ̄₄`) and (6) needs `y_{k+1}`, so [`NnTbcpEstimator::step`] is driven by the observation of
//! instant `k + 1`: it computes `L_k` and `x̂_{k+1}` from the stored `y_k`, then tunes
//! `Ĥ_{k+1}` with `y_{k+1}`, then stores `y_{k+1}`. After the step for instant `k + 1` the
//! estimator therefore holds exactly the paper's `x̂_{k+1}, Ĥ_{k+1}, P̄_{k+1}, Q̄_{k+1}`.
//! Nothing but the arrival flag of `k + 1` is needed in advance, so a receiver that cannot run
//! a replica of the bucket works too.

use nalgebra::{SMatrix, SVector};

use super::bound::{
    normalised_regressor, optimal_gain, propagate_bounds, GainSolver, NnBoundConfig, StepMatrices,
};
use super::system::{Activation, CoupledNoiseSystem, SystemMatrices};
use crate::estimate::Estimate;
use crate::estimator::{Estimator, OnModel};
use crate::linalg::{check_finite, check_spd, symmetrize};
use crate::packet::Packet;
use crate::{Error, Real, Result};

/// The seed 003 estimator on `NX` states, `NW` noises, `NY` measurements and `NPHI` activation
/// outputs. `NP` must equal `NX·NY` (the Kronecker dimension of (35), checked at compile
/// time); `Act` is the activation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NnTbcpEstimator<
    T: Real,
    const NX: usize,
    const NW: usize,
    const NY: usize,
    const NPHI: usize,
    const NP: usize,
    Act,
> {
    cfg: NnBoundConfig<T>,
    act: Act,
    solver: GainSolver,
    k: usize,
    /// `x̂_k` with the bound `P̄_k`.
    est: Estimate<T, NX>,
    h: SMatrix<T, NX, NPHI>,
    q: SMatrix<T, NX, NX>,
    y: Option<SVector<T, NY>>,
    gain: SMatrix<T, NX, NY>,
    phi_norm: T,
    /// `(A_k, B_k, C_k, D_k)`, made by the step to `k` (which needed `C_k`, `D_k`) and kept
    /// for the step from `k`, so that each instant's matrices are made once (`None` before
    /// the first step).
    ahead: Option<SystemMatrices<T, NX, NW, NY>>,
}

impl<
        T: Real,
        const NX: usize,
        const NW: usize,
        const NY: usize,
        const NPHI: usize,
        const NP: usize,
        Act: Activation<T, NX, NPHI>,
    > NnTbcpEstimator<T, NX, NW, NY, NPHI, NP, Act>
{
    /// Starts at instant 0 from `x̂₀`, `Ĥ₀` and the bounds' initial values `P̄₀`, `Q̄₀`
    /// (finite, symmetric positive definite). No measurement of instant 0 is assumed; use
    /// [`Self::with_initial_measurement`] if there is one.
    pub fn new(
        cfg: NnBoundConfig<T>,
        act: Act,
        x0: SVector<T, NX>,
        h0: SMatrix<T, NX, NPHI>,
        p0: SMatrix<T, NX, NX>,
        q0: SMatrix<T, NX, NX>,
    ) -> Result<Self> {
        check_finite(&x0, "x̂₀")?;
        check_finite(&h0, "Ĥ₀")?;
        let est = Estimate::named(x0, p0, "x̂₀", "P̄₀")?;
        check_spd(&q0, "Q̄₀")?;
        let phi_norm = act.eval(&x0).norm();
        Ok(Self {
            cfg,
            act,
            solver: GainSolver::Kronecker,
            k: 0,
            est,
            h: h0,
            q: symmetrize(&q0),
            y: None,
            gain: SMatrix::zeros(),
            phi_norm,
            ahead: None,
        })
    }

    /// Uses `y₀` (transmitted at instant 0) in the first step.
    pub fn with_initial_measurement(mut self, y0: SVector<T, NY>) -> Result<Self> {
        check_finite(&y0, "y₀")?;
        self.y = Some(y0);
        Ok(self)
    }

    /// Selects how (38) is solved (the paper's Kronecker form by default).
    #[must_use]
    pub fn with_gain_solver(mut self, solver: GainSolver) -> Self {
        self.solver = solver;
        self
    }

    /// Instant `k` of the current estimate.
    #[inline]
    pub fn instant(&self) -> usize {
        self.k
    }
    /// `x̂_k` (uses measurements up to `k − 1`) with `P̄_k`, the bound on the
    /// estimation-error covariance.
    #[inline]
    pub fn estimate(&self) -> &Estimate<T, NX> {
        &self.est
    }
    /// `Ĥ_k`.
    #[inline]
    pub fn weights(&self) -> &SMatrix<T, NX, NPHI> {
        &self.h
    }
    /// `Q̄_k`, the bound on the NN-weight-error covariance.
    #[inline]
    pub fn bound_q(&self) -> &SMatrix<T, NX, NX> {
        &self.q
    }
    /// The configuration.
    #[inline]
    pub fn config(&self) -> &NnBoundConfig<T> {
        &self.cfg
    }
    /// The activation.
    #[inline]
    pub fn activation(&self) -> &Act {
        &self.act
    }
    /// `L_{k−1}` used by the last step (zero if that instant's packet was not transmitted).
    #[inline]
    pub fn last_gain(&self) -> &SMatrix<T, NX, NY> {
        &self.gain
    }
    /// `‖φ(x̂_k)‖` of the current estimate (the paper assumes it is at most `φ̄`).
    #[inline]
    pub fn phi_norm(&self) -> T {
        self.phi_norm
    }

    /// Advances from instant `k` to `k + 1` given the observation of instant `k + 1`
    /// (`None` when the token bucket withheld it). See the module docs for the timing.
    ///
    /// On error (non-finite input, a bound overflowing, a singular gain system) nothing
    /// changes.
    ///
    /// `sys` must be the same system at every step (as [`OnModel`] holds it): the matrices
    /// of instant `k + 1`, made here for `C_{k+1}` and `D_{k+1}`, are kept and used by the
    /// next step as `A_{k+1} … D_{k+1}` (on a single-precision FPU, seed 003's `sin k` and
    /// `cos k` are software double-precision kernels and most of a step).
    pub fn step<S: CoupledNoiseSystem<T, NX, NW, NY>>(
        &mut self,
        sys: &S,
        y_next: Option<&SVector<T, NY>>,
    ) -> Result<()> {
        if let Some(y) = y_next {
            check_finite(y, "measurement")?;
        }
        let k = self.k;
        let (x, p) = (*self.est.state(), *self.est.covariance());
        let (a, b, c, d) = match self.ahead {
            Some(m) => m,
            None => sys.matrices(k),
        };
        let ahead = sys.matrices(k + 1);
        let s = StepMatrices {
            a,
            b,
            c,
            d,
            c_next: ahead.2,
            d_next: ahead.3,
            gamma: self.y.is_some(),
            gamma_next: y_next.is_some(),
        };
        check_finite(&s.a, "A_k")?;
        check_finite(&s.b, "B_k")?;
        check_finite(&s.c, "C_k")?;
        check_finite(&s.d, "D_k")?;
        check_finite(&s.c_next, "C_{k+1}")?;
        check_finite(&s.d_next, "D_{k+1}")?;
        // Theorem 2; L_k does not enter (5) or (14) when y_k was not transmitted.
        let l = match self.y {
            Some(_) => optimal_gain::<T, NX, NW, NY, NP>(&self.cfg, &p, &s, self.solver)?,
            None => SMatrix::zeros(),
        };
        // (5).
        let phi = self.act.eval(&x);
        check_finite(&phi, "activation φ(x̂_k)")?;
        let mut x_next = s.a * x + self.h * phi;
        if let Some(y) = &self.y {
            x_next += l * (y - s.c * x);
        }
        check_finite(&x_next, "state estimate")?;
        // Theorem 1.
        let (p_next, q_next) = propagate_bounds(&self.cfg, &p, &self.q, &l, &s)?;
        // (6), with ȳ_{k+1} = y_{k+1} − C_{k+1} x̂_{k+1}.
        let [t1, t2] = self.cfg.theta();
        let (_, m_norm) = s.m_and_norm()?;
        let mut h_next = self.h - self.h * (t1 * t2);
        if let Some(y) = y_next {
            let phib = normalised_regressor(&phi, m_norm);
            let innov = y - s.c_next * x_next;
            h_next += (s.c_next.transpose() * innov * phib.transpose()) * t1;
        }
        check_finite(&h_next, "NN weights Ĥ")?;
        let phi_norm = self.act.eval(&x_next).norm();
        // Commit.
        self.k = k + 1;
        self.est = Estimate::trusted(x_next, p_next);
        self.h = h_next;
        self.q = q_next;
        self.y = y_next.copied();
        self.gain = l;
        self.phi_norm = phi_norm;
        self.ahead = Some(ahead);
        Ok(())
    }
}

/// Delivered: `γ_{k+1} = 1`; dropped (withheld by the token bucket) or lost: `γ_{k+1} = 0`.
/// The estimator counts its instants: `k` must be [`NnTbcpEstimator::instant`] + 1.
impl<
        T: Real,
        const NX: usize,
        const NW: usize,
        const NY: usize,
        const NPHI: usize,
        const NP: usize,
        Act: Activation<T, NX, NPHI>,
        S: CoupledNoiseSystem<T, NX, NW, NY>,
    > Estimator<T, NX> for OnModel<S, NnTbcpEstimator<T, NX, NW, NY, NPHI, NP, Act>, NY>
{
    type Measurement = Packet<T, NY>;

    /// [`NnTbcpEstimator::step`] with the observation of instant `k`; refused with
    /// [`Error::OutOfOrder`] unless `k` is the next instant.
    fn step(&mut self, k: usize, y: &Packet<T, NY>) -> Result<()> {
        let expected = self.filter.instant() + 1;
        if k != expected {
            return Err(Error::OutOfOrder { expected, got: k });
        }
        self.filter.step(&self.model, y.delivered())
    }

    #[inline]
    fn estimate(&self) -> &Estimate<T, NX> {
        self.filter.estimate()
    }
}
