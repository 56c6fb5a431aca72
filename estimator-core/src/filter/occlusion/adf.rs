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
//!
//! # A known loss rate ([`AssumedDensityFilter::with_loss_rate`])
//!
//! When the receiver cannot tell a packet lost in transport (probability `p_loss`, independent
//! of the state) from an occlusion dropout, "no packet" has the likelihood
//! `p_loss + (1 − p_loss) p_occ(x)`, and its posterior is the two-component mixture of the
//! prediction `N(x̂⁻, P⁻)` (weight `∝ p_loss`) and the occlusion-dropout posterior above
//! (weight `∝ (1 − p_loss) Z`, `Z = Σ_j Z_j = P(occluded)` under the prediction). Both are laws
//! of `u` times the same Gaussian `x | u`: the prediction is the untruncated `t ~ N(0, 1)`.
//! So the exact moments are those of the `t`-mixture, with `(μ_O, v_O)` the occlusion
//! posterior's `(μ̄, v̄)`,
//!
//! ```text
//! w_L = p_loss / (p_loss + (1 − p_loss) Z),   w_O = 1 − w_L       (log domain)
//! μ̄  = w_O μ_O,   v̄ = w_L · 1 + w_O v_O + w_L w_O μ_O²
//! ```
//!
//! in the same `x̂`, `P̂` as above (`μ̄ = 0`, `v̄ = 1` give back the prediction). `Z` is summed
//! over every region (`gauss::ln_interval_prob`, log domain). The label is 0 when
//! `p_loss > (1 − p_loss) Z_best`, the most probable region otherwise. A dropout no region
//! can explain (`Z = 0`) is then a loss instead of an error. Arrivals are unchanged: the factor
//! `1 − p_loss` of their likelihood is a constant. `p_loss = 0` (the default) is the filter
//! above, bit for bit.

use nalgebra::{SMatrix, SVector};

use super::skeleton::{OcclusionFilter, OcclusionUpdate};
use super::truncnorm::{truncated_std_normal, union_moments, Intervals};
use crate::filter::kalman::kalman_update;
use crate::gauss::{ln_interval_prob, LogSumExp};
use crate::linalg::check_finite;
use crate::model::LinearSystem;
use crate::packet::check_loss_rate;
use crate::protocol::occlusion::Occlusion;
use crate::CovarianceUpdate;
use crate::{Error, Real, Result};

/// Assumed-density filter with the exact occlusion likelihood (`n_e = 1`, `S` regions): the
/// [`OcclusionFilter`] of an [`AdfConfig`].
pub type AssumedDensityFilter<T, const NX: usize, const S: usize> =
    OcclusionFilter<T, NX, AdfConfig<T, NX, S>>;

/// The configuration of an [`AssumedDensityFilter`]: the occlusion model and its regions as
/// sorted intervals, whether an arrival truncates, the covariance form of the Kalman update
/// and the loss rate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdfConfig<T: Real, const NX: usize, const S: usize> {
    occ: Occlusion<T, NX, 1, S>,
    /// Regions as sorted intervals `(lower, upper, index)`.
    sorted: [(T, T, usize); S],
    truncate_on_arrival: bool,
    form: CovarianceUpdate,
    /// `(p_loss, ln p_loss, ln(1 − p_loss))` of [`AdfConfig::with_loss_rate`] (`p_loss = 0`:
    /// none).
    loss: (T, T, T),
}

/// The running state of an [`AssumedDensityFilter`] beside its estimate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdfState<T: Real> {
    /// The most probable region at the last dropout (`1..=S`; 0 after an arrival, and after
    /// a dropout more probably a loss).
    pub label: usize,
    /// `(m, s)` of `u`'s predicted marginal at the last dropout (`s = 0` before any): the
    /// region probabilities are computed from it when asked for.
    pub dropout_marginal: (T, T),
}

impl<T: Real, const NX: usize, const S: usize> AdfConfig<T, NX, S> {
    /// The occlusion model (its regions sorted here, once).
    pub fn new(occ: Occlusion<T, NX, 1, S>) -> Self {
        Self {
            sorted: occ.regions.sorted_intervals(),
            occ,
            truncate_on_arrival: true,
            form: CovarianceUpdate::Joseph,
            loss: (T::zero(), -T::one() / T::zero(), T::zero()),
        }
    }

    /// Whether an arrival also truncates `u` to "no region" (default `true`).
    #[must_use]
    pub fn with_arrival_truncation(mut self, on: bool) -> Self {
        self.truncate_on_arrival = on;
        self
    }

    /// Selects the covariance form of the Kalman part of the arrival update (Joseph by
    /// default).
    #[must_use]
    pub fn with_covariance_update(mut self, form: CovarianceUpdate) -> Self {
        self.form = form;
        self
    }

    /// The occlusion model.
    #[inline]
    pub fn occlusion(&self) -> &Occlusion<T, NX, 1, S> {
        &self.occ
    }

    /// Region `i` as the interval `(ζ_i − r_i, ζ_i + r_i)`.
    #[inline]
    fn region(&self, i: usize) -> (T, T) {
        let c = self.occ.regions.centre(i)[0];
        let r = self.occ.regions.radius(i);
        (c - r, c + r)
    }

    /// Moments of `N(mx, p)` conditioned on `u = E x + n` lying in one of the disjoint
    /// intervals of the event (`p` exactly symmetric): on an arrival the gaps between the
    /// regions, half-lines included, on a dropout the regions (or a loss, with a loss rate).
    /// Returns the moments, the label of the dropout (the most probable region's `1..=S`, or 0
    /// for a loss) and `(m, s)` of `u`'s marginal. `u` is
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
        let moments = union_moments(&events);
        let (mbar, vbar, label) = if !arrival && self.loss.0 > T::zero() {
            self.with_loss(&ends, moments)
        } else {
            let Some((mbar, vbar, best)) = moments else {
                return Err(Error::Numerical {
                    what: "occlusion event has zero probability under the prior",
                });
            };
            (mbar, vbar, best + 1)
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
        Ok((x, p_new, label, (m, s)))
    }

    /// The dropout's `(μ̄, v̄, label)` with a loss rate: the mixture of the untruncated
    /// `N(0, 1)` (a loss) and the occlusion posterior `occ` (`None`: `Z = 0`), `ends` the
    /// regions in standard units (module docs, "A known loss rate").
    fn with_loss(&self, ends: &[(T, T, usize); S], occ: Option<(T, T, usize)>) -> (T, T, usize) {
        let (_, ln_p, ln_1p) = self.loss;
        let Some((mu_o, v_o, best)) = occ else {
            return (T::zero(), T::one(), 0);
        };
        let mut ln_z = LogSumExp::default();
        let mut ln_z_best = -T::one() / T::zero();
        for &(lo, hi, i) in ends {
            let l = ln_interval_prob(lo, hi);
            ln_z.push(l);
            if i == best {
                ln_z_best = l;
            }
        }
        // r = ln((1 − p) Z / p): w_O = 1 / (1 + e^−r), w_L = 1 / (1 + e^r).
        let r = ln_1p + ln_z.value() - ln_p;
        let (w_o, w_l) = (
            T::one() / (T::one() + (-r).exp()),
            T::one() / (T::one() + r.exp()),
        );
        let mbar = w_o * mu_o;
        let vbar = w_l + w_o * v_o + w_l * w_o * mu_o * mu_o;
        let label = if ln_p > ln_1p + ln_z_best {
            0
        } else {
            best + 1
        };
        (mbar, vbar, label)
    }
}

impl<T: Real, const NX: usize, const S: usize> OcclusionUpdate<T, NX> for AdfConfig<T, NX, S> {
    type State = AdfState<T>;
    type Output = usize;

    fn initial_state(&self) -> AdfState<T> {
        AdfState {
            label: 0,
            dropout_marginal: (T::zero(), T::zero()),
        }
    }

    #[inline]
    fn output(state: &AdfState<T>) -> usize {
        state.label
    }

    /// The dropout update becomes the exact moments of the two-component posterior (module
    /// docs, "A known loss rate").
    fn with_loss_rate(mut self, p_loss: T) -> Result<Self> {
        let p = check_loss_rate(p_loss)?;
        self.loss = (p, p.ln(), (-p).ln_1p());
        Ok(self)
    }

    #[inline]
    fn loss_rate(&self) -> T {
        self.loss.0
    }

    /// The Kalman update (18), then (by default) the truncation of `u` to the gaps between
    /// the regions; label 0.
    #[inline(always)]
    fn arrival_update<const NY: usize, M: LinearSystem<T, NX, NY>>(
        &self,
        model: &M,
        k: usize,
        xp: &SVector<T, NX>,
        pp: &SMatrix<T, NX, NX>,
        y: &SVector<T, NY>,
        state: &AdfState<T>,
    ) -> Result<(SVector<T, NX>, SMatrix<T, NX, NX>, AdfState<T>)> {
        let (x1, p1, _) =
            kalman_update(xp, pp, &model.c(k), &model.measurement_cov(k), y, self.form)?;
        let (x, p) = if self.truncate_on_arrival {
            let (x, p, _, _) = self.truncate(&x1, &p1, true)?;
            (x, p)
        } else {
            (x1, p1)
        };
        Ok((
            x,
            p,
            AdfState {
                label: 0,
                dropout_marginal: state.dropout_marginal,
            },
        ))
    }

    /// The exact moments of the prediction truncated to the regions.
    #[inline(always)]
    fn dropout_update<const NY: usize, M: LinearSystem<T, NX, NY>>(
        &self,
        _model: &M,
        _k: usize,
        xp: &SVector<T, NX>,
        pp: &SMatrix<T, NX, NX>,
        _state: &AdfState<T>,
    ) -> Result<(SVector<T, NX>, SMatrix<T, NX, NX>, AdfState<T>)> {
        let (x, p, label, dropout_marginal) = self.truncate(xp, pp, false)?;
        Ok((
            x,
            p,
            AdfState {
                label,
                dropout_marginal,
            },
        ))
    }
}

impl<T: Real, const NX: usize, const S: usize> AssumedDensityFilter<T, NX, S> {
    /// Starts from `x̂_0 = x0`, `P_0 = p0`.
    pub fn new(
        x0: SVector<T, NX>,
        p0: SMatrix<T, NX, NX>,
        occ: Occlusion<T, NX, 1, S>,
    ) -> Result<Self> {
        Self::from_config(x0, p0, AdfConfig::new(occ))
    }

    /// Whether an arrival also truncates `u` to "no region" (default `true`). `false` gives
    /// the ablation "exact dropout update, plain Kalman arrival update".
    #[must_use]
    pub fn with_arrival_truncation(self, on: bool) -> Self {
        self.map_config(|c| c.with_arrival_truncation(on))
    }

    /// Selects the covariance form of the Kalman part of the arrival update (Joseph by
    /// default).
    #[must_use]
    pub fn with_covariance_update(self, form: CovarianceUpdate) -> Self {
        self.map_config(|c| c.with_covariance_update(form))
    }

    /// The most probable region at the last dropout (1..=S; 0 after an arrival, and after a
    /// dropout more probably a loss, see [`OcclusionFilter::with_loss_rate`]).
    #[inline]
    pub fn label(&self) -> usize {
        self.state().label
    }

    /// `ln P(u_k ∈ R_i | prediction)` per region at the last dropout (0 before any). The step
    /// evaluates only the regions that can change its result, so these are computed here,
    /// from the dropout's predicted marginal of `u`.
    pub fn region_log_probs(&self) -> [T; S] {
        let (m, s) = self.state().dropout_marginal;
        core::array::from_fn(|i| {
            if s == T::zero() {
                return T::zero();
            }
            let (lo, hi) = self.config().region(i);
            truncated_std_normal((lo - m) / s, (hi - m) / s).0
        })
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

    /// With a loss rate: the posterior moments of the prediction times the likelihood of "no
    /// packet", `p_loss + (1 − p_loss) 1{u ∈ ∪R_i}` (integrated against the noise `n`, as above),
    /// by quadrature over u on ±12 s around the prediction; and the label: region 1 while
    /// `(1 − p) Z₁ > p`, 0 (a loss) above that.
    #[test]
    fn dropout_with_a_loss_rate_matches_quadrature_over_u() {
        let (m, occ) = paper();
        let x0 = vector![21.0, 2.0, -1.0];
        let p0 = matrix![6.0, 0.5, 0.1; 0.5, 2.0, 0.2; 0.1, 0.2, 1.0];
        let xp = m.a * x0;
        let pp = m.a * p0 * m.a.transpose() + m.b * m.q * m.b.transpose();
        let s2 = pp[(0, 0)] + 0.1;
        let (sd, k) = (s2.sqrt(), pp.column(0) / s2);
        let in_region = |u: f64| {
            [20.0, 40.0, 60.0, 80.0]
                .iter()
                .any(|c| (u - c).abs() <= 5.0)
        };
        let phi = |t: f64| 0.5 * libm::erfc(-t / core::f64::consts::SQRT_2);
        let z1 = phi((25.0 - xp[0]) / sd) - phi((15.0 - xp[0]) / sd);
        for p_loss in [0.05, 0.2, 0.6] {
            let mut f = AssumedDensityFilter::new(x0, p0, occ)
                .unwrap()
                .with_loss_rate(p_loss)
                .unwrap();
            let h = f.step::<2, _>(&m, 1, None).unwrap();
            // Simpson over u on [xp − 14 s, xp + 14 s], in pieces between the region ends (the
            // likelihood jumps there), each piece's midpoint deciding inside or outside.
            let (a, b) = (xp[0] - 14.0 * sd, xp[0] + 14.0 * sd);
            let mut cuts = [a, 15.0, 25.0, 35.0, 45.0, 55.0, 65.0, 75.0, 85.0, b];
            for c in cuts.iter_mut() {
                *c = c.clamp(a, b);
            }
            let (mut z, mut m1, mut m2) = (0.0, 0.0, 0.0);
            for w in cuts.windows(2) {
                let (lo, hi) = (w[0], w[1]);
                if hi <= lo {
                    continue;
                }
                let lik = p_loss + (1.0 - p_loss) * f64::from(u8::from(in_region(0.5 * (lo + hi))));
                let n = 4000;
                let hh = (hi - lo) / n as f64;
                for j in 0..=n {
                    let u = lo + j as f64 * hh;
                    let wt = if j == 0 || j == n {
                        1.0
                    } else if j % 2 == 1 {
                        4.0
                    } else {
                        2.0
                    };
                    let d = u - xp[0];
                    let g = wt * hh * lik * (-0.5 * d * d / s2).exp();
                    z += g;
                    m1 += g * u;
                    m2 += g * u * u;
                }
            }
            let (mu, vu) = (m1 / z, m2 / z - (m1 / z).powi(2));
            let want_x = xp + k * (mu - xp[0]);
            let want_p = pp - k * k.transpose() * s2 + k * k.transpose() * vu;
            assert!(
                (f.estimate().state() - want_x).amax() < 1e-7,
                "p_loss {p_loss}: {} vs {want_x}",
                f.estimate().state()
            );
            assert!((f.estimate().covariance() - want_p).amax() < 1e-7);
            assert_eq!(h, if (1.0 - p_loss) * z1 > p_loss { 1 } else { 0 });
        }
    }

    #[test]
    fn loss_rate_is_validated_zero_is_the_default_and_a_far_dropout_a_loss() {
        let (m, occ) = paper();
        let f =
            AssumedDensityFilter::new(vector![21.0, 2.0, -1.0], SMatrix::identity(), occ).unwrap();
        for bad in [-0.5, 1.0, f64::NAN, f64::INFINITY] {
            assert!(matches!(
                f.with_loss_rate(bad),
                Err(Error::InvalidConfig {
                    field: "loss_rate",
                    ..
                })
            ));
        }
        let (mut a, mut b) = (f, f.with_loss_rate(0.0).unwrap());
        assert_eq!(a, b);
        for k in 1..=6 {
            let y = (k % 3 == 0).then_some(vector![30.0, 20.0]);
            a.step(&m, k, y.as_ref()).unwrap();
            b.step(&m, k, y.as_ref()).unwrap();
        }
        assert_eq!(a, b);
        // Far above every region (f32): without a loss rate the dropout pins u to the last
        // region's edge; with one it is a loss (label 0) and the update is the prediction
        // (w_O underflows to 0: x̂ exactly, P up to the rounding of P − PEᵀEP/s² + PEᵀEP/s²).
        let m32 = m.cast::<f32>().unwrap();
        let far = AssumedDensityFilter::<f32, 3, 4>::new(
            vector![5000.0, 0.0, 0.0],
            SMatrix::identity() * 0.01,
            Seed001Example::occlusion().unwrap(),
        )
        .unwrap();
        assert_eq!(far.clone().step::<2, _>(&m32, 1, None).unwrap(), 4);
        let mut lossy = far.with_loss_rate(0.1).unwrap();
        assert_eq!(lossy.step::<2, _>(&m32, 1, None).unwrap(), 0);
        let mut pred = far;
        pred.predict_to::<2, _>(&m32, 1).unwrap();
        assert_eq!(lossy.estimate().state(), pred.estimate().state());
        let dp = lossy.estimate().covariance() - pred.estimate().covariance();
        assert!(dp.amax() <= 1e-6 * pred.estimate().covariance().amax());
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
