//! `kf-io`: a linear MMSE filter that treats packet arrival as a Bernoulli variable whose
//! probability comes from the prior — the baseline the seed 001 paper compares against
//! (its ref. \[37\], Thapliyal et al. 2019), which it cites without equations. The construction
//! is fixed in docs/design.md ("Seed 001", KF-IO):
//!
//! ```text
//! p_k = P(u_k in no region)                    under u_k ~ N(E x̂⁻, E P⁻ Eᵀ + Ψ)
//! ỹ_k = γ_k z_k                                (0 on a dropout)
//! X   = P⁻ + x̂⁻ x̂⁻ᵀ
//! S_y = p² C P⁻ Cᵀ + p(1 − p) C X Cᵀ + p DRDᵀ
//! K   = p P⁻ Cᵀ S_y⁻¹
//! x̂   = x̂⁻ + K (ỹ − p C x̂⁻)
//! P   = P⁻ − K S_y Kᵀ
//! ```
//!
//! Computed with `S' = S_y / p = p C P⁻ Cᵀ + (1 − p) C X Cᵀ + DRDᵀ` (positive definite for
//! every `p ∈ [0, 1]`), so `K = P⁻ Cᵀ S'⁻¹` and `P = P⁻ − p K S' Kᵀ`: identical for `p > 0`
//! and well defined as `p → 0`. `p_k` is the sum of the probabilities of the gaps between
//! the (sorted, disjoint) intervals, each from `gauss::ln_interval_prob`, so it keeps its
//! digits when it is tiny. `n_e = 1` (intervals).
//!
//! With a known loss rate ([`KfIo::with_loss_rate`]: a packet is also lost in transport with
//! probability `p_loss`, independently of the state, and the receiver cannot tell a loss from
//! a dropout) the packet arrives iff it is not occluded and not lost, so the arrival
//! probability becomes
//!
//! ```text
//! p_k = P(u_k in no region) · (1 − p_loss)
//! ```
//!
//! and the equations above are unchanged otherwise (`p_loss = 0`, the default, is the filter
//! above).

use core::cmp::Ordering;

use nalgebra::{SMatrix, SVector};

use super::skeleton::{OcclusionFilter, OcclusionUpdate};
use crate::estimate::Estimate;
use crate::filter::gate::InnovationGate;
use crate::filter::time_update::predict;
use crate::gauss::{ln_interval_prob_each, ln_interval_prob_one, LogSumExp};
use crate::linalg::{all_finite, check_finite, solve_spd_right, symmetrize};
use crate::model::LinearSystem;
use crate::packet::check_loss_rate;
use crate::protocol::occlusion::Occlusion;
use crate::{Error, Real, Result};

/// Gaps of [`KfIoConfig::prob_outside`] evaluated together (as many as
/// [`ln_interval_prob_each`] takes side by side).
const GAPS: usize = crate::gauss::side_by_side::LANES / 2;

/// The KF-IO-style linear MMSE filter on `NX` states with `S` occlusion intervals: the
/// [`OcclusionFilter`] of a [`KfIoConfig`]. Its running state is the arrival probability `p_k`
/// of the last update.
pub type KfIo<T, const NX: usize, const S: usize> = OcclusionFilter<T, NX, KfIoConfig<T, NX, S>>;

/// The configuration of a [`KfIo`]: the occlusion model, its regions as sorted intervals and
/// the loss rate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KfIoConfig<T: Real, const NX: usize, const S: usize> {
    occ: Occlusion<T, NX, 1, S>,
    sorted: [(T, T, usize); S],
    /// `p_loss` of [`KfIoConfig::with_loss_rate`].
    loss_rate: T,
}

impl<T: Real, const NX: usize, const S: usize> KfIoConfig<T, NX, S> {
    /// The occlusion model (its regions sorted here, once).
    pub fn new(occ: Occlusion<T, NX, 1, S>) -> Self {
        Self {
            sorted: occ.regions.sorted_intervals(),
            occ,
            loss_rate: T::zero(),
        }
    }

    /// The occlusion model.
    #[inline]
    pub fn occlusion(&self) -> &Occlusion<T, NX, 1, S> {
        &self.occ
    }

    /// `P(u in no region)` for `u ~ N(m, s²)`: the log-sum-exp of the gaps' `ln P` in gap
    /// order, bit for bit, but without evaluating a gap whose term provably cannot change
    /// the sum. [`LogSumExp`] keeps `(top, sum)` with `sum ≥ 1` once a finite term is in; a
    /// term `x < top − 40` adds `exp(x − top) < 4.3·10⁻¹⁸`, under half an ulp of `sum`, so
    /// the state stays the same bits. A gap in standard units `(a, b)` has
    /// `ln P ≤ −a²/2` for `a > 0` and `≤ −b²/2` for `b < 0` (`Q(a) ≤ e^{−a²/2}/2`), so
    /// a gap whose bound is 40 below the running top is skipped. Gaps before the first
    /// evaluated one are skipped when it exceeds all of their bounds by `41 + S`
    /// (`≥ 40 + ln(S + 1)`: their whole sum then vanishes in its `1` the same way); when it
    /// does not, they are evaluated after all, in order, before it. The gap with the
    /// largest bound is the reference for the leading gaps.
    ///
    /// The gaps whose bound is near the anchor's are evaluated first, together
    /// ([`GapLogProbs::ahead`]: their continued fractions run side by side, so the step
    /// waits for the longest one instead of their sum), any other the sum needs when it
    /// needs it: the same bits either way.
    fn prob_outside(&self, m: T, s: T) -> T {
        let neg_inf = -T::one() / T::zero();
        let margin = T::lit(40.0);
        let lead_margin = T::lit(41.0 + S as f64);
        let mut gaps = GapLogProbs::new(&self.sorted, m, s);
        let mut anchor = (0, neg_inf);
        for j in 0..=S {
            let u = gaps.bound(j);
            if u > anchor.1 {
                anchor = (j, u);
            }
        }
        // The gaps the sum is likely to need, together: within the skip margin of the
        // anchor's bound, and some slack for how loose the bounds are.
        // (Not on a size-optimised build nor on an in-order core: there nothing runs side by
        // side, so every gap is evaluated only when the sum needs it.)
        let likely = anchor.1 - margin - T::lit(SPECULATION_SLACK);
        if !cfg!(any(small_code, in_order_core)) {
            gaps.ahead(likely);
        }
        let at_anchor = gaps.get(anchor.0);
        let mut total = LogSumExp::default();
        let mut top = neg_inf;
        let mut skipped_lead = neg_inf;
        for j in 0..=S {
            let x = if j == anchor.0 {
                at_anchor
            } else {
                let u = gaps.bound(j);
                if top.finite() {
                    if u < top - margin {
                        continue;
                    }
                } else if top == neg_inf && u < at_anchor - lead_margin {
                    if u > skipped_lead {
                        skipped_lead = u;
                    }
                    continue;
                }
                gaps.get(j)
            };
            if top == neg_inf
                && skipped_lead > neg_inf
                && x.partial_cmp(&(skipped_lead + lead_margin)) != Some(Ordering::Greater)
            {
                // The leading gaps were skipped against the anchor, but this term is not
                // far enough above them: push them as the plain sum would have.
                for i in 0..j {
                    let l = gaps.get(i);
                    total.push(l);
                    if raises(l, top) {
                        top = l;
                    }
                }
                skipped_lead = neg_inf;
            }
            total.push(x);
            if raises(x, top) {
                top = x;
            }
        }
        total.value().exp().min(T::one())
    }

    /// The prediction of instant `k`, the arrival probability `p_k` and `S' = S_y / p_k`
    /// (module docs).
    ///
    /// `S'` is formed as the module docs write it; only if that is not finite (after one
    /// accepted huge measurement, `x̂⁻x̂⁻ᵀ` in `X` overflows and `0 · ∞` turns `S'` into NaN
    /// at `p_k = 1`, so every later step used to fail) is it formed again as
    /// `C P⁻ Cᵀ + DRDᵀ + (√(1 − p) C x̂⁻)(√(1 − p) C x̂⁻)ᵀ`, the same matrix without the
    /// overflowing product: the filter recovers instead of refusing every instant.
    #[allow(clippy::type_complexity)]
    fn prior<const NY: usize, M: LinearSystem<T, NX, NY>>(
        &self,
        est: &Estimate<T, NX>,
        model: &M,
        k: usize,
    ) -> Result<(SVector<T, NX>, SMatrix<T, NX, NX>, T, SMatrix<T, NY, NY>)> {
        let (xp, pp) = predict(model, k, est.state(), est.covariance())?;
        let (p, s_prime) = self.bernoulli(model, k, &xp, &pp)?;
        Ok((xp, pp, p, s_prime))
    }

    /// `p_k` and `S'` from the prediction `(x̂⁻, P⁻)` of instant `k` ([`Self::prior`]).
    fn bernoulli<const NY: usize, M: LinearSystem<T, NX, NY>>(
        &self,
        model: &M,
        k: usize,
        xp: &SVector<T, NX>,
        pp: &SMatrix<T, NX, NX>,
    ) -> Result<(T, SMatrix<T, NY, NY>)> {
        let (xp, pp) = (*xp, *pp);
        let e = &self.occ.e;
        let s2 = (e * pp * e.transpose())[(0, 0)] + self.occ.psi[(0, 0)];
        // × (1 − p_loss): the packet must also survive the transport (exactly × 1 by default).
        let p = self.prob_outside((e * xp)[0], s2.sqrt()) * (T::one() - self.loss_rate);
        if !p.finite() {
            return Err(Error::Numerical {
                what: "arrival probability",
            });
        }
        let c = model.c(k);
        let r = model.measurement_cov(k);
        let big_x = pp + xp * xp.transpose();
        let s_prime = symmetrize(
            &(c * pp * c.transpose() * p + c * big_x * c.transpose() * (T::one() - p) + r),
        );
        if all_finite(&s_prime) {
            return Ok((p, s_prime));
        }
        let cx = c * xp * (T::one() - p).sqrt();
        let s_prime = symmetrize(&(c * pp * c.transpose() + r + cx * cx.transpose()));
        Ok((p, s_prime))
    }

    /// The linear MMSE update of the prediction with `ỹ` (`z_k` on an arrival, 0 on a
    /// dropout); returns `p_k` as the new state.
    #[inline(always)]
    #[allow(clippy::type_complexity)]
    fn update<const NY: usize, M: LinearSystem<T, NX, NY>>(
        &self,
        model: &M,
        k: usize,
        xp: &SVector<T, NX>,
        pp: &SMatrix<T, NX, NX>,
        y_tilde: &SVector<T, NY>,
    ) -> Result<(SVector<T, NX>, SMatrix<T, NX, NX>, T)> {
        let (xp, pp) = (*xp, *pp);
        let (p, s_prime) = self.bernoulli(model, k, &xp, &pp)?;
        let c = model.c(k);
        let pct = pp * c.transpose();
        let gain = solve_spd_right(&pct, &s_prime, "KF-IO innovation covariance")?;
        let x = xp + gain * (y_tilde - c * xp * p);
        let p_new = symmetrize(&(pp - gain * s_prime * gain.transpose() * p));
        check_finite(&x, "updated state")?;
        check_finite(&p_new, "updated covariance")?;
        Ok((x, p_new, p))
    }
}

/// Delivered or dropped: the linear MMSE update (`ỹ = z_k` or `0`); the state beside the
/// estimate is the arrival probability `p_k`.
impl<T: Real, const NX: usize, const S: usize> OcclusionUpdate<T, NX> for KfIoConfig<T, NX, S> {
    type State = T;
    type Output = ();

    fn initial_state(&self) -> T {
        T::one()
    }

    #[inline]
    fn output(_: &T) {}

    /// The arrival probability becomes `p_k (1 − p_loss)` (module docs).
    fn with_loss_rate(mut self, p_loss: T) -> Result<Self> {
        self.loss_rate = check_loss_rate(p_loss)?;
        Ok(self)
    }

    #[inline]
    fn loss_rate(&self) -> T {
        self.loss_rate
    }

    #[inline(always)]
    fn arrival_update<const NY: usize, M: LinearSystem<T, NX, NY>>(
        &self,
        model: &M,
        k: usize,
        xp: &SVector<T, NX>,
        pp: &SMatrix<T, NX, NX>,
        y: &SVector<T, NY>,
        _state: &T,
    ) -> Result<(SVector<T, NX>, SMatrix<T, NX, NX>, T)> {
        self.update(model, k, xp, pp, y)
    }

    #[inline(always)]
    fn dropout_update<const NY: usize, M: LinearSystem<T, NX, NY>>(
        &self,
        model: &M,
        k: usize,
        xp: &SVector<T, NX>,
        pp: &SMatrix<T, NX, NX>,
        _state: &T,
    ) -> Result<(SVector<T, NX>, SMatrix<T, NX, NX>, T)> {
        self.update(model, k, xp, pp, &SVector::<T, NY>::zeros())
    }

    /// Whether `gate` admits the delivered `y_k`: the NIS of the filter's own innovation
    /// `ỹ − p_k C x̂⁻` with `ỹ = y_k` against `S_y = p_k S'` (docs/gate.md). A delivery at
    /// `p_k = 0` (certainly occluded) is never admitted. The off gate admits without a test.
    fn admits<const NY: usize, M: LinearSystem<T, NX, NY>>(
        &self,
        est: &Estimate<T, NX>,
        _state: &T,
        model: &M,
        k: usize,
        y: &SVector<T, NY>,
        gate: &InnovationGate<T>,
    ) -> Result<bool> {
        if gate.is_off() {
            return Ok(true);
        }
        check_finite(y, "measurement")?;
        let (xp, _, p, s_prime) = self.prior(est, model, k)?;
        if p <= T::zero() {
            return Ok(false);
        }
        let nu = y - model.c(k) * xp * p;
        gate.admits(&nu, &(s_prime * p))
    }
}

impl<T: Real, const NX: usize, const S: usize> KfIo<T, NX, S> {
    /// Starts from `x̂_0 = x0`, `P_0 = p0`.
    pub fn new(
        x0: SVector<T, NX>,
        p0: SMatrix<T, NX, NX>,
        occ: Occlusion<T, NX, 1, S>,
    ) -> Result<Self> {
        Self::from_config(x0, p0, KfIoConfig::new(occ))
    }

    /// `p_k` used by the last step (with a loss rate: `P(u_k in no region) · (1 − p_loss)`).
    #[inline]
    pub fn arrival_prob(&self) -> T {
        *self.state()
    }
}

/// How far below the skip margin of the anchor's bound [`KfIoConfig::prob_outside`] still
/// evaluates a gap ahead: the bounds overstate `ln P` by about `ln(a √(2π))` for a tail gap
/// from `a`, a few units here. Only the speed depends on it.
const SPECULATION_SLACK: f64 = 8.0;

/// The `ln P` of the gaps of one [`KfIoConfig::prob_outside`] call, in standard units of
/// `u ~ N(m, s²)`: gap j (`0..=S`: below the first region, between regions, above the last)
/// is (`upper[j − 1]`, `lower[j]`), the infinite ends `(±∞ − m)/s` (NaN for a NaN m or s,
/// as every end). Each is evaluated once: ahead, with others, or when first asked for.
struct GapLogProbs<T: Real, const S: usize> {
    lower: [T; S],
    upper: [T; S],
    below: T,
    above: T,
    /// [`gap_bound`] of gap j < S at j, of the gap above the last region in `bound_last`.
    bounds: [T; S],
    bound_last: T,
    /// Gap j < S at j; the gap above the last region in `last`.
    ln_p: [Option<T>; S],
    last: Option<T>,
}

impl<T: Real, const S: usize> GapLogProbs<T, S> {
    fn new(sorted: &[(T, T, usize); S], m: T, s: T) -> Self {
        let neg_inf = -T::one() / T::zero();
        let mut lower = [T::zero(); S];
        let mut upper = [T::zero(); S];
        for ((l, u), &(lo, hi, _)) in lower.iter_mut().zip(&mut upper).zip(sorted) {
            *l = (lo - m) / s;
            *u = (hi - m) / s;
        }
        let mut g = Self {
            lower,
            upper,
            below: (neg_inf - m) / s,
            above: (-neg_inf - m) / s,
            bounds: [T::zero(); S],
            bound_last: T::zero(),
            ln_p: [None; S],
            last: None,
        };
        for j in 0..S {
            g.bounds[j] = gap_bound(g.gap(j));
        }
        g.bound_last = gap_bound(g.gap(S));
        g
    }

    /// [`gap_bound`] of gap j.
    #[inline]
    fn bound(&self, j: usize) -> T {
        self.bounds.get(j).copied().unwrap_or(self.bound_last)
    }

    /// Gap j's ends.
    #[inline]
    fn gap(&self, j: usize) -> (T, T) {
        let lo = match j.checked_sub(1) {
            Some(i) => self.upper.get(i).copied().unwrap_or(self.above),
            None => self.below,
        };
        (lo, self.lower.get(j).copied().unwrap_or(self.above))
    }

    #[inline]
    fn slot(&mut self, j: usize) -> &mut Option<T> {
        match self.ln_p.get_mut(j) {
            Some(v) => v,
            None => &mut self.last,
        }
    }

    /// Evaluates every gap whose bound is at least `likely`, [`GAPS`] at a time together
    /// (a lone one is left to [`GapLogProbs::get`]: nothing to run beside it).
    fn ahead(&mut self, likely: T) {
        if (0..=S)
            .filter(|&j| self.bound(j) >= likely)
            .nth(1)
            .is_none()
        {
            return;
        }
        let mut block = [(T::zero(), T::zero()); GAPS];
        let mut which = [0usize; GAPS];
        let mut ln_p = [T::zero(); GAPS];
        let mut n = 0;
        for j in 0..=S {
            let g = self.gap(j);
            if self.bound(j) >= likely {
                if let (Some(b), Some(w)) = (block.get_mut(n), which.get_mut(n)) {
                    (*b, *w) = (g, j);
                    n += 1;
                }
            }
            if n == GAPS || (j == S && n > 0) {
                ln_interval_prob_each(&block[..n], &mut ln_p[..n]);
                for (&j, &l) in which.iter().zip(&ln_p).take(n) {
                    *self.slot(j) = Some(l);
                }
                n = 0;
            }
        }
    }

    /// Gap j's `ln P`, evaluated now if it was not ahead.
    fn get(&mut self, j: usize) -> T {
        if let Some(l) = *self.slot(j) {
            return l;
        }
        let (a, b) = self.gap(j);
        let l = ln_interval_prob_one(a, b);
        *self.slot(j) = Some(l);
        l
    }
}

/// An upper bound of `ln P(a < Z < b)`: `−a²/2` for `a > 0`, `−b²/2` for `b < 0`, else
/// 0 (NaN for NaN ends, which compares false and so is never skipped).
#[inline]
fn gap_bound<T: Real>((a, b): (T, T)) -> T {
    let half = T::lit(0.5);
    if a > T::zero() {
        -half * a * a
    } else if b < T::zero() {
        -half * b * b
    } else if a.partial_cmp(&b).is_none() {
        a + b
    } else {
        T::zero()
    }
}

/// Whether the term `x` becomes [`LogSumExp`]'s top after `top`: a larger one, or NaN, which
/// then stays.
#[inline]
fn raises<T: Real>(x: T, top: T) -> bool {
    top.partial_cmp(&top).is_some() && (x > top || x.partial_cmp(&x).is_none())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::KalmanFilter;
    use crate::model::LinearModel;
    use crate::papers::Seed001Example;
    use nalgebra::{matrix, vector};

    /// `P(u in no region)` as the module docs define it: every gap's
    /// `gauss::ln_interval_prob`, summed in gap order in the log domain.
    fn plain_prob_outside<T: Real, const S: usize>(f: &KfIo<T, 1, S>, m: T, s: T) -> T {
        let neg_inf = -T::one() / T::zero();
        let mut ends = [(T::zero(), T::zero()); 9];
        let mut lo = neg_inf;
        for (e, &(a, b, _)) in ends.iter_mut().zip(&f.config().sorted) {
            *e = (lo, a);
            lo = b;
        }
        ends[S] = (lo, -neg_inf);
        let mut total = LogSumExp::default();
        for &(a, b) in &ends[..=S] {
            total.push(crate::gauss::ln_interval_prob((a - m) / s, (b - m) / s));
        }
        total.value().exp().min(T::one())
    }

    /// The skips, the gaps evaluated ahead and those evaluated on demand give the plain
    /// sum's bits: means inside, between, beside and far from the regions, spreads from
    /// tiny (every gap but one vanishes) to huge (every gap counts), NaN and ∞, in f64 and
    /// f32, with the regions of the example and with regions of very different widths.
    /// A one-state `KfIo` (`u = x + n`, `Ψ = 0.1`) with regions `centres ± radii`.
    fn on_regions<T: Real, const S: usize>(centres: [T; S], radii: [T; S]) -> KfIo<T, 1, S> {
        use crate::protocol::occlusion::OcclusionRegions;
        let regions = OcclusionRegions::new(centres.map(|c| vector![c]), radii).unwrap();
        let occ = Occlusion::new(matrix![T::one()], matrix![T::lit(0.1)], regions).unwrap();
        KfIo::new(vector![T::zero()], SMatrix::identity(), occ).unwrap()
    }

    #[test]
    fn arrival_probability_is_the_plain_sum_bit_for_bit() {
        let example = on_regions([20.0, 40.0, 60.0, 80.0], [5.0; 4]);
        let uneven = on_regions([-3.0, 0.5, 30.0], [0.01, 2.0, 20.0]);
        let spreads = [
            1e-3,
            0.05,
            0.3,
            1.0,
            2.5,
            7.0,
            30.0,
            1e3,
            1e6,
            f64::INFINITY,
            f64::NAN,
        ];
        let mut cases = 0;
        for i in -60..=260 {
            let m = f64::from(i) * 0.5 - 20.0;
            for &s in &spreads {
                for (got, want) in [
                    (
                        example.config().prob_outside(m, s),
                        plain_prob_outside(&example, m, s),
                    ),
                    (
                        uneven.config().prob_outside(m, s),
                        plain_prob_outside(&uneven, m, s),
                    ),
                ] {
                    assert_eq!(
                        got.to_bits(),
                        want.to_bits(),
                        "m {m}, s {s}: {got} vs {want}"
                    );
                    cases += 1;
                }
            }
        }
        for m in [f64::NAN, f64::INFINITY, -f64::INFINITY, 1e300] {
            let (got, want) = (
                example.config().prob_outside(m, 1.0),
                plain_prob_outside(&example, m, 1.0),
            );
            assert_eq!(got.to_bits(), want.to_bits(), "m {m}");
        }
        let narrow = on_regions([20.0f32, 40.0, 60.0, 80.0], [5.0; 4]);
        for i in -60..=260 {
            let m = i as f32 * 0.5 - 20.0;
            for &s in &spreads {
                let s = s as f32;
                let (got, want) = (
                    narrow.config().prob_outside(m, s),
                    plain_prob_outside(&narrow, m, s),
                );
                assert_eq!(got.to_bits(), want.to_bits(), "f32 m {m}, s {s}");
            }
        }
        assert!(cases > 7000);
    }

    fn setup() -> (LinearModel<f64, 3, 3, 2, 2>, Occlusion<f64, 3, 1, 4>) {
        (
            Seed001Example::model().unwrap(),
            Seed001Example::occlusion().unwrap(),
        )
    }

    /// docs/design.md's equations written literally (S_y, its inverse, K = p P Cᵀ S_y⁻¹), with
    /// and without a loss rate (p = P(no region)·(1 − p_loss)).
    #[test]
    fn matches_the_design_equations_literally() {
        let (m, occ) = setup();
        let x0 = vector![22.0, 1.0, 2.0];
        let p0 = matrix![3.0, 0.2, 0.0; 0.2, 1.0, 0.1; 0.0, 0.1, 2.0];
        for (y, p_loss) in [
            (Some(vector![70.0, 25.0]), 0.0),
            (None, 0.0),
            (Some(vector![70.0, 25.0]), 0.2),
            (None, 0.35),
        ] {
            let mut f = KfIo::new(x0, p0, occ)
                .unwrap()
                .with_loss_rate(p_loss)
                .unwrap();
            assert_eq!(f.loss_rate(), p_loss);
            f.step(&m, 1, y.as_ref()).unwrap();
            let xp = m.a * x0;
            let pp = m.a * p0 * m.a.transpose() + m.b * m.q * m.b.transpose();
            let s = (pp[(0, 0)] + 0.1f64).sqrt();
            // p = 1 − Σ_i [Φ(b_i) − Φ(a_i)], Φ via erfc here.
            let phi = |t: f64| 0.5 * libm::erfc(-t / core::f64::consts::SQRT_2);
            let mut inside = 0.0;
            for c in [20.0, 40.0, 60.0, 80.0] {
                inside += phi((c + 5.0 - xp[0]) / s) - phi((c - 5.0 - xp[0]) / s);
            }
            let p = (1.0 - inside) * (1.0 - p_loss);
            assert!((f.arrival_prob() - p).abs() < 1e-12);
            let c = m.c;
            let x_big = pp + xp * xp.transpose();
            let sy = c * pp * c.transpose() * (p * p)
                + c * x_big * c.transpose() * (p * (1.0 - p))
                + m.d * m.r * m.d.transpose() * p;
            let k = pp * c.transpose() * p * sy.try_inverse().unwrap();
            let yt = y.unwrap_or_else(SVector::zeros);
            let want_x = xp + k * (yt - c * xp * p);
            let want_p = pp - k * sy * k.transpose();
            assert!((f.estimate().state() - want_x).amax() < 1e-10 * want_x.amax().max(1.0));
            assert!((f.estimate().covariance() - want_p).amax() < 1e-10 * want_p.amax().max(1.0));
        }
    }

    #[test]
    fn loss_rate_is_validated_and_zero_is_the_default() {
        let (m, occ) = setup();
        let f = KfIo::new(vector![22.0, 1.0, 2.0], SMatrix::identity(), occ).unwrap();
        for bad in [-0.1, 1.0, 1.5, f64::NAN, f64::INFINITY] {
            assert_eq!(
                f.with_loss_rate(bad),
                Err(Error::InvalidConfig {
                    field: "loss_rate",
                    reason: "must be finite and in [0, 1)"
                })
            );
        }
        let (mut a, mut b) = (f, f.with_loss_rate(0.0).unwrap());
        assert_eq!(a, b);
        for k in 1..=5 {
            let y = (k % 2 == 0).then_some(vector![30.0, 20.0]);
            a.step(&m, k, y.as_ref()).unwrap();
            b.step(&m, k, y.as_ref()).unwrap();
        }
        assert_eq!(a, b);
    }

    #[test]
    fn far_from_regions_it_is_the_kalman_filter() {
        let (m, occ) = setup();
        let mut f = KfIo::new(vector![-50.0, 0.0, 0.0], SMatrix::identity(), occ).unwrap();
        let mut kf = KalmanFilter::new(vector![-50.0, 0.0, 0.0], SMatrix::identity()).unwrap();
        let y = vector![-100.0, -50.0];
        f.step(&m, 1, Some(&y)).unwrap();
        kf.step(&m, 1, &y).unwrap();
        assert_eq!(f.arrival_prob(), 1.0);
        assert!((f.estimate().state() - kf.estimate().state()).amax() < 1e-9);
        let before = f;
        assert!(f.step(&m, 2, Some(&vector![f64::NAN, 0.0])).is_err());
        assert_eq!(f, before);
    }
}
