//! Federated Tobit Kalman fusion of `L` local filters (seed 004, Theorem 4, eqs. 50-51,
//! Algorithm 1).
//!
//! ```text
//! P^g = (Σ_m P̄_m⁻¹)⁻¹,   x̂^g = P^g Σ_m P̄_m⁻¹ x̂_m                        (50)
//! Q_m = α_m⁻¹ Q,  P̄_m ← α_m⁻¹ P^g,  x̂_m ← x̂^g    (Σ α_m = 1)              (51)
//! ```
//!
//! One [`TobitFusion::step`] is one pass of Algorithm 1's outer loop on the estimator side:
//! every local filter runs (21)-(23), (37), (30) on what its node delivered, the fusion
//! centre forms (50), and the reset (51) hands the fused result back to every local filter
//! for the next prediction. (The protocol lines of Algorithm 1 — trigger, bucket update — run
//! on the sensor side, [`crate::protocol::shared_token_bucket`].) Initialisation follows (51)
//! too: local filters start from `x̄₀` and `α_m⁻¹ P₀`.
//!
//! The information matrices `P̄_m⁻¹` and `P^g` are the paper's results, so they are formed as
//! inverses; `P̄_m⁻¹ x̂_m` and `x̂^g` come from solves with the same Cholesky factor
//! ([`inverse_and_solve_spd`]: one factorisation per matrix).

use nalgebra::{SMatrix, SVector};

use super::config::diagonal_variances;
use super::config::TobitFilterConfig;
use super::local::{BoundCheck, TobitFilter};
use crate::estimate::Estimate;
use crate::estimator::{Estimator, OnModel};
use crate::filter::gate::{GateCounts, GatedStep, InnovationGate};
use crate::filter::silence::Arrival;
use crate::linalg::{check_finite, check_spd, inverse_and_solve_spd, symmetrize};
use crate::model::LinearSystem;
use crate::packet::Packet;
use crate::{Error, Real, Result};

/// Eq. (50): fuses local estimates with their bounds. Returns `(x̂^g, P^g)`.
pub fn federated_fuse<T: Real, const NX: usize, const L: usize>(
    xs: &[SVector<T, NX>; L],
    ps: &[SMatrix<T, NX, NX>; L],
) -> Result<(SVector<T, NX>, SMatrix<T, NX, NX>)> {
    let mut info = SMatrix::<T, NX, NX>::zeros();
    let mut info_x = SVector::<T, NX>::zeros();
    for m in 0..L {
        let (inv, inv_x) = inverse_and_solve_spd(&ps[m], &xs[m], "local bound")?;
        info += inv;
        info_x += inv_x;
    }
    let info = symmetrize(&info);
    let (pg, xg) = inverse_and_solve_spd(&info, &info_x, "fused information")?;
    check_finite(&xg, "fused estimate")?;
    Ok((xg, pg))
}

/// The federated fusion filter: `L` local Tobit filters and the fusion centre.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TobitFusion<T: Real, const NX: usize, const NY: usize, const L: usize> {
    locals: [TobitFilter<T, NX, NY>; L],
    alpha: [T; L],
    /// `(x̂^g, P^g)`.
    est: Estimate<T, NX>,
    /// Every node's `(x̂_m, P̄_m)` of the last step, before the reset (51).
    local_est: [Estimate<T, NX>; L],
}

impl<T: Real, const NX: usize, const NY: usize, const L: usize> TobitFusion<T, NX, NY, L> {
    /// Equal information weights `α_m = 1/L` (the paper's default).
    pub fn new(
        cfgs: [TobitFilterConfig<T, NY>; L],
        x0: SVector<T, NX>,
        p0: SMatrix<T, NX, NX>,
    ) -> Result<Self> {
        Self::with_weights(cfgs, x0, p0, [T::one() / T::lit(L as f64); L])
    }

    /// Explicit information weights: positive, finite, summing to 1 (within `√eps`).
    pub fn with_weights(
        cfgs: [TobitFilterConfig<T, NY>; L],
        x0: SVector<T, NX>,
        p0: SMatrix<T, NX, NX>,
        alpha: [T; L],
    ) -> Result<Self> {
        if L == 0 {
            return Err(Error::InvalidConfig {
                field: "nodes",
                reason: "fusion needs at least one local filter",
            });
        }
        let mut sum = T::zero();
        for a in alpha {
            if !a.finite() {
                return Err(Error::NonFinite {
                    what: "information weight",
                });
            }
            if a <= T::zero() {
                return Err(Error::InvalidConfig {
                    field: "alpha",
                    reason: "information weights must be positive",
                });
            }
            sum += a;
        }
        if (sum - T::one()).abs() > T::EPS.sqrt() {
            return Err(Error::InvalidConfig {
                field: "alpha",
                reason: "information weights must sum to 1 (eq. 51)",
            });
        }
        let est = Estimate::new(x0, p0)?;
        let mut locals = [TobitFilter::new(cfgs[0], x0, p0)?; L];
        let mut local_est = [est; L];
        for m in 0..L {
            let p_m = symmetrize(&(p0 / alpha[m]));
            locals[m] = TobitFilter::new(cfgs[m], x0, p_m)?;
            local_est[m] = Estimate::trusted(x0, p_m);
        }
        Ok(Self {
            locals,
            alpha,
            est,
            local_est,
        })
    }

    /// The fused estimate x̂^g_{t|t} with P^g_{t|t} (a bound, fused from the local bounds).
    #[inline]
    pub fn estimate(&self) -> &Estimate<T, NX> {
        &self.est
    }
    /// Node `m`'s local estimate x̂_{m,t|t} and bound P̄_{m,t|t} of the last step, before the
    /// reset (51).
    #[inline]
    pub fn local_estimate(&self, m: usize) -> Option<&Estimate<T, NX>> {
        self.local_est.get(m)
    }
    /// Node `m`'s local filter (after the reset).
    #[inline]
    pub fn local(&self, m: usize) -> Option<&TobitFilter<T, NX, NY>> {
        self.locals.get(m)
    }
    /// The information weights α_m.
    #[inline]
    pub fn weights(&self) -> &[T; L] {
        &self.alpha
    }

    /// One instant `k ≥ 1` with explicit matrices per node: `a` = A_{k−1}, `bqb` = B Q Bᵀ
    /// (scaled by α_m⁻¹ inside, eq. 51), `c[m]` = C_{m,k}, `r[m]` = the variances of node m,
    /// `received[m]` = the measurement node m delivered (None: θ = 1). All-or-nothing.
    pub fn step(
        &mut self,
        a: &SMatrix<T, NX, NX>,
        bqb: &SMatrix<T, NX, NX>,
        c: &[SMatrix<T, NY, NX>; L],
        r: &[SVector<T, NY>; L],
        received: [Option<&SVector<T, NY>>; L],
    ) -> Result<()> {
        self.step_with_input(a, bqb, None, c, r, received)
    }

    /// [`TobitFusion::step`] for a system with a known input term `gu` = G u_{k−1}, which
    /// every local filter adds to its prior mean.
    pub fn step_with_input(
        &mut self,
        a: &SMatrix<T, NX, NX>,
        bqb: &SMatrix<T, NX, NX>,
        gu: Option<&SVector<T, NX>>,
        c: &[SMatrix<T, NY, NX>; L],
        r: &[SVector<T, NY>; L],
        received: [Option<&SVector<T, NY>>; L],
    ) -> Result<()> {
        let arrivals = received.map(|y| match y {
            Some(y) => Arrival::Received(y),
            None => Arrival::Held,
        });
        self.step_arrivals(a, bqb, gu, c, r, &arrivals)
    }

    /// [`TobitFusion::step_with_input`] on what every node's packet was ([`Arrival`]: the
    /// silence-reading local filters tell a held trigger from a silence without a token or a
    /// lost packet; the paper's and [`super::Silence::Predict`] do not). All-or-nothing.
    pub fn step_arrivals(
        &mut self,
        a: &SMatrix<T, NX, NX>,
        bqb: &SMatrix<T, NX, NX>,
        gu: Option<&SVector<T, NX>>,
        c: &[SMatrix<T, NY, NX>; L],
        r: &[SVector<T, NY>; L],
        arrivals: &[Arrival<'_, T, NY>; L],
    ) -> Result<()> {
        // All-or-nothing: the local filters step in place and are put back on any error
        // (one copy of them per step, not two).
        let saved = self.locals;
        let stepped = self.step_in_place(a, bqb, gu, c, r, arrivals);
        if stepped.is_err() {
            self.locals = saved;
        }
        stepped
    }

    /// The body of [`TobitFusion::step_arrivals`]: changes the local filters as it goes,
    /// the fused and local estimates only once everything succeeded.
    fn step_in_place(
        &mut self,
        a: &SMatrix<T, NX, NX>,
        bqb: &SMatrix<T, NX, NX>,
        gu: Option<&SVector<T, NX>>,
        c: &[SMatrix<T, NY, NX>; L],
        r: &[SVector<T, NY>; L],
        arrivals: &[Arrival<'_, T, NY>; L],
    ) -> Result<()> {
        let mut xs = [SVector::<T, NX>::zeros(); L];
        let mut ps = [SMatrix::<T, NX, NX>::zeros(); L];
        for m in 0..L {
            let q_m = bqb / self.alpha[m];
            let local = &mut self.locals[m];
            // Every local bound is factorised by `federated_fuse` below, under the same name.
            local.step_arrival_bound(
                a,
                &q_m,
                gu,
                &c[m],
                &r[m],
                arrivals[m],
                BoundCheck::ByCaller,
            )?;
            (xs[m], ps[m]) = local.estimate().into_parts();
        }
        let (xg, pg) = federated_fuse(&xs, &ps)?;
        // The reset (51) hands node m `P^g / α_m`: with `α_m > 0` it is positive definite
        // exactly when `P^g` is, so `P^g` is factorised once here instead of every node's
        // copy (`x̂^g` is finite: `federated_fuse` checked it).
        check_spd(&pg, "reset bound")?;
        for m in 0..L {
            let p = symmetrize(&(pg / self.alpha[m]));
            check_finite(&p, "reset bound")?;
            self.locals[m].reset_checked(Estimate::trusted(xg, p));
        }
        self.local_est = core::array::from_fn(|m| Estimate::trusted(xs[m], ps[m]));
        self.est = Estimate::trusted(xg, pg);
        Ok(())
    }

    /// One instant `k ≥ 1` from per-node models (A and B Q Bᵀ from node 0's model, which all
    /// nodes share in seed 004; C and the diagonal R from each node's).
    pub fn step_models<M: LinearSystem<T, NX, NY>>(
        &mut self,
        models: &[M; L],
        k: usize,
        received: [Option<&SVector<T, NY>>; L],
    ) -> Result<()> {
        let arrivals = received.map(|y| match y {
            Some(y) => Arrival::Received(y),
            None => Arrival::Held,
        });
        self.step_arrivals_models(models, k, &arrivals)
    }

    /// [`TobitFusion::step_models`] on every node's [`Arrival`].
    pub fn step_arrivals_models<M: LinearSystem<T, NX, NY>>(
        &mut self,
        models: &[M; L],
        k: usize,
        arrivals: &[Arrival<'_, T, NY>; L],
    ) -> Result<()> {
        let prev = k.saturating_sub(1);
        let mut c = [SMatrix::<T, NY, NX>::zeros(); L];
        let mut r = [SVector::<T, NY>::zeros(); L];
        for m in 0..L {
            c[m] = models[m].c(k);
            r[m] = diagonal_variances(&models[m].measurement_cov(k))?;
        }
        self.step_arrivals(
            &models[0].a(prev),
            &models[0].process_cov(prev),
            models[0].input(prev).as_ref(),
            &c,
            &r,
            arrivals,
        )
    }
}

/// Behind a gate: each node's delivered measurement is tested by its local filter
/// ([`TobitFilter::admits`]); a rejected one is stepped as dropped (θ = 1).
impl<T: Real, const NX: usize, const NY: usize, const L: usize, M: LinearSystem<T, NX, NY>>
    GatedStep<T, NX> for OnModel<[M; L], TobitFusion<T, NX, NY, L>, NY>
{
    fn step_gated(
        &mut self,
        k: usize,
        y: &[Packet<T, NY>; L],
        gate: &InnovationGate<T>,
    ) -> Result<GateCounts> {
        let (models, prev) = (&self.model, k.saturating_sub(1));
        let (a, bqb) = (models[0].a(prev), models[0].process_cov(prev));
        let mut counts = GateCounts::NONE;
        let mut received: [Option<&SVector<T, NY>>; L] = [None; L];
        for m in 0..L {
            if let Some(z) = y[m].delivered() {
                let r = diagonal_variances(&models[m].measurement_cov(k))?;
                let q_m = bqb / self.filter.alpha[m];
                let used = self.filter.locals[m].admits(&a, &q_m, &models[m].c(k), &r, z, gate)?;
                counts.add(GateCounts::one(used));
                received[m] = used.then_some(z);
            }
        }
        self.filter.step_models(models, k, received)?;
        Ok(counts)
    }
}

/// Every node's packet as [`TobitFilter`]'s [`Estimator`] impl reads it (lost is treated like
/// dropped, provisionally); A and B Q Bᵀ from node 0's model.
impl<T: Real, const NX: usize, const NY: usize, const L: usize, M: LinearSystem<T, NX, NY>>
    Estimator<T, NX> for OnModel<[M; L], TobitFusion<T, NX, NY, L>, NY>
{
    type Measurement = [Packet<T, NY>; L];

    #[inline]
    fn step(&mut self, k: usize, y: &[Packet<T, NY>; L]) -> Result<()> {
        let received = core::array::from_fn(|m| y[m].delivered());
        self.filter.step_models(&self.model, k, received)
    }

    #[inline]
    fn estimate(&self) -> &Estimate<T, NX> {
        self.filter.estimate()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::tobit::config::BoundScalars;
    use crate::protocol::event_trigger::EventTriggerConfig;
    use nalgebra::{matrix, vector};

    fn cfgs() -> [TobitFilterConfig<f64, 2>; 3] {
        let mk = |sigma: f64, lambda: f64| {
            TobitFilterConfig::new(
                vector![0.0, 0.0],
                BoundScalars::paper_example(),
                EventTriggerConfig::new_allowing_paper_violation(sigma, 5.0, lambda, 1.5).unwrap(),
                1.5,
                2.0,
            )
            .unwrap()
        };
        [mk(0.1, 0.1), mk(0.2, 0.2), mk(0.3, 0.1)]
    }

    fn oscillator() -> (SMatrix<f64, 2, 2>, SMatrix<f64, 2, 2>) {
        let w = 0.052 * core::f64::consts::PI;
        let b = vector![0.16, 0.18];
        (
            matrix![w.cos(), w.sin(); -w.sin(), w.cos()],
            b * b.transpose() * 0.05,
        )
    }

    #[test]
    fn fused_covariance_is_inverse_of_summed_information() {
        let xs = [vector![1.0, 2.0], vector![1.5, 1.0], vector![0.0, 3.0]];
        let ps = [
            matrix![2.0, 0.3; 0.3, 1.0],
            matrix![0.5, -0.1; -0.1, 0.8],
            matrix![4.0, 1.0; 1.0, 3.0],
        ];
        let (xg, pg) = federated_fuse(&xs, &ps).unwrap();
        // Direct computation with nalgebra's general LU inverse.
        let inv = |m: &SMatrix<f64, 2, 2>| m.try_inverse().unwrap();
        let y: SMatrix<f64, 2, 2> = ps.iter().map(inv).sum();
        let pg_direct = inv(&y);
        let xg_direct = pg_direct * (0..3).map(|m| inv(&ps[m]) * xs[m]).sum::<SVector<f64, 2>>();
        assert!((pg - pg_direct).amax() < 1e-14);
        assert!((xg - xg_direct).amax() < 1e-13);
    }

    #[test]
    fn step_fuses_locals_and_resets_them() {
        let (a, bqb) = oscillator();
        let c = [SMatrix::<f64, 2, 2>::identity(); 3];
        let r = [vector![0.5, 0.5]; 3];
        let mut f =
            TobitFusion::<f64, 2, 2, 3>::new(cfgs(), vector![5.0, 0.0], SMatrix::identity())
                .unwrap();
        // Initialisation (51): P̄_m = 3 P₀.
        assert!(
            (f.local(1).unwrap().estimate().covariance() - SMatrix::<f64, 2, 2>::identity() * 3.0)
                .amax()
                < 1e-15
        );
        let y = [vector![4.8, 0.2], vector![5.3, 0.0], vector![4.9, 0.4]];
        f.step(&a, &bqb, &c, &r, [Some(&y[0]), None, Some(&y[2])])
            .unwrap();
        // (50) from the pre-reset locals.
        let xs = [0, 1, 2].map(|m| *f.local_estimate(m).unwrap().state());
        let ps = [0, 1, 2].map(|m| *f.local_estimate(m).unwrap().covariance());
        let (xg, pg) = federated_fuse(&xs, &ps).unwrap();
        assert_eq!(f.estimate().state(), &xg);
        assert_eq!(f.estimate().covariance(), &pg);
        // (51): every local filter restarts from x̂^g and 3 P^g.
        for m in 0..3 {
            assert_eq!(f.local(m).unwrap().estimate().state(), &xg);
            assert!((f.local(m).unwrap().estimate().covariance() - pg * 3.0).amax() < 1e-14);
        }
        // The fused bound is tighter than every local one (information adds).
        for m in 0..3 {
            assert!(pg.trace() < ps[m].trace());
        }
        // Local filter m with Q_m = 3 Q from the same starting point reproduces node 0.
        let mut alone =
            TobitFilter::new(cfgs()[0], vector![5.0, 0.0], SMatrix::identity() * 3.0).unwrap();
        alone
            .step(&a, &(bqb * 3.0), &c[0], &r[0], Some(&y[0]))
            .unwrap();
        assert!((alone.estimate().state() - xs[0]).amax() < 1e-14);
    }

    #[test]
    fn weights_validated_and_state_unchanged_on_error() {
        let x0 = vector![5.0, 0.0];
        let p0 = SMatrix::<f64, 2, 2>::identity();
        assert!(
            TobitFusion::<f64, 2, 2, 3>::with_weights(cfgs(), x0, p0, [0.5, 0.5, 0.5]).is_err()
        );
        assert!(
            TobitFusion::<f64, 2, 2, 3>::with_weights(cfgs(), x0, p0, [1.0, 0.0, 0.0]).is_err()
        );
        assert!(
            TobitFusion::<f64, 2, 2, 3>::with_weights(cfgs(), x0, p0, [0.5, f64::NAN, 0.5])
                .is_err()
        );
        assert!(TobitFusion::<f64, 2, 2, 3>::new(cfgs(), x0, -p0).is_err());
        let ok =
            TobitFusion::<f64, 2, 2, 3>::with_weights(cfgs(), x0, p0, [0.5, 0.25, 0.25]).unwrap();
        assert!((ok.local(0).unwrap().estimate().covariance() - p0 * 2.0).amax() < 1e-15);

        let (a, bqb) = oscillator();
        let c = [SMatrix::<f64, 2, 2>::identity(); 3];
        let r = [vector![0.5, 0.5]; 3];
        let mut f = TobitFusion::<f64, 2, 2, 3>::new(cfgs(), x0, p0).unwrap();
        let y = vector![4.0, 1.0];
        f.step(&a, &bqb, &c, &r, [Some(&y); 3]).unwrap();
        let before = f;
        let bad = vector![f64::NAN, 0.0];
        assert!(f
            .step(&a, &bqb, &c, &r, [Some(&y), Some(&y), Some(&bad)])
            .is_err());
        assert_eq!(f, before);
        assert!(f
            .step(
                &a,
                &bqb,
                &c,
                &[vector![0.5, 0.5], vector![0.5, 0.0], vector![0.5, 0.5]],
                [None; 3]
            )
            .is_err());
        assert_eq!(f, before);
    }

    #[test]
    fn f32_and_f64_agree_over_the_paper_example_shape() {
        let (a, bqb) = oscillator();
        let c = [SMatrix::<f64, 2, 2>::identity(); 3];
        let r = [vector![0.5, 0.5]; 3];
        let x0 = vector![5.0, 0.0];
        let mut f = TobitFusion::<f64, 2, 2, 3>::new(cfgs(), x0, SMatrix::identity()).unwrap();
        let c32 = cfgs().map(|c| c.cast::<f32>().unwrap());
        let mut g = TobitFusion::<f32, 2, 2, 3>::new(c32, x0.cast(), SMatrix::identity()).unwrap();
        for t in 1..=100 {
            let s = t as f64;
            let truth = vector![5.0 * (0.163 * s).cos(), -5.0 * (0.163 * s).sin()];
            let y = truth.map(|v| v.max(0.0));
            let rec = [
                (t % 2 == 0).then_some(y),
                (t % 3 == 0).then_some(y),
                (t % 5 != 0).then_some(y),
            ];
            f.step(
                &a,
                &bqb,
                &c,
                &r,
                [rec[0].as_ref(), rec[1].as_ref(), rec[2].as_ref()],
            )
            .unwrap();
            let rec32 = rec.map(|o| o.map(|v| v.cast::<f32>()));
            g.step(
                &a.cast(),
                &bqb.cast(),
                &c.map(|m| m.cast()),
                &r.map(|v| v.cast()),
                [rec32[0].as_ref(), rec32[1].as_ref(), rec32[2].as_ref()],
            )
            .unwrap();
        }
        // Stated tolerance: f32 rounding (6e-8) amplified by the 100-step recursion stays
        // below 1e-3 on states of size 5.
        assert!((f.estimate().state() - g.estimate().state().cast::<f64>()).amax() < 1e-3);
        assert!(
            (f.estimate().covariance() - g.estimate().covariance().cast::<f64>()).amax()
                < 1e-3 * f.estimate().covariance().amax().max(1.0)
        );
    }
}
