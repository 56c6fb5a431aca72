//! Scenario and estimator lookup for `run`, `demo` and `replay`: one place that maps names to
//! objects, so the three commands (and `eval`) can never disagree.

use crate::Estimator;
use anyhow::{bail, Result};
use channel_sim::publisher::{self, PublisherArgs};
use channel_sim::Scenario;

/// A factory for a fresh set of estimators (called again when a stream restarts).
pub type EstimatorFactory = Box<dyn Fn() -> Result<Vec<Box<dyn Estimator>>>>;

/// The scenario `name` (or the TOML `config`) and its default horizon.
pub fn scenario(name: &str, config: Option<&std::path::Path>) -> Result<(Box<dyn Scenario>, u32)> {
    let args = PublisherArgs {
        scenario: name.to_string(),
        config: config.map(Into::into),
        seed: 0,
        run: 0,
        steps: None,
        rate: 0.0,
        prefix: String::new(),
        connect_timeout: 0.0,
        linger: 0.0,
        debug_wire_version: None,
        debug_nan_every: None,
        quiet: true,
    };
    publisher::resolve_scenario(&args)
}

/// Estimators for `scenario`: `names` (comma-separated) or all applicable ones when empty.
pub fn estimators(scenario: &dyn Scenario, names: &[String]) -> Result<EstimatorFactory> {
    if scenario.name() == publisher::selftest::NAME {
        for n in names {
            if n != "kf" {
                bail!(
                    "estimator {n:?} does not apply to {}; available: kf",
                    scenario.name()
                );
            }
        }
        return Ok(Box::new(|| {
            Ok(vec![
                Box::new(super::selftest::SelfTestKf::new()) as Box<dyn Estimator>
            ])
        }));
    }
    bail!(
        "no estimators registered for scenario {:?}",
        scenario.name()
    )
}
