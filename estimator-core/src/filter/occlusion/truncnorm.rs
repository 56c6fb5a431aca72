//! The kernel of [`super::adf`]: the first two moments of a standard normal conditioned on a
//! union of disjoint intervals, `z ∈ ∪_j (α_j, β_j)`, for the `S` regions of a dropout or the
//! `S + 1` gaps of an arrival.
//!
//! [`union_moments`] gives the moments of the full mixture over *all* intervals (the equations
//! of the module documentation of [`super::adf`]), but evaluates only the intervals that can
//! change them:
//!
//! 1. the interval nearest to the mode `z = 0` is evaluated exactly;
//! 2. an interval at distance `d ≥ 5` from 0 has mass `Z_j ≤ Q(d) < φ(d)/d ≤ φ(d)/5`, its
//!    mean lies within 0.8 of its near end `t_j` (`λ(a) − a ≤ λ(0) < 0.8`) and its variance is
//!    below 1. With `W`, `μ̄`, `v̄` the total mass, mean and variance of the evaluated intervals
//!    and `ρ_j = Z_j / W`, adding interval `j` moves `μ̄` by at most `ρ_j D_j` and `v̄` by at
//!    most `ρ_j (1 + v̄ + 2 D_j²)`, `D_j = |t_j − μ̄| + 1`. [`negligible`] is a sufficient,
//!    transcendental-free test that both bounds are below `EPS √v̄ / n` and `EPS v̄ / n` (`n`
//!    intervals): with `ln(1 + 2D²) ≤ D/5 + 3.31` (and `ln D` below it),
//!    `d²/2 − D/5 ≥ ln(n (1 + v̄) / (EPS v̄ w)) − top + 3.31 − ln √(2π) − ln 5` (+¼ for the
//!    rounding of the test itself), where `W = w e^{top}` ([`Mixture`]). So the intervals
//!    skipped together move the standardised mean by less than `EPS √v̄` and the variance by
//!    less than `EPS (1 + EPS) v̄`: in the filter, the state by less than `EPS` posterior
//!    standard deviations and `P̂_ij` by less than `EPS (1 + EPS) √(P̂_ii P̂_jj)` — one rounding
//!    of the results;
//! 3. the test is decided from the nearest interval alone, which is summed first (see
//!    [`pass`]), and then re-checked against the final mixture; if the re-check fails for any
//!    skipped interval, every interval is evaluated.
//!
//! [`truncated_std_normal`] is the moment formula for one interval. It evaluates each inverse
//! Mills ratio once (`λ` and `δ = λ(λ − ζ)` together, [`mills`], and `ln Q(ζ)` from the same
//! `λ`), the density at an end once (for both `φ` and `ζφ`), and drops the terms of an end whose
//! contribution is below the rounding of the result: the far end of an upper-tail interval when
//! `Q(b)/Q(a) ≤ e^{−(b²−a²)/2}` makes it so (the half-line result, which the general formula
//! then equals to within rounding), and an end beyond `±B` of an interval that contains 0, where
//! `Φ` rounds to 0 or 1 and `φ(B)` is negligible (`B = 10` in `f64`, 7 in `f32`).

use crate::gauss::{cdf, cf_tail, ln_pdf, pdf, sf, CF_THRESHOLD};
use crate::Real;

/// `ln(1/EPS)` of `T`.
#[inline]
fn ln_inv_eps<T: Real>() -> T {
    if T::EPS.to_f64() < 1e-10 {
        T::lit(52.0 * core::f64::consts::LN_2)
    } else {
        T::lit(23.0 * core::f64::consts::LN_2)
    }
}

/// The end `B` of a two-sided interval beyond which `Φ` rounds to 0 or 1 and `|ζ| φ(ζ)` is far
/// below the rounding of the moments (`φ(10) = 7.7e−23`, `φ(7) = 9.1e−12`).
#[inline]
fn far_end<T: Real>() -> T {
    if T::EPS.to_f64() < 1e-10 {
        T::lit(10.0)
    } else {
        T::lit(7.0)
    }
}

/// `(λ(ζ), δ(ζ))`, `λ = φ/(1 − Φ)` and `δ = λ(λ − ζ)`, bit-identical to
/// [`crate::gauss::inv_mills`] and [`crate::gauss::inv_mills_delta`] (the same continued
/// fraction, `gauss`'s own), from one evaluation.
#[inline]
fn mills<T: Real>(z: T) -> (T, T) {
    if z > T::lit(CF_THRESHOLD) {
        let t = cf_tail(z);
        (z + t, (z + t) * t)
    } else {
        let l = pdf(z) / sf(z);
        (l, l * (l - z))
    }
}

/// `(ln Z, mean, variance)` of a standard normal truncated to `(a, b)` (`a`, `b` may be
/// infinite). An empty interval gives `ln Z = −∞`. The variance is clamped at 0 where rounding
/// in the general formula would make it negative (narrow intervals far in a tail).
pub(crate) fn truncated_std_normal<T: Real>(a: T, b: T) -> (T, T, T) {
    if a.partial_cmp(&b) != Some(core::cmp::Ordering::Less) {
        return (-T::one() / T::zero(), T::zero(), T::zero());
    }
    // The lower tail by symmetry.
    let flip = a + b < T::zero();
    let (l, m, v) = if flip { upper(-b, -a) } else { upper(a, b) };
    (l, if flip { -m } else { m }, v)
}

/// [`truncated_std_normal`] for `a < b`, `a + b ≥ 0`.
#[inline]
fn upper<T: Real>(a: T, b: T) -> (T, T, T) {
    let zero = T::zero();
    if a <= zero {
        // The interval contains the mode's side: Z ≥ Φ(b) − ½ is not small unless b − a is.
        // An end beyond ±B contributes Φ = 0 or 1 exactly and |ζ|φ(ζ) below the rounding.
        let big = far_end::<T>();
        let (ca, pa, xa) = if a >= -big {
            let p = pdf(a);
            (cdf(a), p, a * p)
        } else {
            (zero, zero, zero)
        };
        // (b > B whenever a < −B, since a + b ≥ 0: then Z = 1 − 0.)
        let (cb, pb, xb) = if b <= big {
            let p = pdf(b);
            (cdf(b), p, b * p)
        } else {
            (T::one(), zero, zero)
        };
        let z = cb - ca;
        let mean = (pa - pb) / z;
        let var = T::one() + (xa - xb) / z - mean * mean;
        return (z.ln(), mean, var.max(zero));
    }
    // Upper tail, 0 < a < b.
    let (la, da) = mills(a);
    let ln_sa = ln_pdf(a) - la.ln();
    // Q(b)/Q(a) ≤ e^{−(b−a)(b+a)/2}; with ln(1 + ζ²) ≤ ζ/5 + 2.62 the test below gives
    // q b² (a² + 1) e² ≤ EPS, where the general formula equals the half-line one to rounding.
    if !b.finite()
        || (a + b) * ((b - a) * T::lit(0.5) - T::lit(0.2)) >= ln_inv_eps::<T>() + T::lit(7.5)
    {
        return (ln_sa, la, (T::one() - da).max(zero));
    }
    let (lb, _) = mills(b);
    let q = ((ln_pdf(b) - lb.ln()) - ln_sa).exp();
    let one_q = T::one() - q;
    let lnz = ln_sa + (-q).ln_1p();
    let lam_a = la / one_q;
    let lam_b = lb * q / one_q;
    let mean = lam_a - lam_b;
    let var = if q * b * b * (a * a + T::one()) < T::EPS {
        T::one() - da
    } else {
        T::one() + a * lam_a - b * lam_b - mean * mean
    };
    (lnz, mean, var.max(zero))
}

/// Mean and variance of a mixture whose components arrive one at a time with log-domain
/// weights: a weighted Welford update with the largest weight so far factored out, so no
/// weight overflows and a mixture far in a tail does not underflow to 0/0.
#[derive(Clone, Copy, Debug)]
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
    #[inline]
    fn push(&mut self, l: T, mu: T, var: T) {
        if l == -T::one() / T::zero() {
            return;
        }
        if self.w == T::zero() && l.finite() {
            // The first component: what the general update gives, without its two exp.
            *self = Self {
                top: l,
                w: T::one(),
                mean: mu,
                m2: var,
            };
            return;
        }
        if l > self.top {
            let r = (self.top - l).exp();
            self.w *= r;
            self.m2 *= r;
            self.top = l;
        }
        let wj = if l == self.top {
            T::one()
        } else {
            (l - self.top).exp()
        };
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
    #[cfg(test)]
    fn ln_total(&self) -> T {
        self.top + self.w.ln()
    }

    /// `true` iff `ln Σ exp(l_j)` is finite (`w ≥ 1` once a finite weight is in).
    #[inline]
    fn total_finite(&self) -> bool {
        self.top.finite() && self.w.finite() && self.w > T::zero()
    }

    #[inline]
    fn variance(&self) -> T {
        (self.m2 / self.w).max(T::zero())
    }

    /// The right-hand side of [`negligible`] for this mixture (NaN or +∞ when nothing may be
    /// skipped: an empty mixture or a zero variance).
    #[inline]
    fn skip_threshold(&self, n: usize) -> T {
        let v = self.variance();
        (T::lit(n as f64) * (T::one() + v) / (T::EPS * v * self.w)).ln() - self.top
            + T::lit(SKIP_SLACK)
    }
}

/// The constant of the skip test: `3.31` (from `ln(1 + 2D²) ≤ D/5 + 3.31`) `− ln √(2π) − ln 5`
/// (from `Q(d) ≤ φ(d)/d`, `d ≥ 5`) `+ 0.25` for the rounding of the test itself.
const SKIP_SLACK: f64 = 3.31 - 0.918_938_533_204_672_7 - 1.609_437_912_434_100_4 + 0.25;

/// Distance from 0 to `[lo, hi]` and the end nearest to 0 (`0, 0` if it contains 0).
#[inline]
fn reach<T: Real>(lo: T, hi: T) -> (T, T) {
    if lo > T::zero() {
        (lo, lo)
    } else if hi < T::zero() {
        (-hi, hi)
    } else {
        (T::zero(), T::zero())
    }
}

/// Whether an interval at distance `d` from 0 (`d ≥ 5`) with near end `t` changes a mixture
/// of mean `mean` and skip threshold `h` ([`Mixture::skip_threshold`]) by less than the bound
/// of the module documentation. False for NaN or infinite arguments.
#[inline]
fn negligible<T: Real>(d: T, t: T, mean: T, h: T) -> bool {
    let big_d = (t - mean).abs() + T::one();
    d >= T::lit(5.0) && d * d * T::lit(0.5) - big_d * T::lit(0.2) >= h
}

/// The intervals of an event in standard units, from the `S` regions sorted by lower end,
/// `sorted[i] = (lo_i, hi_i, index in the model)`: a dropout's are the regions, an arrival's
/// the `S + 1` gaps `(hi_{j−1}, lo_j)`, with `hi_{−1} = −∞` and `lo_S = +∞`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Intervals<'a, T> {
    pub(crate) sorted: &'a [(T, T, usize)],
    pub(crate) gaps: bool,
}

impl<T: Real> Intervals<'_, T> {
    #[inline]
    fn len(&self) -> usize {
        self.sorted.len() + usize::from(self.gaps)
    }

    #[inline]
    fn get(&self, j: usize) -> (T, T) {
        if !self.gaps {
            return (self.sorted[j].0, self.sorted[j].1);
        }
        let inf = T::one() / T::zero();
        let lo = if j == 0 { -inf } else { self.sorted[j - 1].1 };
        let hi = if j == self.sorted.len() {
            inf
        } else {
            self.sorted[j].0
        };
        (lo, hi)
    }

    /// The label of interval `j`: the region's index in the model, or the gap's position.
    #[inline]
    fn key(&self, j: usize) -> usize {
        if self.gaps {
            j
        } else {
            self.sorted[j].2
        }
    }
}

/// The moments `(μ̄, v̄)` of a standard normal conditioned on `z` lying in one of the disjoint
/// intervals `iv`, and the key of the most probable interval (the smallest of equals); `None`
/// when the union has zero (or NaN) probability (the full mixture's verdict).
pub(crate) fn union_moments<T: Real>(iv: &Intervals<'_, T>) -> Option<(T, T, usize)> {
    // The interval nearest to the mode (the first of equals).
    let n = iv.len();
    let (mut near, mut d_near) = (0usize, T::one() / T::zero());
    for j in 0..n {
        let (lo, hi) = iv.get(j);
        let (d, _) = reach(lo, hi);
        if d < d_near {
            (near, d_near) = (j, d);
        }
    }
    let (lo, hi) = iv.get(near);
    let first = truncated_std_normal(lo, hi);
    let mut one = Mixture::new();
    one.push(first.0, first.1, first.2);
    let h1 = one.skip_threshold(n);
    // The skips decided from the nearest interval; if the re-check against the mixture kept
    // fails, every interval (a NaN threshold skips none).
    pass(iv, near, first, h1)
        .unwrap_or_else(|| pass(iv, near, first, T::zero() / T::zero()).flatten())
}

/// One pass of [`union_moments`]: the nearest interval `near` (moments `first`) first, then
/// the others in order, skipping those [`negligible`] for `near` alone (`h1` its
/// threshold). `None` if the skips fail the re-check against the mixture kept.
///
/// (The nearest interval goes first because it carries most of the mass, or a share
/// comparable to the largest: the one-pass sum then adds small corrections to it. Had a
/// far interval of relative weight `ρ` come first, the mean would be formed as
/// `μ_far + (μ − μ_far)(1 − ρ)` and `v̄` would lose `EPS·d²/v̄` of its digits, `d` the
/// distance between the two, where its true share is `ρ d²`.)
#[inline(never)]
fn pass<T: Real>(
    iv: &Intervals<'_, T>,
    near: usize,
    first: (T, T, T),
    h1: T,
) -> Option<Option<(T, T, usize)>> {
    let n = iv.len();
    let mut mix = Mixture::new();
    mix.push(first.0, first.1, first.2);
    let (mut best, mut best_lz) = (0usize, -T::one() / T::zero());
    let (mut skipped, mut kept) = (0usize, 1usize);
    for j in 0..n {
        let (lo, hi) = iv.get(j);
        let (d, t) = reach(lo, hi);
        let l = if j == near {
            first.0
        } else if negligible(d, t, first.1, h1) {
            skipped += 1;
            continue;
        } else {
            let (l, mu, v) = truncated_std_normal(lo, hi);
            kept += 1;
            mix.push(l, mu, v);
            l
        };
        let key = iv.key(j);
        if l > best_lz || (l == best_lz && key < best) {
            (best, best_lz) = (key, l);
        }
    }
    if skipped > 0 && kept > 1 {
        // Re-check the skipped intervals against the mixture actually kept (with `near`
        // alone kept, it is the mixture they were decided on).
        let h = mix.skip_threshold(n);
        for j in 0..n {
            let (lo, hi) = iv.get(j);
            let (d, t) = reach(lo, hi);
            if j != near && negligible(d, t, first.1, h1) && !negligible(d, t, mix.mean, h) {
                return None;
            }
        }
    }
    if !mix.total_finite() {
        // (Not reached with skips: they need a finite `h1`, so a finite nearest weight.)
        return if skipped > 0 { None } else { Some(None) };
    }
    Some(Some((mix.mean, mix.variance(), best)))
}

#[cfg(test)]
mod tests;
