//! Scenarios: a plant, its channel stages and the initial distribution, under a name.
//!
//! [`ComposedScenario`] ([`composed`]) is the one [`Scenario`] implementation; its parts come
//! from a preset ([`presets`], by name) or a TOML file ([`config`]). [`resolve`] is the one
//! entry point that turns a command line's `--scenario NAME` / `--config FILE` into the
//! scenario: the `channel-sim` publisher and every `ipc-runner` command call it, so the two
//! processes can never disagree about what a name means.

pub mod composed;
pub mod config;
pub mod initial;
pub mod presets;

use std::path::Path;

use crate::error::ScenarioError;
use crate::sim::Scenario;

pub use composed::{ComposedScenario, ComposedSimulation};
pub use initial::InitialDistribution;
pub use presets::{preset, preset_names, PresetFn, PRESETS};

/// The scenario file `config` (TOML, see [`config`]) when given, else the preset `name`.
pub fn resolve(name: &str, config: Option<&Path>) -> Result<Box<dyn Scenario>, ScenarioError> {
    Ok(match config {
        Some(path) => Box::new(config::load(path)?),
        None => preset(name)?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::Simulation;

    #[test]
    fn resolve_takes_the_file_when_given_else_the_preset() {
        assert_eq!(resolve("linear", None).unwrap().name(), "linear");
        let file = Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/scenarios/example.toml"
        ));
        assert_eq!(resolve("linear", Some(file)).unwrap().name(), "example");
        assert_eq!(
            resolve("nope", None).unwrap_err(),
            preset("nope").unwrap_err()
        );
    }

    #[test]
    fn same_seed_same_instants_and_channel_does_not_change_plant() {
        let s = preset("linear").unwrap();
        let c = s.as_any().downcast_ref::<ComposedScenario>().unwrap();
        let bare = c.without_channel();
        let (mut a, mut b, mut n) = (c.simulate(5, 9), c.simulate(5, 9), bare.simulate(5, 9));
        assert_eq!(a.initial_truth(), n.initial_truth());
        let mut dropped = 0;
        for _ in 0..200 {
            let (ia, ib, inn) = (a.next_instant(), b.next_instant(), n.next_instant());
            assert_eq!(ia, ib);
            assert_eq!(ia.truth, inn.truth);
            assert_eq!(a.raw_observations().unwrap(), &inn.obs[..]);
            assert!(inn.obs.iter().all(|o| o.delivered && o.flags == 0));
            for (o, r) in ia.obs.iter().zip(a.raw_observations().unwrap()) {
                if o.delivered {
                    assert_eq!(o, r);
                } else {
                    dropped += 1;
                }
            }
        }
        assert!(dropped > 0);
        let mut other = c.simulate(5, 10);
        assert_ne!(
            other.next_instant().truth,
            c.simulate(5, 9).next_instant().truth
        );
    }
}
