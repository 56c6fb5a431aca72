//! Why a scenario could not be built.
//!
//! The bottom of the crate: plants, channel stages, presets and the TOML loader all report
//! through this one type, so it imports nothing from them.
//!
//! A scenario that cannot be built is bad input, as a bad flag is ([`is_bad_input`]).

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

/// Whether an error chain was caused by bad input ([`estpipe_process::flags::BadInput`] or a
/// scenario that could not be built, [`ScenarioError`]): such a command exits with code 2.
pub fn is_bad_input(e: &anyhow::Error) -> bool {
    estpipe_process::flags::BadInput::is_in(e) || e.chain().any(|c| c.is::<ScenarioError>())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_input_is_found_anywhere_in_the_chain() {
        use anyhow::Context as _;
        let e = Err::<(), _>(estpipe_process::flags::BadInput("x".into()))
            .context("outer")
            .unwrap_err();
        assert!(is_bad_input(&e));
        let e = Err::<(), _>(ScenarioError::invalid("a", "b"))
            .context("outer")
            .unwrap_err();
        assert!(is_bad_input(&e));
        assert!(!is_bad_input(&anyhow::anyhow!("io")));
    }
}
