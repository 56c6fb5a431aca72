//! Computes the Gaussian-sum tables of `src/gsum.rs` ahead of time (seed 001, Section IV).
//!
//! Run `cargo run --release -p estimator-core --example gsum_tables` and paste the output
//! over the generated block at the end of `src/gsum.rs`. (The optimisation takes about a
//! minute unoptimised, too slow for a build script that every build and CI run would pay.)
//!
//! A uniform density on the unit interval [−1, 1] (or the unit disc / ball) is approximated by
//! N equally weighted Gaussians whose means sample the region on a regular grid (interval:
//! N equally spaced points including both endpoints; ball: the points of a cubic lattice with
//! `m` points per axis, endpoints included, that lie inside the closed ball) and share one
//! isotropic standard deviation σ̂. σ̂ minimises KL(uniform ‖ sum) (the direction the paper
//! writes). The region's own scale enters only as `σ = r σ̂` (KL is invariant under scaling),
//! so one table serves every radius.
//!
//! The estimator step does no table construction: the filters scale these unit tables once,
//! at construction.

use std::f64::consts::PI;
use std::fmt::Write as _;

/// Interval tables for N = 2..=MAX_INTERVAL_N.
const MAX_INTERVAL_N: usize = 32;
/// (dimension, points per axis) of the ball tables.
const BALLS: &[(usize, usize)] = &[(2, 3), (2, 5), (2, 7), (2, 9), (3, 3), (3, 5)];

/// Equal-weight mixture density at `x` (dimension = x.len()), isotropic std `s`.
fn mixture(x: &[f64], means: &[Vec<f64>], s: f64) -> f64 {
    let d = x.len() as i32;
    let norm = (2.0 * PI * s * s).powi(d).sqrt();
    let mut acc = 0.0;
    for m in means {
        let mut q = 0.0;
        for (a, b) in x.iter().zip(m) {
            q += (a - b) * (a - b);
        }
        acc += (-0.5 * q / (s * s)).exp();
    }
    acc / (means.len() as f64 * norm)
}

/// KL(uniform on [−1, 1] ‖ mixture), composite Simpson on a grid much finer than σ̂.
fn kl_interval(means: &[Vec<f64>], s: f64) -> f64 {
    // ≥ 24 points per σ and ≥ 2000 in all: Simpson's error is far below the digits reported.
    let n = (((2.0 / s) * 24.0) as usize).max(2000) & !1usize;
    let h = 2.0 / n as f64;
    let mut acc = 0.0;
    for j in 0..=n {
        let x = -1.0 + j as f64 * h;
        let w = if j == 0 || j == n {
            1.0
        } else if j % 2 == 1 {
            4.0
        } else {
            2.0
        };
        acc += w * (0.5f64 / mixture(&[x], means, s)).ln();
    }
    0.5 * acc * h / 3.0
}

/// Volume of the unit ball in `d` dimensions.
fn unit_ball_volume(d: usize) -> f64 {
    match d {
        1 => 2.0,
        2 => PI,
        3 => 4.0 / 3.0 * PI,
        _ => unreachable!(),
    }
}

/// KL(uniform on the unit ball ‖ mixture) in 2 or 3 dimensions, by Gauss–Legendre in the
/// radius and (for 3-D) in cos θ, and the periodic trapezoid rule (spectrally accurate) in
/// the azimuth.
fn kl_ball(d: usize, means: &[Vec<f64>], s: f64) -> f64 {
    let vol = unit_ball_volume(d);
    let p = 1.0 / vol;
    // Panels no wider than s/2, 4-point Gauss-Legendre on each.
    let (gx, gw) = gauss_legendre4();
    let panels_r = ((1.0 / (0.5 * s)).ceil() as usize).max(4);
    let n_phi = ((2.0 * PI / (0.25 * s)).ceil() as usize).max(32);
    let mut acc = 0.0;
    for pr in 0..panels_r {
        let (r0, r1) = (
            pr as f64 / panels_r as f64,
            (pr + 1) as f64 / panels_r as f64,
        );
        for (xi, wi) in gx.iter().zip(gw.iter()) {
            let r = 0.5 * (r0 + r1) + 0.5 * (r1 - r0) * xi;
            let wr = 0.5 * (r1 - r0) * wi;
            if d == 2 {
                for k in 0..n_phi {
                    let phi = 2.0 * PI * k as f64 / n_phi as f64;
                    let x = [r * phi.cos(), r * phi.sin()];
                    let w = wr * r * (2.0 * PI / n_phi as f64);
                    acc += w * p * (p / mixture(&x, means, s)).ln();
                }
            } else {
                let panels_t = ((2.0 / (0.5 * s)).ceil() as usize).max(4);
                for pt in 0..panels_t {
                    let (c0, c1) = (
                        -1.0 + 2.0 * pt as f64 / panels_t as f64,
                        -1.0 + 2.0 * (pt + 1) as f64 / panels_t as f64,
                    );
                    for (xj, wj) in gx.iter().zip(gw.iter()) {
                        let ct = 0.5 * (c0 + c1) + 0.5 * (c1 - c0) * xj;
                        let wt = 0.5 * (c1 - c0) * wj;
                        let st = (1.0 - ct * ct).max(0.0).sqrt();
                        for k in 0..n_phi {
                            let phi = 2.0 * PI * k as f64 / n_phi as f64;
                            let x = [r * st * phi.cos(), r * st * phi.sin(), r * ct];
                            let w = wr * r * r * wt * (2.0 * PI / n_phi as f64);
                            acc += w * p * (p / mixture(&x, means, s)).ln();
                        }
                    }
                }
            }
        }
    }
    acc
}

fn gauss_legendre4() -> ([f64; 4], [f64; 4]) {
    let a = (3.0 / 7.0 - 2.0 / 7.0 * (6.0f64 / 5.0).sqrt()).sqrt();
    let b = (3.0 / 7.0 + 2.0 / 7.0 * (6.0f64 / 5.0).sqrt()).sqrt();
    let wa = (18.0 + 30.0f64.sqrt()) / 36.0;
    let wb = (18.0 - 30.0f64.sqrt()) / 36.0;
    ([-b, -a, a, b], [wb, wa, wa, wb])
}

/// Golden-section minimisation of `f` on [lo, hi].
fn golden(mut lo: f64, mut hi: f64, iters: usize, f: impl Fn(f64) -> f64) -> (f64, f64) {
    let g = (5.0f64.sqrt() - 1.0) / 2.0;
    let mut a = hi - g * (hi - lo);
    let mut b = lo + g * (hi - lo);
    let (mut fa, mut fb) = (f(a), f(b));
    for _ in 0..iters {
        if fa < fb {
            hi = b;
            b = a;
            fb = fa;
            a = hi - g * (hi - lo);
            fa = f(a);
        } else {
            lo = a;
            a = b;
            fa = fb;
            b = lo + g * (hi - lo);
            fb = f(b);
        }
    }
    let x = 0.5 * (lo + hi);
    (x, f(x))
}

fn ball_grid(d: usize, m: usize) -> Vec<Vec<f64>> {
    let h = 2.0 / (m - 1) as f64;
    let mut pts = Vec::new();
    let coord = |j: usize| -1.0 + j as f64 * h;
    if d == 2 {
        for i in 0..m {
            for j in 0..m {
                let p = vec![coord(i), coord(j)];
                if p.iter().map(|v| v * v).sum::<f64>() <= 1.0 + 1e-12 {
                    pts.push(p);
                }
            }
        }
    } else {
        for i in 0..m {
            for j in 0..m {
                for k in 0..m {
                    let p = vec![coord(i), coord(j), coord(k)];
                    if p.iter().map(|v| v * v).sum::<f64>() <= 1.0 + 1e-12 {
                        pts.push(p);
                    }
                }
            }
        }
    }
    pts
}

fn main() {
    let mut out = String::new();
    out.push_str(
        "// @generated by `cargo run --release -p estimator-core --example gsum_tables`.\n",
    );
    out.push_str(
        "/// Interval tables, N = 2..: (N, σ̂ as a fraction of the half-width, KL in nats).\n",
    );
    let _ = writeln!(
        out,
        "pub(crate) const INTERVAL_TABLE: [(usize, f64, f64); {}] = [",
        MAX_INTERVAL_N - 1
    );
    for n in 2..=MAX_INTERVAL_N {
        let means: Vec<Vec<f64>> = (0..n)
            .map(|s| vec![-1.0 + 2.0 * s as f64 / (n - 1) as f64])
            .collect();
        let spacing = 2.0 / (n - 1) as f64;
        let (s, kl) = golden(0.1 * spacing, 1.5 * spacing, 48, |s| kl_interval(&means, s));
        let _ = writeln!(out, "    ({n}, {s:.17e}, {kl:.17e}),");
    }
    out.push_str("];\n");

    out.push_str(
        "/// Ball tables: (dimension, points per axis m, N, σ̂ as a fraction of the radius, KL in nats).\n",
    );
    let _ = writeln!(
        out,
        "pub(crate) const BALL_TABLE: [(usize, usize, usize, f64, f64); {}] = [",
        BALLS.len()
    );
    for &(d, m) in BALLS {
        let pts = ball_grid(d, m);
        let spacing = 2.0 / (m - 1) as f64;
        let iters = if d == 2 { 36 } else { 28 };
        let (s, kl) = golden(0.15 * spacing, 1.2 * spacing, iters, |s| {
            kl_ball(d, &pts, s)
        });
        let _ = writeln!(out, "    ({d}, {m}, {}, {s:.17e}, {kl:.17e}),", pts.len());
    }
    out.push_str("];\n");
    print!("{out}");
}
