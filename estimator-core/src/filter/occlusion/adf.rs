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
//! w_j = Z_j / Σ Z_l                    (log domain, accumulated in one pass: `Mixture`)
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

use nalgebra::{SMatrix, SVector};

use crate::estimate::Estimate;
use crate::estimator::{Estimator, OnModel};
use crate::filter::kalman::kalman_update;
use crate::filter::time_update::predict;
use crate::gauss::{cdf, inv_mills, inv_mills_delta, ln_sf, pdf, sf};
use crate::linalg::{check_finite, symmetrize};
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
    region_log_probs: [T; S],
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
            region_log_probs: [T::zero(); S],
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

    /// `ln P(u_k ∈ R_i | prediction)` per region at the last dropout.
    #[inline]
    pub fn region_log_probs(&self) -> &[T; S] {
        &self.region_log_probs
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
        let inf = T::one() / T::zero();
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
                    // The gaps between the sorted regions, half-lines included.
                    let gap = |j: usize| {
                        let lo = if j == 0 { -inf } else { self.sorted[j - 1].1 };
                        let hi = if j == S { inf } else { self.sorted[j].0 };
                        (lo, hi)
                    };
                    let (x, p, _) = self.truncate(&x1, &p1, S + 1, gap, |_, _| {})?;
                    (x, p)
                } else {
                    (x1, p1)
                };
                self.est = Estimate::trusted(x, p);
                self.label = 0;
            }
            None => {
                let region = |i: usize| {
                    let c = self.occ.regions.centre(i)[0];
                    let r = self.occ.regions.radius(i);
                    (c - r, c + r)
                };
                let mut lp = [-inf; S];
                let (x, p, best) = self.truncate(&xp, &pp, S, region, |i, l| lp[i] = l)?;
                self.est = Estimate::trusted(x, p);
                self.label = best + 1;
                self.region_log_probs = lp;
            }
        }
        Ok(self.label)
    }

    /// Instant `k ≥ 1` without information (a packet lost in transport,
    /// [`Packet::Lost`]): the prediction (11) only; the label and the region probabilities keep the values of the last update. On error nothing changes.
    pub fn predict_to<const NY: usize, M: LinearSystem<T, NX, NY>>(
        &mut self,
        model: &M,
        k: usize,
    ) -> Result<()> {
        let (x, p) = predict(model, k, self.est.state(), self.est.covariance())?;
        self.est = Estimate::trusted(x, p);
        Ok(())
    }

    /// Moments of `N(mx, p)` conditioned on `u = E x + n` lying in one of the `n` disjoint
    /// intervals `interval(0..n)`. Returns the moments and the index of the most probable
    /// interval, and reports `ln Z_j` of every interval to `ln_z`. One pass, no per-interval
    /// storage: the stack stays small whatever the number of regions.
    fn truncate(
        &self,
        mx: &SVector<T, NX>,
        p: &SMatrix<T, NX, NX>,
        n: usize,
        interval: impl Fn(usize) -> (T, T),
        mut ln_z: impl FnMut(usize, T),
    ) -> Result<(SVector<T, NX>, SMatrix<T, NX, NX>, usize)> {
        let e = &self.occ.e;
        let pet = p * e.transpose();
        let s2 = (e * pet)[(0, 0)] + self.occ.psi[(0, 0)];
        if !s2.finite() || s2 <= T::zero() {
            return Err(Error::NotPositiveDefinite {
                what: "E P Eᵀ + Ψ"
            });
        }
        let s = s2.sqrt();
        let m = (e * mx)[0];
        let mut mix = Mixture::new();
        let (mut best, mut best_lz) = (0usize, -T::one() / T::zero());
        for j in 0..n {
            let (lo, hi) = interval(j);
            let (l, mj, vj) = truncated_std_normal((lo - m) / s, (hi - m) / s);
            ln_z(j, l);
            mix.push(l, mj, vj);
            if l > best_lz {
                (best, best_lz) = (j, l);
            }
        }
        if !mix.ln_total().finite() {
            return Err(Error::Numerical {
                what: "occlusion event has zero probability under the prior",
            });
        }
        // In standard units u = m + s·z: E[z] = mbar, Var[z] = vbar.
        let (mbar, vbar) = (mix.mean, mix.variance());
        let x = mx + pet * (mbar / s);
        let pe_ep = pet * pet.transpose() / s2;
        let p_new = symmetrize(&((p - pe_ep) + pe_ep * vbar));
        check_finite(&x, "updated state")?;
        check_finite(&p_new, "updated covariance")?;
        Ok((x, p_new, best))
    }
}

/// Mean and variance of a mixture whose components arrive one at a time with log-domain
/// weights: a weighted Welford update with the largest weight so far factored out, so no
/// weight overflows and a mixture far in a tail does not underflow to 0/0.
struct Mixture<T: Real> {
    /// Largest log-weight so far.
    top: T,
    /// Σ exp(l_j − top).
    w: T,
    mean: T,
    /// Σ w_j (var_j + (mu_j − mean)²), scaled like `w`.
    m2: T,
}

impl<T: Real> Mixture<T> {
    fn new() -> Self {
        Self {
            top: -T::one() / T::zero(),
            w: T::zero(),
            mean: T::zero(),
            m2: T::zero(),
        }
    }

    /// Adds a component with weight `exp(l)`, mean `mu` and variance `var`. Zero weights are
    /// skipped; a NaN weight poisons the total (reported by the caller).
    fn push(&mut self, l: T, mu: T, var: T) {
        if l == -T::one() / T::zero() {
            return;
        }
        if l > self.top {
            let r = (self.top - l).exp();
            self.w *= r;
            self.m2 *= r;
            self.top = l;
        }
        let wj = (l - self.top).exp();
        if wj == T::zero() {
            return;
        }
        let w_new = self.w + wj;
        let d = mu - self.mean;
        let mean_new = self.mean + d * (wj / w_new);
        self.m2 += wj * var + wj * d * (mu - mean_new);
        self.mean = mean_new;
        self.w = w_new;
    }

    /// `ln Σ exp(l_j)`.
    fn ln_total(&self) -> T {
        self.top + self.w.ln()
    }

    fn variance(&self) -> T {
        (self.m2 / self.w).max(T::zero())
    }
}

/// `x φ(x)`, 0 at ±∞.
#[inline]
fn x_pdf<T: Real>(x: T) -> T {
    if x.finite() {
        x * pdf(x)
    } else {
        T::zero()
    }
}

/// `(ln Z, mean, variance)` of a standard normal truncated to `(a, b)` (`a`, `b` may be
/// infinite). An empty interval gives `ln Z = −∞`. The variance is clamped at 0 where rounding
/// in the general formula would make it negative (narrow intervals far in a tail).
pub(crate) fn truncated_std_normal<T: Real>(a: T, b: T) -> (T, T, T) {
    let neg_inf = -T::one() / T::zero();
    if a.partial_cmp(&b) != Some(core::cmp::Ordering::Less) {
        return (neg_inf, T::zero(), T::zero());
    }
    if a + b < T::zero() {
        let (l, m, v) = truncated_std_normal(-b, -a);
        return (l, -m, v);
    }
    if a <= T::zero() {
        // The interval contains the mode's side: Z ≥ Φ(b) − ½ is not small unless b − a is.
        let z = if a.finite() {
            cdf(b) - cdf(a)
        } else {
            T::one() - sf(b)
        };
        let (pa, pb) = (
            if a.finite() { pdf(a) } else { T::zero() },
            if b.finite() { pdf(b) } else { T::zero() },
        );
        let mean = (pa - pb) / z;
        let var = T::one() + (x_pdf(a) - x_pdf(b)) / z - mean * mean;
        return (z.ln(), mean, var.max(T::zero()));
    }
    // Upper tail, 0 < a < b.
    let la = inv_mills(a);
    let ln_sa = ln_sf(a);
    if !b.finite() {
        return (ln_sa, la, (T::one() - inv_mills_delta(a)).max(T::zero()));
    }
    let q = (ln_sf(b) - ln_sa).exp();
    let one_q = T::one() - q;
    let lnz = ln_sa + (-q).ln_1p();
    let lb = inv_mills(b);
    let lam_a = la / one_q;
    let lam_b = lb * q / one_q;
    let mean = lam_a - lam_b;
    let var = if q * b * b * (a * a + T::one()) < T::EPS {
        T::one() - inv_mills_delta(a)
    } else {
        T::one() + a * lam_a - b * lam_b - mean * mean
    };
    (lnz, mean, var.max(T::zero()))
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

    /// Moments of a truncated standard normal by brute-force Simpson quadrature.
    fn quad_moments(a: f64, b: f64) -> (f64, f64, f64) {
        let n = 200_000;
        let h = (b - a) / n as f64;
        let (mut z, mut m1, mut m2) = (0.0, 0.0, 0.0);
        for j in 0..=n {
            let t = a + j as f64 * h;
            let w = if j == 0 || j == n {
                1.0
            } else if j % 2 == 1 {
                4.0
            } else {
                2.0
            };
            let f = w * (-0.5 * t * t).exp() / (2.0 * core::f64::consts::PI).sqrt();
            z += f;
            m1 += f * t;
            m2 += f * t * t;
        }
        let mean = m1 / z;
        ((z * h / 3.0).ln(), mean, m2 / z - mean * mean)
    }

    #[test]
    fn streaming_mixture_matches_two_pass_moments() {
        // Log-weights near −1000 (exp underflows to 0 without the shift), an empty interval
        // and one negligible far component.
        let comps = [
            (-1000.0f64, 2.0, 0.5),
            (-1001.5, -3.0, 0.1),
            (-999.2, 0.7, 1.3),
            (f64::NEG_INFINITY, 5.0, 9.0),
            (-1040.0, 100.0, 0.0),
        ];
        let mut mix = Mixture::new();
        for &(l, mu, v) in &comps {
            mix.push(l, mu, v);
        }
        let top = -999.2f64;
        let w = comps.map(|c| (c.0 - top).exp());
        let wt: f64 = w.iter().sum();
        let mean: f64 = comps.iter().zip(&w).map(|(c, w)| w * c.1).sum::<f64>() / wt;
        let var: f64 = comps
            .iter()
            .zip(&w)
            .map(|(c, w)| w * (c.2 + (c.1 - mean) * (c.1 - mean)))
            .sum::<f64>()
            / wt;
        assert!((mix.ln_total() - (top + wt.ln())).abs() < 1e-12);
        assert!((mix.mean - mean).abs() < 1e-12, "{} vs {mean}", mix.mean);
        assert!(
            (mix.variance() - var).abs() < 1e-12,
            "{} vs {var}",
            mix.variance()
        );
        let mut empty = Mixture::<f64>::new();
        empty.push(f64::NEG_INFINITY, 1.0, 1.0);
        assert!(!empty.ln_total().finite());
    }

    #[test]
    fn truncated_moments_match_quadrature() {
        for (a, b) in [
            (-1.0, 2.0),
            (-12.0, 12.0),
            (0.5, 1.0),
            (3.0, 9.0),
            (-9.0, -3.0),
            (-0.01, 0.02),
            (6.0, 6.5),
        ] {
            let (l, m, v) = truncated_std_normal(a, b);
            let (lq, mq, vq) = quad_moments(a, b);
            assert!((l - lq).abs() < 1e-9, "lnZ ({a},{b}) {l} {lq}");
            assert!((m - mq).abs() < 1e-8, "mean ({a},{b}) {m} {mq}");
            assert!(
                (v - vq).abs() < 1e-8 * vq.max(1e-3),
                "var ({a},{b}) {v} {vq}"
            );
        }
        // Far tail, where Φ(b) − Φ(a) is 0 − 0: moments tend to a + 1/a, 1/a².
        let (l, m, v) = truncated_std_normal(1000.0f64, 1020.0);
        assert!(l.is_finite() && (l - ln_sf(1000.0)).abs() < 1e-9);
        assert!((m - 1000.0 - 1e-3).abs() < 1e-8);
        assert!((v * 1e6 - 1.0).abs() < 1e-4);
        let (_, m, _) = truncated_std_normal(-1020.0f64, -1000.0);
        assert!((m + 1000.0 + 1e-3).abs() < 1e-8);
        let (l, m, v) = truncated_std_normal(f64::NEG_INFINITY, f64::INFINITY);
        assert_eq!((l, m, v), (0.0, 0.0, 1.0));
        assert_eq!(truncated_std_normal(1.0f64, 1.0).0, f64::NEG_INFINITY);
    }

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
