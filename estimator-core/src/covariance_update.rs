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

/// Where a filter's covariance form is decided: at run time ([`CovarianceUpdate`] itself, the
/// default: a value the filter holds and can change), or at compile time ([`JosephForm`],
/// [`StandardForm`]: types without data, so that a filter of that type contains only its own
/// form's code; on a microcontroller the other form is not linked). Both give the same bits
/// for the same form.
pub trait CovarianceForm: Copy + core::fmt::Debug + PartialEq {
    /// The form the update uses.
    fn form(&self) -> CovarianceUpdate;
}

impl CovarianceForm for CovarianceUpdate {
    #[inline(always)]
    fn form(&self) -> CovarianceUpdate {
        *self
    }
}

/// [`CovarianceUpdate::Joseph`], fixed at compile time.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct JosephForm;

impl CovarianceForm for JosephForm {
    #[inline(always)]
    fn form(&self) -> CovarianceUpdate {
        CovarianceUpdate::Joseph
    }
}

/// [`CovarianceUpdate::Standard`], fixed at compile time.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StandardForm;

impl CovarianceForm for StandardForm {
    #[inline(always)]
    fn form(&self) -> CovarianceUpdate {
        CovarianceUpdate::Standard
    }
}
