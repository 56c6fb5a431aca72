//! The local Tobit Kalman filter of one sensor node under the dynamic event trigger and the
//! shared token bucket (seed 004, eqs. 21-23, Theorem 1 (29)-(30), Theorem 2 (37)).
//!
//! ```text
//! x̂_{t|t−1} = A x̂_{t−1|t−1}                                              (21)
//! ŷ_{t|t−1} = Q̄ (C x̂_{t|t−1} + λ∘√R) + (I − Q̄) τ                          (23)
//! x̂_{t|t}   = x̂_{t|t−1} + K (ȳ_t − ŷ_{t|t−1})                               (22)
//! P̄_{t|t−1} = A P̄ Aᵀ + B Q Bᵀ                                              (29)
//! P̄_{t|t}   = κ₁ (I − K Q̄ C) P̄_{t|t−1} (I − K Q̄ C)ᵀ + K M Kᵀ               (30)
//! K         = Ψ Φ⁻¹,  Ψ = κ₁ P̄_{t|t−1} Cᵀ Q̄,  Φ = κ₁ Q̄ C P̄_{t|t−1} Cᵀ Q̄ + M   (37)
//! ```
//!
//! with `θ = 1 − αβ` (0 when the node's measurement arrived) and
//!
//! ```text
//! M = (1−θ)² (Ω₃∘R) + κ₂ Q̄ (λ∘√R)(λ∘√R)ᵀ Q̄ + (1−θ)² κ₃ C(Υ∘Ω₁)Cᵀ + θ² κ₄ Q̄ C Ω₁ Cᵀ Q̄
//!   + θ² κ₅ Ω₂ + (1−θ)² κ₆ Ξ(Ḡ) I + θ² κ₇ (I − Q̄) τ τᵀ (I − Q̄) + (1−θ)² κ₈ Υ∘(τ τᵀ),
//! Ω₁ = (1+ε₁₄) P̄_{t|t−1} + (1+ε₁₄⁻¹) x̂_{t|t−1} x̂ᵀ_{t|t−1},  Ω₂ = ȳ_{t−1} ȳᵀ_{t−1},
//! Ω₃ = Υ + Q̄ Q̄ᵀ,  Υ = diag(ϱ̄ (1 − ϱ̄)),
//! Ḡ_{t+1} = Ξ(Ḡ_t) = ((1+d)(1+e)λ_m² + (1+χ)(1+d⁻¹)/χ²) Ḡ_t
//!                  + ((1+d)(1+e⁻¹) + (1+d⁻¹)(1+χ⁻¹)) σ²,   Ḡ₀ = η₀².
//! ```
//!
//! The gain (37) and the bound (30) are [`GainProblem`]'s; the configuration (κ, τ, Ξ, where
//! Υ enters) is [`TobitFilterConfig`]'s.
//!
//! Decisions (docs/design.md, "Seed 004"): the `K_{t+1}` of the κ₇ term is `K_t`. The
//! received measurement ȳ starts at τ; Ḡ starts at η₀² and the first processed instant uses
//! Ξ(Ḡ₀), as the trigger's first instant uses η₀. The paper's `P_{t|t−1}` in Ω₁ is the bound
//! `P̄_{t|t−1}` (the true covariance is unknown to the filter). Only the variances `R_j` enter
//! (eqs. 5-7 are per component), so a model's measurement covariance must be diagonal.
//!
//! With [`Silence::Predict`] (the product's option, not the paper's) an instant without a
//! measurement is the prediction (21), (29) alone: no gain, no (22), no (30). With
//! [`Silence::PseudoMeasurement`] or [`Silence::TruncatedGaussian`] (the product's options,
//! docs/tobit-fusion.md "Silence that speaks") an instant whose trigger held is the silence
//! update on the node's silence set ([`crate::filter::silence`]), and one without a token or
//! lost is the prediction; these filters keep the receiver's [`TriggerKnowledge`] of the node.

use nalgebra::{SMatrix, SVector};

use super::config::{diagonal_variances, Kappas, Silence, TobitFilterConfig, UpsilonPlacement};
use super::gain::GainProblem;
use crate::estimate::Estimate;
use crate::estimator::{Estimator, OnModel};
use crate::filter::gate::{GateCounts, GatedStep, InnovationGate};
use crate::filter::silence::set::{uniform_moments, CensoredPrior, SilenceBox};
use crate::filter::silence::truncated::truncate_box;
use crate::filter::silence::Arrival;
use crate::linalg::{check_finite, check_spd, symmetrize};
use crate::model::LinearSystem;
use crate::packet::Packet;
use crate::protocol::tobit::TobitStats;
use crate::protocol::trigger_knowledge::{SilenceBall, TriggerKnowledge};
use crate::{Error, Real, Result};

/// Everything one local step computes before the gain: the quantities of (23), (29), (30).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LocalStepPlan<T: Real, const NX: usize, const NY: usize> {
    /// x̂_{t|t−1} (21).
    pub x_prior: SVector<T, NX>,
    /// Tobit statistics at `C x̂_{t|t−1}` (ϱ̄, λ, Υ, ŷ of eq. 23).
    pub stats: TobitStats<T, NY>,
    /// θ = 1 − αβ (0 when the measurement arrived).
    pub theta: T,
    /// ȳ_t (19): the received measurement, or the held one.
    pub y_bar: SVector<T, NY>,
    /// Ξ(Ḡ_t).
    pub xi: T,
    /// κ₁ … κ₈.
    pub kappas: Kappas<T>,
    /// Ω₁.
    pub omega1: SMatrix<T, NX, NX>,
    /// Ω₂ = ȳ_{t−1} ȳᵀ_{t−1}.
    pub omega2: SMatrix<T, NY, NY>,
    /// The gain problem (P̄_{t|t−1}, Q̄C, M).
    pub problem: GainProblem<T, NX, NY>,
}

/// Who validates the bound a local step forms (positive definite, by a Cholesky
/// factorisation named "local bound").
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum BoundCheck {
    /// The step itself, before it changes anything: a filter on its own.
    Here,
    /// The fusion centre, whose (50) factorises every local bound under the same name before
    /// any filter is committed (the step is all-or-nothing there too).
    ByCaller,
}

/// One node's local Tobit filter: x̂, P̄, the held measurement ȳ and Ḡ.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TobitFilter<T: Real, const NX: usize, const NY: usize> {
    cfg: TobitFilterConfig<T, NY>,
    est: Estimate<T, NX>,
    y_held: SVector<T, NY>,
    g: T,
    last_theta: T,
    /// The receiver's knowledge of the node's trigger (kept only when the silence is read).
    knowledge: TriggerKnowledge<T, NY>,
}

impl<T: Real, const NX: usize, const NY: usize> TobitFilter<T, NX, NY> {
    /// Starts from `x0`, `P̄₀ = p0` (symmetric positive definite), ȳ = τ, Ḡ = η₀².
    pub fn new(
        cfg: TobitFilterConfig<T, NY>,
        x0: SVector<T, NX>,
        p0: SMatrix<T, NX, NX>,
    ) -> Result<Self> {
        if cfg.placement == UpsilonPlacement::AsWritten && NX != NY {
            return Err(Error::InvalidConfig {
                field: "placement",
                reason: "C(Upsilon o Omega1)C^T as written needs n_x = n_y; use OutsideC",
            });
        }
        let est = Estimate::new(x0, p0)?;
        let eta0 = cfg.trigger.eta0();
        Ok(Self {
            cfg,
            est,
            y_held: cfg.tau,
            g: eta0 * eta0,
            last_theta: T::one(),
            knowledge: TriggerKnowledge::new(cfg.trigger, cfg.tau)?,
        })
    }

    /// x̂_{t|t} with P̄_{t|t}, the bound on the error covariance.
    #[inline]
    pub fn estimate(&self) -> &Estimate<T, NX> {
        &self.est
    }
    /// ȳ the filter holds (the last measurement received; τ before any).
    #[inline]
    pub fn held_measurement(&self) -> &SVector<T, NY> {
        &self.y_held
    }
    /// Ḡ for the next instant.
    #[inline]
    pub fn g_bar(&self) -> T {
        self.g
    }
    /// θ of the last step (0: measurement received).
    #[inline]
    pub fn last_theta(&self) -> T {
        self.last_theta
    }
    /// The configuration.
    #[inline]
    pub fn config(&self) -> &TobitFilterConfig<T, NY> {
        &self.cfg
    }
    /// The receiver's knowledge of the node's trigger (advanced only when the configured
    /// [`Silence`] reads the set).
    #[inline]
    pub fn trigger_knowledge(&self) -> &TriggerKnowledge<T, NY> {
        &self.knowledge
    }

    /// Overwrites x̂ and P̄ (the fusion reset (51)); validated, unchanged on error.
    pub fn reset(&mut self, x: SVector<T, NX>, p: SMatrix<T, NX, NX>) -> Result<()> {
        self.est = Estimate::named(x, p, "reset state", "reset bound")?;
        Ok(())
    }

    /// [`TobitFilter::reset`] with an estimate the fusion has already validated.
    #[inline]
    pub(crate) fn reset_checked(&mut self, est: Estimate<T, NX>) {
        self.est = est;
    }

    /// Computes (21), (23), (29) and the matrices of (30) for one instant without changing
    /// anything. `a` = A_{t−1}, `bqb` = B Q_m Bᵀ, `c` = C_{m,t}, `r` = the variances R_j,
    /// `received` = the measurement if it arrived (θ = 0).
    pub fn plan(
        &self,
        a: &SMatrix<T, NX, NX>,
        bqb: &SMatrix<T, NX, NX>,
        c: &SMatrix<T, NY, NX>,
        r: &SVector<T, NY>,
        received: Option<&SVector<T, NY>>,
    ) -> Result<LocalStepPlan<T, NX, NY>> {
        self.plan_with_input(a, bqb, None, c, r, received)
    }

    /// [`TobitFilter::plan`] for a system with a known input term `gu` = G u_{t−1}: the
    /// prior mean (21) becomes `A x̂ + G u`, and every term of (30) built on it (Ω₁, the
    /// Tobit statistics) uses that prior.
    pub fn plan_with_input(
        &self,
        a: &SMatrix<T, NX, NX>,
        bqb: &SMatrix<T, NX, NX>,
        gu: Option<&SVector<T, NX>>,
        c: &SMatrix<T, NY, NX>,
        r: &SVector<T, NY>,
        received: Option<&SVector<T, NY>>,
    ) -> Result<LocalStepPlan<T, NX, NY>> {
        check_finite(a, "A")?;
        check_finite(bqb, "process covariance")?;
        check_finite(c, "C")?;
        let (theta, y_bar) = match received {
            Some(y) => {
                check_finite(y, "measurement")?;
                (T::zero(), *y)
            }
            None => (T::one(), self.y_held),
        };
        let (x, p) = (*self.est.state(), *self.est.covariance());
        let x_prior = match gu {
            None => a * x,
            Some(gu) => {
                check_finite(gu, "input")?;
                a * x + gu
            }
        };
        let p_prior = symmetrize(&(a * p * a.transpose() + bqb));
        check_finite(&p_prior, "predicted bound")?;
        let stats = TobitStats::new(&(c * x_prior), &self.cfg.tau, r)?;
        let kap = self.cfg.scalars.kappas();
        let e14 = self.cfg.scalars.eps(14);
        let one = T::one();
        let omega1 = symmetrize(
            &(p_prior * (one + e14) + x_prior * x_prior.transpose() * (one + one / e14)),
        );
        let omega2 = self.y_held * self.y_held.transpose();
        let xi = self.cfg.xi(self.g);
        let (qc, m) = self.bound_terms(c, &stats, theta, &omega1, &omega2, xi, &kap)?;
        Ok(LocalStepPlan {
            x_prior,
            stats,
            theta,
            y_bar,
            xi,
            kappas: kap,
            omega1,
            omega2,
            problem: GainProblem {
                kappa1: kap.0[0],
                p_prior,
                qc,
                m,
            },
        })
    }

    /// Q̄ C and the M of (30) (module docs) at θ, from the Tobit statistics, Ω₁, Ω₂ and Ξ(Ḡ).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn bound_terms(
        &self,
        c: &SMatrix<T, NY, NX>,
        stats: &TobitStats<T, NY>,
        theta: T,
        omega1: &SMatrix<T, NX, NX>,
        omega2: &SMatrix<T, NY, NY>,
        xi: T,
        kap: &Kappas<T>,
    ) -> Result<(SMatrix<T, NY, NX>, SMatrix<T, NY, NY>)> {
        let tau = self.cfg.tau;
        let k = |i: usize| kap.0[i - 1];
        let one = T::one();
        let qbar = SMatrix::<T, NY, NY>::from_diagonal(&stats.rho);
        let qc = qbar * c;
        let v = qbar * stats.lambda.component_mul(&stats.sqrt_r);
        let i_q_tau = tau - qbar * tau; // (I − Q̄) τ
        let (s, u) = ((one - theta) * (one - theta), theta * theta);
        let mut m = SMatrix::<T, NY, NY>::zeros();
        // (1−θ)²(Ω₃∘R): Ω₃ = Υ + Q̄Q̄ᵀ is diagonal with ϱ̄(1−ϱ̄) + ϱ̄² = ϱ̄.
        // (1−θ)²κ₈ Υ∘(ττᵀ) and (1−θ)²κ₆ Ξ I are diagonal too.
        for j in 0..NY {
            let rj = stats.sqrt_r[j] * stats.sqrt_r[j];
            let omega3 = stats.upsilon[j] + stats.rho[j] * stats.rho[j];
            m[(j, j)] += s * (omega3 * rj + k(8) * stats.upsilon[j] * tau[j] * tau[j] + k(6) * xi);
        }
        m += v * v.transpose() * k(2);
        let ups_term = match self.cfg.placement {
            UpsilonPlacement::AsWritten => {
                // Υ∘Ω₁ with Υ diagonal: diag(Υ_ii Ω₁_ii) (n_x = n_y checked in `new`).
                let mut h = SMatrix::<T, NX, NX>::zeros();
                for i in 0..NX.min(NY) {
                    h[(i, i)] = stats.upsilon[i] * omega1[(i, i)];
                }
                c * h * c.transpose()
            }
            UpsilonPlacement::OutsideC => {
                let co = c * omega1 * c.transpose();
                SMatrix::from_diagonal(&SVector::from_fn(|j, _| stats.upsilon[j] * co[(j, j)]))
            }
        };
        m += ups_term * (s * k(3));
        m += (qc * omega1 * qc.transpose() * k(4) + omega2 * k(5)) * u;
        m += i_q_tau * i_q_tau.transpose() * (u * k(7));
        let m = symmetrize(&m);
        check_finite(&m, "bound terms")?;
        Ok((qc, m))
    }

    /// One instant with explicit matrices (see [`TobitFilter::plan`]): gain (37), estimate
    /// (22), bound (30), then Ḡ ← Ξ(Ḡ); with [`Silence::Predict`] and no measurement, the
    /// prediction (21), (29) instead of (37), (22), (30). Nothing changes on error.
    pub fn step(
        &mut self,
        a: &SMatrix<T, NX, NX>,
        bqb: &SMatrix<T, NX, NX>,
        c: &SMatrix<T, NY, NX>,
        r: &SVector<T, NY>,
        received: Option<&SVector<T, NY>>,
    ) -> Result<()> {
        self.step_with_input(a, bqb, None, c, r, received)
    }

    /// [`TobitFilter::step`] with a known input term (see [`TobitFilter::plan_with_input`]).
    pub fn step_with_input(
        &mut self,
        a: &SMatrix<T, NX, NX>,
        bqb: &SMatrix<T, NX, NX>,
        gu: Option<&SVector<T, NX>>,
        c: &SMatrix<T, NY, NX>,
        r: &SVector<T, NY>,
        received: Option<&SVector<T, NY>>,
    ) -> Result<()> {
        let arrival = match received {
            Some(y) => Arrival::Received(y),
            None => Arrival::Held,
        };
        self.step_arrival(a, bqb, gu, c, r, arrival)
    }

    /// One instant on what the node's packet was ([`Arrival`]). The paper's filter and
    /// [`Silence::Predict`] read every arrival but `Received` as "nothing arrived" (θ = 1),
    /// as [`TobitFilter::step_with_input`] does; the silence-reading options update a `Held`
    /// silence with the set and predict on `Blocked` and `Lost`. Nothing changes on error.
    pub fn step_arrival(
        &mut self,
        a: &SMatrix<T, NX, NX>,
        bqb: &SMatrix<T, NX, NX>,
        gu: Option<&SVector<T, NX>>,
        c: &SMatrix<T, NY, NX>,
        r: &SVector<T, NY>,
        arrival: Arrival<'_, T, NY>,
    ) -> Result<()> {
        self.step_arrival_bound(a, bqb, gu, c, r, arrival, BoundCheck::Here)
    }

    /// [`TobitFilter::step_arrival`], with the factorisation that validates the new bound
    /// left to the caller where it factorises the same bound anyway ([`BoundCheck`]).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn step_arrival_bound(
        &mut self,
        a: &SMatrix<T, NX, NX>,
        bqb: &SMatrix<T, NX, NX>,
        gu: Option<&SVector<T, NX>>,
        c: &SMatrix<T, NY, NX>,
        r: &SVector<T, NY>,
        arrival: Arrival<'_, T, NY>,
        bound_check: BoundCheck,
    ) -> Result<()> {
        let received = match arrival {
            Arrival::Received(y) => Some(y),
            _ => None,
        };
        let mut knowledge = self.knowledge;
        let set = self.read_arrival(&mut knowledge, arrival)?;
        let pseudo = self.pseudo_measurement(set, a, gu, c, r);
        let measured = match &pseudo {
            Some((mean, _)) => Some(mean),
            None => received,
        };
        let mut plan = self.plan_with_input(a, bqb, gu, c, r, measured)?;
        self.add_pseudo_variance(&mut plan, pseudo.as_ref());
        let (x, p) = self.estimate_and_bound(&plan, received, set, pseudo.as_ref(), c, r)?;
        check_finite(&x, "local estimate")?;
        match bound_check {
            BoundCheck::Here => check_spd(&p, "local bound")?,
            // Finite all the same: the caller's factorisation must see what this one would.
            BoundCheck::ByCaller => check_finite(&p, "local bound")?,
        }
        let g = plan.xi;
        if !g.finite() {
            return Err(Error::NonFinite { what: "G bar" });
        }
        if received.is_none() {
            plan.theta = T::one();
        }
        self.est = Estimate::trusted(x, p);
        self.y_held = plan.y_bar;
        self.g = g;
        self.last_theta = plan.theta;
        self.knowledge = knowledge;
        Ok(())
    }

    /// Advances the receiver's knowledge of the trigger past this arrival (committed with the
    /// step) and returns the silence set a held silence offers: only with a silence-reading
    /// option (otherwise the knowledge stays as it is and there is no set).
    #[inline(always)]
    fn read_arrival(
        &self,
        knowledge: &mut TriggerKnowledge<T, NY>,
        arrival: Arrival<'_, T, NY>,
    ) -> Result<Option<SilenceBall<T, NY>>> {
        if !self.cfg.silence.reads_set() {
            return Ok(None);
        }
        let ball = match arrival {
            Arrival::Held => knowledge.silence_set(),
            _ => None,
        };
        match arrival {
            Arrival::Received(y) => knowledge.delivered(y)?,
            Arrival::Held | Arrival::Blocked => knowledge.silent(),
            Arrival::Lost => knowledge.lost(),
        }
        Ok(ball)
    }

    /// (S3), (S7): with the pseudo-measurement option a silence's set gives its centre as a
    /// measurement at θ = 0 and its covariance added to M (the mean and per-axis variance).
    #[inline(always)]
    fn pseudo_measurement(
        &self,
        set: Option<SilenceBall<T, NY>>,
        a: &SMatrix<T, NX, NX>,
        gu: Option<&SVector<T, NX>>,
        c: &SMatrix<T, NY, NX>,
        r: &SVector<T, NY>,
    ) -> Option<(SVector<T, NY>, SVector<T, NY>)> {
        match (set, self.cfg.silence) {
            (Some(ball), Silence::PseudoMeasurement) => {
                // (S3') weighs the atom at τ with the filter's own censoring model (5):
                // z ~ N(C x̂_{t|t−1}, R), x̂_{t|t−1} as `plan_with_input` predicts it.
                let x = a * self.est.state();
                let x_prior = gu.map_or(x, |gu| x + gu);
                let prior = CensoredPrior {
                    tau: self.cfg.tau,
                    mean: c * x_prior,
                    var: *r,
                };
                Some(uniform_moments(&ball, Some(&prior)))
            }
            _ => None,
        }
    }

    /// (S7): a pseudo-measurement's variance added to M's diagonal; the held ȳ stays (it is
    /// the trigger's reference).
    #[inline(always)]
    fn add_pseudo_variance(
        &self,
        plan: &mut LocalStepPlan<T, NX, NY>,
        pseudo: Option<&(SVector<T, NY>, SVector<T, NY>)>,
    ) {
        if let Some((_, var)) = pseudo {
            for j in 0..NY {
                plan.problem.m[(j, j)] += var[j];
            }
            plan.y_bar = self.y_held;
        }
    }

    /// x̂_{t|t} and its bound by the silence option and what arrived: the update (37), (22),
    /// (30) on ȳ or on the pseudo-measurement, the truncated Gaussian of the silence box, or
    /// the prediction (21), (29).
    #[inline(always)]
    fn estimate_and_bound(
        &self,
        plan: &LocalStepPlan<T, NX, NY>,
        received: Option<&SVector<T, NY>>,
        set: Option<SilenceBall<T, NY>>,
        pseudo: Option<&(SVector<T, NY>, SVector<T, NY>)>,
        c: &SMatrix<T, NY, NX>,
        r: &SVector<T, NY>,
    ) -> Result<(SVector<T, NX>, SMatrix<T, NX, NX>)> {
        Ok(match (received, set, self.cfg.silence, pseudo) {
            (None, Some(_), Silence::PseudoMeasurement, Some((mean, _))) => {
                let k = plan.problem.gain()?;
                (
                    plan.x_prior + k * (mean - plan.stats.mean),
                    plan.problem.bound(&k),
                )
            }
            (None, Some(ball), Silence::TruncatedGaussian, _) => truncate_box(
                &plan.x_prior,
                &plan.problem.p_prior,
                c,
                &SMatrix::from_diagonal(r),
                &SilenceBox::of_ball(&ball, Some(&self.cfg.tau)),
            )?,
            // Silence::Predict, and a silence-reading filter without a usable set: the
            // prediction (21), (29) is the estimate and its bound.
            (None, _, s, _) if s != Silence::HeldMeasurement => {
                (plan.x_prior, plan.problem.p_prior)
            }
            _ => {
                let k = plan.problem.gain()?;
                (
                    plan.x_prior + k * (plan.y_bar - plan.stats.mean),
                    plan.problem.bound(&k),
                )
            }
        })
    }

    /// Whether `gate` admits the received `y` (docs/gate.md): the NIS of the innovation of
    /// (22), `y − ŷ_{t|t−1}`, against `Φ` of (37) at θ = 0 — the paper's bound on its
    /// covariance, so a consistent filter rejects fewer than `1 − p` of its good measurements.
    /// Arguments as [`TobitFilter::plan`]. A `Φ` that cannot be factored (components whose
    /// `Φ_jj` underflowed, to which the gain gives no weight) cannot be tested: admitted.
    pub fn admits(
        &self,
        a: &SMatrix<T, NX, NX>,
        bqb: &SMatrix<T, NX, NX>,
        c: &SMatrix<T, NY, NX>,
        r: &SVector<T, NY>,
        y: &SVector<T, NY>,
        gate: &InnovationGate<T>,
    ) -> Result<bool> {
        if gate.is_off() {
            return Ok(true);
        }
        let plan = self.plan(a, bqb, c, r, Some(y))?;
        let nu = plan.y_bar - plan.stats.mean;
        Ok(gate.admits(&nu, &plan.problem.phi()).unwrap_or(true))
    }

    /// One instant `k ≥ 1` of a model: `A_{k−1}`, `B Q_{k−1} Bᵀ` scaled by `q_scale`
    /// (α_m⁻¹ under fusion, 1 alone), `C_k`, and the diagonal of the measurement covariance.
    pub fn step_model<M: LinearSystem<T, NX, NY>>(
        &mut self,
        model: &M,
        k: usize,
        q_scale: T,
        received: Option<&SVector<T, NY>>,
    ) -> Result<()> {
        let prev = k.saturating_sub(1);
        let r = diagonal_variances(&model.measurement_cov(k))?;
        self.step_with_input(
            &model.a(prev),
            &(model.process_cov(prev) * q_scale),
            model.input(prev).as_ref(),
            &model.c(k),
            &r,
            received,
        )
    }
}

/// Delivered: θ = 0; dropped: θ = 1 (the held ȳ and the trigger's bound enter (30)).
/// Lost is treated like dropped, provisionally: the estimator cannot tell whether the
/// trigger fired (see [`crate::estimator`]).
impl<T: Real, const NX: usize, const NY: usize, M: LinearSystem<T, NX, NY>> Estimator<T, NX>
    for OnModel<M, TobitFilter<T, NX, NY>, NY>
{
    type Measurement = Packet<T, NY>;

    /// [`TobitFilter::step_model`] with the model's own process noise (`q_scale = 1`).
    #[inline]
    fn step(&mut self, k: usize, y: &Packet<T, NY>) -> Result<()> {
        self.filter
            .step_model(&self.model, k, T::one(), y.delivered())
    }

    #[inline]
    fn estimate(&self) -> &Estimate<T, NX> {
        self.filter.estimate()
    }
}

/// Behind a gate: a delivered packet the gate rejects is stepped as dropped (θ = 1, the
/// held ȳ — never the rejected measurement — enters (30)), as a lost one is.
impl<T: Real, const NX: usize, const NY: usize, M: LinearSystem<T, NX, NY>> GatedStep<T, NX>
    for OnModel<M, TobitFilter<T, NX, NY>, NY>
{
    fn step_gated(
        &mut self,
        k: usize,
        y: &Packet<T, NY>,
        gate: &InnovationGate<T>,
    ) -> Result<GateCounts> {
        let Some(z) = y.delivered() else {
            return self.step(k, y).map(|()| GateCounts::NONE);
        };
        let (m, prev) = (&self.model, k.saturating_sub(1));
        let r = diagonal_variances(&m.measurement_cov(k))?;
        let used = self
            .filter
            .admits(&m.a(prev), &m.process_cov(prev), &m.c(k), &r, z, gate)?;
        let received = if used { Some(z) } else { None };
        self.filter.step_model(&self.model, k, T::one(), received)?;
        Ok(GateCounts::one(used))
    }
}

#[cfg(test)]
mod tests;
