//! Tests of the truncated-normal kernels of the ADF step.

use super::*;
use crate::gauss::{inv_mills, inv_mills_delta, ln_sf};

/// Most intervals a test mixture has (fixed-capacity vectors: the crate stays allocation-free,
/// its tests too).
const MAX_IV: usize = 16;

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

/// The one-interval formula before issue 23, verbatim: the reference for the shared and
/// dropped evaluations of [`truncated_std_normal`].
fn old_truncated_std_normal<T: Real>(a: T, b: T) -> (T, T, T) {
    let x_pdf = |x: T| if x.finite() { x * pdf(x) } else { T::zero() };
    let neg_inf = -T::one() / T::zero();
    if a.partial_cmp(&b) != Some(core::cmp::Ordering::Less) {
        return (neg_inf, T::zero(), T::zero());
    }
    if a + b < T::zero() {
        let (l, m, v) = old_truncated_std_normal(-b, -a);
        return (l, -m, v);
    }
    if a <= T::zero() {
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

/// Interval ends from −60 to 60 (and ±∞), densest near 0 and near the shortcuts' edges.
fn ends() -> impl Iterator<Item = f64> + Clone {
    let grid = (-240..=240).map(|i| i as f64 * 0.25);
    let special = [
        1e-9, 0.01, 3.99, 4.0, 4.01, 6.5, 7.0, 7.01, 9.99, 10.0, 10.01, 37.5, 38.5,
    ];
    grid.chain(special.into_iter().flat_map(|x| [x, -x]))
        .chain([f64::INFINITY, f64::NEG_INFINITY])
}

#[test]
fn mills_is_gauss_bit_for_bit() {
    for z in ends() {
        let (l, d) = mills(z);
        assert_eq!(l.to_bits(), inv_mills(z).to_bits(), "λ({z})");
        assert_eq!(d.to_bits(), inv_mills_delta(z).to_bits(), "δ({z})");
        let z = z as f32;
        let (l, d) = mills(z);
        assert_eq!(l.to_bits(), inv_mills(z).to_bits(), "λ({z}) f32");
        assert_eq!(d.to_bits(), inv_mills_delta(z).to_bits(), "δ({z}) f32");
    }
}

/// The new one-interval moments against the old formula: identical, except where an end's
/// contribution was dropped, and there within the rounding of the result (`ln Z` to a few
/// EPS absolute — a log-weight —, the mean to EPS absolute in standard units, the
/// variance to a few EPS relative).
fn one_interval_agrees<T: Real>(tol_ulps: f64) {
    let (mut same, mut total) = (0usize, 0usize);
    for a in ends() {
        for b in ends() {
            let (a, b) = (T::lit(a), T::lit(b));
            let got = truncated_std_normal(a, b);
            let want = old_truncated_std_normal(a, b);
            total += 1;
            let g = [got.0, got.1, got.2].map(T::to_f64);
            let w = [want.0, want.1, want.2].map(T::to_f64);
            if g.iter().zip(&w).all(|(x, y)| x.to_bits() == y.to_bits()) {
                same += 1;
                continue;
            }
            let eps = T::EPS.to_f64() * tol_ulps;
            assert!(
                (g[0] - w[0]).abs() <= eps * w[0].abs().max(1.0),
                "ln Z ({a:?}, {b:?}): {g:?} {w:?}"
            );
            assert!(
                (g[1] - w[1]).abs() <= eps * w[1].abs().max(1.0),
                "mean ({a:?}, {b:?}): {g:?} {w:?}"
            );
            assert!(
                (g[2] - w[2]).abs() <= eps * w[2],
                "var ({a:?}, {b:?}): {g:?} {w:?}"
            );
        }
    }
    // Most pairs take no shortcut at all.
    assert!(same * 2 > total, "{same} of {total} bit-identical");
    std::println!("{same} of {total} intervals bit-identical");
}

#[test]
fn one_interval_agrees_with_the_old_formula_f64() {
    one_interval_agrees::<f64>(4.0);
}

#[test]
fn one_interval_agrees_with_the_old_formula_f32() {
    one_interval_agrees::<f32>(4.0);
}

#[test]
fn the_bounds_behind_the_skips_hold() {
    // ln(1 + 2D²) ≤ D/5 + 3.31 and ln(1 + ζ²) ≤ ζ/5 + 2.62 for all D, ζ ≥ 0 (the maxima of
    // the differences are 3.303 at D ≈ 9.95 and 2.615 at ζ ≈ 9.90); Q(d) < φ(d)/d (Mills);
    // λ(a) − a ≤ λ(0) < 0.8 (λ − a is decreasing); Var < 1 after any truncation.
    let mut x = 0.0f64;
    while x < 1e4 {
        assert!((1.0 + 2.0 * x * x).ln() <= x / 5.0 + 3.31, "D = {x}");
        assert!((1.0 + x * x).ln() <= x / 5.0 + 2.62, "ζ = {x}");
        assert!(
            sf(x) <= 0.5 * (-0.5 * x * x).exp() * (1.0 + 1e-15),
            "Q({x})"
        );
        assert!(
            inv_mills(x) - x <= inv_mills(0.0) && inv_mills(0.0) < 0.8,
            "λ({x})"
        );
        x += if x < 50.0 { 1e-3 } else { 0.37 };
    }
    for a in ends() {
        for b in ends() {
            let (l, _, v) = truncated_std_normal(a, b);
            if l.is_finite() {
                assert!(v <= 1.0 + 1e-15, "var ({a}, {b}) = {v}");
            }
        }
    }
}

/// The full mixture over every interval (what `union_moments` stands for), with the old
/// one-interval formula: summed as the old step did (one pass, index order) and, as the
/// accuracy reference, in two passes (the weights relative to the largest, then the mean,
/// then the variances about it). The one-pass sum loses digits of v̄ when a far interval
/// comes first (the mean is then formed as μ_far + (μ − μ_far)) or when components far
/// apart both count.
fn full_mixture(iv: &[(f64, f64)], two_pass: bool) -> Option<(f64, f64, usize)> {
    let c: heapless::Vec<(f64, f64, f64), MAX_IV> = iv
        .iter()
        .map(|&(lo, hi)| old_truncated_std_normal(lo, hi))
        .collect();
    let (mut best, mut top) = (0usize, f64::NEG_INFINITY);
    let mut mix = Mixture::new();
    for (j, c) in c.iter().enumerate() {
        mix.push(c.0, c.1, c.2);
        if c.0 > top {
            (best, top) = (j, c.0);
        }
    }
    if !mix.total_finite() {
        return None;
    }
    if !two_pass {
        return Some((mix.mean, mix.variance(), best));
    }
    let w: heapless::Vec<f64, MAX_IV> = c.iter().map(|c| (c.0 - top).exp()).collect();
    let wt: f64 = w.iter().sum();
    let mean = c.iter().zip(&w).map(|(c, w)| w * c.1).sum::<f64>() / wt;
    let var = c
        .iter()
        .zip(&w)
        .map(|(c, w)| w * (c.2 + (c.1 - mean).powi(2)))
        .sum::<f64>()
        / wt;
    Some((mean, var, best))
}

/// `union_moments` on `iv` against the full mixture: the same label, and at least as close
/// to the two-pass sums as the old one-pass sum, to 1e-14 (the mean relative to
/// `√v̄ + |μ̄|`, the variance relative). Returns the two distances.
fn union(iv: &[(f64, f64)]) -> Option<(f64, f64, usize)> {
    let sorted: heapless::Vec<(f64, f64, usize), MAX_IV> =
        iv.iter().enumerate().map(|(j, i)| (i.0, i.1, j)).collect();
    union_moments(&Intervals {
        sorted: &sorted,
        gaps: false,
    })
}

fn check_union(
    iv: &[(f64, f64)],
    tag: core::fmt::Arguments<'_>,
) -> Option<((f64, f64), (f64, f64))> {
    let got = union(iv);
    let (old, exact) = (full_mixture(iv, false), full_mixture(iv, true));
    let (Some(g), Some(o), Some(e)) = (got, old, exact) else {
        assert_eq!(got.is_none(), old.is_none(), "{tag}");
        return None;
    };
    assert_eq!(g.2, e.2, "label, {tag}");
    let dist = |m: (f64, f64, usize)| {
        (
            (m.0 - e.0).abs() / (e.1.sqrt() + e.0.abs()),
            (m.1 - e.1).abs() / e.1,
        )
    };
    let (dn, dold) = (dist(g), dist(o));
    assert!(
        dn.0 <= dold.0 + 1e-14 && dn.1 <= dold.1 + 1e-14,
        "{tag}: new {g:?} old {o:?} two-pass {e:?}"
    );
    Some((dn, dold))
}

#[test]
fn union_moments_match_the_full_mixture() {
    // Unit-width regions 10 apart, shifted and scaled so that the mode sits anywhere
    // relative to them, from 1000 standard deviations away to regions 1e-3 wide.
    let (mut worst_new, mut worst_old) = ((0.0f64, 0.0f64), (0.0f64, 0.0f64));
    for scale in [1e-3, 0.1, 0.5, 1.0, 2.0, 5.0, 30.0] {
        for shift in -400..=400 {
            let c = shift as f64 * 0.37;
            let iv: heapless::Vec<(f64, f64), MAX_IV> = [-20.0, -10.0, 0.0, 10.0, 20.0]
                .iter()
                .map(|&z| ((z - 5.0 - c) / scale, (z - 5.0 - c + 1.0) / scale))
                .collect();
            if let Some((n, o)) = check_union(&iv, format_args!("scale {scale} shift {c}")) {
                worst_new = (worst_new.0.max(n.0), worst_new.1.max(n.1));
                worst_old = (worst_old.0.max(o.0), worst_old.1.max(o.1));
            }
        }
    }
    std::println!(
        "distance from the two-pass sums (mean relative to √v̄ + |μ̄|, variance relative): \
         new {worst_new:?}, old {worst_old:?}"
    );
}

#[test]
fn a_failed_recheck_evaluates_every_interval() {
    // The nearest interval is narrow and a wide one follows: judged from the narrow one
    // alone (tiny v̄), a third, far interval is not negligible, and judged from the mixture
    // kept it may be; whatever the re-check decides, the result is the full mixture's.
    for far in [8.0, 9.0, 10.0, 11.0, 12.0, 14.0, 20.0, 40.0] {
        let iv = [(-0.001, 0.001), (1.5, 6.0), (far, far + 1.0)];
        check_union(&iv, format_args!("far {far}")).unwrap();
        let iv = [(far, far + 1.0), (-0.001, 0.001), (-6.0, -2.5)];
        check_union(&iv, format_args!("far {far}, reversed")).unwrap();
    }
    // Nothing finite: None, as the full mixture; NaN bounds likewise.
    let inf = f64::INFINITY;
    assert_eq!(union(&[(inf, inf), (1.0, 1.0)]), None);
    check_union(&[(f64::NAN, 1.0), (2.0, 3.0)], format_args!("NaN"));
    assert!(union(&[(f64::NAN, f64::NAN)]).is_none());
}
