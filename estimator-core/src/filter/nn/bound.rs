//! Seed 003, Theorems 1 and 2: the upper bounds `P̄_k ≥ E[e eᵀ]`, `Q̄_k ≥ E[H̃ H̃ᵀ]`
//! ((14)-(17)) and the gain `L_k` that minimises `tr(P̄_{k+1} + Q̄_{k+1})` ((33)-(35)).
//!
//! The scalars `α_i` (i = 1..4), `β_i` (i = 1..12), `θ₁, θ₂` and the bounds `H̄, φ̄, ε̄, w̄²`
//! form the validated [`NnBoundConfig`]. The paper allows `α_{i,k}, β_{i,k}` to vary with `k`;
//! its example (and this configuration) keeps them constant.

use nalgebra::{SMatrix, SVector};

use crate::linalg::eig::max_eigenvalue;
use crate::linalg::kron::{solve_kron_spd, solve_two_sided_spd};
use crate::linalg::{check_finite, symmetrize};
use crate::{Error, Real, Result};

/// Validated scalars of Theorems 1-2.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NnBoundConfig<T: Real> {
    pub(crate) alpha: [T; 4],
    pub(crate) beta: [T; 12],
    pub(crate) theta: [T; 2],
    pub(crate) h_bar: T,
    pub(crate) phi_bar: T,
    pub(crate) eps_bar: T,
    pub(crate) w_bar_sq: T,
}

const ALPHA_NAMES: [&str; 4] = ["alpha[1]", "alpha[2]", "alpha[3]", "alpha[4]"];
const BETA_NAMES: [&str; 12] = [
    "beta[1]", "beta[2]", "beta[3]", "beta[4]", "beta[5]", "beta[6]", "beta[7]", "beta[8]",
    "beta[9]", "beta[10]", "beta[11]", "beta[12]",
];

fn positive<T: Real>(v: T, field: &'static str) -> Result<()> {
    if !v.finite() {
        return Err(Error::NonFinite { what: field });
    }
    if v <= T::zero() {
        return Err(Error::InvalidConfig {
            field,
            reason: "must be a positive scalar (seed 003, Theorems 1-2)",
        });
    }
    Ok(())
}

impl<T: Real> NnBoundConfig<T> {
    /// `alpha = [α₁..α₄]`, `beta = [β₁..β₁₂]`, `theta = [θ₁, θ₂]` (tuning law (6)), `H̄ ≥ ‖H‖`,
    /// `φ̄ ≥ ‖φ(·)‖`, `ε̄ ≥ ‖ε_k‖`, `w̄² ≥ E[wᵀw]`. All must be finite and positive.
    pub fn new(
        alpha: [T; 4],
        beta: [T; 12],
        theta: [T; 2],
        h_bar: T,
        phi_bar: T,
        eps_bar: T,
        w_bar_sq: T,
    ) -> Result<Self> {
        for (v, n) in alpha.iter().zip(ALPHA_NAMES) {
            positive(*v, n)?;
        }
        for (v, n) in beta.iter().zip(BETA_NAMES) {
            positive(*v, n)?;
        }
        positive(theta[0], "theta[1]")?;
        positive(theta[1], "theta[2]")?;
        positive(h_bar, "H_bar")?;
        positive(phi_bar, "phi_bar")?;
        positive(eps_bar, "eps_bar")?;
        positive(w_bar_sq, "w_bar_sq")?;
        Ok(Self {
            alpha,
            beta,
            theta,
            h_bar,
            phi_bar,
            eps_bar,
            w_bar_sq,
        })
    }

    /// `[θ₁, θ₂]`.
    #[inline]
    pub fn theta(&self) -> [T; 2] {
        self.theta
    }
    /// `φ̄`.
    #[inline]
    pub fn phi_bar(&self) -> T {
        self.phi_bar
    }
    /// `H̄`.
    #[inline]
    pub fn h_bar(&self) -> T {
        self.h_bar
    }
    /// `w̄²`.
    #[inline]
    pub fn w_bar_sq(&self) -> T {
        self.w_bar_sq
    }

    /// `δ₁ = (1 + β₁ + … + β₅)(1 − θ₁θ₂)²` of (16): the factor by which `Q̄` is multiplied each
    /// step. `δ₁ ≥ 1` makes the bound grow at least geometrically.
    pub fn delta1(&self) -> T {
        let b = &self.beta;
        let s = T::one() + b[0] + b[1] + b[2] + b[3] + b[4];
        let m = T::one() - self.theta[0] * self.theta[1];
        s * m * m
    }

    /// `(2φ̄H̄ + ε̄)²`, the bound on `‖ε̄_k‖²` used in (14) and (17).
    fn eps_sq(&self) -> T {
        let v = T::lit(2.0) * self.phi_bar * self.h_bar + self.eps_bar;
        v * v
    }

    /// The coefficients of (14): `(1+α₁+α₂, 1+α₁⁻¹+α₃+α₄, 1+α₃⁻¹, 1+α₂⁻¹+α₄⁻¹)`.
    fn p_coeffs(&self) -> [T; 4] {
        let [a1, a2, a3, a4] = self.alpha;
        let one = T::one();
        [
            one + a1 + a2,
            one + one / a1 + a3 + a4,
            one + one / a3,
            one + one / a2 + one / a4,
        ]
    }

    /// `δ₁, δ̄₂ … δ̄₇` of (16)-(17) for an instant whose next measurement is (`gamma_next`) or
    /// is not transmitted, with `m_norm = ‖C_{k+1}ᵀ C_{k+1}‖₂`.
    pub fn deltas(&self, gamma_next: bool, m_norm: T) -> Deltas<T> {
        let b = &self.beta;
        let one = T::one();
        let [t1, t2] = self.theta;
        let g = if gamma_next { t1 * t1 } else { T::zero() };
        let d2 = (one + one / b[0] + b[5] + b[6] + b[7]) * g;
        let d3 = (one + one / b[1] + one / b[5] + b[8] + b[9] + b[10]) * g;
        let d4 = (one + one / b[2] + one / b[8]) * g;
        let d5 = (one + one / b[3] + one / b[6] + one / b[9] + b[11]) * g;
        let d6 = g;
        let d7 = (one + one / b[4] + one / b[7] + one / b[10] + one / b[11]) * t1 * t1 * t2 * t2;
        // Every δ̄ divided by ‖M‖² multiplies a term carrying M (or Cᵀ D), so C = 0 zeroes it.
        let inv_m2 = if m_norm > T::zero() {
            one / (m_norm * m_norm)
        } else {
            T::zero()
        };
        let phi2 = self.phi_bar * self.phi_bar;
        Deltas {
            d1: self.delta1(),
            d2: d2 * inv_m2,
            d3: d3 * phi2 * inv_m2,
            d4: d4 * self.w_bar_sq * inv_m2,
            d5: d5 * self.eps_sq(),
            d6: d6 * self.w_bar_sq * inv_m2,
            d7: d7 * self.h_bar * self.h_bar,
        }
    }
}

/// `δ₁` and `δ̄₂ … δ̄₇` of (16)-(17) for one instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Deltas<T: Real> {
    /// `δ₁`.
    pub d1: T,
    /// `δ̄₂ = δ₂/‖M‖²`.
    pub d2: T,
    /// `δ̄₃ = δ₃ φ̄²/‖M‖²`.
    pub d3: T,
    /// `δ̄₄ = δ₄ w̄²/‖M‖²`.
    pub d4: T,
    /// `δ̄₅ = δ₅ (2φ̄H̄ + ε̄)²`.
    pub d5: T,
    /// `δ̄₆ = δ₆ w̄²/‖M‖²`.
    pub d6: T,
    /// `δ̄₇ = δ₇ H̄²`.
    pub d7: T,
}

/// The matrices of one bound/gain step: `A_k, B_k, C_k, D_k` and `C_{k+1}, D_{k+1}`, with the
/// transmission indicators `1{μ_k ≥ 0}` and `1{μ_{k+1} ≥ 0}`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepMatrices<T: Real, const NX: usize, const NW: usize, const NY: usize> {
    /// `A_k`.
    pub a: SMatrix<T, NX, NX>,
    /// `B_k`.
    pub b: SMatrix<T, NX, NW>,
    /// `C_k`.
    pub c: SMatrix<T, NY, NX>,
    /// `D_k`.
    pub d: SMatrix<T, NY, NW>,
    /// `C_{k+1}`.
    pub c_next: SMatrix<T, NY, NX>,
    /// `D_{k+1}`.
    pub d_next: SMatrix<T, NY, NW>,
    /// `1{μ_k ≥ 0}`.
    pub gamma: bool,
    /// `1{μ_{k+1} ≥ 0}`.
    pub gamma_next: bool,
}

impl<T: Real, const NX: usize, const NW: usize, const NY: usize> StepMatrices<T, NX, NW, NY> {
    /// `M = C_{k+1}ᵀ C_{k+1}` and its spectral norm.
    pub fn m_and_norm(&self) -> Result<(SMatrix<T, NX, NX>, T)> {
        let m = self.c_next.transpose() * self.c_next;
        // ‖CᵀC‖₂ = λ_max(C Cᵀ): the smaller NY × NY problem.
        let norm = max_eigenvalue(&(self.c_next * self.c_next.transpose()), "C_{k+1}")?;
        Ok((m, norm.max(T::zero())))
    }
}

/// How the gain equation (38) is solved.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum GainSolver {
    /// The paper's (35): Cholesky solve of the `NX·NY` Kronecker system.
    #[default]
    Kronecker,
    /// Simultaneous diagonalisation of the two sides (same solution, `O(NX³ + NY³)`).
    TwoSided,
}

/// Theorem 2, (33)-(35): the gain `L_k` minimising `tr(P̄_{k+1} + Q̄_{k+1})` given `P̄_k`.
///
/// Only meaningful when `1{μ_k ≥ 0} = 1` (otherwise `L_k` does not enter (5) or (14)).
/// `NP` must equal `NX·NY` (checked at compile time by the Kronecker solve).
pub fn optimal_gain<T: Real, const NX: usize, const NW: usize, const NY: usize, const NP: usize>(
    cfg: &NnBoundConfig<T>,
    p: &SMatrix<T, NX, NX>,
    s: &StepMatrices<T, NX, NW, NY>,
    solver: GainSolver,
) -> Result<SMatrix<T, NX, NY>> {
    let (m, m_norm) = s.m_and_norm()?;
    let dl = cfg.deltas(s.gamma_next, m_norm);
    let [c1, _, c3, _] = cfg.p_coeffs();
    let mm = m * m;
    let id = SMatrix::<T, NX, NX>::identity();
    let t1 = symmetrize(&(id * c1 + mm * dl.d2));
    let t2 = symmetrize(&(s.c * p * s.c.transpose()));
    let t3 = symmetrize(&(id * (c3 * cfg.w_bar_sq) + mm * dl.d4));
    let t4 = symmetrize(&(s.d * s.d.transpose()));
    let apc = s.a * p * s.c.transpose();
    let bd = s.b * s.d.transpose();
    let phi = apc * c1 + bd * (c3 * cfg.w_bar_sq) + mm * apc * dl.d2 + mm * bd * dl.d4;
    match solver {
        GainSolver::Kronecker => solve_kron_spd::<T, NX, NY, NP>(&t1, &t2, &t3, &t4, &phi),
        GainSolver::TwoSided => solve_two_sided_spd(&t1, &t2, &t3, &t4, &phi),
    }
}

/// Theorem 1, (14)-(15): `(P̄_{k+1}, Q̄_{k+1})` from `(P̄_k, Q̄_k)` for a given gain `L_k`.
///
/// In (15) the factor printed `C_{k+1} C_{k+1}` after `Ā P̄ Āᵀ` is read as `C_{k+1}ᵀ C_{k+1}`
/// (docs/design.md, "Seed 003": the only dimensionally valid reading).
pub fn propagate_bounds<T: Real, const NX: usize, const NW: usize, const NY: usize>(
    cfg: &NnBoundConfig<T>,
    p: &SMatrix<T, NX, NX>,
    q: &SMatrix<T, NX, NX>,
    l: &SMatrix<T, NX, NY>,
    s: &StepMatrices<T, NX, NW, NY>,
) -> Result<(SMatrix<T, NX, NX>, SMatrix<T, NX, NX>)> {
    let (m, m_norm) = s.m_and_norm()?;
    let dl = cfg.deltas(s.gamma_next, m_norm);
    let [c1, c2, c3, c4] = cfg.p_coeffs();
    let (a_bar, b_bar) = if s.gamma {
        (s.a - l * s.c, s.b - l * s.d)
    } else {
        (s.a, s.b)
    };
    let id = SMatrix::<T, NX, NX>::identity();
    let apa = a_bar * p * a_bar.transpose();
    let bb = b_bar * b_bar.transpose();
    let phi2 = cfg.phi_bar * cfg.phi_bar;
    let p_next = apa * c1 + q * (c2 * phi2) + bb * (c3 * cfg.w_bar_sq) + id * (c4 * cfg.eps_sq());
    let cd = s.c_next.transpose() * s.d_next;
    let q_next = q * dl.d1
        + m * apa * m * dl.d2
        + m * q * m * dl.d3
        + m * bb * m * dl.d4
        + id * (dl.d5 + dl.d7)
        + cd * cd.transpose() * dl.d6;
    let p_next = symmetrize(&p_next);
    let q_next = symmetrize(&q_next);
    check_finite(
        &p_next,
        "bound P̄ (overflow: see the assumption checker, δ₁ ≥ 1)",
    )?;
    check_finite(
        &q_next,
        "bound Q̄ (overflow: see the assumption checker, δ₁ ≥ 1)",
    )?;
    Ok((p_next, q_next))
}

/// `φ̄(x̂_k) = φ / (|1 + φᵀφ| ‖C_{k+1}ᵀ C_{k+1}‖)`, the normalised regressor of (6).
/// Returns 0 when `C_{k+1} = 0` (the update term then vanishes anyway).
pub fn normalised_regressor<T: Real, const NPHI: usize>(
    phi: &SVector<T, NPHI>,
    m_norm: T,
) -> SVector<T, NPHI> {
    let den = (T::one() + phi.dot(phi)).abs() * m_norm;
    if den > T::zero() {
        phi / den
    } else {
        SVector::zeros()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn config_rejects_bad_scalars_by_name() {
        let bad = |r: Result<NnBoundConfig<f64>>| match r {
            Err(Error::InvalidConfig { field, .. }) | Err(Error::NonFinite { what: field }) => {
                field
            }
            other => panic!("{other:?}"),
        };
        assert_eq!(
            bad(NnBoundConfig::new(
                [0.1, 0.0, 0.1, 0.1],
                [0.9; 12],
                [1e-3; 2],
                8.0,
                1.0,
                0.1,
                0.1
            )),
            "alpha[2]"
        );
        let mut beta = [0.9; 12];
        beta[9] = -1.0;
        assert_eq!(
            bad(NnBoundConfig::new(
                [0.1; 4], beta, [1e-3; 2], 8.0, 1.0, 0.1, 0.1
            )),
            "beta[10]"
        );
        assert_eq!(
            bad(NnBoundConfig::new(
                [0.1; 4],
                [0.9; 12],
                [1e-3, f64::NAN],
                8.0,
                1.0,
                0.1,
                0.1
            )),
            "theta[2]"
        );
        assert_eq!(
            bad(NnBoundConfig::new(
                [0.1; 4], [0.9; 12], [1e-3; 2], 8.0, 0.0, 0.1, 0.1
            )),
            "phi_bar"
        );
    }
}
