//! Symmetric eigendecomposition by cyclic Jacobi rotations, for any const dimension.
//!
//! nalgebra's `symmetric_eigen` needs type-level bounds (`Const<N>: DimSub<U1>`) that would
//! leak into every generic estimator; cyclic Jacobi needs none, is accurate to a few ulps of
//! `‖A‖` for the small matrices used here, and never allocates.

use nalgebra::{SMatrix, SVector};

use super::check_finite;
use crate::{Error, Real, Result};

/// Eigenvalues `λ` and orthonormal eigenvectors `U` (columns) with `A = U diag(λ) Uᵀ`.
///
/// `a` must be finite and is symmetrised first. Fails with [`Error::Numerical`] if 64 sweeps
/// do not converge (not observed for finite input; quadratic convergence needs ~6-10).
pub fn symmetric_eigen<T: Real, const N: usize>(
    a: &SMatrix<T, N, N>,
    what: &'static str,
) -> Result<(SVector<T, N>, SMatrix<T, N, N>)> {
    check_finite(a, what)?;
    let mut m = super::symmetrize(a);
    let mut u = SMatrix::<T, N, N>::identity();
    let scale = m.amax();
    if scale == T::zero() {
        return Ok((SVector::zeros(), u));
    }
    for _sweep in 0..64 {
        let mut off = T::zero();
        for p in 0..N {
            for q in (p + 1)..N {
                off += m[(p, q)] * m[(p, q)];
            }
        }
        if off.sqrt() <= T::EPS * scale {
            let lam = SVector::<T, N>::from_fn(|i, _| m[(i, i)]);
            return Ok((lam, u));
        }
        for p in 0..N {
            for q in (p + 1)..N {
                let apq = m[(p, q)];
                if apq == T::zero() {
                    continue;
                }
                // Rotation that zeroes m[p,q] (Golub & Van Loan, Alg. 8.5.1).
                let tau = (m[(q, q)] - m[(p, p)]) / (apq + apq);
                let t = if tau >= T::zero() {
                    T::one() / (tau + (T::one() + tau * tau).sqrt())
                } else {
                    -T::one() / (-tau + (T::one() + tau * tau).sqrt())
                };
                let c = T::one() / (T::one() + t * t).sqrt();
                let s = t * c;
                for k in 0..N {
                    let mkp = m[(k, p)];
                    let mkq = m[(k, q)];
                    m[(k, p)] = c * mkp - s * mkq;
                    m[(k, q)] = s * mkp + c * mkq;
                }
                for k in 0..N {
                    let mpk = m[(p, k)];
                    let mqk = m[(q, k)];
                    m[(p, k)] = c * mpk - s * mqk;
                    m[(q, k)] = s * mpk + c * mqk;
                }
                for k in 0..N {
                    let ukp = u[(k, p)];
                    let ukq = u[(k, q)];
                    u[(k, p)] = c * ukp - s * ukq;
                    u[(k, q)] = s * ukp + c * ukq;
                }
            }
        }
    }
    Err(Error::Numerical {
        what: "Jacobi eigenvalue iteration did not converge",
    })
}

/// Largest eigenvalue of a symmetric matrix (the spectral norm when it is PSD).
pub fn max_eigenvalue<T: Real, const N: usize>(
    a: &SMatrix<T, N, N>,
    what: &'static str,
) -> Result<T> {
    let (lam, _) = symmetric_eigen(a, what)?;
    Ok(lam.max())
}

/// Smallest eigenvalue of a symmetric matrix.
pub fn min_eigenvalue<T: Real, const N: usize>(
    a: &SMatrix<T, N, N>,
    what: &'static str,
) -> Result<T> {
    let (lam, _) = symmetric_eigen(a, what)?;
    Ok(lam.min())
}

/// Spectral norm `‖M‖₂ = σ_max(M)` of a rectangular matrix, as `sqrt(λ_max(Mᵀ M))`.
pub fn spectral_norm<T: Real, const R: usize, const C: usize>(
    m: &SMatrix<T, R, C>,
    what: &'static str,
) -> Result<T> {
    let g = m.transpose() * m;
    Ok(max_eigenvalue(&g, what)?.max(T::zero()).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::matrix;

    #[test]
    fn reconstructs_and_matches_nalgebra() {
        let a = matrix![4.0, 1.0, -2.0, 0.5; 1.0, 3.0, 0.0, 1.0; -2.0, 0.0, 5.0, 0.3; 0.5, 1.0, 0.3, 1.0];
        let (lam, u) = symmetric_eigen(&a, "a").unwrap();
        let back = u * SMatrix::<f64, 4, 4>::from_diagonal(&lam) * u.transpose();
        assert!((back - a).amax() < 1e-13);
        assert!((u.transpose() * u - SMatrix::<f64, 4, 4>::identity()).amax() < 1e-14);
        let mut mine: [f64; 4] = lam.into();
        let mut reference: [f64; 4] = a.symmetric_eigenvalues().into();
        mine.sort_by(f64::total_cmp);
        reference.sort_by(f64::total_cmp);
        for i in 0..4 {
            assert!((mine[i] - reference[i]).abs() < 1e-13);
        }
        let c = matrix![0.9, 0.25, 1.0; 0.9, 0.25, 1.0];
        // Rank-1 C: ‖C‖₂ = ‖row‖·√2.
        let row: f64 = 0.81 + 0.0625 + 1.0;
        assert!((spectral_norm(&c, "c").unwrap() - (2.0 * row).sqrt()).abs() < 1e-14);
        assert_eq!(
            max_eigenvalue(&matrix![f64::NAN], "m"),
            Err(Error::NonFinite { what: "m" })
        );
    }
}
