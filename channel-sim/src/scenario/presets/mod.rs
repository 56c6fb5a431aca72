//! The paper presets and a small example, looked up by name with [`preset`].
//!
//! Adding one is a line in [`PRESETS`] and a file `scenario/presets/<name>.rs` with a
//! `pub fn preset() -> Result<Box<dyn Scenario>, ScenarioError>`.

pub mod linear;
pub mod nn_token_bucket;
pub mod occlusion;
pub mod tobit_fusion;

use crate::error::ScenarioError;
use crate::sim::Scenario;

/// A constructor of a preset scenario.
pub type PresetFn = fn() -> Result<Box<dyn Scenario>, ScenarioError>;

/// The preset registry: name → constructor. Paper presets add one line each.
pub const PRESETS: &[(&str, PresetFn)] = &[
    ("linear", linear::preset),
    ("occlusion", occlusion::preset),
    ("nn-token-bucket", nn_token_bucket::preset),
    ("tobit-fusion", tobit_fusion::preset),
];

/// The preset named `name`.
pub fn preset(name: &str) -> Result<Box<dyn Scenario>, ScenarioError> {
    match PRESETS.iter().find(|(n, _)| *n == name) {
        Some((_, make)) => make(),
        None => Err(ScenarioError::UnknownScenario {
            name: name.to_owned(),
            known: preset_names().join(", "),
        }),
    }
}

/// Names of all presets, in registry order.
pub fn preset_names() -> Vec<&'static str> {
    PRESETS.iter().map(|(n, _)| *n).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_preset_lists_known_names() {
        let e = preset("nope").unwrap_err().to_string();
        assert!(e.starts_with("unknown scenario 'nope' (known: "), "{e}");
        assert!(e.contains("linear"));
    }
}
