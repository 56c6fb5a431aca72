//! Estimator lookup for `run`, `demo` and `replay`: the same [`crate::estimators::FACTORIES`]
//! as `eval`, so the commands can never disagree about what a name means (scenarios: every
//! command and the publisher call `channel_sim::scenario::resolve`).

use crate::estimators::{build_all, EvalOptions, FACTORIES};
use crate::Estimator;
use anyhow::{bail, Result};
use channel_sim::Scenario;
use std::sync::Arc;

/// A factory for a fresh set of estimators (called again when a stream restarts).
pub type EstimatorFactory = Box<dyn Fn() -> Result<Vec<Box<dyn Estimator>>>>;

/// What the estimator factories are built for (as in `eval`: estimators may depend on the
/// seed, the run and the horizon).
#[derive(Clone, Copy, Debug)]
pub struct Experiment {
    /// Experiment seed.
    pub seed: u64,
    /// Run index.
    pub run: u64,
    /// Horizon T.
    pub horizon: u32,
}

/// The estimators that can run on live data for `scenario`: `names` (all when empty). The
/// full-information oracles of `eval` (`Estimator::full_information`) read observations from
/// before the channel, which a real-time loop does not have; they are left out.
pub fn estimators(
    scenario: Arc<dyn Scenario>,
    names: &[String],
    exp: Experiment,
) -> Result<EstimatorFactory> {
    // Estimator families add fields to EvalOptions; the rest default, as in `eval`.
    #[allow(clippy::needless_update)]
    let options = EvalOptions {
        runs: 1,
        horizon: exp.horizon,
        seed: exp.seed,
        ..EvalOptions::default()
    };
    let all = build_all(FACTORIES, scenario.as_ref(), &options, exp.seed, exp.run)?;
    let available: Vec<&'static str> = all
        .iter()
        .filter(|e| !e.full_information())
        .map(|e| e.name())
        .collect();
    for n in names {
        if !available.contains(&n.as_str()) {
            let oracle = all.iter().any(|e| e.name() == n && e.full_information());
            bail!(
                "estimator {n:?} {} for scenario {:?}; available: {}",
                if oracle {
                    "is a full-information oracle (offline `eval` only)"
                } else {
                    "does not exist"
                },
                scenario.name(),
                available.join(", ")
            );
        }
    }
    if available.is_empty() {
        bail!(
            "no real-time estimator applies to scenario {:?}",
            scenario.name()
        );
    }
    let names = names.to_vec();
    Ok(Box::new(move || {
        let built = build_all(FACTORIES, scenario.as_ref(), &options, exp.seed, exp.run)?;
        Ok(built
            .into_iter()
            .filter(|e| !e.full_information())
            .filter(|e| names.is_empty() || names.iter().any(|n| n == e.name()))
            .collect())
    }))
}
