//! The floor of a Kalman step (issue #37): a dense `f32` predict and update with nothing
//! validated and nothing spent on anything but the arithmetic the step must do, written over
//! plain arrays so that at opt-level 3 it compiles to straight-line code. It is the
//! reference the core's filter is measured against, not a filter to use: a singular S gives
//! an infinite gain, not an error.
//!
//! The step is the textbook one (predict x⁻ = A x̂, P⁻ = A P Aᵀ + Q; update S = C P⁻ Cᵀ + R,
//! K = P⁻ Cᵀ S⁻¹, x̂ = x⁻ + K (z − C x⁻), P = P⁻ − K (P⁻ Cᵀ)ᵀ), every symmetric matrix
//! computed on its upper triangle only and mirrored, S inverted in closed form (one
//! division). [`ops`] counts its operations; the firmware README and BENCHMARKS.md put the
//! count and the measured instructions beside the core's.

use nalgebra::Vector2;

use super::{KfStep, Problem, NY};

/// The straight-line filter on a problem of `NX` states and two measurements.
#[derive(Clone, Copy, Debug)]
pub struct Floor<const NX: usize> {
    a: [[f32; NX]; NX],
    q: [[f32; NX]; NX],
    c: [[f32; NX]; NY],
    r: [[f32; NY]; NY],
    x: [f32; NX],
    p: [[f32; NX]; NX],
}

impl<const NX: usize> Floor<NX> {
    /// The filter at the problem's prior.
    pub fn new(pb: &Problem<NX>) -> Self {
        let (a, q, c, r) = (pb.a(), pb.q(), pb.c(), pb.r());
        Self {
            a: core::array::from_fn(|i| core::array::from_fn(|j| a[(i, j)])),
            q: core::array::from_fn(|i| core::array::from_fn(|j| q[(i, j)])),
            c: core::array::from_fn(|i| core::array::from_fn(|j| c[(i, j)])),
            r: core::array::from_fn(|i| core::array::from_fn(|j| r[(i, j)])),
            x: core::array::from_fn(|i| pb.x0[i]),
            p: core::array::from_fn(|i| core::array::from_fn(|j| pb.p0[(i, j)])),
        }
    }
}

/// Sum of `n` products `f(l)`, left to right.
#[inline(always)]
fn dot<const N: usize>(f: impl Fn(usize) -> f32) -> f32 {
    let mut s = f(0);
    for l in 1..N {
        s += f(l);
    }
    s
}

impl<const NX: usize> KfStep<NX> for Floor<NX> {
    #[inline(never)]
    fn step(&mut self, _k: usize, y: &Vector2<f32>) -> bool {
        let (a, c) = (&self.a, &self.c);
        let x: [f32; NX] = core::array::from_fn(|i| dot::<NX>(|l| a[i][l] * self.x[l]));
        let ap: [[f32; NX]; NX] = core::array::from_fn(|i| {
            core::array::from_fn(|j| dot::<NX>(|l| a[i][l] * self.p[l][j]))
        });
        let mut p = [[0.0f32; NX]; NX];
        for i in 0..NX {
            for j in i..NX {
                p[i][j] = dot::<NX>(|l| ap[i][l] * a[j][l]) + self.q[i][j];
                p[j][i] = p[i][j];
            }
        }
        // U = P⁻ Cᵀ (n × 2), then S = C U + R on its upper triangle.
        let u: [[f32; NY]; NX] =
            core::array::from_fn(|i| core::array::from_fn(|j| dot::<NX>(|l| p[i][l] * c[j][l])));
        let s00 = dot::<NX>(|l| c[0][l] * u[l][0]) + self.r[0][0];
        let s01 = dot::<NX>(|l| c[0][l] * u[l][1]) + self.r[0][1];
        let s11 = dot::<NX>(|l| c[1][l] * u[l][1]) + self.r[1][1];
        let e: [f32; NY] = core::array::from_fn(|i| y[i] - dot::<NX>(|l| c[i][l] * x[l]));
        let d = 1.0 / (s00 * s11 - s01 * s01);
        let (i00, i01, i11) = (s11 * d, -(s01 * d), s00 * d);
        let k: [[f32; NY]; NX] = core::array::from_fn(|i| {
            [u[i][0] * i00 + u[i][1] * i01, u[i][0] * i01 + u[i][1] * i11]
        });
        for i in 0..NX {
            self.x[i] = x[i] + (k[i][0] * e[0] + k[i][1] * e[1]);
            for j in i..NX {
                let v = p[i][j] - (k[i][0] * u[j][0] + k[i][1] * u[j][1]);
                self.p[i][j] = v;
                self.p[j][i] = v;
            }
        }
        true
    }
    fn x(&self, i: usize) -> f32 {
        self.x[i]
    }
    fn p(&self, i: usize, j: usize) -> f32 {
        self.p[i][j]
    }
}

/// Floating-point operations of one step of an `n`-state, `m`-measurement Kalman filter.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Ops {
    /// Multiplications.
    pub mul: usize,
    /// Additions.
    pub add: usize,
    /// Subtractions and negations.
    pub sub: usize,
    /// Divisions.
    pub div: usize,
}

impl Ops {
    /// All of them.
    pub const fn total(&self) -> usize {
        self.mul + self.add + self.sub + self.div
    }
}

/// The operations [`Floor`]'s step does for `n` states and two measurements, term by term;
/// `t` = n (n + 1) / 2 is a symmetric n × n matrix's upper triangle. With `predict_only`,
/// the step of an instant without a measurement (the intermittent filter's dropout).
pub const fn ops(n: usize, predict_only: bool) -> Ops {
    let m = NY;
    let t = n * (n + 1) / 2;
    // x⁻ = A x̂; A P; P⁻ = (A P) Aᵀ + Q on t entries.
    let mut mul = n * n + n * n * n + t * n;
    let mut add = n * (n - 1) + n * n * (n - 1) + t * (n - 1) + t;
    let mut sub = 0;
    let mut div = 0;
    if !predict_only {
        let tm = m * (m + 1) / 2;
        // U = P⁻ Cᵀ; S = C U + R on tm entries; C x⁻ and z − C x⁻.
        mul += n * m * n + tm * n + m * n;
        add += n * m * (n - 1) + tm * (n - 1) + tm + m * (n - 1);
        sub += m;
        // det S (2 mul, 1 sub), 1 / det, S⁻¹'s three entries (3 mul, 1 negation).
        mul += 2 + 3;
        sub += 2;
        div += 1;
        // K = U S⁻¹; x̂ = x⁻ + K e; P = P⁻ − K Uᵀ on t entries.
        mul += n * m * m + n * m + t * m;
        add += n * m * (m - 1) + n * (m - 1) + n + t * (m - 1);
        sub += t;
    }
    Ops { mul, add, sub, div }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_of_the_two_problems() {
        // 3x2: the figures derived by hand in the README (issue #37 counted 121 mul,
        // 99 add, 13 sub, 1 div in LLVM's output of a dense straight-line version).
        assert_eq!(
            ops(3, false),
            Ops {
                mul: 122,
                add: 85,
                sub: 10,
                div: 1
            }
        );
        assert_eq!(
            ops(4, false),
            Ops {
                mul: 221,
                add: 168,
                sub: 14,
                div: 1
            }
        );
        assert_eq!(
            ops(3, true),
            Ops {
                mul: 54,
                add: 42,
                sub: 0,
                div: 0
            }
        );
    }
}
