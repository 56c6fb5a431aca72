//! The two-sided linear matrix equation `Θ₁ L Θ₂ + Θ₃ L Θ₄ = Φ` (seed 003, (38)), solved two
//! independent ways:
//!
//! * [`solve_kron_spd`]: the paper's (35)/(41), `vec(L) = Θ̄⁻¹ vec(Φ)` with
//!   `Θ̄ = Θ₂ᵀ ⊗ Θ₁ + Θ₄ᵀ ⊗ Θ₃` (Lemma 3: `vec(AXB) = (Bᵀ ⊗ A) vec(X)`), by a Cholesky solve of
//!   the `NM × NM` system. The product dimension is its own const parameter `P`, checked equal to
//!   `N·M` at compile time.
//! * [`solve_two_sided_spd`]: simultaneous diagonalisation, `O(N³ + M³)` without forming the
//!   Kronecker matrix: with `Θ₁ = W Wᵀ`, `Θ₃ = W Λ Wᵀ` and `Θ₂ = Z Σ Zᵀ`, `Θ₄ = Z (I − Σ) Zᵀ`,
//!   the substitution `Y = Wᵀ L Z` decouples the equation into
//!   `Y_ij (σ_j + λ_i (1 − σ_j)) = (W⁻¹ Φ Z⁻ᵀ)_ij`.
//!
//! Both require `Θ₁` symmetric positive definite, `Θ₂, Θ₃, Θ₄` symmetric positive
//! semi-definite and `Θ̄` positive definite (in Theorem 2: `Θ₃ ≻ 0` and `Θ₂ + Θ₄ ≻ 0`).

use nalgebra::{SMatrix, SVector};

use super::eig::symmetric_eigen;
use super::{check_finite, cholesky, solve_spd, symmetrize};
use crate::{Error, Real, Result};

/// `vec(X)`: the columns of `X` stacked (Definition 1, (12)). `P` must equal `N·M`.
#[must_use]
pub fn vec<T: Real, const N: usize, const M: usize, const P: usize>(
    x: &SMatrix<T, N, M>,
) -> SMatrix<T, P, 1> {
    const { assert!(P == N * M, "vec: P must equal N·M") };
    let mut v = SMatrix::<T, P, 1>::zeros();
    for j in 0..M {
        for i in 0..N {
            v[j * N + i] = x[(i, j)];
        }
    }
    v
}

/// Inverse of [`vec`]: refills an `N × M` matrix column by column.
#[must_use]
pub fn unvec<T: Real, const N: usize, const M: usize, const P: usize>(
    v: &SMatrix<T, P, 1>,
) -> SMatrix<T, N, M> {
    const { assert!(P == N * M, "unvec: P must equal N·M") };
    let mut x = SMatrix::<T, N, M>::zeros();
    for j in 0..M {
        for i in 0..N {
            x[(i, j)] = v[j * N + i];
        }
    }
    x
}

/// The Kronecker product `B ⊗ A` for square `A` (`N × N`) and `B` (`M × M`), written as the
/// operator of `X ↦ A X Bᵀ` on `vec(X)`: entry `((j·N + i), (l·N + k)) = B[j, l] A[i, k]`.
#[must_use]
pub fn kron<T: Real, const N: usize, const M: usize, const P: usize>(
    b: &SMatrix<T, M, M>,
    a: &SMatrix<T, N, N>,
) -> SMatrix<T, P, P> {
    const { assert!(P == N * M, "kron: P must equal N·M") };
    let mut k = SMatrix::<T, P, P>::zeros();
    for j in 0..M {
        for l in 0..M {
            let bjl = b[(j, l)];
            for i in 0..N {
                for c in 0..N {
                    k[(j * N + i, l * N + c)] = bjl * a[(i, c)];
                }
            }
        }
    }
    k
}

/// `Θ̄ = Θ₂ᵀ ⊗ Θ₁ + Θ₄ᵀ ⊗ Θ₃` of (33).
#[must_use]
pub fn kron_sum<T: Real, const N: usize, const M: usize, const P: usize>(
    t1: &SMatrix<T, N, N>,
    t2: &SMatrix<T, M, M>,
    t3: &SMatrix<T, N, N>,
    t4: &SMatrix<T, M, M>,
) -> SMatrix<T, P, P> {
    kron::<T, N, M, P>(&t2.transpose(), t1) + kron::<T, N, M, P>(&t4.transpose(), t3)
}

/// Solves `Θ₁ L Θ₂ + Θ₃ L Θ₄ = Φ` as the paper's (35): `vec(L) = Θ̄⁻¹ vec(Φ)` with a Cholesky
/// solve of the symmetric positive-definite `Θ̄` (never an explicit inverse).
///
/// `P` is the product dimension `N·M`, checked at compile time.
pub fn solve_kron_spd<T: Real, const N: usize, const M: usize, const P: usize>(
    t1: &SMatrix<T, N, N>,
    t2: &SMatrix<T, M, M>,
    t3: &SMatrix<T, N, N>,
    t4: &SMatrix<T, M, M>,
    phi: &SMatrix<T, N, M>,
) -> Result<SMatrix<T, N, M>> {
    check_inputs(t1, t2, t3, t4, phi)?;
    let theta_bar = symmetrize(&kron_sum::<T, N, M, P>(t1, t2, t3, t4));
    let v = solve_spd(&theta_bar, &vec::<T, N, M, P>(phi), "Θ̄ (Kronecker sum)")?;
    Ok(unvec::<T, N, M, P>(&v))
}

/// Solves `Θ₁ L Θ₂ + Θ₃ L Θ₄ = Φ` by simultaneous diagonalisation (see the module docs), an
/// independent method that never forms the `NM × NM` Kronecker matrix. Needs `Θ₁ ≻ 0`,
/// `Θ₂ + Θ₄ ≻ 0` (either may be singular alone).
pub fn solve_two_sided_spd<T: Real, const N: usize, const M: usize>(
    t1: &SMatrix<T, N, N>,
    t2: &SMatrix<T, M, M>,
    t3: &SMatrix<T, N, N>,
    t4: &SMatrix<T, M, M>,
    phi: &SMatrix<T, N, M>,
) -> Result<SMatrix<T, N, M>> {
    check_inputs(t1, t2, t3, t4, phi)?;
    // Θ₁ = R Rᵀ; R⁻¹ Θ₃ R⁻ᵀ = U Λ Uᵀ ⇒ W = R U gives Θ₁ = W Wᵀ, Θ₃ = W Λ Wᵀ.
    let (r1, lam, u1) = diagonalise_pair(t1, t3, ["Θ₁", "Θ₁ factor", "R⁻¹ Θ₃ R⁻ᵀ"])?;
    // W⁻¹ Φ = Uᵀ R⁻¹ Φ.
    let r_inv_phi = r1.solve_lower_triangular(phi).ok_or(Error::Numerical {
        what: "Θ₁ factor"
    })?;
    let w_inv_phi_rows = u1.transpose() * r_inv_phi;
    // Θ₂ may be singular (C_k of the seed 003 example has rank 1 at k = 0) while Θ₂ + Θ₄ is
    // not: factor G = Θ₂ + Θ₄ = S Sᵀ, S⁻¹ Θ₂ S⁻ᵀ = V Σ Vᵀ, so with Z = S V: Θ₂ = Z Σ Zᵀ and
    // Θ₄ = Z (I − Σ) Zᵀ, σ_j ∈ [0, 1].
    let (s, sigma, v) =
        diagonalise_pair(&(t2 + t4), t2, ["Θ₂ + Θ₄", "Θ₂ + Θ₄ factor", "S⁻¹ Θ₂ S⁻ᵀ"])?;
    // F = W⁻¹ Φ Z⁻ᵀ with Z = S V: (W⁻¹Φ) S⁻ᵀ V = ((S⁻¹ (W⁻¹Φ)ᵀ)ᵀ) V.
    let s_inv_ft = s
        .solve_lower_triangular(&w_inv_phi_rows.transpose())
        .ok_or(Error::Numerical {
            what: "Θ₂ + Θ₄ factor",
        })?;
    let f = s_inv_ft.transpose() * v;
    let y = divide_by_pair_eigenvalues(&f, &lam, &sigma)?;
    // L = W⁻ᵀ Y Z⁻¹ = R⁻ᵀ U Y Vᵀ S⁻¹.
    let uy = u1 * y * v.transpose();
    let left = r1
        .transpose()
        .solve_upper_triangular(&uy)
        .ok_or(Error::Numerical {
            what: "Θ₁ factor"
        })?;
    // X S⁻¹ = left ⇔ Sᵀ Xᵀ = leftᵀ.
    let lt = s
        .transpose()
        .solve_upper_triangular(&left.transpose())
        .ok_or(Error::Numerical {
            what: "Θ₂ factor"
        })?;
    let l = lt.transpose();
    check_finite(&l, "two-sided solve")?;
    Ok(l)
}

/// Simultaneous diagonalisation of the pair `(A, B)`, `A ≻ 0`: `A = L Lᵀ` (Cholesky) and
/// `L⁻¹ B L⁻ᵀ = U Λ Uᵀ`, so that `W = L U` gives `A = W Wᵀ`, `B = W Λ Wᵀ`. Returns
/// `(L, Λ, U)`; `names` are the factorisation's, the factor's solves' and the eigenproblem's.
#[inline(always)]
fn diagonalise_pair<T: Real, const N: usize>(
    a: &SMatrix<T, N, N>,
    b: &SMatrix<T, N, N>,
    names: [&'static str; 3],
) -> Result<(SMatrix<T, N, N>, SVector<T, N>, SMatrix<T, N, N>)> {
    let [chol_name, factor_name, eigen_name] = names;
    let l = cholesky(a, chol_name)?.l();
    let lb = l
        .solve_lower_triangular(b)
        .ok_or(Error::Numerical { what: factor_name })?;
    let m = symmetrize(
        &l.solve_lower_triangular(&lb.transpose())
            .ok_or(Error::Numerical { what: factor_name })?,
    );
    let (lam, u) = symmetric_eigen(&m, eigen_name)?;
    Ok((l, lam, u))
}

/// `Y_ij = F_ij / (σ_j + λ_i (1 − σ_j))`: the two-sided equation in the pairs' common bases.
/// The divisors are the eigenvalues of Θ̄ in that basis, positive iff Θ̄ is positive definite;
/// one not above `√ε` is refused.
#[inline(always)]
fn divide_by_pair_eigenvalues<T: Real, const N: usize, const M: usize>(
    f: &SMatrix<T, N, M>,
    lam: &SVector<T, N>,
    sigma: &SVector<T, M>,
) -> Result<SMatrix<T, N, M>> {
    let mut y = *f;
    for i in 0..N {
        for j in 0..M {
            // Y_ij (σ_j + λ_i (1 − σ_j)) = F_ij: these are the eigenvalues of Θ̄ in the new
            // basis, positive iff Θ̄ is positive definite.
            let d = sigma[j] + lam[i] * (T::one() - sigma[j]);
            if !d.finite() || d <= T::EPS.sqrt() {
                return Err(Error::NotPositiveDefinite {
                    what: "Θ̄ = Θ₂ᵀ⊗Θ₁ + Θ₄ᵀ⊗Θ₃ (two-sided solve)",
                });
            }
            y[(i, j)] = f[(i, j)] / d;
        }
    }
    Ok(y)
}

fn check_inputs<T: Real, const N: usize, const M: usize>(
    t1: &SMatrix<T, N, N>,
    t2: &SMatrix<T, M, M>,
    t3: &SMatrix<T, N, N>,
    t4: &SMatrix<T, M, M>,
    phi: &SMatrix<T, N, M>,
) -> Result<()> {
    check_finite(t1, "Θ₁")?;
    check_finite(t2, "Θ₂")?;
    check_finite(t3, "Θ₃")?;
    check_finite(t4, "Θ₄")?;
    check_finite(phi, "Φ")
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::matrix;

    #[test]
    fn kron_matches_lemma_3() {
        // vec(A X B) = (Bᵀ ⊗ A) vec(X) for a random-looking 3×2 X.
        let a = matrix![1.0, 2.0, 0.5; -1.0, 0.3, 2.0; 0.7, 0.0, -1.5];
        let b = matrix![0.4, -2.0; 1.1, 0.9];
        let x = matrix![1.0, -0.5; 2.0, 0.25; -3.0, 4.0];
        let lhs = vec::<f64, 3, 2, 6>(&(a * x * b));
        let rhs = kron::<f64, 3, 2, 6>(&b.transpose(), &a) * vec::<f64, 3, 2, 6>(&x);
        assert!((lhs - rhs).amax() < 1e-14);
        assert_eq!(unvec::<f64, 3, 2, 6>(&vec::<f64, 3, 2, 6>(&x)), x);
    }

    type Example = (
        SMatrix<f64, 3, 3>,
        SMatrix<f64, 2, 2>,
        SMatrix<f64, 3, 3>,
        SMatrix<f64, 2, 2>,
        SMatrix<f64, 3, 2>,
    );

    fn example() -> Example {
        // Θ₄ rank 1 (D Dᵀ with D 2×1), as in the seed 003 example.
        let d = matrix![0.95; 0.4];
        (
            matrix![1.2, 0.1, 0.0; 0.1, 1.3, 0.2; 0.0, 0.2, 1.1],
            matrix![5.0, 1.0; 1.0, 3.0],
            matrix![1.1, 0.0, 0.05; 0.0, 1.1, 0.0; 0.05, 0.0, 1.1],
            d * d.transpose(),
            matrix![1.0, -2.0; 0.5, 3.0; 4.0, 0.0],
        )
    }

    #[test]
    fn kronecker_and_two_sided_solves_agree_and_satisfy_the_equation() {
        let (t1, t2, t3, t4, phi) = example();
        let lk = solve_kron_spd::<f64, 3, 2, 6>(&t1, &t2, &t3, &t4, &phi).unwrap();
        let ld = solve_two_sided_spd(&t1, &t2, &t3, &t4, &phi).unwrap();
        let resid = |l: &SMatrix<f64, 3, 2>| (t1 * l * t2 + t3 * l * t4 - phi).amax();
        assert!(resid(&lk) < 1e-13, "{}", resid(&lk));
        assert!(resid(&ld) < 1e-13, "{}", resid(&ld));
        assert!((lk - ld).amax() < 1e-13);
        // f32 agrees to single precision.
        let c = |m: &SMatrix<f64, 3, 3>| m.map(|v| v as f32);
        let c2 = |m: &SMatrix<f64, 2, 2>| m.map(|v| v as f32);
        let l32 = solve_kron_spd::<f32, 3, 2, 6>(
            &c(&t1),
            &c2(&t2),
            &c(&t3),
            &c2(&t4),
            &phi.map(|v| v as f32),
        )
        .unwrap();
        assert!((l32.map(|v| v as f64) - lk).amax() < 1e-5);
    }

    #[test]
    fn singular_theta2_is_fine_when_theta_bar_is_definite() {
        // Seed 003 at k = 0: C₀ has two equal rows, so Θ₂ = C P Cᵀ has rank 1; D₀ = [0.95, 0]ᵀ
        // makes Θ₄ = D Dᵀ cover the other direction.
        let (t1, _, t3, _, phi) = example();
        let t2 = matrix![3.0, 3.0; 3.0, 3.0];
        let t4 = matrix![0.9025, 0.0; 0.0, 0.0];
        let lk = solve_kron_spd::<f64, 3, 2, 6>(&t1, &t2, &t3, &t4, &phi).unwrap();
        let ld = solve_two_sided_spd(&t1, &t2, &t3, &t4, &phi).unwrap();
        assert!((t1 * lk * t2 + t3 * lk * t4 - phi).amax() < 1e-12);
        assert!((lk - ld).amax() < 1e-12);
    }

    #[test]
    fn rejects_non_finite_and_indefinite() {
        let (t1, t2, t3, t4, mut phi) = example();
        phi[(0, 0)] = f64::NAN;
        assert_eq!(
            solve_kron_spd::<f64, 3, 2, 6>(&t1, &t2, &t3, &t4, &phi),
            Err(Error::NonFinite { what: "Φ" })
        );
        assert!(solve_two_sided_spd(&t1, &t2, &t3, &t4, &phi).is_err());
        let (t1, _, t3, t4, phi) = example();
        let bad = matrix![1.0, 2.0; 2.0, 1.0];
        assert!(solve_two_sided_spd(&t1, &bad, &t3, &t4, &phi).is_err());
        assert!(solve_kron_spd::<f64, 3, 2, 6>(&(-t1), &bad, &t3, &t4, &phi).is_err());
    }
}
