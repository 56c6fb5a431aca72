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
//! measurement is the prediction (21), (29) alone: no gain, no (22), no (30).

use nalgebra::{SMatrix, SVector};

use super::config::{Kappas, Silence, TobitFilterConfig, UpsilonPlacement};
use super::gain::GainProblem;
use crate::estimate::Estimate;
use crate::estimator::{Estimator, OnModel};
use crate::filter::gate::{GateCounts, GatedStep, InnovationGate};
use crate::linalg::{check_finite, check_spd, symmetrize};
use crate::model::LinearSystem;
use crate::packet::Packet;
use crate::protocol::tobit::TobitStats;
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

/// One node's local Tobit filter: x̂, P̄, the held measurement ȳ and Ḡ.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TobitFilter<T: Real, const NX: usize, const NY: usize> {
    cfg: TobitFilterConfig<T, NY>,
    est: Estimate<T, NX>,
    y_held: SVector<T, NY>,
    g: T,
    last_theta: T,
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

    /// Overwrites x̂ and P̄ (the fusion reset (51)); validated, unchanged on error.
    pub fn reset(&mut self, x: SVector<T, NX>, p: SMatrix<T, NX, NX>) -> Result<()> {
        self.est = Estimate::named(x, p, "reset state", "reset bound")?;
        Ok(())
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
        let tau = self.cfg.tau;
        let stats = TobitStats::new(&(c * x_prior), &tau, r)?;
        let kap = self.cfg.scalars.kappas();
        let k = |i: usize| kap.0[i - 1];
        let e14 = self.cfg.scalars.eps(14);
        let one = T::one();
        let omega1 = symmetrize(
            &(p_prior * (one + e14) + x_prior * x_prior.transpose() * (one + one / e14)),
        );
        let omega2 = self.y_held * self.y_held.transpose();
        let xi = self.cfg.xi(self.g);

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
                kappa1: k(1),
                p_prior,
                qc,
                m,
            },
        })
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
        let plan = self.plan_with_input(a, bqb, gu, c, r, received)?;
        let (x, p) = if received.is_none() && self.cfg.silence == Silence::Predict {
            // Silence::Predict: the prediction (21), (29) is the estimate and its bound.
            (plan.x_prior, plan.problem.p_prior)
        } else {
            let k = plan.problem.gain()?;
            (
                plan.x_prior + k * (plan.y_bar - plan.stats.mean),
                plan.problem.bound(&k),
            )
        };
        check_finite(&x, "local estimate")?;
        check_spd(&p, "local bound")?;
        let g = plan.xi;
        if !g.finite() {
            return Err(Error::NonFinite { what: "G bar" });
        }
        self.est = Estimate::trusted(x, p);
        self.y_held = plan.y_bar;
        self.g = g;
        self.last_theta = plan.theta;
        Ok(())
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

/// The variances of a diagonal measurement covariance; refuses correlated noise, which the
/// per-component Tobit model (eqs. 5-7) cannot represent.
pub fn diagonal_variances<T: Real, const NY: usize>(
    r: &SMatrix<T, NY, NY>,
) -> Result<SVector<T, NY>> {
    check_finite(r, "measurement covariance")?;
    let tol = T::EPS.sqrt();
    for i in 0..NY {
        for j in 0..NY {
            if i != j && r[(i, j)].abs() > tol * (r[(i, i)] * r[(j, j)]).abs().sqrt() {
                return Err(Error::InvalidConfig {
                    field: "measurement covariance",
                    reason: "the Tobit model (eqs. 5-7) needs independent components (diagonal R)",
                });
            }
        }
    }
    let d = r.diagonal();
    if d.iter().any(|&v| v <= T::zero()) {
        return Err(Error::NotPositiveDefinite {
            what: "measurement covariance",
        });
    }
    Ok(d)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::tobit::config::BoundScalars;
    use crate::filter::KalmanFilter;
    use crate::protocol::event_trigger::EventTriggerConfig;
    use nalgebra::{matrix, vector};

    fn paper_cfg(lambda: f64, sigma: f64) -> TobitFilterConfig<f64, 2> {
        let trig =
            EventTriggerConfig::new_allowing_paper_violation(sigma, 5.0, lambda, 1.5).unwrap();
        TobitFilterConfig::new(
            vector![0.0, 0.0],
            BoundScalars::paper_example(),
            trig,
            1.5,
            2.0,
        )
        .unwrap()
    }

    fn oscillator() -> (SMatrix<f64, 2, 2>, SMatrix<f64, 2, 2>) {
        let w = 0.052 * core::f64::consts::PI;
        let a = matrix![w.cos(), w.sin(); -w.sin(), w.cos()];
        let b = vector![0.16, 0.18];
        (a, b * b.transpose() * 0.05)
    }

    #[test]
    fn xi_recursion_by_hand() {
        // λ = 0.1, χ = 5, σ = 0.1, d = 1.5, e = 2:
        // a = 2.5·3·0.01 + 6·(1 + 1/1.5)/25 = 0.075 + 0.4 = 0.475,
        // b = (2.5·1.5 + (5/3)·1.2)·0.01 = 0.0575.
        let cfg = paper_cfg(0.1, 0.1);
        assert!((cfg.xi(2.25) - (0.475 * 2.25 + 0.0575)).abs() < 1e-14);
        let (a, bqb) = oscillator();
        let mut f = TobitFilter::new(cfg, vector![5.0, 0.0], SMatrix::identity() * 3.0).unwrap();
        assert!((f.g_bar() - 2.25).abs() < 1e-15);
        f.step(&a, &bqb, &SMatrix::identity(), &vector![0.5, 0.5], None)
            .unwrap();
        assert!((f.g_bar() - (0.475 * 2.25 + 0.0575)).abs() < 1e-14);
    }

    #[test]
    fn predict_on_silence_is_the_prediction_and_changes_nothing_else() {
        let (a, bqb) = oscillator();
        let c = SMatrix::<f64, 2, 2>::identity();
        let r = vector![0.5, 0.5];
        let (x0, p0) = (vector![5.0, -1.0], SMatrix::identity() * 3.0);
        let held = TobitFilter::new(paper_cfg(0.1, 0.1), x0, p0).unwrap();
        let cfg = paper_cfg(0.1, 0.1).with_silence(Silence::Predict);
        assert_eq!(cfg.cast::<f32>().unwrap().silence, Silence::Predict);
        let mut f = TobitFilter::new(cfg, x0, p0).unwrap();
        let mut paper = held;
        // An arrival: the same update bit for bit as the paper's filter.
        let y = vector![4.0, -2.0];
        f.step(&a, &bqb, &c, &r, Some(&y)).unwrap();
        paper.step(&a, &bqb, &c, &r, Some(&y)).unwrap();
        assert_eq!(f.estimate(), paper.estimate());
        // Silence: x̂ = A x̂, P̄ = A P̄ Aᵀ + BQBᵀ (written out here), where the paper updates.
        let (x1, p1) = f.estimate().into_parts();
        let (g1, y_held) = (f.g_bar(), *f.held_measurement());
        f.step(&a, &bqb, &c, &r, None).unwrap();
        paper.step(&a, &bqb, &c, &r, None).unwrap();
        let x_pred = a * x1;
        let p_pred = a * p1 * a.transpose() + bqb;
        assert_eq!(*f.estimate().state(), x_pred);
        assert!((f.estimate().covariance() - p_pred).abs().max() < 1e-14);
        assert_ne!(paper.estimate().state(), f.estimate().state());
        assert_eq!(f.last_theta(), 1.0);
        assert_eq!(*f.held_measurement(), y_held);
        assert_eq!(f.g_bar(), f.config().xi(g1));
        assert_eq!(f.g_bar(), paper.g_bar());
    }

    /// Eq. (30) assembled term by term from the plan's ingredients, written out as printed
    /// (independently of `GainProblem::bound`).
    fn bound_as_printed(
        plan: &LocalStepPlan<f64, 2, 2>,
        c: &SMatrix<f64, 2, 2>,
        tau: &SVector<f64, 2>,
        k: &SMatrix<f64, 2, 2>,
    ) -> SMatrix<f64, 2, 2> {
        let kap = |i: usize| plan.kappas.0[i - 1];
        let th = plan.theta;
        let st = &plan.stats;
        let qbar = SMatrix::<f64, 2, 2>::from_diagonal(&st.rho);
        let ups = SMatrix::<f64, 2, 2>::from_diagonal(&st.upsilon);
        let r = SMatrix::<f64, 2, 2>::from_diagonal(&st.sqrt_r.component_mul(&st.sqrt_r));
        let lam_sr = st.lambda.component_mul(&st.sqrt_r);
        let i = SMatrix::<f64, 2, 2>::identity();
        let ikqc = i - k * qbar * c;
        let p = plan.problem.p_prior;
        let omega3 = ups + qbar * qbar.transpose();
        let tt = tau * tau.transpose();
        kap(1) * ikqc * p * ikqc.transpose()
            + (1.0 - th).powi(2) * k * omega3.component_mul(&r) * k.transpose()
            + kap(2) * k * qbar * lam_sr * lam_sr.transpose() * qbar * k.transpose()
            + (1.0 - th).powi(2)
                * kap(3)
                * k
                * c
                * ups.component_mul(&plan.omega1)
                * c.transpose()
                * k.transpose()
            + th * th * kap(4) * k * qbar * c * plan.omega1 * c.transpose() * qbar * k.transpose()
            + th * th * kap(5) * k * plan.omega2 * k.transpose()
            + (1.0 - th).powi(2) * kap(6) * plan.xi * k * k.transpose()
            + th * th * kap(7) * k * (i - qbar) * tt * (i - qbar).transpose() * k.transpose()
            + (1.0 - th).powi(2) * kap(8) * k * ups.component_mul(&tt) * k.transpose()
    }

    #[test]
    fn gain_minimises_the_trace_of_the_bound() {
        // Both θ = 0 and θ = 1, a nonzero τ and a prediction near the threshold so that every
        // term of (30) is active. At the minimiser the finite-difference gradient of tr P̄ in
        // each of the 4 gain entries must vanish: central differences with h = 1e-5 are exact
        // for a quadratic up to rounding (≈1e-16·tr/h² ≈ 1e-6 relative), so the gradient is
        // compared with the gradient scale tr P̄ / ‖K‖ at 1e-6; moving the gain must also
        // increase the trace.
        let (a, bqb) = oscillator();
        let c = matrix![1.0, 0.2; -0.3, 1.0];
        let r = vector![0.5, 0.8];
        let tau = vector![0.3, -0.4];
        let mut cfg = paper_cfg(0.2, 0.2);
        cfg.tau = tau;
        let mut f = TobitFilter::new(cfg, vector![0.4, -0.2], matrix![1.5, 0.2; 0.2, 0.9]).unwrap();
        f.step(&a, &bqb, &c, &r, Some(&vector![0.7, 0.1])).unwrap();
        for received in [Some(vector![0.9, -0.1]), None] {
            let plan = f.plan(&a, &bqb, &c, &r, received.as_ref()).unwrap();
            let k = plan.problem.gain().unwrap();
            let tr = |k: &SMatrix<f64, 2, 2>| bound_as_printed(&plan, &c, &tau, k).trace();
            // The implementation's (30) equals the printed one.
            assert!(
                (plan.problem.bound(&k) - bound_as_printed(&plan, &c, &tau, &k)).amax() < 1e-12
            );
            let h = 1e-5;
            let scale = tr(&k) / k.norm();
            for idx in 0..4 {
                let mut kp = k;
                kp[idx] += h;
                let mut km = k;
                km[idx] -= h;
                let grad = (tr(&kp) - tr(&km)) / (2.0 * h);
                assert!(
                    grad.abs() < 1e-6 * scale,
                    "∂tr/∂K[{idx}] = {grad} (θ = {})",
                    plan.theta
                );
                assert!(tr(&kp) > tr(&k) && tr(&km) > tr(&k));
            }
        }
    }

    #[test]
    fn reduces_to_kalman_without_censoring_and_with_every_measurement() {
        // τ far below every measurement → ϱ̄ = 1, λ = 0, Υ = 0 exactly; σ = η₀ = 0 → Ξ = 0;
        // ε₁…ε₅ = 1e-12 → κ₁ = 1 + 5e-12. (30) and (37) then are the Kalman equations up to
        // κ₁ − 1 = 5e-12 relative per step; over 100 steps of a stable filter the gap stays
        // below 1e-9 (stated tolerance).
        let trig = EventTriggerConfig::new(0.0, 5.0, 0.5, 0.0).unwrap();
        let mut eps = [0.7; 14];
        for e in eps.iter_mut().take(5) {
            *e = 1e-12;
        }
        let cfg = TobitFilterConfig::new(
            vector![-1e3, -1e3],
            BoundScalars::new(eps).unwrap(),
            trig,
            1.5,
            2.0,
        )
        .unwrap();
        let (a, bqb) = oscillator();
        let c = matrix![1.0, 0.0; 0.3, 1.0];
        let r = vector![0.5, 0.4];
        let x0 = vector![5.0, 0.0];
        let mut tf = TobitFilter::new(cfg, x0, SMatrix::identity()).unwrap();
        let mut kf = KalmanFilter::new(x0, SMatrix::identity()).unwrap();
        for t in 1..=100 {
            let s = t as f64;
            let y = vector![
                5.0 * (0.16 * s).cos() + 0.3 * (2.1 * s).sin(),
                -4.0 * (0.16 * s).sin()
            ];
            tf.step(&a, &bqb, &c, &r, Some(&y)).unwrap();
            kf.predict_with(&a, &bqb).unwrap();
            kf.update_with(&c, &SMatrix::from_diagonal(&r), &y).unwrap();
            assert!(
                (tf.estimate().state() - kf.estimate().state()).amax() < 1e-9,
                "t = {t}"
            );
            assert!(
                (tf.estimate().covariance() - kf.estimate().covariance()).amax() < 1e-9,
                "t = {t}"
            );
        }
    }

    #[test]
    fn placements_agree_when_c_is_diagonal_and_differ_otherwise() {
        let (a, bqb) = oscillator();
        let r = vector![0.5, 0.5];
        let base = paper_cfg(0.1, 0.1);
        let f1 = TobitFilter::new(base, vector![0.2, -0.1], SMatrix::identity()).unwrap();
        let f2 = TobitFilter::new(
            base.with_placement(UpsilonPlacement::OutsideC),
            vector![0.2, -0.1],
            SMatrix::identity(),
        )
        .unwrap();
        let eye = SMatrix::<f64, 2, 2>::identity();
        let y = vector![0.3, 0.2];
        let p1 = f1.plan(&a, &bqb, &eye, &r, Some(&y)).unwrap();
        let p2 = f2.plan(&a, &bqb, &eye, &r, Some(&y)).unwrap();
        assert!((p1.problem.m - p2.problem.m).amax() < 1e-14);
        let c = matrix![1.0, 0.5; 0.5, 1.0];
        let p1 = f1.plan(&a, &bqb, &c, &r, Some(&y)).unwrap();
        let p2 = f2.plan(&a, &bqb, &c, &r, Some(&y)).unwrap();
        assert!((p1.problem.m - p2.problem.m).amax() > 1e-3);
        // As written needs n_x = n_y.
        let cfg1 = TobitFilterConfig::new(
            vector![0.0],
            BoundScalars::paper_example(),
            base.trigger,
            1.5,
            2.0,
        )
        .unwrap();
        assert!(matches!(
            TobitFilter::<f64, 2, 1>::new(cfg1, vector![0.0, 0.0], SMatrix::identity()),
            Err(Error::InvalidConfig {
                field: "placement",
                ..
            })
        ));
        assert!(TobitFilter::<f64, 2, 1>::new(
            cfg1.with_placement(UpsilonPlacement::OutsideC),
            vector![0.0, 0.0],
            SMatrix::identity()
        )
        .is_ok());
    }

    #[test]
    fn far_censored_component_gets_no_gain_and_f32_runs() {
        // Prediction 40 σ below the threshold in component 2: ϱ̄₂ underflows (f32) or is
        // ~1e-350 → 0 (f64); the step must still succeed and the estimate stay finite.
        let (a, bqb) = oscillator();
        let cfg = paper_cfg(0.1, 0.1);
        let mut f = TobitFilter::new(cfg, vector![3.0, -30.0], SMatrix::identity()).unwrap();
        let c = SMatrix::<f64, 2, 2>::identity();
        for t in 0..5 {
            let rec = (t % 2 == 0).then_some(vector![3.0, 0.0]);
            f.step(&a, &bqb, &c, &vector![0.5, 0.5], rec.as_ref())
                .unwrap();
            assert!(f.estimate().state().iter().all(|v| v.is_finite()));
        }
        let cfg32 = cfg.cast::<f32>().unwrap();
        let mut g =
            TobitFilter::<f32, 2, 2>::new(cfg32, vector![5.0, 0.0], SMatrix::identity()).unwrap();
        let mut h = TobitFilter::new(cfg, vector![5.0, 0.0], SMatrix::identity()).unwrap();
        for t in 1..=50 {
            let s = t as f64;
            let y = vector![
                (5.0 * (0.16 * s).cos()).max(0.0),
                (-5.0 * (0.16 * s).sin()).max(0.0)
            ];
            let rec = (t % 3 != 0).then_some(y);
            h.step(&a, &bqb, &c, &vector![0.5, 0.5], rec.as_ref())
                .unwrap();
            g.step(
                &a.cast(),
                &bqb.cast(),
                &c.cast(),
                &vector![0.5f32, 0.5],
                rec.map(|y| y.cast()).as_ref(),
            )
            .unwrap();
        }
        // f32 vs f64 of a stable recursion: 1e-3 relative to the state's scale (5).
        assert!((h.estimate().state() - g.estimate().state().cast::<f64>()).amax() < 5e-3);
    }

    #[test]
    fn bad_inputs_rejected_and_state_unchanged() {
        let (a, bqb) = oscillator();
        let c = SMatrix::<f64, 2, 2>::identity();
        let r = vector![0.5, 0.5];
        let cfg = paper_cfg(0.1, 0.1);
        let mut f = TobitFilter::new(cfg, vector![5.0, 0.0], SMatrix::identity()).unwrap();
        f.step(&a, &bqb, &c, &r, Some(&vector![4.0, 0.0])).unwrap();
        let before = f;
        assert!(f
            .step(&a, &bqb, &c, &r, Some(&vector![f64::NAN, 0.0]))
            .is_err());
        assert!(f.step(&a, &bqb, &c, &vector![0.5, -1.0], None).is_err());
        assert!(f.step(&(a * f64::INFINITY), &bqb, &c, &r, None).is_err());
        assert!(f
            .reset(vector![0.0, 0.0], matrix![1.0, 2.0; 2.0, 1.0])
            .is_err());
        assert_eq!(f, before);
        assert!(BoundScalars::new([0.0; 14]).is_err());
        assert!(BoundScalars::new([f64::NAN; 14]).is_err());
        assert!(TobitFilterConfig::new(
            vector![0.0],
            BoundScalars::paper_example(),
            cfg.trigger,
            -1.0,
            2.0
        )
        .is_err());
        assert!(TobitFilter::new(cfg, vector![0.0, 0.0], SMatrix::zeros()).is_err());
        assert!(diagonal_variances(&matrix![1.0, 0.3; 0.3, 1.0]).is_err());
    }
}
