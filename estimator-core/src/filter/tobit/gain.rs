//! The gain of a local Tobit filter (seed 004, Theorem 2 (37)) as the minimiser of the trace
//! of its bound (30), which is a quadratic in the gain `K`.
//!
//! Since (30) is `κ₁(I − KQ̄C)P̄(…)ᵀ + K M Kᵀ`, the gain (37) is exactly its trace minimiser and
//! (30) is evaluated in that Joseph-like form for any gain ([`GainProblem::bound`]).
//!
//! Numerics: Φ scales like `Q̄²` in components whose prediction is far below the threshold,
//! so the gain is solved on the Jacobi-equilibrated `D Φ D` (`D = diag(Φ)^{-1/2}`); a component
//! whose `Φ_jj` underflowed to 0 (so `ϱ̄_j ≈ 0`) carries no information and gets a zero gain
//! column.

use nalgebra::{SMatrix, SVector};

use crate::linalg::{check_finite, solve_spd_right, symmetrize};
use crate::{Error, Real, Result};

/// The quadratic in K whose trace (30) the gain (37) minimises:
/// `P̄(K) = κ₁ (I − K Q̄C) P̄⁻ (I − K Q̄C)ᵀ + K M Kᵀ`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GainProblem<T: Real, const NX: usize, const NY: usize> {
    /// κ₁.
    pub kappa1: T,
    /// P̄_{t|t−1}.
    pub p_prior: SMatrix<T, NX, NX>,
    /// Q̄ C.
    pub qc: SMatrix<T, NY, NX>,
    /// M: every term of (30) that is `K (·) Kᵀ`.
    pub m: SMatrix<T, NY, NY>,
}

impl<T: Real, const NX: usize, const NY: usize> GainProblem<T, NX, NY> {
    /// Ψ of (37).
    #[must_use]
    pub fn psi(&self) -> SMatrix<T, NX, NY> {
        self.p_prior * self.qc.transpose() * self.kappa1
    }

    /// Φ of (37).
    #[must_use]
    pub fn phi(&self) -> SMatrix<T, NY, NY> {
        symmetrize(&(self.qc * self.p_prior * self.qc.transpose() * self.kappa1 + self.m))
    }

    /// Eq. (30) for an arbitrary gain.
    #[must_use]
    pub fn bound(&self, k: &SMatrix<T, NX, NY>) -> SMatrix<T, NX, NX> {
        let i_kqc = SMatrix::<T, NX, NX>::identity() - k * self.qc;
        symmetrize(
            &(i_kqc * self.p_prior * i_kqc.transpose() * self.kappa1 + k * self.m * k.transpose()),
        )
    }

    /// Eq. (37), `K = Ψ Φ⁻¹`, by a Cholesky solve on the equilibrated Φ.
    pub fn gain(&self) -> Result<SMatrix<T, NX, NY>> {
        let phi = self.phi();
        let psi = self.psi();
        check_finite(&phi, "gain denominator Phi")?;
        let mut scale = SVector::<T, NY>::zeros();
        for j in 0..NY {
            let d = phi[(j, j)];
            if d > T::zero() {
                scale[j] = T::one() / d.sqrt();
            } else if d < T::zero() {
                return Err(Error::NotPositiveDefinite {
                    what: "gain denominator Phi",
                });
            }
        }
        let mut phi_s = SMatrix::<T, NY, NY>::identity();
        for i in 0..NY {
            for j in 0..NY {
                if scale[i] > T::zero() && scale[j] > T::zero() {
                    phi_s[(i, j)] = phi[(i, j)] * scale[i] * scale[j];
                }
            }
        }
        let psi_s = SMatrix::<T, NX, NY>::from_fn(|r, c| psi[(r, c)] * scale[c]);
        let x = solve_spd_right(&psi_s, &phi_s, "gain denominator Phi")?;
        Ok(SMatrix::from_fn(|r, c| x[(r, c)] * scale[c]))
    }
}
