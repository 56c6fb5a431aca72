//! The standard normal distribution, accurate in both tails.
//!
//! * [`pdf`], [`ln_pdf`], [`cdf`], [`sf`] (survival `1 − Φ`) — `Φ` goes through `libm::erfc`,
//!   which is accurate *relatively* deep into the tail, so `sf(8)` has all its digits where
//!   `1 − cdf(8)` has none.
//! * [`inv_mills`] λ(ζ) = φ(ζ)/(1 − Φ(ζ)) and [`inv_mills_delta`] φ(ζ) = λ(ζ)(λ(ζ) − ζ), the
//!   two functions of the Tobit model (seed 004, eq. 7). For ζ > 4 they come from the
//!   continued fraction `λ(ζ) = ζ + 1/(ζ + 2/(ζ + 3/(ζ + …)))`, whose tail *is* λ − ζ, so the
//!   cancellation in `λ − ζ` never happens.
//! * [`ln_interval_prob`] `ln P(a < Z < b)` without underflow, and [`log_sum_exp`] for mixture
//!   weights kept in the log domain.
//! * [`ln_sf_each`] and [`ln_interval_prob_each`]: many of them at once, bit for bit the
//!   single ones, with their continued fractions side by side ([`side_by_side`]).
//!
//! (Here φ in λ's definition is the normal density, as in the paper; the paper reuses the
//! letter for the variance factor, which this crate names `inv_mills_delta`.)

use crate::Real;

pub mod side_by_side;
pub use side_by_side::{ln_interval_prob_each, ln_interval_prob_one, ln_sf_each};

/// `1/√(2π)`.
pub const FRAC_1_SQRT_2PI: f64 = 0.398_942_280_401_432_677_94;
/// `ln √(2π)`.
pub const LN_SQRT_2PI: f64 = 0.918_938_533_204_672_741_78;

/// Above this ζ, λ is evaluated by its continued fraction instead of `pdf/sf`.
pub(crate) const CF_THRESHOLD: f64 = 4.0;
/// Terms of the backward continued-fraction evaluation at `z`, for the precision of `T`. The
/// fraction converges faster the larger ζ is. In `f64` these counts reach one ulp with a
/// margin of 1.5× (measured against a 40-digit reference: 40 terms at ζ = 4, 32 at 5, 24 at
/// 6, 16 from 8 on, for the tail `t = λ − ζ` itself to half an ulp, which
/// [`inv_mills_delta`] needs). In `f32` far fewer do (half an `f32` ulp of `t` by 12 terms
/// at ζ = 4, 9 at 5, 8 at 6, 6 at 8; the counts below are 1.5× those): the
/// single-precision filters, the firmware's, do not pay for digits they cannot hold (the
/// test `f32_tail_terms_reach_the_f64_reference` holds them to it).
#[inline]
fn cf_terms<T: Real>(z: T) -> usize {
    let z = z.to_f64();
    let single = T::EPS.to_f64() > 1e-10;
    match (single, z) {
        (false, z) if z < 5.0 => 64,
        (false, z) if z < 6.0 => 48,
        (false, z) if z < 8.0 => 36,
        (false, _) => 24,
        (true, z) if z < 5.0 => 18,
        (true, z) if z < 6.0 => 14,
        (true, z) if z < 8.0 => 12,
        (true, _) => 9,
    }
}

/// Standard normal density φ(x).
#[inline]
#[must_use]
pub fn pdf<T: Real>(x: T) -> T {
    T::lit(FRAC_1_SQRT_2PI) * (-(x * x) * T::lit(0.5)).exp()
}

/// `ln φ(x)`, exact for any finite x (no underflow).
#[inline]
#[must_use]
pub fn ln_pdf<T: Real>(x: T) -> T {
    -(x * x) * T::lit(0.5) - T::lit(LN_SQRT_2PI)
}

/// Standard normal cdf Φ(x) = erfc(−x/√2)/2.
#[inline]
#[must_use]
pub fn cdf<T: Real>(x: T) -> T {
    T::lit(0.5) * (-x * T::lit(core::f64::consts::FRAC_1_SQRT_2)).erfc()
}

/// Survival function 1 − Φ(x) = erfc(x/√2)/2, relatively accurate for large x.
#[inline]
#[must_use]
pub fn sf<T: Real>(x: T) -> T {
    T::lit(0.5) * (x * T::lit(core::f64::consts::FRAC_1_SQRT_2)).erfc()
}

/// `t(ζ) = λ(ζ) − ζ = 1/(ζ + 2/(ζ + 3/(ζ + …)))`, for ζ ≥ [`CF_THRESHOLD`].
#[inline]
pub(crate) fn cf_tail<T: Real>(z: T) -> T {
    let mut t = T::zero();
    let mut n = cf_terms(z);
    while n >= 2 {
        t = T::lit(n as f64) / (z + t);
        n -= 1;
    }
    T::one() / (z + t)
}

/// Inverse Mills ratio λ(ζ) = φ(ζ)/(1 − Φ(ζ)) (seed 004, eq. 7), accurate to ~1e-13
/// relative in f64 on the whole real line (it underflows to 0 only where φ(ζ) does, ζ < −38).
#[must_use]
pub fn inv_mills<T: Real>(z: T) -> T {
    if z > T::lit(CF_THRESHOLD) {
        z + cf_tail(z)
    } else {
        pdf(z) / sf(z)
    }
}

/// [`inv_mills`] where `sf_z` = [`sf`]`(z)` is already known (the Tobit statistics need both):
/// the same bits, without evaluating `erfc` a second time.
#[inline]
#[must_use]
pub fn inv_mills_given_sf<T: Real>(z: T, sf_z: T) -> T {
    if z > T::lit(CF_THRESHOLD) {
        z + cf_tail(z)
    } else {
        pdf(z) / sf_z
    }
}

/// φ(ζ) = λ(ζ)(λ(ζ) − ζ) (seed 004, eq. 7): the factor by which truncation below ζ shrinks a
/// unit variance, `Var(Z | Z > ζ) = 1 − φ(ζ)`. Always in (0, 1) mathematically.
#[must_use]
pub fn inv_mills_delta<T: Real>(z: T) -> T {
    if z > T::lit(CF_THRESHOLD) {
        let t = cf_tail(z);
        (z + t) * t
    } else {
        let l = pdf(z) / sf(z);
        l * (l - z)
    }
}

/// `ln(1 − Φ(x))` without underflow: through λ in the upper tail.
#[must_use]
pub fn ln_sf<T: Real>(x: T) -> T {
    if x > T::zero() {
        ln_pdf(x) - inv_mills(x).ln()
    } else {
        sf(x).ln()
    }
}

/// [`ln_sf`] at two points, bit for bit. Each continued fraction of the upper tail is a
/// chain of dependent divisions whose latency, not its instruction count, is the cost; two
/// interleaved overlap.
#[must_use]
pub fn ln_sf_pair<T: Real>(a: T, b: T) -> (T, T) {
    let cf = T::lit(CF_THRESHOLD);
    if a > cf && b > cf {
        let (ta, tb) = cf_tail_pair(a, b);
        (ln_pdf(a) - (a + ta).ln(), ln_pdf(b) - (b + tb).ln())
    } else {
        (ln_sf(a), ln_sf(b))
    }
}

/// [`cf_tail`] of `a` and of `b`, each with its own number of terms, the two recurrences
/// side by side: the same operations per point as two calls.
#[inline]
fn cf_tail_pair<T: Real>(a: T, b: T) -> (T, T) {
    let (na, nb) = (cf_terms(a), cf_terms(b));
    let (mut ta, mut tb) = (T::zero(), T::zero());
    let mut n = na.max(nb);
    // The point with more terms goes first, alone, until the other's terms begin.
    while n > na.min(nb) {
        let c = T::lit(n as f64);
        if n <= na {
            ta = c / (a + ta);
        } else {
            tb = c / (b + tb);
        }
        n -= 1;
    }
    while n >= 2 {
        let c = T::lit(n as f64);
        ta = c / (a + ta);
        tb = c / (b + tb);
        n -= 1;
    }
    (T::one() / (a + ta), T::one() / (b + tb))
}

/// `ln Φ(x)` without underflow.
#[inline]
#[must_use]
pub fn ln_cdf<T: Real>(x: T) -> T {
    ln_sf(-x)
}

/// `ln P(a < Z < b)` for a standard normal Z and `a < b` (−∞ if `a ≥ b`), accurate when both
/// ends are far in the same tail (where `Φ(b) − Φ(a)` would be `0 − 0`).
#[must_use]
pub fn ln_interval_prob<T: Real>(a: T, b: T) -> T {
    if a >= b {
        return -T::one() / T::zero();
    }
    if a > T::zero() {
        let (la, lb) = ln_sf_pair(a, b);
        la + (-(lb - la).exp()).ln_1p()
    } else if b < T::zero() {
        ln_interval_prob(-b, -a)
    } else {
        (T::one() - sf(b) - sf(-a)).ln()
    }
}

/// [`log_sum_exp`] of terms that arrive one at a time, without storing them: the largest term
/// so far is factored out and the running sum rescaled when a larger one arrives.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LogSumExp<T: Real> {
    top: T,
    sum: T,
}

impl<T: Real> Default for LogSumExp<T> {
    fn default() -> Self {
        Self {
            top: -T::one() / T::zero(),
            sum: T::zero(),
        }
    }
}

impl<T: Real> LogSumExp<T> {
    /// Adds the term `exp(x)`; −∞ adds nothing, NaN poisons the result.
    pub fn push(&mut self, x: T) {
        if x.partial_cmp(&x).is_none() {
            self.top = x;
            return;
        }
        if x == -T::one() / T::zero() || self.top.partial_cmp(&self.top).is_none() {
            return;
        }
        if x > self.top && x.finite() {
            // `sum · e^{top − x} + e^0` with `e^0 = 1` exactly, and nothing to rescale
            // before the first finite term: the same bits without one or two `exp`s.
            if self.sum != T::zero() {
                self.sum *= (self.top - x).exp();
            }
            self.top = x;
            self.sum += T::one();
            return;
        }
        if x > self.top {
            self.sum *= (self.top - x).exp();
            self.top = x;
        }
        self.sum += (x - self.top).exp();
    }

    /// `ln Σ exp(xᵢ)` so far (−∞ before any finite term).
    #[must_use]
    pub fn value(&self) -> T {
        if self.sum == T::zero() {
            return if self.top.partial_cmp(&self.top).is_none() {
                self.top
            } else {
                -T::one() / T::zero()
            };
        }
        // ln 1 = 0 exactly: one term, or every other one too small to count.
        if self.sum == T::one() {
            return self.top + T::zero();
        }
        self.top + self.sum.ln()
    }
}

/// `ln Σ exp(xᵢ)`, shifted by the maximum so that no term overflows and at least one is 1.
/// Returns −∞ for an empty slice or when every term is −∞; NaN propagates.
#[must_use]
pub fn log_sum_exp<T: Real>(xs: &[T]) -> T {
    let neg_inf = -T::one() / T::zero();
    let mut m = neg_inf;
    for &x in xs {
        if x.partial_cmp(&x).is_none() {
            return x;
        }
        if x > m {
            m = x;
        }
    }
    if m == neg_inf {
        return neg_inf;
    }
    let mut s = T::zero();
    for &x in xs {
        s += (x - m).exp();
    }
    m + s.ln()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The `f32` continued fraction with its own term counts ([`cf_terms`]) against the `f64`
    /// one: `t = λ − ζ` and λ within 2 `f32` ulps of the `f64` values (rounded to `f32`) on
    /// a fine grid over every count's range, which is what the `f32` recurrence reaches
    /// with as many terms as `f64` takes (its own rounding, not the truncation, is what is
    /// left: `f32_tail_error_is_rounding_not_truncation` below). Too few terms would miss
    /// by hundreds of ulps at ζ = 4.
    #[test]
    fn f32_tail_terms_reach_the_f64_reference() {
        let ulps = |a: f32, b: f32| (a.to_bits() as i64 - b.to_bits() as i64).abs();
        let mut worst = (0, 0.0f32);
        let mut z = 4.0001f32;
        while z < 40.0 {
            let t32 = cf_tail(z);
            let t64 = cf_tail(f64::from(z)) as f32;
            let l32 = inv_mills(z);
            let l64 = inv_mills(f64::from(z)) as f32;
            let d = ulps(t32, t64).max(ulps(l32, l64));
            if d > worst.0 {
                worst = (d, z);
            }
            z += 0.003;
        }
        assert!(worst.0 <= 2, "{} ulps at ζ = {}", worst.0, worst.1);
    }

    /// The truncation error the `f32` counts leave is far below the rounding error: the
    /// tail with 64 terms in every range (the `f64` counts, in `f32` arithmetic) and with
    /// the `f32` counts differ by at most one ulp anywhere on the grid.
    #[test]
    fn f32_tail_error_is_rounding_not_truncation() {
        let long = |z: f32| {
            let mut t = 0.0f32;
            let mut n = 64;
            while n >= 2 {
                t = n as f32 / (z + t);
                n -= 1;
            }
            1.0 / (z + t)
        };
        let mut z = 4.0001f32;
        while z < 40.0 {
            let (a, b) = (cf_tail(z), long(z));
            assert!(
                (a.to_bits() as i64 - b.to_bits() as i64).abs() <= 1,
                "ζ = {z}: {a} against {b}"
            );
            z += 0.003;
        }
    }

    /// The pair is the two single evaluations bit for bit, on both sides of the continued
    /// fraction's threshold and of its term counts, at ∞, in f64 and f32.
    #[test]
    fn ln_sf_pair_is_two_ln_sf_bit_for_bit() {
        let pts = [
            0.0,
            0.3,
            2.0,
            3.999,
            4.0,
            4.0001,
            4.7,
            5.0,
            5.5,
            6.0,
            7.9,
            8.0,
            12.0,
            38.0,
            1e3,
            f64::INFINITY,
            -1.0,
            f64::NAN,
        ];
        for &a in &pts {
            for &b in &pts {
                let (la, lb) = ln_sf_pair(a, b);
                assert_eq!(la.to_bits(), ln_sf(a).to_bits(), "({a}, {b})");
                assert_eq!(lb.to_bits(), ln_sf(b).to_bits(), "({a}, {b})");
                let (fa, fb) = ln_sf_pair(a as f32, b as f32);
                assert_eq!(fa.to_bits(), ln_sf(a as f32).to_bits(), "f32 ({a}, {b})");
                assert_eq!(fb.to_bits(), ln_sf(b as f32).to_bits(), "f32 ({a}, {b})");
            }
        }
    }

    /// The push and value shortcuts (`e^0 = 1`, `ln 1 = 0`, nothing to rescale before the
    /// first term) give the textbook recursion's bits, in f64 and f32, for sequences with
    /// ties, ±∞, NaN and terms far apart.
    #[test]
    fn log_sum_exp_shortcuts_are_bit_identical() {
        fn textbook<T: Real>(xs: &[T]) -> T {
            let (mut top, mut sum) = (-T::one() / T::zero(), T::zero());
            for &x in xs {
                if x.partial_cmp(&x).is_none() {
                    top = x;
                    continue;
                }
                if x == -T::one() / T::zero() || top.partial_cmp(&top).is_none() {
                    continue;
                }
                if x > top {
                    sum *= (top - x).exp();
                    top = x;
                }
                sum += (x - top).exp();
            }
            if sum == T::zero() {
                return if top.partial_cmp(&top).is_none() {
                    top
                } else {
                    -T::one() / T::zero()
                };
            }
            top + sum.ln()
        }
        let pool = [
            -0.5,
            -3.0,
            -3.0,
            -41.0,
            -800.0,
            0.0,
            -0.0,
            -1e-300,
            -12.25,
            -2.0,
            -39.9,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NAN,
            -7.0e3,
            -1.5,
        ];
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        let mut checked = 0;
        for len in 0..=7 {
            for _ in 0..400 {
                let xs: heapless::Vec<f64, 8> = (0..len)
                    .map(|_| {
                        state ^= state << 13;
                        state ^= state >> 7;
                        state ^= state << 17;
                        pool[(state % pool.len() as u64) as usize]
                    })
                    .collect();
                let mut a = LogSumExp::default();
                let mut b = LogSumExp::<f32>::default();
                for &x in &xs {
                    a.push(x);
                    b.push(x as f32);
                }
                let xs32: heapless::Vec<f32, 8> = xs.iter().map(|&x| x as f32).collect();
                assert_eq!(a.value().to_bits(), textbook(&xs).to_bits(), "{xs:?}");
                assert_eq!(b.value().to_bits(), textbook(&xs32).to_bits(), "{xs:?} f32");
                checked += 1;
            }
        }
        assert!(checked > 2000);
    }

    /// Mills ratio R(z) = (1 − Φ(z))/φ(z) = ∫₀^∞ exp(−z s − s²/2) ds for z ≥ 0, by composite
    /// Simpson with Kahan summation: independent of erfc and of the continued fraction.
    fn mills_quadrature(z: f64) -> f64 {
        let l = -z + (z * z + 2.0 * 60.0).sqrt();
        let n = 40_000usize;
        let h = l / n as f64;
        let f = |s: f64| (-z * s - 0.5 * s * s).exp();
        let (mut sum, mut c) = (0.0f64, 0.0f64);
        for i in 0..=n {
            let w = if i == 0 || i == n {
                1.0
            } else if i % 2 == 1 {
                4.0
            } else {
                2.0
            };
            let y = w * f(i as f64 * h) - c;
            let t = sum + y;
            c = (t - sum) - y;
            sum = t;
        }
        sum * h / 3.0
    }

    /// λ(z) and λ(z)(λ(z) − z) from the quadrature reference.
    fn reference(z: f64) -> (f64, f64) {
        if z >= 0.0 {
            let r = mills_quadrature(z);
            let lam = 1.0 / r;
            // λ − z = (1 − zR)/R; 1 − zR = ∫ s·exp(−zs − s²/2) ds / 1 … computed directly:
            // integrate by parts: 1 − zR = ∫₀^∞ s exp(−zs − s²/2) ds.
            let l = -z + (z * z + 2.0 * 60.0).sqrt();
            let n = 40_000usize;
            let h = l / n as f64;
            let mut acc = 0.0;
            for i in 0..=n {
                let w = if i == 0 || i == n {
                    1.0
                } else if i % 2 == 1 {
                    4.0
                } else {
                    2.0
                };
                let s = i as f64 * h;
                acc += w * s * (-z * s - 0.5 * s * s).exp();
            }
            let one_minus_zr = acc * h / 3.0;
            (lam, lam * one_minus_zr / r)
        } else {
            // 1 − Φ(z) = 1 − Q(|z|), Q(|z|) = φ(|z|) R(|z|).
            let a = -z;
            let phi = (-0.5 * z * z).exp() * FRAC_1_SQRT_2PI;
            let q = phi * mills_quadrature(a);
            let lam = phi / (1.0 - q);
            (lam, lam * (lam - z))
        }
    }

    #[test]
    fn inverse_mills_matches_quadrature_from_minus_40_to_40() {
        let mut worst = (0.0f64, 0.0f64);
        let mut z = -40.0;
        while z <= 40.0 + 1e-9 {
            let (lam_ref, del_ref) = reference(z);
            let lam = inv_mills(z);
            let del = inv_mills_delta(z);
            for (got, want) in [(lam, lam_ref), (del, del_ref)] {
                if want.abs() > 1e-290 {
                    let rel = ((got - want) / want).abs();
                    if rel > worst.0 {
                        worst = (rel, z);
                    }
                    assert!(
                        rel < 1e-12,
                        "z = {z}: got {got:e}, want {want:e}, rel {rel:e}"
                    );
                } else {
                    assert!(got.abs() < 1e-280, "z = {z}: got {got:e}, want ~0");
                }
            }
            z += 0.25;
        }
        // Keep the measured accuracy visible when the test is run with --nocapture.
        std::println!("worst relative error {:e} at z = {}", worst.0, worst.1);
    }

    #[test]
    fn naive_quotient_fails_where_ours_does_not() {
        // The textbook φ/(1 − Φ) with 1 − Φ formed by subtraction: no digits left at ζ = 9.
        let z = 9.0f64;
        let naive = pdf(z) / (1.0 - cdf(z));
        let (want, _) = reference(z);
        assert!(!naive.is_finite() || ((naive - want) / want).abs() > 1e-3);
        assert!(((inv_mills(z) - want) / want).abs() < 1e-13);
    }

    #[test]
    fn f32_tracks_f64() {
        for i in -80..=80 {
            let z = i as f64 * 0.5;
            let (l64, d64) = (inv_mills(z), inv_mills_delta(z));
            let (l32, d32) = (inv_mills(z as f32) as f64, inv_mills_delta(z as f32) as f64);
            if l64 > 1e-30 {
                assert!(((l32 - l64) / l64).abs() < 1e-4, "λ f32 at {z}");
            }
            if d64 > 1e-30 {
                assert!(((d32 - d64) / d64).abs() < 2e-3, "δ f32 at {z}");
            }
        }
    }

    #[test]
    fn cdf_pdf_known_values() {
        assert!((cdf(0.0f64) - 0.5).abs() < 1e-16);
        assert!((cdf(1.96f64) - 0.975_002_104_851_780).abs() < 1e-14);
        assert!((sf(10.0f64) - 7.619_853_024_160_527e-24).abs() / 7.6e-24 < 1e-13);
        assert!((pdf(1.0f64) - 0.241_970_724_519_143_37).abs() < 1e-16);
        assert!((ln_pdf(50.0f64) - (-1250.0 - LN_SQRT_2PI)).abs() < 1e-12);
    }

    #[test]
    fn interval_probability_in_far_tails() {
        // P(30 < Z < 31) ≈ sf(30) (sf(31)/sf(30) ≈ e^{-30.5}).
        let got = ln_interval_prob(30.0f64, 31.0);
        let want = ln_sf(30.0f64);
        assert!((got - want).abs() < 1e-12);
        assert!((ln_interval_prob(-31.0f64, -30.0) - got).abs() < 1e-12);
        assert!((ln_interval_prob(-1.0f64, 1.0).exp() - 0.682_689_492_137_085_9).abs() < 1e-15);
        // Far beyond where sf underflows, ln_sf is still finite and matches −z²/2 − ln(z√2π).
        let z = 60.0f64;
        let approx = -0.5 * z * z - (z * (2.0 * core::f64::consts::PI).sqrt()).ln();
        assert!((ln_sf(z) - approx).abs() < 1e-3);
    }

    #[test]
    fn streaming_log_sum_exp_matches_the_slice_version() {
        let xs = [-1000.0f64, f64::NEG_INFINITY, -999.0, -1003.5, -998.25];
        let mut acc = LogSumExp::default();
        for &x in &xs {
            acc.push(x);
        }
        assert!((acc.value() - log_sum_exp(&xs)).abs() < 1e-12);
        assert_eq!(LogSumExp::<f64>::default().value(), f64::NEG_INFINITY);
        let mut nan = LogSumExp::default();
        nan.push(1.0f64);
        nan.push(f64::NAN);
        nan.push(2.0);
        assert!(nan.value().is_nan());
    }

    #[test]
    fn log_sum_exp_is_shift_invariant_and_safe() {
        let xs = [-1000.0f64, -1001.0, -1002.0];
        let want = -1000.0 + (1.0 + (-1.0f64).exp() + (-2.0f64).exp()).ln();
        assert!((log_sum_exp(&xs) - want).abs() < 1e-12);
        assert_eq!(log_sum_exp::<f64>(&[]), f64::NEG_INFINITY);
        assert_eq!(log_sum_exp(&[f64::NEG_INFINITY; 2]), f64::NEG_INFINITY);
        assert!(log_sum_exp(&[0.0, f64::NAN]).is_nan());
    }
}
