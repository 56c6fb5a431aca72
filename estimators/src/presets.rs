//! The presets' specs and runs for the families' tests (dev-dependency on channel-sim: the
//! estimators themselves never read a simulator).

use std::sync::Arc;

use estpipe_spec::EstimatorSpec;

/// The spec of preset `name`.
pub(crate) fn preset_spec(name: &str) -> Arc<EstimatorSpec> {
    channel_sim::scenario::preset(name)
        .expect("a preset")
        .estimator_spec()
}

/// The spec of preset `name` and its run `(seed, run)`, for tests that need simulated
/// instants.
pub(crate) fn preset_run(
    name: &str,
    seed: u64,
    run: u64,
) -> (Arc<EstimatorSpec>, Box<dyn channel_sim::Simulation>) {
    let s = channel_sim::scenario::preset(name).expect("a preset");
    (s.estimator_spec(), s.start(seed, run))
}
