//! Why a scenario could not be built.
//!
//! The bottom of the crate: plants, channel stages, presets and the TOML loader all report
//! through this one type, so it imports nothing from them.

use std::fmt;

/// Why a scenario could not be built.
#[derive(Clone, Debug, PartialEq)]
pub enum ScenarioError {
    /// No preset has this name.
    UnknownScenario {
        /// The requested name.
        name: String,
        /// The known names, comma-separated.
        known: String,
    },
    /// A parameter is invalid.
    Invalid {
        /// Dotted path of the field (`model.q`, `stages[1].p_loss`).
        field: String,
        /// Why.
        reason: String,
    },
    /// A scenario file could not be read or parsed.
    File {
        /// The file.
        path: String,
        /// What went wrong (one line).
        reason: String,
    },
}

impl ScenarioError {
    /// An [`ScenarioError::Invalid`] for `field`.
    pub fn invalid(field: impl Into<String>, reason: impl Into<String>) -> Self {
        ScenarioError::Invalid {
            field: field.into(),
            reason: reason.into(),
        }
    }
}

impl fmt::Display for ScenarioError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ScenarioError::UnknownScenario { name, known } => {
                write!(f, "unknown scenario '{name}' (known: {known})")
            }
            ScenarioError::Invalid { field, reason } => write!(f, "invalid `{field}`: {reason}"),
            ScenarioError::File { path, reason } => write!(f, "{path}: {reason}"),
        }
    }
}

impl std::error::Error for ScenarioError {}

impl From<estpipe_spec::SpecError> for ScenarioError {
    fn from(e: estpipe_spec::SpecError) -> Self {
        match e {
            estpipe_spec::SpecError::Invalid { field, reason } => {
                ScenarioError::Invalid { field, reason }
            }
            estpipe_spec::SpecError::File { path, reason } => ScenarioError::File { path, reason },
        }
    }
}
