//! The one error type of the core.

use core::fmt;

/// Why a constructor or a step refused its input.
///
/// Every step that returns an error leaves the estimator exactly as it was before the call.
#[non_exhaustive]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Error {
    /// An input (measurement, matrix, parameter) contains NaN or ±∞.
    NonFinite {
        /// Which input.
        what: &'static str,
    },
    /// A matrix that must be symmetric positive definite is not (Cholesky failed or the matrix
    /// is not symmetric).
    NotPositiveDefinite {
        /// Which matrix.
        what: &'static str,
    },
    /// A configuration value is outside what the algorithm or the paper allows.
    InvalidConfig {
        /// The offending field.
        field: &'static str,
        /// Why it is refused.
        reason: &'static str,
    },
    /// A computation lost all numerical meaning (e.g. every mixture weight is zero).
    Numerical {
        /// What went wrong.
        what: &'static str,
    },
    /// A step for another instant than the one an estimator that counts its own instants
    /// expects next.
    OutOfOrder {
        /// The instant the estimator expects.
        expected: usize,
        /// The instant it was given.
        got: usize,
    },
    /// A late packet for an instant older than the fixed-lag history keeps
    /// ([`FixedLag`](crate::FixedLag)): it is dropped.
    TooLate {
        /// The oldest instant a late packet may still belong to (`newest + 1` when none).
        oldest: usize,
        /// The packet's instant.
        got: usize,
    },
}

/// Result alias used throughout the crate.
pub type Result<T> = core::result::Result<T, Error>;

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::NonFinite { what } => write!(f, "non-finite value in {what}"),
            Error::NotPositiveDefinite { what } => {
                write!(f, "{what} is not symmetric positive definite")
            }
            Error::InvalidConfig { field, reason } => write!(f, "invalid {field}: {reason}"),
            Error::Numerical { what } => write!(f, "numerical failure: {what}"),
            Error::OutOfOrder { expected, got } => {
                write!(f, "step for instant {got}, expected instant {expected}")
            }
            Error::TooLate { oldest, got } => write!(
                f,
                "late packet for instant {got} is older than the fixed lag keeps (oldest {oldest})"
            ),
        }
    }
}

impl core::error::Error for Error {}
