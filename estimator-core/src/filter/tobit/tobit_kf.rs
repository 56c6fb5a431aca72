//! The Tobit Kalman filter in the standard form a practitioner would take first (Allik,
//! Miller, Piovoso & Zurakowski, "The Tobit Kalman filter: an estimator for censored
//! measurements", IEEE TCST 2016): the baseline `tobit-kf` beside seed 004's estimators
//! (docs/tobit-fusion.md, "At the information bound").
//!
//! Centralised over the `L` nodes: one Kalman prediction per instant, then every delivered
//! packet in node order, each as one vector update whose statistics come from the predicted
//! measurement `μ = C x̂⁻` and the noise alone (ζ_j = (τ_j − μ_j)/√R_j, ϱ̄_j = Φ(−ζ_j), λ_j the
//! inverse Mills ratio, [`crate::protocol::tobit`]):
//!
//! ```text
//! ŷ = Q̄ (μ + λ∘√R) + (I − Q̄) τ,        Q̄ = diag(ϱ̄)                                     (T1)
//! P_yy = Q̄ C P⁻ Cᵀ Q̄ + R_tt,         R_tt = diag(R_j (1 − λ_j (λ_j − ζ_j)))                (T2)
//! P_xy = P⁻ Cᵀ Q̄,  K = P_xy P_yy⁻¹                                                       (T3)
//! x̂ = x̂⁻ + K (y − ŷ),  P = (I − K Q̄ C) P⁻                                               (T4)
//! ```
//!
//! `R_tt` is the variance of the noise truncated to the uncensored region, as in the paper's
//! (7). A node that delivered nothing (no trigger, no token, lost) is skipped: the baseline
//! predicts on silence, as the paper's filter does not. It reads neither the protocol nor
//! the silence.

use nalgebra::{SMatrix, SVector};

use super::config::diagonal_variances;
use crate::estimate::Estimate;
use crate::estimator::{Estimator, OnModel};
use crate::filter::gate::{GateCounts, GatedStep, InnovationGate};
use crate::filter::KalmanFilter;
use crate::linalg::{check_finite, check_spd, solve_spd_right, symmetrize};
use crate::model::LinearSystem;
use crate::packet::Packet;
use crate::protocol::tobit::TobitStats;
use crate::{Real, Result};

/// The centralised Tobit Kalman filter of `L` nodes (T1)-(T4).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TobitKf<T: Real, const NX: usize, const NY: usize, const L: usize> {
    kf: KalmanFilter<T, NX>,
    tau: [SVector<T, NY>; L],
}

/// (T1)-(T4) with one node's delivered `y`: returns `(x̂, P, ν, P_yy)`.
pub fn tobit_update<T: Real, const NX: usize, const NY: usize>(
    x: &SVector<T, NX>,
    p: &SMatrix<T, NX, NX>,
    c: &SMatrix<T, NY, NX>,
    r: &SVector<T, NY>,
    tau: &SVector<T, NY>,
    y: &SVector<T, NY>,
) -> Result<TobitUpdate<T, NX, NY>> {
    check_finite(y, "measurement")?;
    let stats = TobitStats::new(&(c * x), tau, r)?;
    let q = SMatrix::<T, NY, NY>::from_diagonal(&stats.rho);
    let r_tt = SMatrix::<T, NY, NY>::from_diagonal(&stats.paper_variance());
    let qc = q * c;
    let p_yy = symmetrize(&(qc * p * qc.transpose() + r_tt));
    let p_xy = p * qc.transpose();
    let k = solve_spd_right(&p_xy, &p_yy, "Tobit innovation covariance")?;
    let nu = y - stats.mean;
    let x = x + k * nu;
    let p = symmetrize(&(p - k * qc * p));
    check_finite(&x, "Tobit KF estimate")?;
    check_spd(&p, "Tobit KF covariance")?;
    Ok(TobitUpdate { x, p, nu, p_yy })
}

/// What (T1)-(T4) return: the posterior, the innovation `y − ŷ` and its covariance `P_yy`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TobitUpdate<T: Real, const NX: usize, const NY: usize> {
    /// x̂.
    pub x: SVector<T, NX>,
    /// P.
    pub p: SMatrix<T, NX, NX>,
    /// `y − ŷ`.
    pub nu: SVector<T, NY>,
    /// `P_yy`.
    pub p_yy: SMatrix<T, NY, NY>,
}

impl<T: Real, const NX: usize, const NY: usize, const L: usize> TobitKf<T, NX, NY, L> {
    /// The prior and every node's censoring thresholds.
    pub fn new(prior: Estimate<T, NX>, tau: [SVector<T, NY>; L]) -> Result<Self> {
        for t in &tau {
            check_finite(t, "censoring threshold")?;
        }
        let (x, p) = prior.into_parts();
        Ok(Self {
            kf: KalmanFilter::new(x, p)?,
            tau,
        })
    }

    /// x̂ and P.
    #[inline]
    pub fn estimate(&self) -> &Estimate<T, NX> {
        self.kf.estimate()
    }

    /// One instant on every node's model; `gate` tests each delivered packet's innovation
    /// against `P_yy` (a rejected one is skipped). Nothing changes on error.
    pub fn step_gated<M: LinearSystem<T, NX, NY>>(
        &mut self,
        models: &[M; L],
        k: usize,
        y: &[Packet<T, NY>; L],
        gate: &InnovationGate<T>,
    ) -> Result<GateCounts> {
        let mut kf = self.kf;
        kf.predict(&models[0], k.saturating_sub(1))?;
        let (mut x, mut p) = kf.estimate().into_parts();
        let mut counts = GateCounts::NONE;
        for m in 0..L {
            if let Some(z) = y[m].delivered() {
                let r = diagonal_variances(&models[m].measurement_cov(k))?;
                let u = tobit_update(&x, &p, &models[m].c(k), &r, &self.tau[m], z)?;
                let admitted = gate.admits(&u.nu, &u.p_yy)?;
                if !gate.is_off() {
                    counts.add(GateCounts::one(admitted));
                }
                if admitted {
                    (x, p) = (u.x, u.p);
                }
            }
        }
        kf.reset(x, p)?;
        self.kf = kf;
        Ok(counts)
    }
}

impl<T: Real, const NX: usize, const NY: usize, const L: usize, M: LinearSystem<T, NX, NY>>
    GatedStep<T, NX> for OnModel<[M; L], TobitKf<T, NX, NY, L>, NY>
{
    fn step_gated(
        &mut self,
        k: usize,
        y: &[Packet<T, NY>; L],
        gate: &InnovationGate<T>,
    ) -> Result<GateCounts> {
        self.filter.step_gated(&self.model, k, y, gate)
    }
}

impl<T: Real, const NX: usize, const NY: usize, const L: usize, M: LinearSystem<T, NX, NY>>
    Estimator<T, NX> for OnModel<[M; L], TobitKf<T, NX, NY, L>, NY>
{
    type Measurement = [Packet<T, NY>; L];

    #[inline]
    fn step(&mut self, k: usize, y: &[Packet<T, NY>; L]) -> Result<()> {
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
mod tests {
    use super::*;
    use nalgebra::{matrix, vector};

    #[test]
    fn far_above_the_threshold_it_is_the_kalman_update() {
        // τ 60 σ below every prediction: Q̄ = I, λ = 0 to rounding, R_tt = R.
        let (x, p) = (vector![1.0, 2.0], matrix![0.9, 0.3; 0.3, 0.4]);
        let c = matrix![1.0, 0.5; -0.2, 1.0];
        let r = vector![0.3, 0.6];
        let y = vector![1.7, 1.1];
        let u = tobit_update(&x, &p, &c, &r, &vector![-60.0, -60.0], &y).unwrap();
        let mut kf = KalmanFilter::new(x, p).unwrap();
        kf.update_with(&c, &SMatrix::from_diagonal(&r), &y).unwrap();
        assert!((u.x - kf.estimate().state()).amax() < 1e-13);
        assert!((u.p - kf.estimate().covariance()).amax() < 1e-13);
    }

    #[test]
    fn by_hand_in_one_dimension() {
        // x ~ N(0.2, 1), z = x + v, R = 0.5, τ = 0, y = 0.7 (observed).
        let (x, p) = (vector![0.2], matrix![1.0]);
        let u = tobit_update(
            &x,
            &p,
            &matrix![1.0],
            &vector![0.5],
            &vector![0.0],
            &vector![0.7],
        )
        .unwrap();
        let sd = 0.5f64.sqrt();
        let zeta = -0.2 / sd;
        let rho = crate::gauss::sf(zeta);
        let lam = crate::gauss::inv_mills(zeta);
        let yhat = rho * (0.2 + sd * lam);
        let r_tt = 0.5 * (1.0 - lam * (lam - zeta));
        let p_yy = rho * rho + r_tt;
        let k = rho / p_yy;
        assert!((u.x[0] - (0.2 + k * (0.7 - yhat))).abs() < 1e-14);
        assert!((u.p[(0, 0)] - (1.0 - k * rho)).abs() < 1e-14);
    }

    #[test]
    fn bad_input_changes_nothing() {
        let prior = Estimate::new(vector![0.5, 0.0], SMatrix::<f64, 2, 2>::identity()).unwrap();
        let mut f = TobitKf::<f64, 2, 2, 1>::new(prior, [vector![0.0, 0.0]]).unwrap();
        let before = f;
        let i = SMatrix::<f64, 2, 2>::identity();
        let model = crate::model::LinearModel::new(i, i, i, i, i * 0.01, i * 0.5).unwrap();
        let bad = [Packet::Delivered(vector![f64::NAN, 1.0])];
        assert!(f
            .step_gated(&[model], 1, &bad, &InnovationGate::off())
            .is_err());
        assert_eq!(f, before);
    }
}
