//! Where the estimators' spec comes from: a simulated scenario (a preset or a scenario TOML,
//! which produces its [`EstimatorSpec`]) or a spec file written by hand (`--estimator-spec`).
//! The one place the runner's commands meet the simulator: `run/`, `estimators/` and
//! `replay` read only the [`Source`].

use std::path::Path;
use std::sync::Arc;

use channel_sim::Scenario;
use estpipe_spec::EstimatorSpec;
use estpipe_wire::Observation;

use crate::estimators::RunStart;
use crate::limits::BadInput;

/// The estimators' spec and what a run adds to it.
#[derive(Clone, Debug)]
pub struct Source {
    /// What the estimators know.
    pub spec: Arc<EstimatorSpec>,
    /// The observations of instant 0 of the run (a scenario whose sensors measure at k = 0,
    /// seed 003's y₀): the run's instant 0 simulated again, which is what its publisher drew.
    /// `None` for the others and for a spec file (the receiver cannot know a y₀ that was
    /// never on the stream).
    pub initial: Option<Vec<Observation>>,
}

impl Source {
    /// Run `run` of `scenario` seeded by `seed`.
    pub fn of_scenario(scenario: &dyn Scenario, seed: u64, run: u64) -> Self {
        let sim = scenario.start(seed, run);
        Self {
            spec: scenario.estimator_spec(),
            initial: sim.initial_observations().map(<[Observation]>::to_vec),
        }
    }

    /// A spec on its own.
    pub fn of_spec(spec: Arc<EstimatorSpec>) -> Self {
        Self {
            spec,
            initial: None,
        }
    }

    /// The spec of `--estimator-spec FILE` when given, else of the scenario of `--scenario
    /// NAME` / `--config FILE` for run `run` seeded by `seed`. A bad file is bad input naming
    /// the file and the field.
    pub fn resolve(
        scenario: &str,
        config: Option<&Path>,
        estimator_spec: Option<&Path>,
        seed: u64,
        run: u64,
    ) -> anyhow::Result<Self> {
        match estimator_spec {
            Some(path) => {
                let spec = estpipe_spec::file::load(path).map_err(|e| BadInput(e.to_string()))?;
                // Parameters accepted against their paper's own conditions (λχ ≤ 1 by the
                // explicit opt-in), as `eval` says them for a scenario.
                for w in spec.warnings() {
                    estpipe_process::errln!("ipc-runner: warning: {}: {w}", path.display());
                }
                Ok(Self::of_spec(spec))
            }
            None => {
                let scenario = self::scenario(scenario, config)?;
                Ok(Self::of_scenario(&*scenario, seed, run))
            }
        }
    }

    /// The run as the estimator factories see it.
    pub fn start(&self, seed: u64, run: u64) -> RunStart<'_> {
        RunStart {
            seed,
            run,
            initial: self.initial.as_deref(),
        }
    }
}

/// The scenario of `--scenario NAME`, or of `--config FILE` when given. One the simulator
/// cannot build is bad input, marked here, where the runner meets the simulator, in the
/// product's own terms ([`BadInput`]: exit code 2), so that no exit code is the simulator's
/// decision.
pub fn scenario(name: &str, config: Option<&Path>) -> Result<Box<dyn Scenario>, BadInput> {
    channel_sim::scenario::resolve(name, config).map_err(|e| BadInput(e.to_string()))
}

/// `ipc-runner channel-sim`: the simulator's publisher, its failures in the product's terms:
/// what the simulator calls bad input (a flag, a scenario it cannot build) is [`BadInput`],
/// everything else (a peer outside the wire contract among them) keeps its cause.
pub fn publish(args: &channel_sim::publisher::PublisherArgs) -> anyhow::Result<i32> {
    channel_sim::publisher::run(args).map(|_| 0).map_err(|e| {
        if channel_sim::error::is_bad_input(&e) {
            BadInput(format!("{e:#}")).into()
        } else {
            e
        }
    })
}

/// The spec of preset `name` (tests of the estimator families, which never read a simulator
/// themselves).
#[cfg(test)]
pub(crate) fn preset_spec(name: &str) -> Arc<EstimatorSpec> {
    channel_sim::scenario::preset(name)
        .expect("a preset")
        .estimator_spec()
}

/// The estimators of `factories` for run `(seed, run)` of `scenario`: its spec and its
/// instant-0 observations, as `eval` builds them.
pub fn build_for_scenario(
    factories: &[crate::estimators::Factory],
    scenario: &dyn Scenario,
    options: &crate::eval::EvalOptions,
    seed: u64,
    run: u64,
) -> anyhow::Result<Vec<Box<dyn crate::Estimator>>> {
    let source = Source::of_scenario(scenario, seed, run);
    crate::estimators::build_all(factories, &source.spec, options, &source.start(seed, run))
}
