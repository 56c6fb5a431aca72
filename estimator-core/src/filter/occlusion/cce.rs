//! The cross-coupled estimator (CCE) for state-dependent packet dropouts (seed 001,
//! Section III, Algorithms 1 and 2).
//!
//! Each instant `k` predicts with eq. (11), then
//!
//! * **arrival** (`y_k = z_k`): label `ĥ_k = 0` (eq. 17) and the Kalman update (18);
//! * **dropout** (`y_k = φ`): the region-label MAP estimate (eq. 17, argmax over regions
//!   `1..=S`) from the Gaussian-sum weights `ω_{ik}^s` of eq. (15), and the state update of
//!   Algorithm 2: the Gaussian-sum posterior (14)-(15) of the chosen region collapsed to one
//!   Gaussian by moment matching (eq. 21).
//!
//! Implementation notes (same mathematics, better numerics):
//! * `Θ_k` and `θ_{ik}^s` of (15) are computed in gain form: with `S_i = E P⁻ Eᵀ + Σ_i` and
//!   `K_i = P⁻ Eᵀ S_i⁻¹` (a Cholesky solve), `θ^s = x̂⁻ + K_i (ũ^s − E x̂⁻)` and
//!   `Θ = (I − K_i E) P⁻ (I − K_i E)ᵀ + K_i Σ_i K_iᵀ` (Joseph form). This is (15) by the matrix
//!   inversion lemma and needs no inverse of `P⁻`.
//! * The weights `ω_{ik}^s` are kept as logarithms and normalised by log-sum-exp, so a
//!   prediction thousands of standard deviations from every region still yields a proper
//!   posterior instead of `0/0`.
//! * (21) becomes `x̂ = x̂⁻ + K_i (ū − E x̂⁻)` and `P = Θ + K_i C_u K_iᵀ`, with `ū` and `C_u` the
//!   α-weighted mean and covariance of the component means `ũ^s`.
//! * `Σ_i = V_i + Ψ` with `V_i = (r_i σ̂)² I` from the [`GaussSum`] table; with equal radii (as
//!   in the paper) every region shares one `Σ_k`, as eq. (13) writes.
//!
//! # A known loss rate ([`CrossCoupledEstimator::with_loss_rate`])
//!
//! When the receiver cannot tell a packet lost in transport (probability `p_loss`, independent
//! of the state) from an occlusion dropout, the likelihood of "no packet" is
//!
//! ```text
//! P(y = φ | x) = p_occ(x) + (1 − p_occ(x)) p_loss = p_loss + (1 − p_loss) p_occ(x)
//! ```
//!
//! so the hypotheses of a dropout are "lost" (probability `p_loss`, density: the prediction
//! `N(x̂⁻, P⁻)` itself) and "not lost, in region `i`" (probability `(1 − p_loss) P(u ∈ R_i)`,
//! with `P(u ∈ R_i) ≈ (1/N) Σ_s ω_{ik}^s` by the Gaussian sum). The label scoring (17) takes
//! the argmax over both kinds, scaled by `N / (1 − p_loss)`:
//!
//! ```text
//! score(lost) = ln N + ln p_loss − ln(1 − p_loss),   score(i) = ln Σ_s ω_{ik}^s
//! ```
//!
//! If "lost" wins, `ĥ_k = 0` and the update is the prediction only (`x̂ = x̂⁻`, `P = P⁻`);
//! otherwise Algorithm 2 as above. `p_loss = 0` (the default) gives `score(lost) = −∞`: every
//! dropout is an occlusion, as in the paper.

use nalgebra::{SMatrix, SVector};

use super::skeleton::{OcclusionFilter, OcclusionUpdate};
use crate::filter::kalman::kalman_update;
use crate::gauss::LN_SQRT_2PI;
use crate::gsum::GaussSum;
use crate::linalg::small::{self as small, SmallLdl};
use crate::linalg::{check_finite, symmetrize};
use crate::model::LinearSystem;
use crate::packet::check_loss_rate;
use crate::protocol::occlusion::Occlusion;
use crate::CovarianceUpdate;
use crate::{Error, Real, Result};

/// Cross-coupled region-label / state estimator (seed 001) on `NX` states, with `S` occlusion
/// regions in an `NE`-dimensional space, each approximated by `N` Gaussians: the
/// [`OcclusionFilter`] of a [`CceConfig`].
pub type CrossCoupledEstimator<
    T,
    const NX: usize,
    const NE: usize,
    const S: usize,
    const N: usize,
> = OcclusionFilter<T, NX, CceConfig<T, NX, NE, S, N>>;

/// The configuration of a [`CrossCoupledEstimator`]: the occlusion model, the Gaussian-sum
/// table scaled onto every region, the covariance form of the arrival update and the loss
/// rate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CceConfig<T: Real, const NX: usize, const NE: usize, const S: usize, const N: usize> {
    occ: Occlusion<T, NX, NE, S>,
    /// `ũ_i^s`: component means scaled onto each region.
    means: [[SVector<T, NE>; N]; S],
    /// `Σ_i = V_i + Ψ`.
    sigma: [SMatrix<T, NE, NE>; S],
    /// `ln |R_i|`.
    ln_vol: [T; S],
    form: CovarianceUpdate,
    /// `p_loss` of [`CceConfig::with_loss_rate`].
    loss_rate: T,
    /// `ln N + ln p_loss − ln(1 − p_loss)`: the "lost" hypothesis's label score (−∞ at
    /// `p_loss = 0`).
    lost_score: T,
}

/// The running state of a [`CrossCoupledEstimator`] beside its estimate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CceState<T: Real, const S: usize> {
    /// `ĥ_k`: 0 on arrival, `1..=S` on a dropout, 0 on a dropout read as a loss.
    pub label: usize,
    /// `ln Σ_s ω_{ik}^s` of the last dropout (eq. 16 up to the common `1/N`).
    pub region_log_weights: [T; S],
}

impl<T: Real, const NX: usize, const NE: usize, const S: usize, const N: usize>
    CceConfig<T, NX, NE, S, N>
{
    /// The occlusion model with the Gaussian-sum table scaled here, once, onto every region.
    pub fn new(occ: Occlusion<T, NX, NE, S>, gsum: &GaussSum<T, NE, N>) -> Self {
        let mut means = [[SVector::<T, NE>::zeros(); N]; S];
        let mut sigma = [SMatrix::<T, NE, NE>::zeros(); S];
        let mut ln_vol = [T::zero(); S];
        for i in 0..S {
            let (c, r) = (*occ.regions.centre(i), occ.regions.radius(i));
            for s in 0..N {
                means[i][s] = c + gsum.means()[s] * r;
            }
            let sd = r * gsum.sigma();
            sigma[i] = symmetrize(&(SMatrix::<T, NE, NE>::identity() * (sd * sd) + occ.psi));
            ln_vol[i] = occ.regions.volume(i).ln();
        }
        Self {
            occ,
            means,
            sigma,
            ln_vol,
            form: CovarianceUpdate::Joseph,
            loss_rate: T::zero(),
            lost_score: -T::one() / T::zero(),
        }
    }

    /// Selects the covariance form of the arrival update (Joseph by default).
    #[must_use]
    pub fn with_covariance_update(mut self, form: CovarianceUpdate) -> Self {
        self.form = form;
        self
    }

    /// The occlusion model.
    #[inline]
    pub fn occlusion(&self) -> &Occlusion<T, NX, NE, S> {
        &self.occ
    }

    /// Algorithm 1 (dropout branch) and Algorithm 2 steps 5-6 on the prediction: the
    /// components' weights (15), the region they choose (17), the update in it (21).
    #[allow(clippy::type_complexity)]
    fn region_update(
        &self,
        xp: &SVector<T, NX>,
        pp: &SMatrix<T, NX, NX>,
    ) -> Result<(SVector<T, NX>, SMatrix<T, NX, NX>, usize, [T; S])> {
        let e = &self.occ.e;
        let pet = pp * e.transpose();
        let epe = e * pet;
        let ex = e * xp;
        let mut lnw = [[T::zero(); N]; S];
        let mut top = [T::zero(); S];
        let mut factors = [None; S];
        self.component_weights(&epe, &ex, &mut lnw, &mut top, &mut factors)?;
        let mut lw = [-T::one() / T::zero(); S];
        let mut expw = [T::zero(); N];
        let (best, best_sum) = choose_region(&lnw, &top, &mut lw, &mut expw);
        // The "lost" hypothesis (with_loss_rate) against the best region: the prediction is
        // the posterior of a loss.
        if self.lost_score > lw[best] {
            return Ok((*xp, *pp, 0, lw));
        }
        let i = best;
        // K_i = P⁻ Eᵀ S_i⁻¹, with the factor of the weights above.
        let f = factors[i].ok_or(Error::Numerical {
            what: "no factor for the chosen region",
        })?;
        let gain = f.solve_right(&pet);
        let (x, p) = self.update_in_region(i, &gain, &expw, best_sum, &ex, xp, pp);
        check_finite(&x, "updated state")?;
        check_finite(&p, "updated covariance")?;
        Ok((x, p, i + 1, lw))
    }

    /// eq. (15): `ln ω_{ik}^s` of every region's components (`lnw`), each region's largest
    /// (`top`), and the factor of `E P⁻ Eᵀ + Σ_i` per region (`factors`: its gain is formed
    /// with it). Written in place, in the caller's frame: the firmware's step stays one frame.
    #[inline(always)]
    fn component_weights(
        &self,
        epe: &SMatrix<T, NE, NE>,
        ex: &SVector<T, NE>,
        lnw: &mut [[T; N]; S],
        top: &mut [T; S],
        factors: &mut [Option<SmallLdl<T, NE>>; S],
    ) -> Result<()> {
        let half = T::lit(0.5);
        for i in 0..S {
            // ln ω_{ik}^s = ln|R_i| + ln N(ũ^s; E x̂⁻, E P⁻ Eᵀ + Σ_i)   (eq. 15)
            let f = SmallLdl::new(&(epe + self.sigma[i]), "E P Eᵀ + Σ")?;
            let c0 = self.ln_vol[i] - T::lit(NE as f64 * LN_SQRT_2PI) - half * f.ln_det();
            top[i] = -T::one() / T::zero();
            for s in 0..N {
                let d = self.means[i][s] - ex;
                lnw[i][s] = c0 - half * f.mahalanobis(&d);
                if lnw[i][s] > top[i] {
                    top[i] = lnw[i][s];
                }
            }
            if !top[i].finite() {
                return Err(Error::Numerical {
                    what: "region weight is not finite",
                });
            }
            factors[i] = Some(f);
        }
        Ok(())
    }

    /// eq. (21) in region `i` with its gain `K_i`: the α-weighted mean and covariance of the
    /// component means, `x = x̂⁻ + K_i (ū − E x̂⁻)` and
    /// `Θ = (I − K E) P⁻ (I − K E)ᵀ + K Σ_i Kᵀ` (Joseph form) plus `K C_u Kᵀ`.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn update_in_region(
        &self,
        i: usize,
        gain: &SMatrix<T, NX, NE>,
        expw: &[T; N],
        best_sum: T,
        ex: &SVector<T, NE>,
        xp: &SVector<T, NX>,
        pp: &SMatrix<T, NX, NX>,
    ) -> (SVector<T, NX>, SMatrix<T, NX, NX>) {
        // α-weighted mean and covariance of the component means (eq. 21).
        let mut ubar = SVector::<T, NE>::zeros();
        let mut alpha = [T::zero(); N];
        for s in 0..N {
            alpha[s] = expw[s] / best_sum;
            ubar += self.means[i][s] * alpha[s];
        }
        let mut cu = SMatrix::<T, NE, NE>::zeros();
        for s in 0..N {
            let du = self.means[i][s] - ubar;
            cu += du * du.transpose() * alpha[s];
        }
        let x = xp + small::mul_vec(gain, &(ubar - ex));
        // Θ = (I − K E) P⁻ (I − K E)ᵀ + K Σ_i Kᵀ (Joseph form), plus K C_u Kᵀ of (21).
        let i_ke = SMatrix::<T, NX, NX>::identity() - small::mul(gain, &self.occ.e);
        let k_sig_cu = small::congruence(gain, &(self.sigma[i] + cu));
        let p = small::congruence_add(&i_ke, pp, &k_sig_cu);
        (x, p)
    }
}

/// eq. (17): ĥ = argmax over regions 1..=S of ln Σ_s ω^s (first on ties), log-sum-exp with the
/// largest term factored out. A region whose largest term plus ln N is below the best score so
/// far cannot win and is not summed (its score is left at −∞). Returns the chosen region and
/// its sum of `exp(ln ω^s − top)`; writes those terms to `expw` and every region's score to
/// `lw` (which start at 0 and −∞).
#[inline(always)]
fn choose_region<T: Real, const S: usize, const N: usize>(
    lnw: &[[T; N]; S],
    top: &[T; S],
    lw: &mut [T; S],
    expw: &mut [T; N],
) -> (usize, T) {
    let ln_n = T::lit(libm::log(N as f64));
    let mut first = 0usize;
    for i in 1..S {
        if top[i] > top[first] {
            first = i;
        }
    }
    let mut best = first;
    let mut best_sum = T::zero();
    for i in core::iter::once(first).chain((0..S).filter(|&i| i != first)) {
        if i != first && top[i] + ln_n < lw[best] {
            continue;
        }
        let mut sum = T::zero();
        let mut e_i = [T::zero(); N];
        for s in 0..N {
            e_i[s] = (lnw[i][s] - top[i]).exp();
            sum += e_i[s];
        }
        lw[i] = top[i] + sum.ln();
        if i == first || lw[i] > lw[best] || (lw[i] == lw[best] && i < best) {
            best = i;
            best_sum = sum;
            *expw = e_i;
        }
    }
    (best, best_sum)
}

impl<T: Real, const NX: usize, const NE: usize, const S: usize, const N: usize>
    OcclusionUpdate<T, NX> for CceConfig<T, NX, NE, S, N>
{
    type State = CceState<T, S>;
    type Output = usize;

    fn initial_state(&self) -> CceState<T, S> {
        CceState {
            label: 0,
            region_log_weights: [T::zero(); S],
        }
    }

    #[inline]
    fn output(state: &CceState<T, S>) -> usize {
        state.label
    }

    /// The label scoring gains the hypothesis "lost" beside the regions (module docs, "A
    /// known loss rate").
    fn with_loss_rate(mut self, p_loss: T) -> Result<Self> {
        let p = check_loss_rate(p_loss)?;
        self.loss_rate = p;
        self.lost_score = if p > T::zero() {
            T::lit(libm::log(N as f64)) + p.ln() - (-p).ln_1p()
        } else {
            -T::one() / T::zero()
        };
        Ok(self)
    }

    #[inline]
    fn loss_rate(&self) -> T {
        self.loss_rate
    }

    /// The Kalman update (18), label 0; the region weights keep their values.
    #[inline(always)]
    fn arrival_update<const NY: usize, M: LinearSystem<T, NX, NY>>(
        &self,
        model: &M,
        k: usize,
        xp: &SVector<T, NX>,
        pp: &SMatrix<T, NX, NX>,
        y: &SVector<T, NY>,
        state: &CceState<T, S>,
    ) -> Result<(SVector<T, NX>, SMatrix<T, NX, NX>, CceState<T, S>)> {
        let (x, p, _) =
            kalman_update(xp, pp, &model.c(k), &model.measurement_cov(k), y, self.form)?;
        Ok((
            x,
            p,
            CceState {
                label: 0,
                region_log_weights: state.region_log_weights,
            },
        ))
    }

    /// Algorithm 1 (dropout branch) and Algorithm 2.
    #[inline(always)]
    fn dropout_update<const NY: usize, M: LinearSystem<T, NX, NY>>(
        &self,
        _model: &M,
        _k: usize,
        xp: &SVector<T, NX>,
        pp: &SMatrix<T, NX, NX>,
        _state: &CceState<T, S>,
    ) -> Result<(SVector<T, NX>, SMatrix<T, NX, NX>, CceState<T, S>)> {
        let (x, p, label, region_log_weights) = self.region_update(xp, pp)?;
        Ok((
            x,
            p,
            CceState {
                label,
                region_log_weights,
            },
        ))
    }
}

impl<T: Real, const NX: usize, const NE: usize, const S: usize, const N: usize>
    CrossCoupledEstimator<T, NX, NE, S, N>
{
    /// Starts from `x̂_0 = x0`, `P_0 = p0` with the occlusion model and the Gaussian-sum table
    /// (scaled here, once, onto every region).
    pub fn new(
        x0: SVector<T, NX>,
        p0: SMatrix<T, NX, NX>,
        occ: Occlusion<T, NX, NE, S>,
        gsum: &GaussSum<T, NE, N>,
    ) -> Result<Self> {
        Self::from_config(x0, p0, CceConfig::new(occ, gsum))
    }

    /// Selects the covariance form of the arrival update (Joseph by default).
    #[must_use]
    pub fn with_covariance_update(self, form: CovarianceUpdate) -> Self {
        self.map_config(|c| c.with_covariance_update(form))
    }

    /// Last region-label estimate `ĥ_k` (0 on arrival, `1..=S` on a dropout; 0 on a dropout
    /// read as a loss, see [`OcclusionFilter::with_loss_rate`]).
    #[inline]
    pub fn label(&self) -> usize {
        self.state().label
    }

    /// `ln Σ_s ω_{ik}^s` for every region at the last dropout: the label's log-score
    /// (eq. 16 times `N`). Regions whose score provably lies below the winner's are not
    /// summed and read −∞.
    #[inline]
    pub fn region_log_weights(&self) -> &[T; S] {
        &self.state().region_log_weights
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::LinearModel;
    use crate::papers::Seed001Example;
    use crate::protocol::occlusion::OcclusionRegions;
    use nalgebra::{matrix, vector};

    type Cce = CrossCoupledEstimator<f64, 3, 1, 4, 15>;

    fn paper_model() -> LinearModel<f64, 3, 3, 2, 2> {
        Seed001Example::model().unwrap()
    }

    fn paper_occlusion() -> Occlusion<f64, 3, 1, 4> {
        Seed001Example::occlusion().unwrap()
    }

    fn cce(x0: SVector<f64, 3>, p0: SMatrix<f64, 3, 3>) -> Cce {
        Cce::new(x0, p0, paper_occlusion(), &GaussSum::uniform().unwrap()).unwrap()
    }

    /// Seed 001 eqs. (11), (15), (17), (21) written out literally, with explicit inverses,
    /// as the paper prints them (no log domain, no gain form).
    fn literal(
        x: SVector<f64, 3>,
        p: SMatrix<f64, 3, 3>,
        m: &LinearModel<f64, 3, 3, 2, 2>,
        occ: &Occlusion<f64, 3, 1, 4>,
        g: &GaussSum<f64, 1, 15>,
    ) -> (SVector<f64, 3>, SMatrix<f64, 3, 3>, usize) {
        let xp = m.a * x;
        let pp = m.a * p * m.a.transpose() + m.b * m.q * m.b.transpose();
        let e = occ.e;
        let r = 5.0;
        let v = (r * g.sigma()).powi(2);
        let sig = matrix![v] + occ.psi;
        let pp_inv = pp.try_inverse().unwrap();
        let sig_inv = sig.try_inverse().unwrap();
        let theta_cov = (pp_inv + e.transpose() * sig_inv * e)
            .try_inverse()
            .unwrap();
        let mut best = (0usize, -1.0f64);
        let mut all = [[(0.0f64, SVector::<f64, 3>::zeros()); 15]; 4];
        for i in 0..4 {
            let zeta = 20.0 * (i + 1) as f64;
            let mut sum = 0.0;
            for s in 0..15 {
                let u = zeta - r + 2.0 * r * s as f64 / 14.0;
                let cov = (e * pp * e.transpose() + sig)[(0, 0)];
                let d = u - (e * xp)[0];
                let w = 2.0 * r * (-0.5 * d * d / cov).exp()
                    / (2.0 * core::f64::consts::PI * cov).sqrt();
                let th = theta_cov * (pp_inv * xp + e.transpose() * sig_inv * vector![u]);
                all[i][s] = (w, th);
                sum += w;
            }
            if sum > best.1 {
                best = (i, sum);
            }
        }
        let (i, tot) = best;
        let mut xh = SVector::<f64, 3>::zeros();
        for s in 0..15 {
            xh += all[i][s].1 * (all[i][s].0 / tot);
        }
        let mut ph = SMatrix::<f64, 3, 3>::zeros();
        for s in 0..15 {
            let d = xh - all[i][s].1;
            ph += (theta_cov + d * d.transpose()) * (all[i][s].0 / tot);
        }
        (xh, ph, i + 1)
    }

    #[test]
    fn dropout_step_matches_literal_equations() {
        let m = paper_model();
        let occ = paper_occlusion();
        let g = GaussSum::<f64, 1, 15>::uniform().unwrap();
        let p0 = matrix![1.2, 0.3, -0.1; 0.3, 0.9, 0.2; -0.1, 0.2, 0.7];
        // Predictions near region 1 edge, inside region 2, between 3 and 4.
        for x0 in [
            vector![14.5, 2.0, 1.0],
            vector![38.0, 3.0, -2.0],
            vector![68.5, 1.0, 0.5],
        ] {
            let mut f = cce(x0, p0);
            let label = f.step::<2, _>(&m, 1, None).unwrap();
            let (xl, pl, hl) = literal(x0, p0, &m, &occ, &g);
            assert_eq!(label, hl);
            for j in 0..3 {
                assert!((f.estimate().state()[j] - xl[j]).abs() <= 1e-12 * xl[j].abs().max(1.0));
                for l in 0..3 {
                    assert!(
                        (f.estimate().covariance()[(j, l)] - pl[(j, l)]).abs() <= 1e-12,
                        "P[{j},{l}] {} vs {}",
                        f.estimate().covariance()[(j, l)],
                        pl[(j, l)]
                    );
                }
            }
        }
    }

    /// With a loss rate, the literal equations' region score `Σ_s ω^s` (eq. 15, 16 × N) meets
    /// the "lost" hypothesis's `N p_loss / (1 − p_loss)`: just below the best region's score the
    /// region's update is unchanged (bit for bit), just above it the dropout is read as a loss
    /// (prediction only, label 0).
    #[test]
    fn loss_rate_adds_the_lost_hypothesis_to_the_label_scoring() {
        let m = paper_model();
        let occ = paper_occlusion();
        let g = GaussSum::<f64, 1, 15>::uniform().unwrap();
        let p0 = matrix![1.2, 0.3, -0.1; 0.3, 0.9, 0.2; -0.1, 0.2, 0.7];
        for x0 in [vector![14.5, 2.0, 1.0], vector![38.0, 3.0, -2.0]] {
            // The best region's Σ_s ω^s of the literal equations.
            let xp = m.a * x0;
            let pp = m.a * p0 * m.a.transpose() + m.b * m.q * m.b.transpose();
            let (_, _, h) = literal(x0, p0, &m, &occ, &g);
            let cov = pp[(0, 0)] + (5.0 * g.sigma()).powi(2) + 0.1;
            let zeta = 20.0 * h as f64;
            let best: f64 = (0..15)
                .map(|s| {
                    let d = zeta - 5.0 + 10.0 * s as f64 / 14.0 - xp[0];
                    10.0 * (-0.5 * d * d / cov).exp() / (2.0 * core::f64::consts::PI * cov).sqrt()
                })
                .sum();
            // N p / (1 − p) = best · t  ⇔  p = best · t / (N + best · t).
            let rate = |t: f64| best * t / (15.0 + best * t);
            let mut plain = cce(x0, p0);
            assert_eq!(plain.step::<2, _>(&m, 1, None).unwrap(), h);
            let mut below = cce(x0, p0).with_loss_rate(rate(0.99)).unwrap();
            assert_eq!(below.step::<2, _>(&m, 1, None).unwrap(), h);
            assert_eq!(below.estimate(), plain.estimate());
            let mut above = cce(x0, p0).with_loss_rate(rate(1.01)).unwrap();
            assert_eq!(above.step::<2, _>(&m, 1, None).unwrap(), 0);
            assert!((above.estimate().state() - xp).amax() < 1e-12 * xp.amax());
            assert!((above.estimate().covariance() - pp).amax() < 1e-12 * pp.amax());
        }
        // Validated; 0 is the default (the same estimator, the same steps).
        let f = cce(vector![5.0, 5.0, 5.0], SMatrix::identity());
        for bad in [-1e-9, 1.0, f64::NAN, f64::NEG_INFINITY] {
            assert!(matches!(
                f.with_loss_rate(bad),
                Err(Error::InvalidConfig {
                    field: "loss_rate",
                    ..
                })
            ));
        }
        assert_eq!(f.with_loss_rate(0.0).unwrap(), f);
        assert_eq!(f.with_loss_rate(0.2).unwrap().loss_rate(), 0.2);
    }

    #[test]
    fn arrival_step_is_the_kalman_update_and_label_zero() {
        let m = paper_model();
        let mut f = cce(vector![5.0, 5.0, 5.0], SMatrix::identity() * 4.0);
        let mut kf =
            crate::filter::KalmanFilter::new(vector![5.0, 5.0, 5.0], SMatrix::identity() * 4.0)
                .unwrap();
        let y = vector![30.0, 10.0];
        assert_eq!(f.step(&m, 1, Some(&y)).unwrap(), 0);
        kf.step(&m, 1, &y).unwrap();
        assert_eq!(f.estimate().state(), kf.estimate().state());
        assert_eq!(f.estimate().covariance(), kf.estimate().covariance());
    }

    #[test]
    fn label_is_correct_deep_inside_a_region() {
        let m = paper_model();
        for (centre, want) in [(20.0, 1), (40.0, 2), (60.0, 3), (80.0, 4)] {
            // Prediction A x0 has first component ≈ centre; small covariance.
            let x0 = vector![(centre - 0.1 * 0.5) / 1.01, 0.5, 0.0];
            let mut f = cce(x0, SMatrix::identity() * 0.05);
            assert_eq!(f.step::<2, _>(&m, 1, None).unwrap(), want);
            assert!((f.estimate().state()[0] - centre).abs() < 1.0);
        }
    }

    #[test]
    fn log_domain_weights_survive_a_prediction_far_from_every_region() {
        // P⁻₁₁ ≈ 0.31 + ..., so 1000 σ ≈ 600 away from the nearest region (80 + 5).
        let m = paper_model();
        for far in [-600.0, 700.0] {
            let mut f = cce(vector![far, 0.0, 0.0], SMatrix::identity() * 0.01);
            let sd = (f.config().occlusion().e
                * (m.a * f.estimate().covariance() * m.a.transpose()
                    + m.b * m.q * m.b.transpose())
                * f.config().occlusion().e.transpose())[(0, 0)]
                .sqrt();
            let dist = if far < 0.0 {
                15.0 - far * 1.01
            } else {
                far * 1.01 - 85.0
            };
            assert!(dist / sd > 1000.0);
            let h = f.step::<2, _>(&m, 1, None).unwrap();
            // The nearest region wins and the estimate moves onto it.
            assert_eq!(h, if far < 0.0 { 1 } else { 4 });
            assert!(f.estimate().state().iter().all(|v| v.is_finite()));
            assert!(f.estimate().covariance().iter().all(|v| v.is_finite()));
            // All the weight sits on the nearest component mean (the region's edge), and the
            // state moves toward it by the scalar gain P⁻₁₁ / (P⁻₁₁ + V + Ψ) — the paper's
            // Gaussian-sum region is "soft", so it does not jump all the way.
            let edge = if far < 0.0 { 15.0 } else { 85.0 };
            let pp = m.a * SMatrix::<f64, 3, 3>::identity() * 0.01 * m.a.transpose()
                + m.b * m.q * m.b.transpose();
            let xp = far * 1.01;
            let gain = pp[(0, 0)]
                / (pp[(0, 0)]
                    + (5.0 * GaussSum::<f64, 1, 15>::uniform().unwrap().sigma()).powi(2)
                    + 0.1);
            let want = xp + gain * (edge - xp);
            assert!(
                (f.estimate().state()[0] - want).abs() < 1e-9 * want.abs(),
                "{} vs {want}",
                f.estimate().state()[0]
            );
            // The naive linear-domain weights are all exactly zero here.
            assert!(f.region_log_weights().iter().all(|w| w.exp() == 0.0));
        }
    }

    #[test]
    fn nan_input_is_an_error_and_state_unchanged() {
        let m = paper_model();
        let mut f = cce(vector![5.0, 5.0, 5.0], SMatrix::identity() * 4.0);
        f.step::<2, _>(&m, 1, None).unwrap();
        let before = f;
        assert_eq!(
            f.step(&m, 2, Some(&vector![f64::NAN, 1.0])),
            Err(Error::NonFinite {
                what: "measurement"
            })
        );
        assert_eq!(f, before);
        /// A time-varying model that goes bad: A has a NaN.
        struct Bad(LinearModel<f64, 3, 3, 2, 2>);
        impl LinearSystem<f64, 3, 2> for Bad {
            fn a(&self, _k: usize) -> SMatrix<f64, 3, 3> {
                matrix![f64::NAN, 0.0, 0.0; 0.0, 1.0, 0.0; 0.0, 0.0, 1.0]
            }
            fn c(&self, k: usize) -> SMatrix<f64, 2, 3> {
                self.0.c(k)
            }
            fn process_cov(&self, k: usize) -> SMatrix<f64, 3, 3> {
                self.0.process_cov(k)
            }
            fn measurement_cov(&self, k: usize) -> SMatrix<f64, 2, 2> {
                self.0.measurement_cov(k)
            }
        }
        assert!(f.step(&Bad(m), 2, None).is_err());
        assert_eq!(f, before);
        assert!(f.step(&Bad(m), 2, Some(&vector![1.0, 1.0])).is_err());
        assert_eq!(f, before);
        assert!(Cce::new(
            vector![f64::NAN, 0.0, 0.0],
            SMatrix::identity(),
            paper_occlusion(),
            &GaussSum::uniform().unwrap()
        )
        .is_err());
    }

    #[test]
    fn f32_runs_and_tracks_f64() {
        let m = paper_model();
        let m32 = m.cast::<f32>().unwrap();
        let occ = paper_occlusion();
        let occ32 = Occlusion::<f32, 3, 1, 4>::new(
            occ.e.map(|v| v as f32),
            occ.psi.map(|v| v as f32),
            OcclusionRegions::new(
                [vector![20.0], vector![40.0], vector![60.0], vector![80.0]],
                [5.0; 4],
            )
            .unwrap(),
        )
        .unwrap();
        let mut a = cce(vector![18.0, 1.0, 0.5], SMatrix::identity());
        let mut b = CrossCoupledEstimator::<f32, 3, 1, 4, 15>::new(
            vector![18.0, 1.0, 0.5],
            SMatrix::identity(),
            occ32,
            &GaussSum::uniform().unwrap(),
        )
        .unwrap();
        for k in 1..=5 {
            let y = vector![40.0 + k as f64, 20.0];
            let y32 = y.map(|v| v as f32);
            let (ya, yb) = if k % 2 == 0 {
                (Some(&y), Some(&y32))
            } else {
                (None, None)
            };
            assert_eq!(a.step(&m, k, ya).unwrap(), b.step(&m32, k, yb).unwrap());
        }
        for j in 0..3 {
            assert!(
                (a.estimate().state()[j] - b.estimate().state()[j] as f64).abs()
                    < 1e-3 * a.estimate().state()[j].abs().max(1.0)
            );
        }
    }
}
