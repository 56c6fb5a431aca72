//! `adf`: an assumed-density (moment-matching) filter for occlusion dropouts with scalar
//! `u_k = E x_k + n_k` (`n_e = 1`), using the **exact** interval likelihood — the product's
//! improvement on the cross-coupled estimator of seed 001.
//!
//! The CCE (seed 001, Algorithms 1-2) replaces each region's indicator by a Gaussian sum,
//! keeps only the MAP region on a dropout and ignores, on an arrival, that the packet's
//! arrival also says "`u_k` is in no region". This filter keeps the Gaussian prior
//! `N(x̂⁻, P⁻)` of eq. (11) and computes the exact first two moments of the posterior under the
//! exact likelihoods:
//!
//! * dropout: `p(y = φ | x) = Σ_i [Φ((ζ_i + r_i − E x)/√Ψ) − Φ((ζ_i − r_i − E x)/√Ψ)]` —
//!   a mixture over **all** regions;
//! * arrival: `p(z, y ≠ φ | x) = N(z; C x, DRDᵀ) · [1 − Σ_i (…)]` — the Kalman update (18)
//!   followed by truncation of `u` to the complement of the regions.
//!
//! # Derivation
//!
//! Let the Gaussian before the truncation be `N(m_x, P)` (the prediction on a dropout, the
//! Kalman posterior on an arrival; `v_k` and `n_k` are independent, so the two factors of the
//! arrival likelihood can be applied in turn). Then `u = E x + n` is jointly Gaussian with `x`:
//! `u ~ N(m, s²)`, `m = E m_x`, `s² = E P Eᵀ + Ψ`, and
//! `x | u ~ N(m_x + K (u − m), P − K s² Kᵀ)` with `K = P Eᵀ / s²`. Conditioning on the event
//! `u ∈ A` (a union of disjoint intervals `[a_j, b_j]`: the regions on a dropout, the gaps
//! between them — including the two half-lines — on an arrival) only changes the law of `u`:
//! in standard units `t = (u − m)/s` it becomes a mixture of normals truncated to
//! `(α_j, β_j) = ((a_j − m)/s, (b_j − m)/s)` with weights `Z_j = Φ(β_j) − Φ(α_j)`. With
//! `μ_j, v_j` the mean and variance of the `j`-th truncated standard normal,
//!
//! ```text
//! w_j = Z_j / Σ Z_l                    (log domain, accumulated in one pass)
//! μ̄  = Σ w_j μ_j,   v̄ = Σ w_j (v_j + (μ_j − μ̄)²)
//! x̂  = m_x + K s μ̄
//! P̂  = (P − P Eᵀ E P / s²) + v̄ · P Eᵀ E P / s²
//! ```
//!
//! which are the exact posterior mean and covariance (law of total expectation/variance);
//! both terms of `P̂` are positive semi-definite. The truncated moments are
//! `μ = (φ(α) − φ(β))/Z`, `v = 1 + (αφ(α) − βφ(β))/Z − μ²`; in the upper tail (`α > 0`) they
//! are evaluated through the inverse Mills ratio `λ` and `q = Q(β)/Q(α)`:
//! `μ = (λ(α) − q λ(β))/(1 − q)`, and `v = 1 − λ(α)(λ(α) − α)` when `q` is negligible, so an
//! interval thousands of standard deviations away still gives finite, accurate moments (the
//! lower tail by symmetry).
//!
//! The sums over `j` are evaluated by `truncnorm.rs`: the interval nearest to the
//! predicted `u` first and always, the others unless a bound proves that together they move
//! `μ̄` by less than `EPS √v̄` and `v̄` by less than `EPS v̄` (one rounding of the result; see
//! there), so a region ten or more standard deviations away costs a few comparisons instead of
//! its `erfc`, `exp` and `ln` evaluations.

use nalgebra::{SMatrix, SVector};

use super::truncnorm::{truncated_std_normal, union_moments, Intervals};
use crate::estimate::Estimate;
use crate::estimator::{Estimator, OnModel};
use crate::filter::kalman::kalman_update;
use crate::filter::time_update::predict;
use crate::linalg::check_finite;
use crate::model::LinearSystem;
use crate::packet::Packet;
use crate::protocol::occlusion::Occlusion;
use crate::CovarianceUpdate;
use crate::{Error, Real, Result};

/// Assumed-density filter with the exact occlusion likelihood (`n_e = 1`, `S` regions).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AssumedDensityFilter<T: Real, const NX: usize, const S: usize> {
    est: Estimate<T, NX>,
    occ: Occlusion<T, NX, 1, S>,
    /// Regions as sorted intervals `(lower, upper, index)`.
    sorted: [(T, T, usize); S],
    label: usize,
    /// `(m, s)` of `u`'s predicted marginal at the last dropout (`s = 0` before any): the
    /// region probabilities are computed from it when asked for.
    dropout_marginal: (T, T),
    truncate_on_arrival: bool,
    form: CovarianceUpdate,
}

impl<T: Real, const NX: usize, const S: usize> AssumedDensityFilter<T, NX, S> {
    /// Starts from `x̂_0 = x0`, `P_0 = p0`.
    pub fn new(
        x0: SVector<T, NX>,
        p0: SMatrix<T, NX, NX>,
        occ: Occlusion<T, NX, 1, S>,
    ) -> Result<Self> {
        let est = Estimate::new(x0, p0)?;
        Ok(Self {
            est,
            sorted: occ.regions.sorted_intervals(),
            occ,
            label: 0,
            dropout_marginal: (T::zero(), T::zero()),
            truncate_on_arrival: true,
            form: CovarianceUpdate::Joseph,
        })
    }

    /// Whether an arrival also truncates `u` to "no region" (default `true`). `false` gives
    /// the ablation "exact dropout update, plain Kalman arrival update".
    #[must_use]
    pub fn with_arrival_truncation(mut self, on: bool) -> Self {
        self.truncate_on_arrival = on;
        self
    }

    /// Current estimate and covariance.
    #[inline]
    pub fn estimate(&self) -> &Estimate<T, NX> {
        &self.est
    }

    /// The most probable region at the last dropout (1..=S; 0 after an arrival).
    #[inline]
    pub fn label(&self) -> usize {
        self.label
    }

    /// `ln P(u_k ∈ R_i | prediction)` per region at the last dropout (0 before any). The step
    /// evaluates only the regions that can change its result, so these are computed here,
    /// from the dropout's predicted marginal of `u`.
    pub fn region_log_probs(&self) -> [T; S] {
        let (m, s) = self.dropout_marginal;
        core::array::from_fn(|i| {
            if s == T::zero() {
                return T::zero();
            }
            let (lo, hi) = self.region(i);
            truncated_std_normal((lo - m) / s, (hi - m) / s).0
        })
    }

    /// Region `i` as the interval `(ζ_i − r_i, ζ_i + r_i)`.
    #[inline]
    fn region(&self, i: usize) -> (T, T) {
        let c = self.occ.regions.centre(i)[0];
        let r = self.occ.regions.radius(i);
        (c - r, c + r)
    }

    /// One instant `k ≥ 1`: predict, then the exact-likelihood moment-matching update for
    /// `y = Some(z_k)` (arrival) or `None` (dropout). Returns the most probable label.
    /// On error nothing changes.
    pub fn step<const NY: usize, M: LinearSystem<T, NX, NY>>(
        &mut self,
        model: &M,
        k: usize,
        y: Option<&SVector<T, NY>>,
    ) -> Result<usize> {
        if let Some(y) = y {
            check_finite(y, "measurement")?;
        }
        let (xp, pp) = predict(model, k, self.est.state(), self.est.covariance())?;
        match y {
            Some(y) => {
                let (x1, p1, _) = kalman_update(
                    &xp,
                    &pp,
                    &model.c(k),
                    &model.measurement_cov(k),
                    y,
                    self.form,
                )?;
                let (x, p) = if self.truncate_on_arrival {
                    let (x, p, _, _) = self.truncate(&x1, &p1, true)?;
                    (x, p)
                } else {
                    (x1, p1)
                };
                self.est = Estimate::trusted(x, p);
                self.label = 0;
            }
            None => {
                let (x, p, best, marginal) = self.truncate(&xp, &pp, false)?;
                self.est = Estimate::trusted(x, p);
                self.label = best + 1;
                self.dropout_marginal = marginal;
            }
        }
        Ok(self.label)
    }

    /// Instant `k ≥ 1` without information (a packet lost in transport,
    /// [`Packet::Lost`]): the prediction (11) only; the label and the region probabilities keep
    /// the values of the last update. On error nothing changes.
    pub fn predict_to<const NY: usize, M: LinearSystem<T, NX, NY>>(
        &mut self,
        model: &M,
        k: usize,
    ) -> Result<()> {
        let (x, p) = predict(model, k, self.est.state(), self.est.covariance())?;
        self.est = Estimate::trusted(x, p);
        Ok(())
    }

    /// Moments of `N(mx, p)` conditioned on `u = E x + n` lying in one of the disjoint
    /// intervals of the event (`p` exactly symmetric): on an arrival the gaps between the
    /// regions, half-lines included, on a dropout the regions. Returns the moments, the index
    /// of the most probable region (dropout) and `(m, s)` of `u`'s marginal. `u` is
    /// scalar, so the update is the rank-one correction `P − (1 − v̄) P Eᵀ E P / s²`, formed on
    /// the upper triangle as `(P − P Eᵀ E P / s²) + v̄ · P Eᵀ E P / s²` and mirrored (exactly
    /// symmetric). Out of line: one copy serves both events.
    #[allow(clippy::type_complexity)]
    #[inline(never)]
    fn truncate(
        &self,
        mx: &SVector<T, NX>,
        p: &SMatrix<T, NX, NX>,
        arrival: bool,
    ) -> Result<(SVector<T, NX>, SMatrix<T, NX, NX>, usize, (T, T))> {
        let e = &self.occ.e;
        // P Eᵀ, E P Eᵀ + Ψ and E m_x, summed in the order of the matrix products.
        let mut pet = SVector::<T, NX>::zeros();
        for i in 0..NX {
            let mut acc = p[(i, 0)] * e[0];
            for j in 1..NX {
                acc += p[(i, j)] * e[j];
            }
            pet[i] = acc;
        }
        let (mut ep, mut m) = (e[0] * pet[0], e[0] * mx[0]);
        for i in 1..NX {
            ep += e[i] * pet[i];
            m += e[i] * mx[i];
        }
        let s2 = ep + self.occ.psi[(0, 0)];
        if !s2.finite() || s2 <= T::zero() {
            return Err(Error::NotPositiveDefinite {
                what: "E P Eᵀ + Ψ"
            });
        }
        let s = s2.sqrt();
        // The sorted regions' ends in standard units, shared by the regions and the gaps.
        let mut ends = self.sorted;
        for e in ends.iter_mut() {
            e.0 = (e.0 - m) / s;
            e.1 = (e.1 - m) / s;
        }
        let events = Intervals {
            sorted: &ends,
            gaps: arrival,
        };
        let Some((mbar, vbar, best)) = union_moments(&events) else {
            return Err(Error::Numerical {
                what: "occlusion event has zero probability under the prior",
            });
        };
        // In standard units u = m + s·z: E[z] = mbar, Var[z] = vbar.
        // `nan` collects v − v of every entry: 0 if all are finite, NaN otherwise.
        #[allow(clippy::eq_op)] // v − v is the test itself
        let not_finite = |v: T| v - v;
        let g = mbar / s;
        let mut x = *mx;
        let mut nan = T::zero();
        for i in 0..NX {
            x[i] += pet[i] * g;
            nan += not_finite(x[i]);
        }
        let half = T::lit(0.5);
        let mut p_new = *p;
        for j in 0..NX {
            for i in 0..=j {
                let pe = pet[i] * pet[j] / s2;
                let a = (p[(i, j)] - pe) + pe * vbar;
                // (A + Aᵀ)/2 of an exactly symmetric A.
                let v = (a + a) * half;
                p_new[(i, j)] = v;
                p_new[(j, i)] = v;
                nan += not_finite(v);
            }
        }
        if nan != T::zero() {
            check_finite(&x, "updated state")?;
            check_finite(&p_new, "updated covariance")?;
        }
        Ok((x, p_new, best, (m, s)))
    }
}

/// Delivered: the arrival update; dropped: the exact dropout update; lost: prediction only.
impl<T: Real, const NX: usize, const S: usize, const NY: usize, M: LinearSystem<T, NX, NY>>
    Estimator<T, NX> for OnModel<M, AssumedDensityFilter<T, NX, S>, NY>
{
    type Measurement = Packet<T, NY>;

    fn step(&mut self, k: usize, y: &Packet<T, NY>) -> Result<()> {
        match y {
            Packet::Delivered(y) => self.filter.step(&self.model, k, Some(y)).map(|_label| ()),
            Packet::Dropped => self.filter.step(&self.model, k, None).map(|_label| ()),
            Packet::Lost => self.filter.predict_to(&self.model, k),
        }
    }

    #[inline]
    fn estimate(&self) -> &Estimate<T, NX> {
        self.filter.estimate()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::LinearModel;
    use crate::papers::Seed001Example;
    use nalgebra::{matrix, vector};

    fn paper() -> (LinearModel<f64, 3, 3, 2, 2>, Occlusion<f64, 3, 1, 4>) {
        (
            Seed001Example::model().unwrap(),
            Seed001Example::occlusion().unwrap(),
        )
    }

    /// Posterior moments of the prediction times the exact dropout likelihood, by quadrature
    /// over u (independent of the closed form): x | u is Gaussian, so integrate over u only.
    #[test]
    fn dropout_update_matches_quadrature_over_u() {
        let (m, occ) = paper();
        let x0 = vector![21.0, 2.0, -1.0];
        let p0 = matrix![6.0, 0.5, 0.1; 0.5, 2.0, 0.2; 0.1, 0.2, 1.0];
        let mut f = AssumedDensityFilter::new(x0, p0, occ).unwrap();
        let h = f.step::<2, _>(&m, 1, None).unwrap();
        let xp = m.a * x0;
        let pp = m.a * p0 * m.a.transpose() + m.b * m.q * m.b.transpose();
        let s2 = pp[(0, 0)] + 0.1;
        let k = pp.column(0) / s2;
        // ∫ over u in the regions of N(u; m, s²) × (1, u, u²), Simpson on each region.
        let (mut z, mut m1, mut m2) = (0.0, 0.0, 0.0);
        for c in [20.0, 40.0, 60.0, 80.0] {
            let n = 20_000;
            let hh = 10.0 / n as f64;
            for j in 0..=n {
                let u = c - 5.0 + j as f64 * hh;
                let w = if j == 0 || j == n {
                    1.0
                } else if j % 2 == 1 {
                    4.0
                } else {
                    2.0
                };
                let d = u - xp[0];
                let f = w * (-0.5 * d * d / s2).exp();
                z += f;
                m1 += f * u;
                m2 += f * u * u;
            }
        }
        let (mu, vu) = (m1 / z, m2 / z - (m1 / z).powi(2));
        let want_x = xp + k * (mu - xp[0]);
        let want_p = pp - k * k.transpose() * s2 + k * k.transpose() * vu;
        assert!((f.estimate().state() - want_x).amax() < 1e-8);
        assert!((f.estimate().covariance() - want_p).amax() < 1e-8);
        assert_eq!(h, 1);
    }

    #[test]
    fn arrival_truncation_pushes_the_estimate_out_of_the_region() {
        let (m, occ) = paper();
        // A measurement consistent with x₁ ≈ 24 (inside region 1) but the packet arrived:
        // the adf estimate must move toward the edge 25, the plain KF one must not.
        let x0 = vector![23.0 / 1.01, 0.0, 0.0];
        let p0 = SMatrix::identity() * 4.0;
        let z = m.c * vector![24.0, 0.0, 0.0];
        let mut f = AssumedDensityFilter::new(x0, p0, occ).unwrap();
        let mut g = f.with_arrival_truncation(false);
        f.step(&m, 1, Some(&z)).unwrap();
        g.step(&m, 1, Some(&z)).unwrap();
        assert!(f.estimate().state()[0] > g.estimate().state()[0]);
        assert!(f.estimate().covariance()[(0, 0)] > 0.0);
    }

    #[test]
    fn far_prediction_and_nan() {
        let (m, occ) = paper();
        let mut f =
            AssumedDensityFilter::new(vector![700.0, 0.0, 0.0], SMatrix::identity() * 0.01, occ)
                .unwrap();
        assert_eq!(f.step::<2, _>(&m, 1, None).unwrap(), 4);
        // Exact likelihood: u ends up just below 85 (mean 85 − s/|α|), and x₁ takes the share
        // K = P⁻₁₁/(P⁻₁₁ + Ψ) of that move (the rest is explained by the noise n_k).
        let pp = m.a * SMatrix::<f64, 3, 3>::identity() * 0.01 * m.a.transpose()
            + m.b * m.q * m.b.transpose();
        let xp = 707.0;
        let gain = pp[(0, 0)] / (pp[(0, 0)] + 0.1);
        let want = xp + gain * (85.0 - xp);
        assert!(
            (f.estimate().state()[0] - want).abs() < 0.01,
            "{} vs {want}",
            f.estimate().state()[0]
        );
        // u is pinned (variance ~ s²/α²), so P₁₁ → P⁻₁₁ Ψ / (P⁻₁₁ + Ψ).
        let want_p = pp[(0, 0)] * 0.1 / (pp[(0, 0)] + 0.1);
        assert!((f.estimate().covariance()[(0, 0)] - want_p).abs() < 1e-3 * want_p);
        let before = f;
        assert!(f.step(&m, 2, Some(&vector![f64::NAN, 0.0])).is_err());
        assert_eq!(f, before);
        let mut g = AssumedDensityFilter::<f32, 3, 4>::new(
            vector![30.0, 0.0, 0.0],
            SMatrix::identity(),
            Seed001Example::occlusion().unwrap(),
        )
        .unwrap();
        let m32 = m.cast::<f32>().unwrap();
        g.step::<2, _>(&m32, 1, None).unwrap();
        g.step(&m32, 2, Some(&vector![70.0f32, 30.0])).unwrap();
        assert!(g.estimate().state().iter().all(|v| v.is_finite()));
    }
}
