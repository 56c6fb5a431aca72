//! The choice of covariance form in a Kalman measurement update. It sits at the crate root so
//! that the update kernels of [`crate::linalg`] and the filters of [`crate::filter`] share it
//! without the math importing from the filters.

/// How the measurement update forms the posterior covariance.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum CovarianceUpdate {
    /// `P⁺ = (I − KC) P (I − KC)ᵀ + K R Kᵀ`: stays positive semi-definite under rounding and
    /// for any gain (the default).
    #[default]
    Joseph,
    /// `P⁺ = (I − KC) P`: cheaper, only correct for the optimal gain, can lose definiteness.
    Standard,
}
