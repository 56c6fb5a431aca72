//! The Kalman time and measurement updates on SIMD lanes, for hosts (x86-64, AArch64).
//!
//! Each column of a matrix with `NX ≤ 4` rows is one 4-lane vector (`wide::f32x4` or
//! `wide::f64x4`, rows past `NX` zero), so a product `A B` is a few "column × broadcast
//! scalar" steps instead of `NX²` dot products. LLVM does not find this form by itself in the
//! generic kernels of [`crate::linalg::small`] (it vectorises their dot products with shuffles
//! that lengthen the dependency chain; `BENCHMARKS.md` has the measurements).
//!
//! **Bit-identical** to [`crate::linalg::small`]: every entry is the same sequence of IEEE
//! operations in the same order (sums start from their first product and run over `k`
//! ascending; symmetric results are computed on the upper triangle and mirrored; the same
//! [`SmallLdl`] factor), only several entries at a time. So results, tests and the Cortex-M4
//! firmware (which keeps the scalar kernels: it has no SIMD floating point) agree bit for bit;
//! `lanes_are_bit_identical_to_the_scalar_kernels` in [`crate::filter::kalman`]'s tests checks
//! it (beside the scalar update it compares with, so that this module imports nothing from
//! the filters).
//!
//! Every function returns `None` where it does not apply (another scalar type, `NX > 4`)
//! and where the update is refused: the caller then runs the scalar kernels, which produce the
//! exact error (refusals are the cold path).

use core::any::Any;

use nalgebra::{SMatrix, SVector};

use super::small::SmallLdl;
use crate::{CovarianceUpdate, Real};

/// `&dyn Any` downcast: a compile-time constant `TypeId` test after monomorphisation.
#[inline(always)]
fn cast<U: 'static>(v: &dyn Any) -> Option<&U> {
    v.downcast_ref::<U>()
}

/// The body of every entry point: the `f32` lanes, else the `f64` lanes, else `None`
/// (`NX > 4`, or another scalar type).
macro_rules! dispatch {
    ($f:ident::<$($g:ident),+>($($m:ident),+; $($rest:expr),*)) => {{
        if NX > 4 {
            return None;
        }
        if let ($(Some($m),)+) = ($(cast($m),)+) {
            return cast(&f32_lanes::$f::<$($g),+>($($m,)+ $($rest),*)?).copied();
        }
        if let ($(Some($m),)+) = ($(cast($m),)+) {
            return cast(&f64_lanes::$f::<$($g),+>($($m,)+ $($rest),*)?).copied();
        }
        None
    }};
}

/// Same as [`crate::filter::time_update::predict_raw`], on lanes.
#[inline(always)]
pub fn predict<T: Real, const NX: usize>(
    x: &SVector<T, NX>,
    p: &SMatrix<T, NX, NX>,
    a: &SMatrix<T, NX, NX>,
    q: &SMatrix<T, NX, NX>,
) -> Option<(SVector<T, NX>, SMatrix<T, NX, NX>)> {
    dispatch!(predict::<NX>(x, p, a, q;))
}

/// Same as [`crate::filter::kalman::kalman_update`], on lanes; `None` also when it would
/// return an error.
#[inline(always)]
#[allow(clippy::type_complexity)]
pub fn kalman_update<T: Real, const NX: usize, const NY: usize>(
    x: &SVector<T, NX>,
    p: &SMatrix<T, NX, NX>,
    c: &SMatrix<T, NY, NX>,
    r: &SMatrix<T, NY, NY>,
    y: &SVector<T, NY>,
    form: CovarianceUpdate,
) -> Option<(SVector<T, NX>, SMatrix<T, NX, NX>, T)> {
    dispatch!(update::<NX, NY>(x, p, c, r, y; form))
}

/// [`predict`] then [`kalman_update`] (the Kalman filter's step), without leaving the lanes
/// between them.
#[inline(always)]
#[allow(clippy::type_complexity, clippy::too_many_arguments)]
pub fn step<T: Real, const NX: usize, const NY: usize>(
    x: &SVector<T, NX>,
    p: &SMatrix<T, NX, NX>,
    a: &SMatrix<T, NX, NX>,
    q: &SMatrix<T, NX, NX>,
    c: &SMatrix<T, NY, NX>,
    r: &SMatrix<T, NY, NY>,
    y: &SVector<T, NY>,
    form: CovarianceUpdate,
) -> Option<(SVector<T, NX>, SMatrix<T, NX, NX>, T)> {
    dispatch!(step::<NX, NY>(x, p, a, q, c, r, y; form))
}

macro_rules! lanes {
    ($module:ident, $t:ty, $v:ty) => {
        mod $module {
            use super::*;

            type V = $v;
            /// Columns of a matrix with up to 4 rows.
            type Cols<const C: usize> = [V; C];

            #[inline(always)]
            fn s(v: $t) -> V {
                V::splat(v)
            }

            /// Column `j` of `m`, rows past `R` zero.
            #[inline(always)]
            fn col<const R: usize, const C: usize>(m: &SMatrix<$t, R, C>, j: usize) -> V {
                V::from(core::array::from_fn::<$t, 4, _>(|i| {
                    if i < R {
                        m[(i, j)]
                    } else {
                        0.0
                    }
                }))
            }

            #[inline(always)]
            fn cols<const R: usize, const C: usize>(m: &SMatrix<$t, R, C>) -> Cols<C> {
                core::array::from_fn(|j| col(m, j))
            }

            /// `Σ_k a_k b(k, j)` over `k < K`, from the first product: column `j` of `A B`
            /// where `a` are `A`'s columns and `b(k, j)` reads `B`.
            #[inline(always)]
            fn combo<const K: usize>(a: &Cols<K>, b: impl Fn(usize) -> $t) -> V {
                let mut acc = a[0] * s(b(0));
                for k in 1..K {
                    acc += a[k] * s(b(k));
                }
                acc
            }

            /// Columns with the upper triangle mirrored to the lower one (first `R` lanes).
            #[inline(always)]
            fn mirror<const R: usize>(m: &Cols<R>) -> Cols<R> {
                let mut a: [[$t; 4]; R] = core::array::from_fn(|j| m[j].to_array());
                for j in 0..R {
                    for i in (j + 1)..R {
                        a[j][i] = a[i][j];
                    }
                }
                core::array::from_fn(|j| V::from(a[j]))
            }

            /// Every lane of `x` and of `m` finite (`v − v` is 0 for finite `v`, NaN
            /// otherwise), in one reduction.
            #[inline(always)]
            fn finite<const C: usize>(x: V, m: &Cols<C>) -> bool {
                let mut acc = x - x;
                for v in m {
                    acc += *v - *v;
                }
                let a = acc.to_array();
                (a[0] + a[1]) + (a[2] + a[3]) == 0.0
            }

            #[inline(always)]
            fn full<const R: usize, const C: usize>(m: &Cols<C>) -> SMatrix<$t, R, C> {
                let a: [[$t; 4]; C] = core::array::from_fn(|j| m[j].to_array());
                SMatrix::from_fn(|i, j| a[j][i])
            }

            /// The symmetric matrix whose upper triangle is that of `m`'s columns.
            #[inline(always)]
            fn full_sym<const R: usize>(m: &Cols<R>) -> SMatrix<$t, R, R> {
                let a: [[$t; 4]; R] = core::array::from_fn(|j| m[j].to_array());
                SMatrix::from_fn(|i, j| if i <= j { a[j][i] } else { a[i][j] })
            }

            /// `Σ_k u_k v_k` over the first `K` lanes, from the first product.
            #[inline(always)]
            fn dot<const K: usize>(u: V, v: V) -> $t {
                let w = (u * v).to_array();
                let mut acc = w[0];
                for x in w.iter().take(K).skip(1) {
                    acc += *x;
                }
                acc
            }

            /// `(A x, A P Aᵀ + Q)`, the covariance mirrored from its upper triangle.
            #[inline(always)]
            fn predict_cols<const NX: usize>(
                x: &SVector<$t, NX>,
                p: &SMatrix<$t, NX, NX>,
                a: &SMatrix<$t, NX, NX>,
                q: &SMatrix<$t, NX, NX>,
            ) -> (V, Cols<NX>) {
                let ac = cols(a);
                let xn = combo(&ac, |k| x[k]);
                // A P, then (A P) Aᵀ + Q on the upper triangle.
                let m: Cols<NX> = core::array::from_fn(|j| combo(&ac, |k| p[(k, j)]));
                let qc = cols(q);
                let pp: Cols<NX> = core::array::from_fn(|j| combo(&m, |k| a[(j, k)]) + qc[j]);
                (xn, mirror(&pp))
            }

            /// The update on columns; only the upper triangle of `P⁺` is meaningful (read it
            /// with `full_sym`). `None` when refused or when a lane of the result is not
            /// finite.
            #[inline(always)]
            #[allow(clippy::type_complexity)]
            fn update_cols<const NX: usize, const NY: usize>(
                xv: V,
                pc: &Cols<NX>,
                c: &SMatrix<$t, NY, NX>,
                r: &SMatrix<$t, NY, NY>,
                y: &SVector<$t, NY>,
                form: CovarianceUpdate,
            ) -> Option<(V, Cols<NX>, $t)> {
                // G = P Cᵀ; S = C G + R on the upper triangle (rows of C against columns of G).
                let g: Cols<NY> = core::array::from_fn(|m| combo(pc, |k| c[(m, k)]));
                let crow: Cols<NY> = core::array::from_fn(|m| {
                    V::from(core::array::from_fn::<$t, 4, _>(|k| {
                        if k < NX {
                            c[(m, k)]
                        } else {
                            0.0
                        }
                    }))
                });
                let sm = SMatrix::<$t, NY, NY>::from_fn(|i, j| {
                    let (i, j) = if i <= j { (i, j) } else { (j, i) };
                    dot::<NX>(crow[i], g[j]) + r[(i, j)]
                });
                let chol = SmallLdl::new(&sm, "innovation covariance").ok()?;
                let (l, inv_d) = (chol.l(), chol.inv_d());
                // K = G S⁻¹, the row-wise solve of SmallLdl::solve_right on whole columns.
                let mut k = g;
                for i in 1..NY {
                    for j in 0..i {
                        k[i] -= k[j] * s(l[(i, j)]);
                    }
                }
                for i in 0..NY {
                    k[i] *= s(inv_d[i]);
                }
                for i in (0..NY).rev() {
                    for j in (i + 1)..NY {
                        k[i] -= k[j] * s(l[(j, i)]);
                    }
                }
                let nu = SVector::<$t, NY>::from_fn(|m, _| y[m] - dot::<NX>(crow[m], xv));
                let xn = xv + combo(&k, |m| nu[m]);
                let ga: [[$t; 4]; NY] = core::array::from_fn(|m| g[m].to_array());
                let pn: Cols<NX> = match form {
                    CovarianceUpdate::Joseph => {
                        let ikc: Cols<NX> = core::array::from_fn(|j| {
                            let mut e = [0.0; 4];
                            e[j] = 1.0;
                            V::from(e) - combo(&k, |m| c[(m, j)])
                        });
                        let ikcp: Cols<NX> =
                            core::array::from_fn(|j| pc[j] - combo(&k, |m| ga[m][j]));
                        let kr: Cols<NY> = core::array::from_fn(|n| combo(&k, |m| r[(m, n)]));
                        let ka: [[$t; 4]; NY] = core::array::from_fn(|m| k[m].to_array());
                        let ia: [[$t; 4]; NX] = core::array::from_fn(|j| ikc[j].to_array());
                        core::array::from_fn(|j| {
                            combo(&ikcp, |kk| ia[kk][j]) + combo(&kr, |m| ka[m][j])
                        })
                    }
                    // P − K Gᵀ: P is exactly symmetric, so its upper triangle minus that of
                    // K Gᵀ, mirrored, is the scalar path's P − sym(K Gᵀ).
                    CovarianceUpdate::Standard => {
                        core::array::from_fn(|j| pc[j] - combo(&k, |m| ga[m][j]))
                    }
                };
                let nis = chol.mahalanobis(&nu);
                // Lanes below the diagonal and past NX are checked too: a spurious refusal
                // only sends the caller to the scalar path, which decides exactly.
                (finite(xn, &pn) && nis.is_finite()).then_some((xn, pn, nis))
            }

            #[inline(always)]
            pub fn predict<const NX: usize>(
                x: &SVector<$t, NX>,
                p: &SMatrix<$t, NX, NX>,
                a: &SMatrix<$t, NX, NX>,
                q: &SMatrix<$t, NX, NX>,
            ) -> Option<(SVector<$t, NX>, SMatrix<$t, NX, NX>)> {
                let (xn, pp) = predict_cols(x, p, a, q);
                Some((full::<NX, 1>(&[xn]), full(&pp)))
            }

            #[inline(always)]
            #[allow(clippy::type_complexity)]
            pub fn update<const NX: usize, const NY: usize>(
                x: &SVector<$t, NX>,
                p: &SMatrix<$t, NX, NX>,
                c: &SMatrix<$t, NY, NX>,
                r: &SMatrix<$t, NY, NY>,
                y: &SVector<$t, NY>,
                form: CovarianceUpdate,
            ) -> Option<(SVector<$t, NX>, SMatrix<$t, NX, NX>, $t)> {
                let (xn, pn, nis) = update_cols(col(x, 0), &cols(p), c, r, y, form)?;
                Some((full::<NX, 1>(&[xn]), full_sym(&pn), nis))
            }

            /// Predict then update without leaving the lanes in between.
            #[inline(always)]
            #[allow(clippy::type_complexity, clippy::too_many_arguments)]
            pub fn step<const NX: usize, const NY: usize>(
                x: &SVector<$t, NX>,
                p: &SMatrix<$t, NX, NX>,
                a: &SMatrix<$t, NX, NX>,
                q: &SMatrix<$t, NX, NX>,
                c: &SMatrix<$t, NY, NX>,
                r: &SMatrix<$t, NY, NY>,
                y: &SVector<$t, NY>,
                form: CovarianceUpdate,
            ) -> Option<(SVector<$t, NX>, SMatrix<$t, NX, NX>, $t)> {
                let (xp, pp) = predict_cols(x, p, a, q);
                let (xn, pn, nis) = update_cols(xp, &pp, c, r, y, form)?;
                Some((full::<NX, 1>(&[xn]), full_sym(&pn), nis))
            }
        }
    };
}

lanes!(f32_lanes, f32, wide::f32x4);
lanes!(f64_lanes, f64, wide::f64x4);
