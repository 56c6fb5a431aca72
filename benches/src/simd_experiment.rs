//! An experiment, not part of the product: the same Joseph-form KF step as the core's
//! `KalmanFilter::step` (same validation: pivots of S above the singularity floor, finite
//! posterior and NIS; exactly symmetric covariances), written on explicit 4-lane SIMD columns
//! (`wide::f32x4` / `wide::f64x4`, the state padded with zeros to 4 lanes). It answers one
//! question for the ≤ 0.8× `adskalman` target: how much of the gap is vectorisation. The core
//! stays on its generic scalar kernels (`linalg_small`): this code is specific to NX ≤ 4 and
//! NY = 2, to two scalar types, and to `wide`'s lane width. `tests/agreement.rs` checks that
//! it computes the core's step.
use crate::problems::KfProblem;
use estimator_core::model::LinearSystem;
use nalgebra::{SMatrix, SVector};

macro_rules! kf_simd {
    ($name:ident, $t:ty, $v:ty, $nx:literal) => {
        /// One predict + Joseph update from the problem's prior; `None` where the core's
        /// step would return an error.
        #[inline(never)]
        pub fn $name(
            pr: &KfProblem<$t, $nx, 2>,
        ) -> Option<(SVector<$t, $nx>, SMatrix<$t, $nx, $nx>, $t)> {
            type V = $v;
            const N: usize = $nx;
            let z: $t = 0.0;
            let a = pr.model.a(0);
            let q = pr.model.process_cov(0);
            let c = pr.model.c(0);
            let r = pr.model.measurement_cov(0);
            let p = pr.prior.covariance();
            let x = pr.prior.state();
            let y = pr.y;
            let col = |m: &SMatrix<$t, $nx, $nx>, j: usize| -> V {
                V::from(core::array::from_fn::<$t, 4, _>(|i| {
                    if i < N && j < N {
                        m[(i, j)]
                    } else {
                        z
                    }
                }))
            };
            let el = |m: &SMatrix<$t, $nx, $nx>, i: usize, j: usize| -> $t {
                if i < N && j < N {
                    m[(i, j)]
                } else {
                    z
                }
            };
            let cel = |mm: usize, j: usize| -> $t {
                if j < N {
                    c[(mm, j)]
                } else {
                    z
                }
            };
            let s = |v: $t| V::splat(v);
            let hsum = |v: V| -> $t {
                let a = v.to_array();
                (a[0] + a[1]) + (a[2] + a[3])
            };
            let mirror = |m: [V; 4]| -> [V; 4] {
                let mut a: [[$t; 4]; 4] = core::array::from_fn(|j| m[j].to_array());
                for j in 0..4 {
                    for i in (j + 1)..4 {
                        a[j][i] = a[i][j];
                    }
                }
                core::array::from_fn(|j| V::from(a[j]))
            };
            let ac: [V; 4] = core::array::from_fn(|j| col(&a, j));
            let qc: [V; 4] = core::array::from_fn(|j| col(&q, j));
            let xv = V::from(core::array::from_fn::<$t, 4, _>(|i| {
                if i < N {
                    x[i]
                } else {
                    z
                }
            }));
            let xs = xv.to_array();
            let xp = ac[0] * s(xs[0]) + ac[1] * s(xs[1]) + ac[2] * s(xs[2]) + ac[3] * s(xs[3]);
            let m: [V; 4] = core::array::from_fn(|j| {
                ac[0] * s(el(p, 0, j))
                    + ac[1] * s(el(p, 1, j))
                    + ac[2] * s(el(p, 2, j))
                    + ac[3] * s(el(p, 3, j))
            });
            let pp: [V; 4] = core::array::from_fn(|j| {
                m[0] * s(el(&a, j, 0))
                    + m[1] * s(el(&a, j, 1))
                    + m[2] * s(el(&a, j, 2))
                    + m[3] * s(el(&a, j, 3))
                    + qc[j]
            });
            let pp = mirror(pp);
            let g: [V; 2] = core::array::from_fn(|mm| {
                pp[0] * s(cel(mm, 0))
                    + pp[1] * s(cel(mm, 1))
                    + pp[2] * s(cel(mm, 2))
                    + pp[3] * s(cel(mm, 3))
            });
            let crow: [V; 2] = core::array::from_fn(|mm| {
                V::from(core::array::from_fn::<$t, 4, _>(|j| cel(mm, j)))
            });
            let s00 = hsum(crow[0] * g[0]) + r[(0, 0)];
            let s10 = hsum(crow[1] * g[0]) + r[(0, 1)];
            let s11 = hsum(crow[1] * g[1]) + r[(1, 1)];
            let scale = s00.abs().max(s11.abs());
            let floor = <$t>::EPSILON * scale;
            if !(s00 > floor && s00.is_finite() && scale.is_finite()) {
                return None;
            }
            let inv0 = 1.0 / s00;
            let l = s10 * inv0;
            let d1 = s11 - l * s10;
            if !(d1 > floor && d1.is_finite()) {
                return None;
            }
            let inv1 = 1.0 / d1;
            let v0 = g[0] * s(inv0);
            let k1 = (g[1] - g[0] * s(l)) * s(inv1);
            let k0 = v0 - k1 * s(l);
            let nu0 = y[0] - hsum(crow[0] * xp);
            let nu1 = y[1] - hsum(crow[1] * xp);
            let xn = xp + k0 * s(nu0) + k1 * s(nu1);
            let ka = k0.to_array();
            let kb = k1.to_array();
            let ga = g[0].to_array();
            let gb = g[1].to_array();
            let ikc: [V; 4] = core::array::from_fn(|j| {
                let mut e = [z; 4];
                e[j] = 1.0;
                V::from(e) - k0 * s(cel(0, j)) - k1 * s(cel(1, j))
            });
            let ikcp: [V; 4] = core::array::from_fn(|j| pp[j] - k0 * s(ga[j]) - k1 * s(gb[j]));
            let kr0 = k0 * s(r[(0, 0)]) + k1 * s(r[(1, 0)]);
            let kr1 = k0 * s(r[(0, 1)]) + k1 * s(r[(1, 1)]);
            let ikca: [[$t; 4]; 4] = core::array::from_fn(|j| ikc[j].to_array());
            let pn: [V; 4] = core::array::from_fn(|j| {
                ikcp[0] * s(ikca[0][j])
                    + ikcp[1] * s(ikca[1][j])
                    + ikcp[2] * s(ikca[2][j])
                    + ikcp[3] * s(ikca[3][j])
                    + kr0 * s(ka[j])
                    + kr1 * s(kb[j])
            });
            let pa: [[$t; 4]; 4] = core::array::from_fn(|j| pn[j].to_array());
            let z1 = nu1 - l * nu0;
            let nis = nu0 * nu0 * inv0 + z1 * z1 * inv1;
            let fin =
                (xn - xn) + (pn[0] - pn[0]) + (pn[1] - pn[1]) + (pn[2] - pn[2]) + (pn[3] - pn[3]);
            if !(hsum(fin) == 0.0 && nis.is_finite()) {
                return None;
            }
            let xa = xn.to_array();
            Some((
                SVector::from_fn(|i, _| xa[i]),
                SMatrix::from_fn(|i, j| if i <= j { pa[j][i] } else { pa[i][j] }),
                nis,
            ))
        }
    };
}

kf_simd!(step_4x2_f32, f32, wide::f32x4, 4);
kf_simd!(step_3x2_f64, f64, wide::f64x4, 3);
