//! Linear state-space models.
//!
//! ```text
//! x_{k+1} = A_k x_k + G_k u_k + B_k w_k,   w_k ~ N(0, Q_k),  u_k known (optional)
//! y_k     = C_k x_k + D_k v_k,   v_k ~ N(0, R_k)
//! ```
//!
//! Filters only need `A_k`, `C_k`, the known input term `G_k u_k` (none by default) and the
//! *effective* covariances `B_k Q_k B_kᵀ` and `D_k R_k D_kᵀ`, so they are written against the [`LinearSystem`] trait, whose matrices may
//! depend on the time index `k` (the seed 003 and 004 examples are time-varying).
//! [`LinearModel`] is the time-invariant implementation, validated at construction.

use nalgebra::{SMatrix, SVector};

use crate::linalg::{check_finite, check_spd, symmetrize};
use crate::{Real, Result};

/// A (possibly time-varying) linear-Gaussian system as a filter sees it.
///
/// `NX` states, `NY` measurements. Implement it for a model whose matrices depend on `k`;
/// every method must return finite matrices and the covariances must be symmetric positive
/// (semi-)definite — filters check what they use and return an error otherwise.
pub trait LinearSystem<T: Real, const NX: usize, const NY: usize> {
    /// State transition `A_k`.
    fn a(&self, k: usize) -> SMatrix<T, NX, NX>;
    /// Measurement matrix `C_k`.
    fn c(&self, k: usize) -> SMatrix<T, NY, NX>;
    /// Effective process-noise covariance `B_k Q_k B_kᵀ`.
    fn process_cov(&self, k: usize) -> SMatrix<T, NX, NX>;
    /// Effective measurement-noise covariance `D_k R_k D_kᵀ`.
    fn measurement_cov(&self, k: usize) -> SMatrix<T, NY, NY>;
    /// The known input term `G_k u_k` of `x_{k+1}` (a control input both the plant and the
    /// filter know), `None` for a system without one. Every time update adds it to
    /// `A_k x̂_k`; without one the prediction is exactly `A_k x̂_k`. Default: `None`.
    #[inline]
    fn input(&self, _k: usize) -> Option<SVector<T, NX>> {
        None
    }
}

/// A borrowed system is the system (so that an [`OnModel`](crate::OnModel) can borrow its
/// model).
impl<T: Real, const NX: usize, const NY: usize, M: LinearSystem<T, NX, NY> + ?Sized>
    LinearSystem<T, NX, NY> for &M
{
    #[inline]
    fn a(&self, k: usize) -> SMatrix<T, NX, NX> {
        (**self).a(k)
    }
    #[inline]
    fn c(&self, k: usize) -> SMatrix<T, NY, NX> {
        (**self).c(k)
    }
    #[inline]
    fn process_cov(&self, k: usize) -> SMatrix<T, NX, NX> {
        (**self).process_cov(k)
    }
    #[inline]
    fn measurement_cov(&self, k: usize) -> SMatrix<T, NY, NY> {
        (**self).measurement_cov(k)
    }
    #[inline]
    fn input(&self, k: usize) -> Option<SVector<T, NX>> {
        (**self).input(k)
    }
}

/// Time-invariant linear model with explicit noise input matrices.
///
/// `NW` process-noise inputs, `NV` measurement-noise inputs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinearModel<T: Real, const NX: usize, const NW: usize, const NY: usize, const NV: usize>
{
    /// State transition A.
    pub a: SMatrix<T, NX, NX>,
    /// Process-noise input B.
    pub b: SMatrix<T, NX, NW>,
    /// Measurement matrix C.
    pub c: SMatrix<T, NY, NX>,
    /// Measurement-noise input D.
    pub d: SMatrix<T, NY, NV>,
    /// Process-noise covariance Q (of w).
    pub q: SMatrix<T, NW, NW>,
    /// Measurement-noise covariance R (of v).
    pub r: SMatrix<T, NV, NV>,
    bqb: SMatrix<T, NX, NX>,
    drd: SMatrix<T, NY, NY>,
}

impl<T: Real, const NX: usize, const NW: usize, const NY: usize, const NV: usize>
    LinearModel<T, NX, NW, NY, NV>
{
    /// Builds and validates a model: every matrix finite, `Q` and `R` symmetric positive
    /// definite, and `D R Dᵀ` positive definite (a measurement with no noise in some direction
    /// makes the innovation covariance singular).
    pub fn new(
        a: SMatrix<T, NX, NX>,
        b: SMatrix<T, NX, NW>,
        c: SMatrix<T, NY, NX>,
        d: SMatrix<T, NY, NV>,
        q: SMatrix<T, NW, NW>,
        r: SMatrix<T, NV, NV>,
    ) -> Result<Self> {
        check_finite(&a, "A")?;
        check_finite(&b, "B")?;
        check_finite(&c, "C")?;
        check_finite(&d, "D")?;
        check_spd(&q, "Q")?;
        check_spd(&r, "R")?;
        let bqb = symmetrize(&(b * q * b.transpose()));
        let drd = symmetrize(&(d * r * d.transpose()));
        check_spd(&drd, "D R Dᵀ")?;
        Ok(Self {
            a,
            b,
            c,
            d,
            q,
            r,
            bqb,
            drd,
        })
    }

    /// Converts every matrix to another scalar type (e.g. an `f64` design run in `f32`).
    pub fn cast<U: Real>(&self) -> Result<LinearModel<U, NX, NW, NY, NV>> {
        let f = |x: T| U::lit(x.to_f64());
        LinearModel::new(
            self.a.map(f),
            self.b.map(f),
            self.c.map(f),
            self.d.map(f),
            self.q.map(f),
            self.r.map(f),
        )
    }
}

impl<T: Real, const NX: usize, const NW: usize, const NY: usize, const NV: usize>
    LinearSystem<T, NX, NY> for LinearModel<T, NX, NW, NY, NV>
{
    #[inline]
    fn a(&self, _k: usize) -> SMatrix<T, NX, NX> {
        self.a
    }
    #[inline]
    fn c(&self, _k: usize) -> SMatrix<T, NY, NX> {
        self.c
    }
    #[inline]
    fn process_cov(&self, _k: usize) -> SMatrix<T, NX, NX> {
        self.bqb
    }
    #[inline]
    fn measurement_cov(&self, _k: usize) -> SMatrix<T, NY, NY> {
        self.drd
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Error;
    use nalgebra::matrix;

    #[test]
    fn rejects_bad_noise() {
        let m = LinearModel::<f64, 1, 1, 1, 1>::new(
            matrix![1.0],
            matrix![1.0],
            matrix![1.0],
            matrix![1.0],
            matrix![-0.1],
            matrix![1.0],
        );
        assert_eq!(m, Err(Error::NotPositiveDefinite { what: "Q" }));
        let m = LinearModel::<f64, 1, 1, 1, 1>::new(
            matrix![1.0],
            matrix![1.0],
            matrix![1.0],
            matrix![1.0],
            matrix![0.1],
            matrix![f64::INFINITY],
        );
        assert_eq!(m, Err(Error::NonFinite { what: "R" }));
        let m = LinearModel::<f64, 1, 1, 1, 1>::new(
            matrix![f64::NAN],
            matrix![1.0],
            matrix![1.0],
            matrix![1.0],
            matrix![0.1],
            matrix![1.0],
        );
        assert_eq!(m, Err(Error::NonFinite { what: "A" }));
    }

    #[test]
    fn effective_covariances() {
        let m = LinearModel::<f64, 2, 1, 1, 1>::new(
            matrix![1.0, 1.0; 0.0, 1.0],
            matrix![0.5; 1.0],
            matrix![1.0, 0.0],
            matrix![2.0],
            matrix![4.0],
            matrix![0.25],
        )
        .unwrap();
        assert_eq!(m.process_cov(0), matrix![1.0, 2.0; 2.0, 4.0]);
        assert_eq!(m.measurement_cov(7), matrix![1.0]);
    }
}
