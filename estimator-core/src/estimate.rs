//! What every estimator here produces: the state estimate `x̂` and its covariance `P`, as one
//! value (like adskalman's `StateAndCovariance`).
//!
//! For the Kalman-type filters `P` is the filter's error covariance. For the NN estimator
//! (seed 003) and the Tobit filters (seed 004) it is their upper *bound* on the error
//! covariance (`P̄`), which the papers' theorems propagate instead of the covariance itself.

use nalgebra::{SMatrix, SVector};

use crate::linalg::{check_finite, check_spd, symmetrize};
use crate::{Real, Result};

/// A state estimate `x̂` on `NX` states with its covariance `P` (or covariance bound `P̄`, see
/// the module docs): `x̂` finite, `P` finite, exactly symmetric and positive definite when
/// built by [`Estimate::new`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Estimate<T: Real, const NX: usize> {
    x: SVector<T, NX>,
    p: SMatrix<T, NX, NX>,
}

impl<T: Real, const NX: usize> Estimate<T, NX> {
    /// Validates an initial estimate: `x` finite (error names "x0"), `p` symmetric positive
    /// definite (error names "P0"); `p` is stored symmetrised.
    pub fn new(x: SVector<T, NX>, p: SMatrix<T, NX, NX>) -> Result<Self> {
        Self::named(x, p, "x0", "P0")
    }

    /// [`Estimate::new`] with the names the errors give to `x` and `p` (e.g. "x̂₀", "P̄₀").
    pub fn named(
        x: SVector<T, NX>,
        p: SMatrix<T, NX, NX>,
        state: &'static str,
        covariance: &'static str,
    ) -> Result<Self> {
        check_finite(&x, state)?;
        check_spd(&p, covariance)?;
        Ok(Self {
            x,
            p: symmetrize(&p),
        })
    }

    /// A result a filter has already checked (finite, and symmetric as its update forms it).
    #[inline]
    pub(crate) const fn trusted(x: SVector<T, NX>, p: SMatrix<T, NX, NX>) -> Self {
        Self { x, p }
    }

    /// The state estimate `x̂`.
    #[inline]
    pub fn state(&self) -> &SVector<T, NX> {
        &self.x
    }

    /// The covariance `P` of the estimate (for the NN and Tobit filters its bound `P̄`).
    #[inline]
    pub fn covariance(&self) -> &SMatrix<T, NX, NX> {
        &self.p
    }

    /// `(x̂, P)`.
    #[inline]
    pub fn into_parts(self) -> (SVector<T, NX>, SMatrix<T, NX, NX>) {
        (self.x, self.p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Error;
    use nalgebra::{matrix, vector};

    #[test]
    fn refuses_what_a_filter_cannot_start_from() {
        let e = Estimate::new(vector![1.0, 2.0], matrix![2.0, 0.5; 0.5, 1.0]).unwrap();
        assert_eq!(
            e.into_parts(),
            (vector![1.0, 2.0], matrix![2.0, 0.5; 0.5, 1.0])
        );
        assert_eq!(
            Estimate::new(vector![f64::NAN, 0.0], SMatrix::identity()),
            Err(Error::NonFinite { what: "x0" })
        );
        assert_eq!(
            Estimate::new(vector![0.0, 0.0], matrix![1.0, 2.0; 2.0, 1.0]),
            Err(Error::NotPositiveDefinite { what: "P0" })
        );
    }

    #[test]
    fn errors_carry_the_given_names_and_p_is_symmetrised() {
        assert_eq!(
            Estimate::named(vector![f64::INFINITY], matrix![1.0], "x̂₀", "P̄₀"),
            Err(Error::NonFinite { what: "x̂₀" })
        );
        assert_eq!(
            Estimate::named(vector![0.0], matrix![-1.0], "x̂₀", "P̄₀"),
            Err(Error::NotPositiveDefinite { what: "P̄₀" })
        );
        let p = matrix![2.0, 0.5; 0.5 + 1e-12, 1.0];
        let e = Estimate::new(vector![0.0, 0.0], p).unwrap();
        assert_eq!(e.covariance(), &symmetrize(&p));
    }
}
