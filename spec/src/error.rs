//! Why a spec could not be built: the field and the reason, one line.
//!
//! The bottom of the crate: every part reports through this one type.

use std::fmt;

/// A spec field that failed validation, or a spec file that could not be read.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum SpecError {
    /// A field's value is unusable (`invalid `model.q`: is not positive definite`).
    Invalid {
        /// The field, as a TOML path (`sensors[1].r`).
        field: String,
        /// Why, in a few words.
        reason: String,
    },
    /// A spec file that could not be read or parsed; `reason` names the line or field.
    File {
        /// The file as given.
        path: String,
        /// Why.
        reason: String,
    },
}

impl SpecError {
    /// An invalid `field`.
    pub fn invalid(field: impl Into<String>, reason: impl Into<String>) -> Self {
        SpecError::Invalid {
            field: field.into(),
            reason: reason.into(),
        }
    }
}

impl fmt::Display for SpecError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SpecError::Invalid { field, reason } => write!(f, "invalid `{field}`: {reason}"),
            SpecError::File { path, reason } => write!(f, "{path}: {reason}"),
        }
    }
}

impl std::error::Error for SpecError {}
