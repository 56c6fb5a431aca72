//! Kernels for the small symmetric products of a Kalman step.
//!
//! Plain loops over const dimensions: at the papers' sizes (n ≤ 4) a build optimised for speed
//! unrolls them fully and keeps the operands in registers, which nalgebra's generic products
//! do not manage; a build optimised for size (the firmware) keeps the loops over the entries
//! and runs each entry's sum written out (`dot`).
//! Every symmetric result is computed on its upper triangle once and mirrored, so it is
//! exactly symmetric by construction: no symmetrisation pass, no asymmetry test afterwards.
//!
//! Sums start from their first product rather than from zero: `0 + x` cannot be folded away
//! (it turns `−0` into `+0`), and at these sizes one add in four is worth saving. Every entry
//! is one such sum over `k` ascending (`dot`), whatever the kernel, so a product formed with
//! a transposed operand read in place has the bits of the product of the transposed copy.

use nalgebra::{SMatrix, SVector};

use super::all_finite;
use crate::{Error, Real, Result};

/// `Σ_k a(k) b(k)` over `k = 0..K` ascending, starting from the first product: the one sum
/// every kernel here forms. The first four terms are written out: a build optimised for size
/// (the firmware's `opt-level = "s"`) keeps a loop of a few iterations as a loop, whose
/// counting and addressing then cost more instructions than its products; written out, the
/// same sum is both shorter and faster. Optimised for speed, LLVM unrolls the loop the same.
#[inline(always)]
pub(crate) fn dot<T: Real, const K: usize>(a: impl Fn(usize) -> T, b: impl Fn(usize) -> T) -> T {
    let mut acc = a(0) * b(0);
    if K > 1 {
        acc += a(1) * b(1);
    }
    if K > 2 {
        acc += a(2) * b(2);
    }
    if K > 3 {
        acc += a(3) * b(3);
    }
    for k in 4..K {
        acc += a(k) * b(k);
    }
    acc
}

/// `M v`.
#[inline]
pub fn mul_vec<T: Real, const R: usize, const C: usize>(
    m: &SMatrix<T, R, C>,
    v: &SVector<T, C>,
) -> SVector<T, R> {
    SVector::from_fn(|i, _| dot::<T, C>(|k| m[(i, k)], |k| v[k]))
}

/// `A B`.
#[inline]
pub fn mul<T: Real, const R: usize, const K: usize, const C: usize>(
    a: &SMatrix<T, R, K>,
    b: &SMatrix<T, K, C>,
) -> SMatrix<T, R, C> {
    SMatrix::from_fn(|i, j| dot::<T, K>(|k| a[(i, k)], |k| b[(k, j)]))
}

/// `A Bᵀ` (`B` read in place; the products and sums are [`mul`]'s with `Bᵀ`).
#[inline]
pub fn mul_t<T: Real, const R: usize, const K: usize, const C: usize>(
    a: &SMatrix<T, R, K>,
    b: &SMatrix<T, C, K>,
) -> SMatrix<T, R, C> {
    SMatrix::from_fn(|i, j| dot::<T, K>(|k| a[(i, k)], |k| b[(j, k)]))
}

/// `Z − A Bᵀ` (each entry `z_ij − (A Bᵀ)_ij`, the product as [`mul_t`] forms it).
#[inline]
pub fn sub_mul_t<T: Real, const R: usize, const K: usize, const C: usize>(
    z: &SMatrix<T, R, C>,
    a: &SMatrix<T, R, K>,
    b: &SMatrix<T, C, K>,
) -> SMatrix<T, R, C> {
    SMatrix::from_fn(|i, j| z[(i, j)] - dot::<T, K>(|k| a[(i, k)], |k| b[(j, k)]))
}

/// `I − A B` (each entry `δ_ij − (A B)_ij`, with `δ_ij` the identity's 1 or 0 and the product
/// as [`mul`] forms it).
#[inline]
pub fn identity_sub_mul<T: Real, const R: usize, const K: usize>(
    a: &SMatrix<T, R, K>,
    b: &SMatrix<T, K, R>,
) -> SMatrix<T, R, R> {
    SMatrix::from_fn(|i, j| {
        let delta = if i == j { T::one() } else { T::zero() };
        delta - dot::<T, K>(|k| a[(i, k)], |k| b[(k, j)])
    })
}

/// `out_ij = Σ_k a(i, k) b(j, k) (+ z_ij)` for a product known to be symmetric: the upper
/// triangle computed once and mirrored, `Z`'s upper triangle added.
#[inline(always)]
fn sym_upper<T: Real, const R: usize, const K: usize>(
    a: impl Fn(usize, usize) -> T,
    b: impl Fn(usize, usize) -> T,
    z: Option<&SMatrix<T, R, R>>,
) -> SMatrix<T, R, R> {
    let mut out = SMatrix::<T, R, R>::zeros();
    for i in 0..R {
        for j in i..R {
            let mut acc = dot::<T, K>(|k| a(i, k), |k| b(j, k));
            if let Some(z) = z {
                acc += z[(i, j)];
            }
            // (i, j) and (j, i) are in bounds (i ≤ j < R), which the compiler does not see at
            // opt-level "s": indexing kept a panic (its message and location in the image);
            // `get_mut` has none.
            if let Some(e) = out.get_mut((i, j)) {
                *e = acc;
            }
            if let Some(e) = out.get_mut((j, i)) {
                *e = acc;
            }
        }
    }
    out
}

/// `A Bᵀ` for a product known to be symmetric (e.g. `M Σ · Mᵀ`), computed on the upper
/// triangle and mirrored.
#[inline]
pub fn sym_mul_t<T: Real, const R: usize, const K: usize>(
    a: &SMatrix<T, R, K>,
    b: &SMatrix<T, R, K>,
) -> SMatrix<T, R, R> {
    sym_upper::<T, R, K>(|i, k| a[(i, k)], |j, k| b[(j, k)], None)
}

/// [`sym_mul_t`] plus a symmetric `Z`, of which only the upper triangle is read.
///
/// A Kalman step calls it twice with the same shapes (`A P · Aᵀ + Q` and the Joseph form's
/// `(P − K Gᵀ)(I − K C)ᵀ + K R Kᵀ`): built for size (`small_code`, see `build.rs`), one copy
/// out of line serves both.
#[cfg_attr(small_code, inline(never))]
#[cfg_attr(not(small_code), inline)]
pub fn sym_mul_t_add<T: Real, const R: usize, const K: usize>(
    a: &SMatrix<T, R, K>,
    b: &SMatrix<T, R, K>,
    z: &SMatrix<T, R, R>,
) -> SMatrix<T, R, R> {
    sym_upper::<T, R, K>(|i, k| a[(i, k)], |j, k| b[(j, k)], Some(z))
}

/// `A B + Z` for a product known to be symmetric (e.g. `C · P Cᵀ + R`), `B` read in place:
/// the bits of [`sym_mul_t_add`] with `Bᵀ`.
#[inline]
pub fn sym_mul_add<T: Real, const R: usize, const K: usize>(
    a: &SMatrix<T, R, K>,
    b: &SMatrix<T, K, R>,
    z: &SMatrix<T, R, R>,
) -> SMatrix<T, R, R> {
    sym_upper::<T, R, K>(|i, k| a[(i, k)], |j, k| b[(k, j)], Some(z))
}

/// `M Σ Mᵀ` for symmetric `Σ` (exactly symmetric result).
#[inline]
pub fn congruence<T: Real, const R: usize, const C: usize>(
    m: &SMatrix<T, R, C>,
    sigma: &SMatrix<T, C, C>,
) -> SMatrix<T, R, R> {
    sym_mul_t(&mul(m, sigma), m)
}

/// `M Σ Mᵀ + Z` for symmetric `Σ` and `Z` (exactly symmetric result; `Z`'s upper triangle is
/// read).
#[inline]
pub fn congruence_add<T: Real, const R: usize, const C: usize>(
    m: &SMatrix<T, R, C>,
    sigma: &SMatrix<T, C, C>,
    z: &SMatrix<T, R, R>,
) -> SMatrix<T, R, R> {
    sym_mul_t_add(&mul(m, sigma), m, z)
}

/// `S = L D Lᵀ` (unit lower `L`, diagonal `D`) of a small symmetric positive-definite
/// matrix: the square-root-free Cholesky factorisation. Without square roots and with the
/// pivots' reciprocals kept, the factor-and-solve chain of a Kalman gain is about half as long
/// as with `L Lᵀ` (a square root and a division per pivot in sequence).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SmallLdl<T: Real, const N: usize> {
    l: SMatrix<T, N, N>,
    d: [T; N],
    inv_d: [T; N],
}

impl<T: Real, const N: usize> SmallLdl<T, N> {
    /// Factors `s`, reading only its lower triangle (callers pass matrices that are
    /// symmetric by construction). Refuses like [`crate::linalg::cholesky`]: a non-finite
    /// entry is [`Error::NonFinite`]; a pivot `d_j ≤ ε · max_i s_ii` (not positive definite,
    /// or numerically singular; `d_j` is the square of Cholesky's `l_jj`) is
    /// [`Error::NotPositiveDefinite`].
    ///
    /// For a positive-definite matrix the largest entry sits on the diagonal, so the scale
    /// of the singularity floor is the same as `linalg::cholesky`'s.
    #[inline]
    pub fn new(s: &SMatrix<T, N, N>, what: &'static str) -> Result<Self> {
        let mut scale = s[(0, 0)].abs();
        for i in 1..N {
            let d = s[(i, i)].abs();
            if d > scale {
                scale = d;
            }
        }
        let floor = T::EPS * scale;
        let mut l = SMatrix::<T, N, N>::identity();
        let mut d = [T::zero(); N];
        let mut inv_d = [T::zero(); N];
        // `ld[k]` = l_jk d_k for the current row j, reused by the rows below it.
        for j in 0..N {
            let mut ld = [T::zero(); N];
            let mut dj = s[(j, j)];
            for k in 0..j {
                ld[k] = l[(j, k)] * d[k];
                dj -= ld[k] * l[(j, k)];
            }
            // `dj > floor` is false for NaN: any non-finite entry of the lower triangle
            // reaches a pivot as NaN or ±∞ (∞ − ∞, ∞ · 0, or −∞²).
            let pivot_ok = dj > floor && dj.finite() && scale.finite();
            if !pivot_ok {
                return Err(Self::refusal(s, what));
            }
            d[j] = dj;
            inv_d[j] = T::one() / dj;
            for i in (j + 1)..N {
                let mut v = s[(i, j)];
                for k in 0..j {
                    v -= l[(i, k)] * ld[k];
                }
                l[(i, j)] = v * inv_d[j];
            }
        }
        Ok(Self { l, d, inv_d })
    }

    /// The refusal's error. Built for size (`small_code`, see `build.rs`) it is inlined (it
    /// only reads `s`), so that where the error's kind is not looked at, the finiteness test
    /// is dead code and vanishes; built for speed it stays cold and out of line (inlined, it
    /// cost the SIMD lanes' callers a few instructions per step on x86-64).
    #[cfg_attr(small_code, inline(always))]
    #[cfg_attr(not(small_code), cold)]
    fn refusal(s: &SMatrix<T, N, N>, what: &'static str) -> Error {
        if all_finite(s) {
            Error::NotPositiveDefinite { what }
        } else {
            Error::NonFinite { what }
        }
    }

    /// The unit lower factor `L`.
    #[inline]
    pub fn l(&self) -> &SMatrix<T, N, N> {
        &self.l
    }

    /// The pivots `D`.
    #[inline]
    pub fn d(&self) -> &[T; N] {
        &self.d
    }

    /// The pivots' reciprocals `1 / d_j`, as every solve uses them.
    #[inline]
    pub fn inv_d(&self) -> &[T; N] {
        &self.inv_d
    }

    /// `ln det S = Σ ln d_j`.
    #[inline]
    pub fn ln_det(&self) -> T {
        let mut s = self.d[0].ln();
        for j in 1..N {
            s += self.d[j].ln();
        }
        s
    }

    /// `L⁻¹ b` (forward substitution with the unit diagonal).
    #[inline]
    fn forward(&self, b: &SVector<T, N>) -> SVector<T, N> {
        let mut z = *b;
        for i in 1..N {
            let mut v = z[i];
            for k in 0..i {
                v -= self.l[(i, k)] * z[k];
            }
            z[i] = v;
        }
        z
    }

    /// `S⁻¹ b`.
    #[inline]
    pub fn solve(&self, b: &SVector<T, N>) -> SVector<T, N> {
        let mut x = self.forward(b);
        for i in 0..N {
            x[i] *= self.inv_d[i];
        }
        for i in (0..N).rev() {
            let mut v = x[i];
            for k in (i + 1)..N {
                v -= self.l[(k, i)] * x[k];
            }
            x[i] = v;
        }
        x
    }

    /// `bᵀ S⁻¹ b = Σ z_i² / d_i` with `z = L⁻¹ b`.
    #[inline]
    pub fn mahalanobis(&self, b: &SVector<T, N>) -> T {
        let z = self.forward(b);
        let mut acc = z[0] * z[0] * self.inv_d[0];
        for i in 1..N {
            acc += z[i] * z[i] * self.inv_d[i];
        }
        acc
    }

    /// `G S⁻¹` for `G` with `N` columns (the shape of a Kalman gain `P Cᵀ S⁻¹`), row by row.
    #[inline]
    pub fn solve_right<const R: usize>(&self, g: &SMatrix<T, R, N>) -> SMatrix<T, R, N> {
        let mut out = SMatrix::<T, R, N>::zeros();
        for r in 0..R {
            let x = self.solve(&g.row(r).transpose());
            for c in 0..N {
                out[(r, c)] = x[c];
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::cholesky;
    use nalgebra::{matrix, vector};

    #[test]
    fn products_match_nalgebra() {
        let a = matrix![1.0, 2.0, -0.5; 0.3, -1.0, 4.0];
        let b = matrix![2.0, 0.1; -3.0, 0.7; 0.25, 1.5];
        let sigma = matrix![2.0, 0.3, -0.1; 0.3, 1.0, 0.2; -0.1, 0.2, 0.7];
        let z = matrix![1.0, 0.2; 0.2, 3.0];
        assert!((mul(&a, &b) - a * b).amax() < 1e-14);
        assert!((mul_t(&a, &b.transpose()) - a * b).amax() < 1e-14);
        assert!(
            (mul_vec(&a, &vector![1.0, -2.0, 0.5]) - a * vector![1.0, -2.0, 0.5]).amax() < 1e-14
        );
        let c = congruence_add(&a, &sigma, &z);
        assert!((c - (a * sigma * a.transpose() + z)).amax() < 1e-13);
        assert!((congruence(&a, &sigma) - a * sigma * a.transpose()).amax() < 1e-13);
        assert_eq!(c, c.transpose());
    }

    #[test]
    fn ldl_agrees_with_cholesky_and_solves() {
        let s = matrix![4.0f64, 1.0, 0.5; 1.0, 3.0, -0.2; 0.5, -0.2, 2.0];
        let f = SmallLdl::new(&s, "s").unwrap();
        let g = cholesky(&s, "s").unwrap();
        // L D Lᵀ and Cholesky's L' L'ᵀ: L' = L D^½.
        for j in 0..3 {
            for i in 0..3 {
                let want = g.l()[(i, j)];
                assert!((f.l()[(i, j)] * f.d()[j].sqrt() - want).abs() < 1e-15);
            }
        }
        let b = vector![1.0, -2.0, 0.3];
        assert!((s * f.solve(&b) - b).amax() < 1e-14);
        assert!((f.mahalanobis(&b) - b.dot(&g.solve(&b))).abs() < 1e-14);
        assert!((f.ln_det() - s.determinant().ln()).abs() < 1e-14);
        let gm = matrix![1.0, 2.0, 3.0; -1.0, 0.5, 0.25];
        assert!((f.solve_right(&gm) * s - gm).amax() < 1e-14);
    }

    #[test]
    fn ldl_refuses_like_the_validated_cholesky() {
        for m in [
            matrix![1.0, 2.0; 2.0, 1.0],
            matrix![1.0, 0.0; 0.0, 0.0],
            matrix![1.0, 0.0; 0.0, -1.0],
            matrix![1.0, f64::NAN; f64::NAN, 1.0],
            matrix![f64::INFINITY, 0.0; 0.0, 1.0],
            matrix![1.0, f64::INFINITY; f64::INFINITY, 1.0],
            matrix![1.0, 1.0; 1.0, 1.0 + 1e-17],
        ] {
            assert_eq!(SmallLdl::new(&m, "m").err(), cholesky(&m, "m").err(), "{m}");
        }
    }
}
