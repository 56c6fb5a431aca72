//! The contract between simulation, transport and estimation.
//!
//! A [`Scenario`] (plant + sensors + channel, fully parameterised) starts a [`Simulation`]
//! for a given `(seed, run)`; the simulation yields one [`Instant`] per sampling time k: the
//! true state (for evaluation only) and one [`Observation`] per sensor node, which is exactly
//! what crosses the channel (and, in the pipeline, the shared memory). Estimators see only
//! observations. The same `(scenario, seed, run)` always yields the same instants, whether
//! consumed in-process by `ipc-runner eval` or published by the `channel-sim` process, so the
//! pipeline reproduces the Monte-Carlo numbers exactly.

// The limits and the channel flags are part of the wire contract (fixed-size payloads, the
// slot's `flags` field), so they are defined there, once.
pub use estpipe_wire::{
    Observation, FLAG_CENSORED, FLAG_OCCLUDED, FLAG_RANDOM_LOSS, FLAG_TOKEN_BLOCKED,
    FLAG_TRIGGERED, MAX_NODES, MAX_NX, MAX_NY,
};

/// One sampling instant of a simulation.
#[derive(Clone, Debug, PartialEq)]
pub struct Instant {
    /// Sampling instant k.
    pub k: u32,
    /// True state x_k (first `nx` entries valid). For evaluation only.
    pub truth: [f64; MAX_NX],
    /// One observation per node, in node order.
    pub obs: heapless::Vec<Observation, MAX_NODES>,
}

/// A running simulation: yields instants k = 1, 2, … without allocating per step.
pub trait Simulation: Send {
    /// The true initial state x_0.
    fn initial_truth(&self) -> [f64; MAX_NX];
    /// The observations of instant 0, after every channel stage, for a scenario whose
    /// sensors measure at k = 0 (seed 003's timing: its token bucket takes its first decision
    /// at k = 0 and its estimators use y₀); `None` for the others (k = 0 is the prior only,
    /// seed 001's convention). They are not part of the stream, whose slots start at k = 1:
    /// the estimators that use them receive them when they are built (docs/design.md,
    /// "Seed 003").
    fn initial_observations(&self) -> Option<&[Observation]> {
        None
    }
    /// Advances to the next instant.
    fn next_instant(&mut self) -> Instant;
    /// The observations of the last instant as the sensors produced them, before any channel
    /// stage acted (every one delivered, nothing censored). For oracle baselines in offline
    /// evaluation only (the full-information `kf`); `None` where unavailable (e.g. a replay).
    fn raw_observations(&self) -> Option<&[Observation]> {
        None
    }
}

/// A fully parameterised experiment: plant, sensors and channel.
pub trait Scenario: Send + Sync + std::fmt::Debug {
    /// Stable lower-case name (`occlusion`, `nn-token-bucket`, `tobit-fusion`, …).
    fn name(&self) -> &str;
    /// State dimension.
    fn nx(&self) -> usize;
    /// The largest node's measurement dimension (every node's, unless the sensors differ:
    /// then [`Scenario::node_ny`]).
    fn ny(&self) -> usize;
    /// Measurement dimension of node `node`, what its slots carry and the stream header
    /// announces. Default: [`Scenario::ny`].
    fn node_ny(&self, _node: usize) -> usize {
        self.ny()
    }
    /// Number of sensor nodes.
    fn nodes(&self) -> usize;
    /// What the estimators know of this scenario: the model, their prior and the channel
    /// effects whose outcome carries information (nothing of the truth's distribution or of
    /// random losses). The runner builds its estimators from this alone, so a spec written by
    /// hand for the same model gives the same estimates (docs/design.md, "Architecture").
    fn estimator_spec(&self) -> std::sync::Arc<estpipe_spec::EstimatorSpec>;
    /// The model fingerprint a stream of this scenario announces in its
    /// [`StreamHeader`](estpipe_wire::StreamHeader): the estimator spec's (`docs/wire.md`,
    /// "Model fingerprint").
    fn fingerprint(&self) -> u64 {
        self.estimator_spec().fingerprint()
    }
    /// Starts run `run` of the experiment seeded by `seed`. Runs are independent streams:
    /// the same `(seed, run)` gives the same instants on every machine and thread count.
    fn start(&self, seed: u64, run: u64) -> Box<dyn Simulation>;
    /// For downcasting to the concrete scenario (estimator factories read its parameters).
    fn as_any(&self) -> &dyn std::any::Any;
}
