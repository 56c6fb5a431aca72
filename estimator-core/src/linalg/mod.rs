//! Small dense linear algebra on fixed-size matrices.
//!
//! This file holds the finiteness checks, symmetrisation and the validated Cholesky solves;
//! the submodules hold one family each:
//!
//! * [`small`]: unrolled kernels for the symmetric products of a Kalman step and the
//!   square-root-free `L D Lᵀ` factor;
//! * `lanes` (with the `simd` feature on x86-64 and AArch64): the same kernels on SIMD lanes,
//!   bit-identical;
//! * [`eig`]: symmetric eigendecomposition by cyclic Jacobi rotations;
//! * [`kron`]: the two-sided matrix equation of seed 003's gain.
//!
//! Every routine returns [`Result`] and none forms an explicit inverse where a solve will do.

use nalgebra::{Cholesky, Const, SMatrix};

use crate::{Error, Real, Result};

pub mod eig;
pub mod kron;
#[cfg(simd_lanes)]
pub mod lanes;
pub mod small;

/// `true` when every entry is finite, in one pass without branches: `v − v` is `0` for a
/// finite `v` and NaN otherwise, and NaN survives the sums. Four partial sums keep the
/// dependency chain short (float adds cannot be reassociated by the compiler); any order of
/// the sums gives the same answer.
///
/// Built for size (`small_code`, see `build.rs`) the entries are read as one slice, four at a
/// time, the last `R·C mod 4` apart: at opt-level "s" the matrix iterator stays a slow loop
/// that the compiler cannot delete where the answer is dead (an error's name nobody reads),
/// while this one it can. Built for speed, the matrix iterator unrolls fully and is a few
/// instructions shorter on x86-64.
#[inline]
#[allow(clippy::eq_op)] // v − v is the test itself: 0 if finite, NaN otherwise
pub fn all_finite<T: Real, const R: usize, const C: usize>(m: &SMatrix<T, R, C>) -> bool {
    #[cfg(small_code)]
    {
        let z = T::zero();
        let (mut a0, mut a1, mut a2, mut a3) = (z, z, z, z);
        let mut chunks = m.as_slice().chunks_exact(4);
        for c in &mut chunks {
            a0 += c[0] - c[0];
            a1 += c[1] - c[1];
            a2 += c[2] - c[2];
            a3 += c[3] - c[3];
        }
        match *chunks.remainder() {
            [u] => a0 += u - u,
            [u, v] => {
                a0 += u - u;
                a1 += v - v;
            }
            [u, v, w] => {
                a0 += u - u;
                a1 += v - v;
                a2 += w - w;
            }
            _ => {}
        }
        (a0 + a1) + (a2 + a3) == z
    }
    #[cfg(not(small_code))]
    {
        let mut acc = [T::zero(); 4];
        for (i, v) in m.iter().enumerate() {
            acc[i % 4] += *v - *v;
        }
        (acc[0] + acc[1]) + (acc[2] + acc[3]) == T::zero()
    }
}

/// Returns [`Error::NonFinite`] naming `what` unless every entry is finite.
#[inline]
pub fn check_finite<T: Real, const R: usize, const C: usize>(
    m: &SMatrix<T, R, C>,
    what: &'static str,
) -> Result<()> {
    if all_finite(m) {
        Ok(())
    } else {
        Err(Error::NonFinite { what })
    }
}

/// `(M + Mᵀ)/2`: removes the asymmetry that rounding leaves in a covariance update.
#[inline]
#[must_use]
pub fn symmetrize<T: Real, const N: usize>(m: &SMatrix<T, N, N>) -> SMatrix<T, N, N> {
    (m + m.transpose()) * T::lit(0.5)
}

/// Largest entry of `|M − Mᵀ|` relative to the largest entry of `|M|` (0 for the zero matrix).
#[must_use]
pub fn asymmetry<T: Real, const N: usize>(m: &SMatrix<T, N, N>) -> T {
    let scale = m.amax();
    if scale == T::zero() {
        return T::zero();
    }
    (m - m.transpose()).amax() / scale
}

/// Cholesky factor of a symmetric positive-definite matrix.
///
/// Refuses non-finite entries, a relative asymmetry above `sqrt(eps)`, and matrices whose
/// factorisation fails or has a pivot below `eps · max|M|` (numerically singular).
pub fn cholesky<T: Real, const N: usize>(
    m: &SMatrix<T, N, N>,
    what: &'static str,
) -> Result<Cholesky<T, Const<N>>> {
    check_finite(m, what)?;
    if asymmetry(m) > T::EPS.sqrt() {
        return Err(Error::NotPositiveDefinite { what });
    }
    let sym = symmetrize(m);
    let scale = sym.amax();
    let chol = sym.cholesky().ok_or(Error::NotPositiveDefinite { what })?;
    let l = chol.l_dirty();
    let floor2 = T::EPS * scale;
    for i in 0..N {
        let d = l[(i, i)];
        if !d.finite() || !above_sqrt(d, floor2) {
            return Err(Error::NotPositiveDefinite { what });
        }
    }
    Ok(chol)
}

/// `d > √x` (`x ≥ 0`, `√x` rounded as `x.sqrt()` rounds it), exactly, but without the square
/// root when `d² > 2x`: then `d > 1.4 √x` even with the rounding of `d²` and `2x`, far above
/// the rounded root. Only pivots within a factor 1.4 of the floor pay for the root (a software
/// routine on the Cortex-M4, called once per factorisation before).
#[inline]
fn above_sqrt<T: Real>(d: T, x: T) -> bool {
    d * d > x + x || d > x.sqrt()
}

/// Validates that `m` is symmetric positive definite (see [`cholesky`]).
pub fn check_spd<T: Real, const N: usize>(m: &SMatrix<T, N, N>, what: &'static str) -> Result<()> {
    cholesky(m, what).map(|_| ())
}

/// Solves `A X = B` for symmetric positive-definite `A`.
pub fn solve_spd<T: Real, const N: usize, const M: usize>(
    a: &SMatrix<T, N, N>,
    b: &SMatrix<T, N, M>,
    what: &'static str,
) -> Result<SMatrix<T, N, M>> {
    let chol = cholesky(a, what)?;
    let x = chol.solve(b);
    check_finite(&x, what)?;
    Ok(x)
}

/// Solves `X A = B` for symmetric positive-definite `A` (so `X = B A⁻¹`), the shape of every
/// Kalman gain `K = P Cᵀ S⁻¹`.
pub fn solve_spd_right<T: Real, const N: usize, const M: usize>(
    b: &SMatrix<T, M, N>,
    a: &SMatrix<T, N, N>,
    what: &'static str,
) -> Result<SMatrix<T, M, N>> {
    // X A = B  ⇔  A Xᵀ = Bᵀ (A symmetric).
    Ok(solve_spd(a, &b.transpose(), what)?.transpose())
}

/// [`inverse_spd`]`(a)` and [`solve_spd`]`(a, b)` from one factorisation of `a`: the same
/// bits and the same errors, in the same order, as the two calls (information-form fusion
/// needs both of every matrix).
#[allow(clippy::type_complexity)]
pub fn inverse_and_solve_spd<T: Real, const N: usize, const M: usize>(
    a: &SMatrix<T, N, N>,
    b: &SMatrix<T, N, M>,
    what: &'static str,
) -> Result<(SMatrix<T, N, N>, SMatrix<T, N, M>)> {
    let chol = cholesky(a, what)?;
    let inv = chol.inverse();
    check_finite(&inv, what)?;
    let x = chol.solve(b);
    check_finite(&x, what)?;
    Ok((symmetrize(&inv), x))
}

/// `ln det A` of a symmetric positive-definite matrix, from its Cholesky factor.
pub fn ln_det_spd<T: Real, const N: usize>(a: &SMatrix<T, N, N>, what: &'static str) -> Result<T> {
    let chol = cholesky(a, what)?;
    let l = chol.l_dirty();
    let mut s = T::zero();
    for i in 0..N {
        s += l[(i, i)].ln();
    }
    Ok(s + s)
}

/// Inverse of a symmetric positive-definite matrix, for the few places where a paper's
/// result *is* an inverse (e.g. information-form fusion). Prefer [`solve_spd`].
pub fn inverse_spd<T: Real, const N: usize>(
    a: &SMatrix<T, N, N>,
    what: &'static str,
) -> Result<SMatrix<T, N, N>> {
    let inv = cholesky(a, what)?.inverse();
    check_finite(&inv, what)?;
    Ok(symmetrize(&inv))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::matrix;

    #[test]
    fn solve_matches_known_solution() {
        let a = matrix![4.0, 1.0; 1.0, 3.0];
        let x = matrix![1.0, -2.0; 0.5, 3.0];
        let b = a * x;
        let got = solve_spd(&a, &b, "a").unwrap();
        assert!((got - x).amax() < 1e-14);
        let got_r = solve_spd_right(&(x.transpose() * a), &a, "a").unwrap();
        assert!((got_r - x.transpose()).amax() < 1e-14);
    }

    #[test]
    fn rejects_indefinite_asymmetric_and_nan() {
        assert_eq!(
            check_spd(&matrix![1.0, 2.0; 2.0, 1.0], "m"),
            Err(Error::NotPositiveDefinite { what: "m" })
        );
        assert_eq!(
            check_spd(&matrix![1.0, 0.5; 0.0, 1.0], "m"),
            Err(Error::NotPositiveDefinite { what: "m" })
        );
        assert_eq!(
            check_spd(&matrix![1.0, f64::NAN; f64::NAN, 1.0], "m"),
            Err(Error::NonFinite { what: "m" })
        );
        assert!(check_spd(&matrix![1.0, 0.0; 0.0, 0.0], "m").is_err());
    }

    #[test]
    fn finiteness_in_one_pass() {
        assert!(all_finite(&matrix![1.0, -2.0; 1e308, -1e308]));
        assert!(!all_finite(&matrix![1.0, f64::NAN; 0.0, 0.0]));
        assert!(!all_finite(&matrix![1.0, 0.0; f64::NEG_INFINITY, 0.0]));
        assert!(!all_finite(&matrix![1.0f32, 0.0; f32::INFINITY, 0.0]));
        assert!(!all_finite(&matrix![
            1.0,
            2.0,
            3.0,
            4.0,
            5.0,
            f64::INFINITY
        ]));
    }

    /// One factorisation gives what the two calls give, bit for bit, and their errors.
    #[test]
    fn inverse_and_solve_is_the_two_calls() {
        let a = matrix![4.0f64, 1.0, 0.3; 1.0, 3.0, -0.7; 0.3, -0.7, 2.0];
        let b = matrix![1.0f64, -2.0; 0.5, 3.0; 7.0, 1e-3];
        let (inv, x) = inverse_and_solve_spd(&a, &b, "a").unwrap();
        assert_eq!(inv, inverse_spd(&a, "a").unwrap());
        assert_eq!(x, solve_spd(&a, &b, "a").unwrap());
        let bad = matrix![1.0f64, 2.0, 0.0; 2.0, 1.0, 0.0; 0.0, 0.0, 1.0];
        assert_eq!(
            inverse_and_solve_spd(&bad, &b, "bad"),
            Err(Error::NotPositiveDefinite { what: "bad" })
        );
        let eye = matrix![1.0f64, 0.0; 0.0, 1.0];
        assert_eq!(
            inverse_and_solve_spd(&eye, &matrix![f64::NAN; 1.0], "b"),
            Err(Error::NonFinite { what: "b" })
        );
    }

    /// The root-free test is `d > √x` itself, at the boundary and around it, in both
    /// precisions (and with the comparisons NaN makes false).
    #[test]
    fn above_sqrt_is_the_comparison_with_the_root() {
        for &x in &[0.0f64, 1e-300, 2.2e-16, 1.0, 2.0, 3.0, 1e300] {
            let r = x.sqrt();
            // Around the root by factors (the ulps next to it below).
            let mut d = r / 2.0;
            while d < r * 2.0 {
                assert_eq!(above_sqrt(d, x), d > r, "{d} against √{x}");
                d *= 1.001;
            }
            for k in -40i64..=40 {
                let d = f64::from_bits((r.to_bits() as i64 + k).max(0) as u64);
                assert_eq!(above_sqrt(d, x), d > r, "{d} against √{x}");
            }
        }
        for &x in &[1.19e-7f32, 1.0, 7.0, 3e38] {
            let r = x.sqrt();
            for k in -40i32..=40 {
                let d = f32::from_bits((r.to_bits() as i32 + k) as u32);
                assert_eq!(above_sqrt(d, x), d > r, "{d} against √{x}");
            }
        }
        assert!(!above_sqrt(f64::NAN, 1.0));
        assert!(!above_sqrt(1.0, f64::NAN));
    }

    #[test]
    fn ln_det_and_inverse() {
        let a = matrix![4.0f64, 1.0; 1.0, 3.0];
        assert!((ln_det_spd(&a, "a").unwrap() - 11.0f64.ln()).abs() < 1e-14);
        let inv = inverse_spd(&a, "a").unwrap();
        assert!((inv * a - SMatrix::<f64, 2, 2>::identity()).amax() < 1e-14);
    }
}
