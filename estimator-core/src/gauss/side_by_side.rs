//! Several normal tails at once, bit for bit the single evaluations.
//!
//! The upper-tail `ln Q(z)` (`z > 4`) is a continued fraction of 24 to 64 terms, each a
//! division that waits for the one before: its cost is that chain's latency, not its
//! instruction count. A filter that needs several tails per step (`kf-io`: one interval per
//! gap between occlusion regions) pays the sum of its chains when it evaluates them one after
//! another, and about the longest one when they run side by side, because independent
//! divisions overlap in the divider. Every point still goes through exactly the operations of
//! its single evaluation, so the results are the same bits. A size-optimised build
//! (`small_code`) and an in-order microcontroller (`in_order_core`, the Cortex-M4: there is
//! no latency to hide) evaluate the intervals one at a time ([`ln_interval_prob_one`]), with
//! the same results.

use super::{cf_terms, ln_interval_prob, ln_pdf, ln_sf, CF_THRESHOLD};
use crate::Real;

/// Points whose continued fractions run side by side at most; longer inputs go in chunks.
pub const LANES: usize = 16;

/// Intervals of [`ln_interval_prob_each`] evaluated together (two ends each).
const INTERVALS: usize = LANES / 2;

/// Replaces every `x` of `xs` by [`ln_sf`]`(x)`, bit for bit, with the continued fractions of
/// the upper-tail points (up to [`LANES`] at a time) side by side.
pub fn ln_sf_each<T: Real>(xs: &mut [T]) {
    for chunk in xs.chunks_mut(LANES) {
        ln_sf_chunk(chunk);
    }
}

/// [`ln_sf_each`] of at most [`LANES`] points.
fn ln_sf_chunk<T: Real>(xs: &mut [T]) {
    let cf = T::lit(CF_THRESHOLD);
    // The continued-fraction points and where they came from.
    let mut z = [T::one(); LANES];
    let mut at = [usize::MAX; LANES];
    let mut lanes = 0;
    for (i, x) in xs.iter_mut().enumerate() {
        if *x > cf {
            if let (Some(zl), Some(al)) = (z.get_mut(lanes), at.get_mut(lanes)) {
                (*zl, *al) = (*x, i);
                lanes += 1;
            }
        } else {
            *x = ln_sf(*x);
        }
    }
    // Blocks as wide as the points need: the chains' cost grows only slowly with the width.
    let mut t = [T::zero(); LANES];
    let mut done = 0;
    while done < lanes {
        let rest = lanes - done;
        done += match rest {
            1 => block::<T, 1>(&z, &mut t, done),
            2 => block::<T, 2>(&z, &mut t, done),
            3 | 4 => block::<T, 4>(&z, &mut t, done),
            _ => block::<T, 8>(&z, &mut t, done),
        };
    }
    for ((&z, &t), &i) in z.iter().zip(&t).zip(&at).take(lanes) {
        if let Some(x) = xs.get_mut(i) {
            // `ln φ(ζ) − ln λ(ζ)` with `λ(ζ) = ζ + t(ζ)`, as [`ln_sf`] above the threshold.
            *x = ln_pdf(z) - (z + t).ln();
        }
    }
}

/// `t(ζ)` of `cf_tail` for the `W` points of `z` from `from` on into `t` (points past the
/// end of `z` are padding: `ζ = 1`, never started); returns `W`.
#[inline(always)]
fn block<T: Real, const W: usize>(z: &[T; LANES], t: &mut [T; LANES], from: usize) -> usize {
    let mut zw = [T::one(); W];
    for (zw, &z) in zw.iter_mut().zip(z.iter().skip(from)) {
        *zw = z;
    }
    let tw = cf_tails(&zw);
    for (t, tw) in t.iter_mut().skip(from).zip(tw) {
        *t = tw;
    }
    W
}

/// `cf_tail` of every point of `z` (each `> 4` or padding `ζ = 1`), the `W` recurrences
/// side by side, each with its own number of terms: `t = n/(ζ + t)` from the last term down,
/// then `1/(ζ + t)`.
#[inline(always)]
fn cf_tails<T: Real, const W: usize>(z: &[T; W]) -> [T; W] {
    let cf = T::lit(CF_THRESHOLD);
    let mut terms = [0usize; W];
    for (m, &z) in terms.iter_mut().zip(z) {
        if z > cf {
            *m = cf_terms(z);
        }
    }
    let mut t = [T::zero(); W];
    let mut n = terms.iter().copied().max().unwrap_or(0);
    while n >= 2 {
        let c = T::lit(n as f64);
        for ((t, &z), &m) in t.iter_mut().zip(z).zip(&terms) {
            // A point with fewer terms has not started: `0/(ζ + 0) = +0` keeps its `t = 0`
            // exactly (`ζ > 0`), with no branch in the chain of divisions.
            let c = if n <= m { c } else { T::zero() };
            *t = c / (z + *t);
        }
        n -= 1;
    }
    for (t, &z) in t.iter_mut().zip(z) {
        *t = T::one() / (z + *t);
    }
    t
}

/// How one interval of a chunk is finished once its ends' `ln Q` are known.
#[derive(Clone, Copy)]
enum Finish<T> {
    /// Already written (no upper-tail end: an empty interval, one around 0, or NaN).
    Done,
    /// Only the near end's `ln Q` at this point counts; `far` is the far end, needed only
    /// if that is not finite.
    Near { at: usize, far: T },
    /// `ln Q(a) + ln(1 − e^{ln Q(b) − ln Q(a)})` with the ends at `at`, `at + 1`.
    Both { at: usize },
}

/// Writes [`ln_interval_prob`]`(a, b)` of every `(a, b)` of `ends` to `out`, bit for bit,
/// with the continued fractions of all their tail ends side by side ([`ln_sf_each`]), and
/// without the far end's `ln Q` where it cannot change the result.
///
/// For `0 < a < b` the probability is `ln Q(a) + ln(1 − e^{ln Q(b) − ln Q(a)})` (and
/// `b < 0` its mirror image); when a bound proves `ln Q(b) − ln Q(a) < −40` the second term
/// is below `4.4·10⁻¹⁸` in magnitude, under half an ulp of `ln Q(a)` (`|ln Q(a)| > ln 2`),
/// so the sum is `ln Q(a)` itself. The bounds: `ln Q(b) ≤ −b²/2` (`Q(b) ≤ e^{−b²/2}/2`) and
/// `ln Q(a) ≥ −a²/2 − 2a` for `a ≥ 1` (from `Q(a) ≥ φ(a) a/(1 + a²)`), `≥ −1.85` for
/// `a < 1` (`Q(1) > 0.158`). The far end `b = ∞` of a half-line is the common case. A
/// non-finite `ln Q(a)` takes the full formula.
///
/// `out` shorter than `ends` gets the first `out.len()` results.
pub fn ln_interval_prob_each<T: Real>(ends: &[(T, T)], out: &mut [T]) {
    if cfg!(any(small_code, in_order_core)) {
        // A size-optimised build, or an in-order core: there is no latency to hide, and the
        // lanes would only add instructions and code.
        for (&(a, b), o) in ends.iter().zip(out) {
            *o = ln_interval_prob_one(a, b);
        }
        return;
    }
    for (ends, out) in ends.chunks(INTERVALS).zip(out.chunks_mut(INTERVALS)) {
        ln_interval_prob_chunk(ends, out);
    }
}

/// [`ln_interval_prob_each`] of at most [`INTERVALS`] intervals.
fn ln_interval_prob_chunk<T: Real>(ends: &[(T, T)], out: &mut [T]) {
    let zero = T::zero();
    let mut pts = [zero; LANES];
    let mut finish = [Finish::Done; INTERVALS];
    let mut n = 0;
    for ((&(a, b), o), f) in ends.iter().zip(out.iter_mut()).zip(finish.iter_mut()) {
        // `P(a < Z < b) = P(−b < Z < −a)`: a lower-tail interval as its upper-tail mirror.
        let (lo, hi) = if b < zero && a < b { (-b, -a) } else { (a, b) };
        if !(lo > zero && lo < hi) {
            *o = ln_interval_prob(a, b);
            continue;
        }
        // Two points per interval and at most `INTERVALS` intervals: always room.
        let Some([p0, p1, ..]) = pts.get_mut(n..) else {
            *o = ln_interval_prob(a, b);
            continue;
        };
        *p0 = lo;
        if far_end_negligible(lo, hi) {
            *f = Finish::Near { at: n, far: hi };
            n += 1;
        } else {
            *p1 = hi;
            *f = Finish::Both { at: n };
            n += 2;
        }
    }
    let pts = pts.get_mut(..n).unwrap_or_default();
    ln_sf_each(pts);
    let ln_q = |i: usize| pts.get(i).copied().unwrap_or(T::zero());
    for (o, f) in out.iter_mut().zip(&finish) {
        let (la, lb) = match *f {
            Finish::Done => continue,
            Finish::Near { at, far } => {
                let la = ln_q(at);
                if la.finite() {
                    *o = la;
                    continue;
                }
                (la, ln_sf(far))
            }
            Finish::Both { at } => (ln_q(at), ln_q(at + 1)),
        };
        *o = la + (-(lb - la).exp()).ln_1p();
    }
}

/// [`ln_interval_prob_each`] of one interval: the same bits, and the same shortcut, with the
/// (at most two) continued fractions of [`ln_interval_prob`] side by side.
pub fn ln_interval_prob_one<T: Real>(a: T, b: T) -> T {
    if a > T::zero() && a < b {
        if far_end_negligible(a, b) {
            let la = ln_sf(a);
            if la.finite() {
                return la;
            }
        }
    } else if b < T::zero() && a < b {
        return ln_interval_prob_one(-b, -a);
    }
    ln_interval_prob(a, b)
}

/// Whether a bound proves `ln Q(b) − ln Q(a) < −40` for `0 < a < b`
/// ([`ln_interval_prob_each`]).
#[inline]
fn far_end_negligible<T: Real>(a: T, b: T) -> bool {
    let half = T::lit(0.5);
    let la_low = if a >= T::one() {
        -half * a * a - (a + a)
    } else {
        T::lit(-1.85)
    };
    -half * b * b - la_low < T::lit(-40.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    const INF: f64 = f64::INFINITY;

    /// Points on both sides of the continued fraction's threshold and of its term counts, at
    /// 0, ±∞ and NaN.
    const POINTS: [f64; 19] = [
        0.0,
        0.3,
        -1.0,
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
        INF,
        -INF,
        f64::NAN,
    ];

    /// Every window of the points (so every mix of term counts and orders) and the whole
    /// list twice over (a second chunk), in f64 and f32.
    #[test]
    fn ln_sf_each_is_ln_sf_bit_for_bit() {
        let mut long = heapless::Vec::<f64, 38>::new();
        for &x in POINTS.iter().chain(POINTS.iter().rev()) {
            long.push(x).unwrap();
        }
        for start in 0..long.len() {
            for end in start..=long.len() {
                let mut got = heapless::Vec::<f64, 38>::from_slice(&long[start..end]).unwrap();
                ln_sf_each(&mut got);
                let mut got32 = heapless::Vec::<f32, 38>::new();
                for &x in &long[start..end] {
                    got32.push(x as f32).unwrap();
                }
                ln_sf_each(&mut got32);
                for (i, &x) in long[start..end].iter().enumerate() {
                    assert_eq!(
                        got[i].to_bits(),
                        ln_sf(x).to_bits(),
                        "{x} in {start}..{end}"
                    );
                    assert_eq!(got32[i].to_bits(), ln_sf(x as f32).to_bits(), "f32 {x}");
                }
            }
        }
    }

    /// Ends near, far and at infinity on both sides, every pair, in runs of 1 to 10
    /// intervals (past one chunk), against [`ln_interval_prob`] one at a time; and the
    /// shortcut was taken.
    #[test]
    fn ln_interval_prob_each_is_ln_interval_prob_bit_for_bit() {
        let ends = [
            -INF,
            -1e3,
            -60.0,
            -38.5,
            -12.0,
            -9.0,
            -7.3,
            -3.0,
            -1.0,
            -0.2,
            0.0,
            0.3,
            1.0,
            1.7,
            2.5,
            6.0,
            8.9,
            9.1,
            11.0,
            25.0,
            40.0,
            77.0,
            1e4,
            INF,
            f64::NAN,
        ];
        let mut pairs = heapless::Vec::<(f64, f64), 640>::new();
        for &a in &ends {
            for &b in &ends {
                pairs.push((a, b)).unwrap();
            }
        }
        let mut shortcut = 0;
        for run in 1..=10 {
            for group in pairs.chunks(run) {
                let mut got = [0.0; 10];
                ln_interval_prob_each(group, &mut got);
                let mut narrow = heapless::Vec::<(f32, f32), 10>::new();
                for &(a, b) in group {
                    narrow.push((a as f32, b as f32)).unwrap();
                }
                let mut got32 = [0.0f32; 10];
                ln_interval_prob_each(&narrow, &mut got32);
                for (i, &(a, b)) in group.iter().enumerate() {
                    let want = ln_interval_prob(a, b);
                    assert_eq!(got[i].to_bits(), want.to_bits(), "({a}, {b}): {}", got[i]);
                    let one = ln_interval_prob_one(a, b);
                    assert_eq!(one.to_bits(), want.to_bits(), "one ({a}, {b})");
                    let one32 = ln_interval_prob_one(a as f32, b as f32);
                    assert_eq!(
                        one32.to_bits(),
                        ln_interval_prob(a as f32, b as f32).to_bits()
                    );
                    let want32 = ln_interval_prob(a as f32, b as f32);
                    assert_eq!(got32[i].to_bits(), want32.to_bits(), "f32 ({a}, {b})");
                    let (lo, hi) = if b < 0.0 && a < b { (-b, -a) } else { (a, b) };
                    shortcut +=
                        usize::from(run == 1 && lo > 0.0 && lo < hi && far_end_negligible(lo, hi));
                }
            }
        }
        assert!(shortcut > 40, "the shortcut was taken {shortcut} times");
    }

    /// `out` shorter than `ends`: the first results, nothing written past it.
    #[test]
    fn a_short_output_gets_the_first_results() {
        let ends = [(5.0, 6.0), (-1.0, 1.0), (7.0, INF)];
        let mut out = [0.0; 2];
        ln_interval_prob_each(&ends, &mut out);
        assert_eq!(out[0].to_bits(), ln_interval_prob(5.0f64, 6.0).to_bits());
        assert_eq!(out[1].to_bits(), ln_interval_prob(-1.0f64, 1.0).to_bits());
    }
}
