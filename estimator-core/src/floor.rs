//! The floor of one step (issue #37): the floating-point operations an estimator's equations
//! need for given dimensions, counted term by term as the code computes them, with nothing
//! spent on validation, symmetrisation, numerics (log domains, equilibration, tail
//! formulas) or bookkeeping. Nothing here runs in an estimator: the firmware README and
//! BENCHMARKS.md (`benches/src/bin/report`, part `firmware`) put these counts beside the
//! measured instructions, and the tests below hold the figures they print.
//!
//! Rules, the same for every estimator (and for the Kalman floor of the firmware's
//! `peers::ops`, which [`kf`] reproduces):
//!
//! * a symmetric result is formed on its upper triangle only (`t = n (n + 1) / 2` entries);
//! * a 2 × 2 symmetric matrix is inverted in closed form (determinant, one division, three
//!   entries, one of them negated); a larger system is solved by Cholesky (a square root per
//!   pivot) and two triangular solves;
//! * a covariance update with the optimal gain is the standard form `P − K Uᵀ` (for the
//!   optimal gain it equals the Joseph form the code uses);
//! * a product of a known step input by a configuration-only constant costs its
//!   multiplications; a product of configuration constants alone is made once, not per
//!   step;
//! * comparisons, absolute values, `max`/`min` and copies are not counted; a negation counts
//!   as a subtraction;
//! * a special function (`exp`, `ln`, `erfc`, `sqrt`, `sin`, `cos`, `tanh`) is one call of
//!   its kind, whatever it costs in instructions (the README prices them from the
//!   per-function profile);
//! * where the code's work depends on the data, the floor is its least work: the occlusion
//!   filters evaluate the one interval nearest the predicted `u` (the ADF's truncated
//!   moments, the KF-IO's gap) and skip the others by their bound tests, whose arithmetic is
//!   counted; the CCE scores every region (eq. 15) and sums the exponentials of the one it
//!   chooses (eq. 17); the moment-matched Tobit filter is counted for what its instant reads
//!   ([`CmmInstant`]: observed and censored components, held silences and their boxes).

use core::ops::{Add, Mul};

/// Operations of one step, by kind.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Ops {
    /// Multiplications.
    pub mul: usize,
    /// Additions.
    pub add: usize,
    /// Subtractions and negations.
    pub sub: usize,
    /// Divisions.
    pub div: usize,
    /// Square roots.
    pub sqrt: usize,
    /// `exp` calls.
    pub exp: usize,
    /// `ln` calls.
    pub ln: usize,
    /// `erfc` calls.
    pub erfc: usize,
    /// `sin` calls.
    pub sin: usize,
    /// `cos` calls.
    pub cos: usize,
    /// `tanh` calls.
    pub tanh: usize,
}

impl Ops {
    /// No operation.
    pub const ZERO: Self = Self {
        mul: 0,
        add: 0,
        sub: 0,
        div: 0,
        sqrt: 0,
        exp: 0,
        ln: 0,
        erfc: 0,
        sin: 0,
        cos: 0,
        tanh: 0,
    };

    /// `mul` multiplications, `add` additions, `sub` subtractions, `div` divisions.
    pub const fn arith(mul: usize, add: usize, sub: usize, div: usize) -> Self {
        Self {
            mul,
            add,
            sub,
            div,
            ..Self::ZERO
        }
    }

    /// The four arithmetic kinds together.
    pub const fn arithmetic(&self) -> usize {
        self.mul + self.add + self.sub + self.div
    }

    /// The calls of every special kind together (square roots included).
    pub const fn calls(&self) -> usize {
        self.sqrt + self.exp + self.ln + self.erfc + self.sin + self.cos + self.tanh
    }
}

impl Add for Ops {
    type Output = Ops;
    fn add(self, o: Ops) -> Ops {
        Ops {
            mul: self.mul + o.mul,
            add: self.add + o.add,
            sub: self.sub + o.sub,
            div: self.div + o.div,
            sqrt: self.sqrt + o.sqrt,
            exp: self.exp + o.exp,
            ln: self.ln + o.ln,
            erfc: self.erfc + o.erfc,
            sin: self.sin + o.sin,
            cos: self.cos + o.cos,
            tanh: self.tanh + o.tanh,
        }
    }
}

impl Mul<usize> for Ops {
    type Output = Ops;
    fn mul(self, k: usize) -> Ops {
        Ops {
            mul: self.mul * k,
            add: self.add * k,
            sub: self.sub * k,
            div: self.div * k,
            sqrt: self.sqrt * k,
            exp: self.exp * k,
            ln: self.ln * k,
            erfc: self.erfc * k,
            sin: self.sin * k,
            cos: self.cos * k,
            tanh: self.tanh * k,
        }
    }
}

/// Entries of a symmetric `n × n` matrix's upper triangle.
const fn tri(n: usize) -> usize {
    n * (n + 1) / 2
}

/// An `r × k` by `k × c` product, dense.
fn prod(r: usize, k: usize, c: usize) -> Ops {
    Ops::arith(r * c * k, r * c * (k - 1), 0, 0)
}

/// An `n × k` by `k × n` product whose result is symmetric: its upper triangle.
fn sym_prod(n: usize, k: usize) -> Ops {
    Ops::arith(tri(n) * k, tri(n) * (k - 1), 0, 0)
}

/// The closed-form inverse of a symmetric 2 × 2 matrix: det (2 mul, 1 sub), 1/det, three
/// entries (3 mul, one negated).
fn inv2() -> Ops {
    Ops::arith(5, 0, 2, 1)
}

/// Cholesky factor of an `n × n` SPD matrix and the two triangular solves of one right-hand
/// side.
fn cholesky_solve(n: usize) -> Ops {
    let f = n * (n - 1) * (n + 1) / 6;
    let half = n * (n - 1) / 2;
    Ops {
        sqrt: n,
        ..Ops::arith(f + 2 * half, 0, f + 2 * half, half + 2 * n)
    }
}

/// Φ(x) = erfc(−x/√2)/2 or Q(x) = erfc(x/√2)/2.
fn normal_cdf() -> Ops {
    Ops {
        erfc: 1,
        ..Ops::arith(2, 0, 0, 0)
    }
}

/// φ(x) = e^{−x²/2}/√(2π).
fn normal_pdf() -> Ops {
    Ops {
        exp: 1,
        ..Ops::arith(3, 0, 0, 0)
    }
}

/// The Kalman prediction (eq. 11 of seed 001; the KF's): x⁻ = A x̂, P⁻ = A P Aᵀ + Q on
/// `n` states.
pub fn kf_predict(n: usize) -> Ops {
    prod(n, n, 1) + prod(n, n, n) + sym_prod(n, n) + Ops::arith(0, tri(n), 0, 0)
}

/// The Kalman update with two measurements (eq. 18 of seed 001; the KF's): U = P⁻ Cᵀ,
/// S = C U + R, S⁻¹ in closed form, K = U S⁻¹, x̂ = x⁻ + K (z − C x⁻), P = P⁻ − K Uᵀ.
pub fn kf_update2(n: usize) -> Ops {
    let m = 2;
    prod(n, n, m)
        + sym_prod(m, n)
        + Ops::arith(0, tri(m), 0, 0)
        + prod(m, n, 1)
        + Ops::arith(0, 0, m, 0)
        + inv2()
        + prod(n, m, m)
        + prod(n, m, 1)
        + Ops::arith(0, n, 0, 0)
        + sym_prod(n, m)
        + Ops::arith(0, 0, tri(n), 0)
}

/// One Kalman step, `n` states and two measurements: the firmware's `peers::ops` (its floor
/// binaries), the same counts.
pub fn kf(n: usize, predict_only: bool) -> Ops {
    if predict_only {
        kf_predict(n)
    } else {
        kf_predict(n) + kf_update2(n)
    }
}

/// `P⁻ Eᵀ`, `E P⁻ Eᵀ` and `E x⁻` of a scalar `u = E x + n`.
fn scalar_marginal(n: usize) -> Ops {
    prod(n, n, 1) + prod(1, n, 1) + prod(1, n, 1)
}

/// The CCE (seed 001, Algorithms 1-2) on `n` states, `S` regions of a scalar `u`, `N`
/// Gaussians per region. An arrival is the Kalman step (eqs. 11, 18); a dropout predicts
/// and then, per region, `s_i = E P⁻ Eᵀ + Σ_i`, `1/s_i`, `½/s_i`, `ln s_i` and
/// `c_i = ln|R_i| − const − ½ ln s_i`, per component `ln ω = c_i − (½/s_i)(ũ − E x⁻)²`
/// (eq. 15); the chosen region's `N` exponentials `e^{ln ω − top}`, their sum and its `ln`
/// (eq. 17); `α = e / Σ` (one division), `ū`, `C_u` (eq. 21); `K = P⁻Eᵀ/s_i`,
/// `x̂ = x⁻ + K (ū − E x⁻)`, `P = P⁻ − (s_i − C_u) K Kᵀ`.
pub fn cce(n: usize, s: usize, comps: usize, dropout: bool) -> Ops {
    if !dropout {
        return kf(n, false);
    }
    let per_region = Ops {
        ln: 1,
        ..Ops::arith(2, 1, 1, 1)
    } + Ops::arith(2, 0, 2, 0) * comps;
    let chosen = Ops {
        exp: comps,
        ln: 1,
        ..Ops::arith(0, comps, comps, 0)
    };
    let moments = Ops::arith(comps, 0, 0, 1)
        + Ops::arith(comps, comps - 1, 0, 0)
        + Ops::arith(2 * comps, comps - 1, comps, 0);
    let update =
        Ops::arith(n, 0, 0, 0) + Ops::arith(n, n, 1, 0) + Ops::arith(2 * tri(n), 0, 1 + tri(n), 0);
    kf_predict(n) + scalar_marginal(n) + per_region * s + chosen + moments + update
}

/// `u`'s marginal in standard units: `s² = E P Eᵀ + Ψ`, `s = √s²`, `1/s`, and the `2 S`
/// interval ends `(e − m)/s`.
fn standardise(s: usize) -> Ops {
    Ops {
        sqrt: 1,
        ..Ops::arith(2 * s, 1, 2 * s, 1)
    }
}

/// The moments of a standard normal truncated to one bounded interval `(a, b)`:
/// `Z = Φ(b) − Φ(a)`, `μ = (φ(a) − φ(b))/Z`, `v = 1 + (aφ(a) − bφ(b))/Z − μ²` (one division
/// for `1/Z`).
fn truncated_moments() -> Ops {
    normal_cdf() * 2 + normal_pdf() * 2 + Ops::arith(1 + 2 + 2, 1, 4, 1)
}

/// The ADF's skip test of an interval it does not evaluate: `D = |t − μ̄| + 1`,
/// `d²/2 − D/5 ≥ h`.
fn skip_test() -> Ops {
    Ops::arith(3, 1, 2, 0)
}

/// The ADF's skip threshold `h = ln(n (1 + v̄)/(EPS v̄ w)) − top + slack`, once per update.
fn skip_threshold() -> Ops {
    Ops {
        ln: 1,
        ..Ops::arith(3, 2, 1, 1)
    }
}

/// The ADF's truncation of `u` to `intervals` intervals (S regions on a dropout, the S + 1
/// gaps on an arrival), the nearest evaluated and the others skipped, then
/// `x̂ = m_x + P Eᵀ μ̄/s`, `P̂ = P − (1 − v̄)/s² · P Eᵀ E P` on the upper triangle.
fn adf_truncate(n: usize, s: usize, intervals: usize) -> Ops {
    scalar_marginal(n)
        + standardise(s)
        + truncated_moments()
        + skip_threshold()
        + skip_test() * (intervals - 1)
        + Ops::arith(1 + n, n, 0, 0)
        + Ops::arith(2 * tri(n), 0, 1 + tri(n), 1)
}

/// The ADF on `n` states with `S` regions of a scalar `u`: predict (eq. 11), then on an
/// arrival the Kalman update (18) and the truncation to the `S + 1` gaps, on a dropout the
/// truncation to the `S` regions (module docs of `filter::occlusion::adf`).
pub fn adf(n: usize, s: usize, dropout: bool) -> Ops {
    if dropout {
        kf_predict(n) + adf_truncate(n, s, s)
    } else {
        kf_predict(n) + kf_update2(n) + adf_truncate(n, s, s + 1)
    }
}

/// KF-IO (docs/design.md, "Seed 001") on `n` states, two measurements, `S` regions, either
/// branch (a dropout is `ỹ = 0`): predict; `p_k` from the gap nearest the predicted `u`
/// (`Φ(b) − Φ(a)`), each of the `S + 1` gaps bounded by `−d²/2` and the other `S` skipped
/// against it; `S' = C P⁻ Cᵀ + (1 − p)(C x⁻)(C x⁻)ᵀ + R` (the design's
/// `p C P⁻ Cᵀ + (1 − p) C X Cᵀ + R` with `X = P⁻ + x⁻x⁻ᵀ`); `K = P⁻ Cᵀ S'⁻¹`;
/// `x̂ = x⁻ + K (ỹ − p C x⁻)`; `P = P⁻ − (p K) Uᵀ`, `U = P⁻ Cᵀ`.
pub fn kf_io(n: usize, s: usize) -> Ops {
    let m = 2;
    let p_k = Ops::arith(n * n + n, n * (n - 1) + (n - 1), 0, 0)
        + Ops::arith(0, 1, 0, 0)
        + Ops {
            sqrt: 1,
            ..Ops::arith(n, n - 1, 0, 0)
        }
        + Ops::arith(2 * s, 0, 2 * s, 1)
        + normal_cdf() * 2
        + Ops::arith(0, 0, 1, 0)
        + Ops::arith(2 * (s + 1), 0, s, 0);
    let s_prime = prod(m, n, n)
        + sym_prod(m, n)
        + prod(m, n, 1)
        + Ops::arith(tri(m) + tri(m), 2 * tri(m), 1, 0);
    let gain = inv2() + prod(n, m, m);
    let update = Ops::arith(m, 0, m, 0)
        + prod(n, m, 1)
        + Ops::arith(0, n, 0, 0)
        + Ops::arith(n * m, 0, 0, 0)
        + sym_prod(n, m)
        + Ops::arith(0, 0, tri(n), 0);
    kf_predict(n) + p_k + s_prime + gain + update
}

/// The NN estimator of seed 003 on its section IV example (3 states, 1 noise, 2
/// measurements, `tanh` on 3 outputs, the Kronecker solve of (35) on 6 unknowns), one step
/// from `k` to `k + 1`: `gamma` = `y_k` was transmitted (the gain (33)-(35) is computed and
/// enters (5) and (14)), `gamma_next` = `y_{k+1}` was (it enters (15) through δ̄₂…δ̄₆ and the
/// tuning law (6)).
///
/// Terms: the matrices of `k + 1` (`sin`, `cos` of `k + 1` and their 5 products; those of
/// `k` were made by the step before); `M = Cᵀ_{k+1} C_{k+1}`, `‖M‖₂` as the largest
/// eigenvalue of the 2 × 2 `C Cᵀ` in closed form; `1/‖M‖²` and δ̄₂, δ̄₃, δ̄₄, δ̄₆; the gain:
/// `M²`, `T₁ = c₁I + δ̄₂M²`, `T₂ = C P Cᵀ`, `T₃ = c₃w̄²I + δ̄₄M²`, `T₄ = D Dᵀ`,
/// `Φ = T₁ (A P Cᵀ) + T₃ (B Dᵀ)`, the Kronecker matrix `T₂ ⊗ T₁ + T₄ ⊗ T₃` on its upper
/// triangle, Cholesky and two triangular solves; (5) with `φ = tanh x̂`; Theorem 1:
/// `Ā = A − L C`, `B̄ = B − L D`, `Ā P Āᵀ`, `B̄ B̄ᵀ`, `P̄_{k+1}` (14), `Q̄_{k+1}` (15) as
/// `δ₁ Q̄ + M (δ̄₂ ĀPĀᵀ + δ̄₃ Q̄ + δ̄₄ B̄B̄ᵀ) M + (δ̄₅ + δ̄₇) I + δ̄₆ (CᵀD)(CᵀD)ᵀ`; the tuning law
/// (6); `‖tanh x̂_{k+1}‖`.
pub fn nn_seed003(gamma: bool, gamma_next: bool) -> Ops {
    let (n, m, phi) = (3, 2, 3);
    let t = tri(n);
    let np = n * m;
    let matrices = Ops {
        sin: 1,
        cos: 1,
        ..Ops::arith(5, 0, 0, 0)
    };
    let m_and_norm = sym_prod(n, m)
        + sym_prod(m, n)
        + Ops {
            sqrt: 1,
            ..Ops::arith(4, 3, 1, 0)
        };
    let deltas = if gamma_next {
        Ops::arith(1 + 4, 0, 0, 1)
    } else {
        Ops::ZERO
    };
    let mut ops = matrices + m_and_norm + deltas;
    if gamma {
        let t1_t3 = sym_prod(n, n) + Ops::arith(2 * t, 2 * n, 0, 0);
        let t2 = prod(m, n, n) + sym_prod(m, n);
        let t4 = Ops::arith(tri(m), 0, 0, 0);
        let phi_rhs = prod(n, n, m) + Ops::arith(n * m, 0, 0, 0) + prod(n, n, m) * 2;
        let phi_rhs = phi_rhs + Ops::arith(0, n * m, 0, 0);
        let kron = Ops::arith(2 * tri(np), tri(np), 0, 0) + cholesky_solve(np);
        ops = ops + t1_t3 + t2 + t4 + phi_rhs + kron;
    }
    // (5): A x̂ + Ĥ φ(x̂) (+ L (y − C x̂)).
    ops =
        ops + Ops {
            tanh: n,
            ..Ops::ZERO
        } + prod(n, n, 1)
            + prod(n, phi, 1)
            + Ops::arith(0, n, 0, 0);
    if gamma {
        ops = ops + prod(m, n, 1) + Ops::arith(0, 0, m, 0) + prod(n, m, 1) + Ops::arith(0, n, 0, 0);
        // Ā = A − L C, B̄ = B − L D.
        ops = ops + prod(n, m, n) + Ops::arith(0, 0, n * n, 0) + prod(n, m, 1);
        ops = ops + Ops::arith(0, 0, n, 0);
    }
    // Ā P Āᵀ, B̄ B̄ᵀ, (14).
    ops = ops + prod(n, n, n) + sym_prod(n, n) + Ops::arith(t, 0, 0, 0);
    ops = ops + Ops::arith(3 * t, 2 * t + n, 0, 0);
    // (15).
    ops = ops + Ops::arith(t, n, 0, 0);
    if gamma_next {
        let inner = Ops::arith(3 * t, 2 * t, 0, 0);
        let mxm = prod(n, n, n) + sym_prod(n, n);
        let cd = prod(n, m, 1) + Ops::arith(n + t, 0, 0, 0);
        ops = ops + inner + mxm + cd + Ops::arith(0, 2 * t, 0, 0);
    }
    // (6): Ĥ (1 − θ₁θ₂), and with y_{k+1} the normalised regressor and the correction.
    ops = ops + Ops::arith(n * phi, 0, 0, 0);
    if gamma_next {
        let regressor = prod(1, phi, 1) + Ops::arith(1 + phi, 1, 0, 1);
        let innov = prod(m, n, 1) + Ops::arith(0, 0, m, 0);
        let corr = prod(n, m, 1) + Ops::arith(n + n * phi, n * phi, 0, 0);
        ops = ops + regressor + innov + corr;
    }
    // ‖tanh x̂_{k+1}‖.
    ops + Ops {
        tanh: n,
        sqrt: 1,
        ..Ops::arith(n, n - 1, 0, 0)
    }
}

/// One local Tobit filter of seed 004 (eqs. 21-23, 29-30, 37) on `n` states and two
/// measurements, with Υ placed as written (`C (Υ∘Ω₁) Cᵀ`) and the held measurement read at
/// θ = 1 (the paper's filter): `received` is θ = 0.
///
/// Terms: `x⁻ = A x̂` (21); `P⁻ = A P̄ Aᵀ + α⁻¹ BQBᵀ` (29, 51); per component
/// `ζ = (τ − (C x⁻)_j)/√R_j`, `ϱ̄ = Q(ζ)`, `λ = φ(ζ)/ϱ̄`, `Υ = ϱ̄ Φ(ζ)`,
/// `ŷ_j = ϱ̄ ((Cx⁻)_j + √R_j λ) + (1 − ϱ̄) τ_j` (23); `Ω₁`, `Ξ(Ḡ)`; `Q̄C`, `Q̄(λ∘√R)`,
/// `(I − Q̄)τ`; the terms of `M` the branch keeps (θ = 0: `Ω₃∘R`, κ₈, κ₆, κ₂, κ₃; θ = 1: κ₂,
/// κ₄, κ₅, κ₇); `Φ = κ₁ Q̄C P⁻ (Q̄C)ᵀ + M`, `Ψ = κ₁ P⁻ (Q̄C)ᵀ`, `K = Ψ Φ⁻¹` (37);
/// `x̂ = x⁻ + K (ȳ − ŷ)` (22); `P̄ = κ₁ P⁻ − K Ψᵀ` (30 at the optimal gain).
pub fn tobit_local(n: usize, received: bool) -> Ops {
    let m = 2;
    let t = tri(n);
    let tm = tri(m);
    let predict = prod(n, n, 1) + prod(n, n, n) + sym_prod(n, n) + Ops::arith(t, t, 0, 0);
    let per_component = Ops {
        sqrt: 1,
        ..Ops::arith(0, 0, 1, 1)
    } + normal_cdf() * 2
        + normal_pdf()
        + Ops::arith(1 + 3, 2, 1, 1);
    let stats = prod(m, n, 1) + per_component * m;
    // Ω₁: its diagonal only where θ = 0 (Υ∘Ω₁ with Υ diagonal), all of it at θ = 1.
    let omega1 = if received {
        Ops::arith(3 * n, n, 0, 0)
    } else {
        Ops::arith(3 * t, t, 0, 0)
    };
    let xi = Ops::arith(1, 1, 0, 0);
    let pieces = Ops::arith(m * n + 2 * m + m, 0, m, 0);
    let m_terms = if received {
        // Diagonal: (ϱ̄ R_j) + κ₈ Υ τ² + κ₆ Ξ; κ₂ v vᵀ; κ₃ C diag(Υ∘Ω₁) Cᵀ.
        Ops::arith(2 * m + 1, 2 * m, 0, 0)
            + Ops::arith(2 * tm, tm, 0, 0)
            + Ops::arith(n + m * n, 0, 0, 0)
            + sym_prod(m, n)
            + Ops::arith(tm, tm, 0, 0)
    } else {
        // κ₂ v vᵀ, κ₄ Q̄C Ω₁ (Q̄C)ᵀ, κ₅ ȳȳᵀ, κ₇ (I − Q̄)τ τᵀ(I − Q̄).
        Ops::arith(2 * tm, 0, 0, 0)
            + prod(m, n, n)
            + sym_prod(m, n)
            + Ops::arith(tm, 0, 0, 0)
            + Ops::arith(2 * tm, 0, 0, 0)
            + Ops::arith(2 * tm, 3 * tm, 0, 0)
    };
    let gain = prod(m, n, n)
        + sym_prod(m, n)
        + Ops::arith(tm, tm, 0, 0)
        + Ops::arith(n * m, 0, 0, 0)
        + inv2()
        + prod(n, m, m);
    let update = Ops::arith(0, 0, m, 0)
        + prod(n, m, 1)
        + Ops::arith(0, n, 0, 0)
        + sym_prod(n, m)
        + Ops::arith(t, 0, t, 0);
    predict + stats + omega1 + xi + pieces + m_terms + gain + update
}

/// The federated fusion (50) of `l` local bounds on `n = 2` states and the reset (51):
/// each `P̄_m⁻¹` in closed form and `P̄_m⁻¹ x̂_m`, their sums, `P^g` in closed form,
/// `x̂^g = P^g Σ P̄_m⁻¹ x̂_m`, and `α_m⁻¹ P^g` for every node.
pub fn tobit_fusion2(l: usize) -> Ops {
    let (n, t) = (2, 3);
    (inv2() + prod(n, n, 1)) * l
        + Ops::arith(0, (l - 1) * (t + n), 0, 0)
        + inv2()
        + prod(n, n, 1)
        + Ops::arith(l * t, 0, 0, 0)
}

/// One step of the Tobit fusion on `n = 2` states: the `l` local filters, `received` of them
/// with a measurement (θ = 0), then the fusion and reset.
pub fn tobit2(l: usize, received: usize) -> Ops {
    tobit_local(2, true) * received + tobit_local(2, false) * (l - received) + tobit_fusion2(l)
}

/// What one instant of the centralised moment-matched Tobit filter reads, which its work
/// depends on ([`tobit_cmm`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CmmInstant {
    /// Delivered components above their threshold: (C1) each.
    pub observed: usize,
    /// Delivered components at their threshold: (C2)-(C3) each.
    pub censored: usize,
    /// Silences the filter reads as held: (S4)-(S6) on the silence box.
    pub held: usize,
    /// Axes of those boxes bounded on both sides (the others, whose ball reaches the
    /// censoring threshold, are half-lines).
    pub bounded: usize,
}

/// The scalar projections of one component `z = c x + v`: `g = P c`, `s = c·g + r`,
/// `μ = c·x̂`.
fn component_marginal(n: usize) -> Ops {
    prod(n, n, 1) + prod(1, n, 1) + Ops::arith(0, 1, 0, 0) + prod(1, n, 1)
}

/// The moments of a standard normal below `b`: `Φ(b)`, `φ(b)`, `λ = φ/Φ`, the mean `−λ` and
/// `1 − v = λ (λ + b)`.
fn half_line_moments() -> Ops {
    normal_cdf() + normal_pdf() + Ops::arith(1, 1, 1, 1)
}

/// (C1) on one observed component: `d = y − μ`, `k = g/s`, `x̂ += k d`, `P −= k gᵀ` on the
/// upper triangle.
fn cmm_observed(n: usize) -> Ops {
    component_marginal(n) + Ops::arith(n + n + tri(n), n, 1 + tri(n), 1)
}

/// (C2)-(C3) on one censored component: `√s`, `1/√s`, `b = (τ − μ)/√s`, the moments below
/// `b`, `x̂ += g (−λ/√s)`, `P −= ((1 − v)/s) g gᵀ` on the upper triangle.
fn cmm_censored(n: usize) -> Ops {
    let standardise = Ops {
        sqrt: 1,
        ..Ops::arith(1, 0, 1, 1)
    };
    let shift_shrink = Ops::arith(1 + 2, 0, 0, 0);
    component_marginal(n)
        + standardise
        + half_line_moments()
        + shift_shrink
        + Ops::arith(n + n + tri(n), n, tri(n), 0)
}

/// One held silence on `ny` axes, every axis a half-line (`bounded` adds the other end): the
/// ball's radius `η̄ (1/χ) + σ`, the box's ends `ȳ ± r̄`; `μ = C x̂`, `G = P Cᵀ`,
/// `S = C G + R` on its upper triangle (R diagonal); per axis j `√S_jj`, `1/√S_jj`,
/// `b = (u_j − μ_j)/√S_jj`, the truncated moments, `shift = √S_jj m`, `f = (1 − v) S_jj`,
/// `k_x = G_j/S_jj`, `x̂ += k_x shift`, `P −= (f k_x) k_xᵀ`, and for each later axis i
/// `k_z,i = S_ij/S_jj`, `μ_i += k_z,i shift`, `G_i −= (f k_x) k_z,i` and `S` among the later
/// axes `−= (f k_z,i) k_z,i'`.
fn cmm_held(n: usize, ny: usize) -> Ops {
    let ball = Ops::arith(1, 1, 0, 0) + Ops::arith(0, ny, ny, 0);
    let joint = prod(ny, n, 1) + prod(n, n, ny) + sym_prod(ny, n) + Ops::arith(0, ny, 0, 0);
    let mut ops = ball + joint;
    for j in 0..ny {
        let later = ny - 1 - j;
        let axis = Ops {
            sqrt: 1,
            ..Ops::arith(1, 0, 1, 1)
        } + half_line_moments()
            + Ops::arith(1 + 1 + 1 + n, 0, 0, 0)
            + Ops::arith(n, n, 0, 0)
            + Ops::arith(n + tri(n), 0, tri(n), 0);
        let coupled =
            Ops::arith(1 + 1 + n + 1, 1, n, 0) * later + Ops::arith(tri(later), 0, tri(later), 0);
        ops = ops + axis + coupled;
    }
    ops
}

/// What a bounded axis of a held box adds to a half-line: the lower end standardised
/// (`a = (ℓ_j − μ_j)/√S_jj`, its `Φ` and `φ`), and `Z = Φ(b) − Φ(a)`, `1/Z`,
/// `m = (φ(a) − φ(b))/Z`, `1 − v = (bφ(b) − aφ(a))/Z + m²` (5 mul, 1 add, 3 sub, 1 div) in
/// place of the half-line's `λ`, `−λ`, `λ (λ + b)` (1 mul, 1 add, 1 sub, 1 div).
fn cmm_bounded_axis() -> Ops {
    normal_cdf() + normal_pdf() + Ops::arith(1 + 4, 0, 1 + 2, 0)
}

/// One instant of the centralised moment-matched Tobit filter (docs/tobit-fusion.md, "At the
/// information bound") on `n` states, `l` nodes of `ny` components each: the Kalman
/// prediction; (C1) on every observed component, (C2)-(C3) on every censored one; every
/// node's trigger knowledge (a node that sent: `‖ȳ − y‖`, `χ(‖ε‖ − σ)`, `η̄ ← λ η̄ + σ`; a
/// silent one: `η̄ ← λ η̄ + σ`); and (S4)-(S6) on every held silence read. The bucket mirror
/// is integer work, not counted.
pub fn tobit_cmm(n: usize, ny: usize, l: usize, w: CmmInstant) -> Ops {
    let sent = (w.observed + w.censored) / ny;
    let delivered = Ops {
        sqrt: 1,
        ..Ops::arith(ny + 1 + 1, ny - 1 + 1, ny + 1, 0)
    };
    let silent = Ops::arith(1, 1, 0, 0);
    kf_predict(n)
        + cmm_observed(n) * w.observed
        + cmm_censored(n) * w.censored
        + delivered * sent
        + silent * (l - sent)
        + cmm_held(n, ny) * w.held
        + cmm_bounded_axis() * w.bounded
}

/// [`tobit_cmm`] on seed 004's example (3 nodes, 2 states, 2 components) for what the
/// firmware's branch code tells: `sent` nodes delivered, `censored` of them with a censored
/// component, `held` silences read. The floor is the least work of such a step: one censored
/// component per censored node, every held box open below on both axes (the commonest box
/// on the example's stream, whose silence balls mostly reach τ = 0).
pub fn tobit_cmm2(sent: usize, censored: usize, held: usize) -> Ops {
    tobit_cmm(
        2,
        2,
        3,
        CmmInstant {
            observed: 2 * sent - censored,
            censored,
            held,
            bounded: 0,
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// (mul, add, sub, div) and the calls (sqrt, exp, ln, erfc, sin, cos, tanh).
    fn of(o: Ops) -> ([usize; 4], [usize; 7]) {
        (
            [o.mul, o.add, o.sub, o.div],
            [o.sqrt, o.exp, o.ln, o.erfc, o.sin, o.cos, o.tanh],
        )
    }

    #[test]
    fn kalman_counts_are_the_firmware_floors() {
        // estimator-firmware's peers::ops: 122 + 85 + 10 + 1, 221 + 168 + 14 + 1, 54 + 42.
        assert_eq!(of(kf(3, false)), ([122, 85, 10, 1], [0; 7]));
        assert_eq!(of(kf(4, false)), ([221, 168, 14, 1], [0; 7]));
        assert_eq!(of(kf(3, true)), ([54, 42, 0, 0], [0; 7]));
    }

    #[test]
    fn building_blocks() {
        // Cholesky of 6 × 6: 35 mul and sub, 15 div, 6 sqrt; two solves: 30 mul and sub,
        // 12 div.
        assert_eq!(
            of(cholesky_solve(6)),
            ([65, 0, 65, 27], [6, 0, 0, 0, 0, 0, 0])
        );
        assert_eq!(
            of(cholesky_solve(2)),
            ([1 + 2, 0, 1 + 2, 1 + 4], [2, 0, 0, 0, 0, 0, 0])
        );
        assert_eq!(
            of(truncated_moments()),
            ([15, 1, 4, 1], [0, 2, 0, 2, 0, 0, 0])
        );
    }

    /// The figures the firmware README and BENCHMARKS.md print, on the firmware's
    /// dimensions: seed 001's 3 states, 2 measurements, 4 regions, 15 Gaussians; seed 003's
    /// example; seed 004's 3 nodes on 2 states.
    #[test]
    fn the_firmware_estimators() {
        assert_eq!(of(cce(3, 4, 15, false)), of(kf(3, false)));
        assert_eq!(
            of(cce(3, 4, 15, true)),
            ([275, 102, 162, 5], [0, 15, 5, 0, 0, 0, 0])
        );
        assert_eq!(
            of(adf(3, 4, true)),
            ([120, 62, 26, 4], [1, 2, 1, 2, 0, 0, 0])
        );
        assert_eq!(
            of(adf(3, 4, false)),
            ([191, 106, 38, 5], [1, 2, 1, 2, 0, 0, 0])
        );
        assert_eq!(of(kf_io(3, 4)), ([173, 99, 24, 2], [1, 0, 0, 2, 0, 0, 0]));
        assert_eq!(
            of(nn_seed003(true, true)),
            ([512, 277, 82, 29], [8, 0, 0, 0, 1, 1, 6])
        );
        assert_eq!(
            of(nn_seed003(false, false)),
            ([135, 80, 1, 0], [2, 0, 0, 0, 1, 1, 6])
        );
        assert_eq!(
            of(tobit_local(2, true)),
            ([137, 55, 13, 5], [2, 2, 0, 4, 0, 0, 0])
        );
        assert_eq!(
            of(tobit_local(2, false)),
            ([149, 59, 13, 5], [2, 2, 0, 4, 0, 0, 0])
        );
        assert_eq!(of(tobit_fusion2(3)), ([45, 18, 8, 4], [0; 7]));
        assert_eq!(
            of(tobit2(3, 0)),
            ([492, 195, 47, 19], [6, 6, 0, 12, 0, 0, 0])
        );
    }

    /// The moment-matched Tobit filter's pieces on n = 2, counted by hand: an observed
    /// component (g 4 + 2, s 2 + 2, μ 2 + 1, k 2, x̂ 2 + 2, P 3 + 3, d, 1/s); a censored one
    /// (the same projections, √s and 1/√s, b, Φ and φ, λ, −λ, λ (λ + b), the shift and
    /// shrink, x̂ 2 + 2, P 2 + 3 + 3); a held silence on two half-lines; a bounded axis.
    #[test]
    fn the_moment_matched_tobit_filter() {
        assert_eq!(of(cmm_observed(2)), ([15, 7, 4, 1], [0; 7]));
        assert_eq!(of(cmm_censored(2)), ([25, 8, 5, 2], [1, 1, 0, 1, 0, 0, 0]));
        assert_eq!(of(cmm_held(2, 2)), ([63, 21, 15, 4], [2, 2, 0, 2, 0, 0, 0]));
        assert_eq!(
            of(cmm_bounded_axis()),
            ([10, 0, 3, 0], [0, 1, 0, 1, 0, 0, 0])
        );
        // Nothing read: the prediction (18 + 12) and three silent nodes' η̄.
        assert_eq!(of(tobit_cmm2(0, 0, 0)), ([21, 15, 0, 0], [0; 7]));
        assert_eq!(
            of(tobit_cmm2(0, 0, 3)),
            ([210, 78, 45, 12], [6, 6, 0, 6, 0, 0, 0])
        );
        assert_eq!(
            of(tobit_cmm2(3, 0, 0)),
            ([120, 60, 33, 6], [3, 0, 0, 0, 0, 0, 0])
        );
        assert_eq!(
            of(tobit_cmm2(3, 3, 0)),
            ([150, 63, 36, 9], [6, 3, 0, 3, 0, 0, 0])
        );
        // A bounded axis adds its piece; a second censored component of a node replaces an
        // observed one.
        let w = CmmInstant {
            observed: 3,
            censored: 1,
            held: 1,
            bounded: 1,
        };
        assert_eq!(
            tobit_cmm(2, 2, 3, w),
            tobit_cmm2(2, 1, 1) + cmm_bounded_axis()
        );
        let two = CmmInstant {
            observed: 0,
            censored: 2,
            ..CmmInstant::default()
        };
        assert_eq!(
            tobit_cmm(2, 2, 3, two) + cmm_observed(2),
            tobit_cmm2(1, 1, 0) + cmm_censored(2)
        );
    }
}
