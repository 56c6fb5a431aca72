//! The contract between simulation, transport and estimation.
//!
//! A [`Scenario`] (plant + sensors + channel, fully parameterised) starts a [`Simulation`]
//! for a given `(seed, run)`; the simulation yields one [`Instant`] per sampling time k: the
//! true state (for evaluation only) and one [`Observation`] per sensor node, which is exactly
//! what crosses the channel (and, in the pipeline, the shared memory). Estimators see only
//! observations. The same `(scenario, seed, run)` always yields the same instants, whether
//! consumed in-process by `ipc-runner eval` or published by the `channel-sim` process, so the
//! pipeline reproduces the Monte-Carlo numbers exactly.

/// Largest state dimension a scenario may have (fixed so wire messages are fixed-size).
pub const MAX_NX: usize = 8;
/// Largest measurement dimension per node.
pub const MAX_NY: usize = 4;
/// Largest number of sensor nodes.
pub const MAX_NODES: usize = 8;

/// What the channel delivers for one sampling instant and one sensor node.
///
/// A dropped packet still produces an observation (with `delivered == false`): in the
/// occlusion model the drop itself is information, so the estimator must see the instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Observation {
    /// Sampling instant k (≥ 1; k = 0 is the prior and has no measurement).
    pub k: u32,
    /// Sensor node index, 0-based.
    pub node: u8,
    /// Whether a measurement reached the estimator at this instant.
    pub delivered: bool,
    /// Number of valid entries in `y`.
    pub ny: u8,
    /// The measurement as received (after censoring, etc.); meaningful iff `delivered`.
    /// Entries at index ≥ `ny` are 0.
    pub y: [f64; MAX_NY],
    /// Channel-side flags of this instant, see the `FLAG_*` constants.
    pub flags: u32,
}

/// The sensor's event trigger fired at this instant (seed 004 eq. 13).
pub const FLAG_TRIGGERED: u32 = 1 << 0;
/// A trigger (or scheduled send) was blocked because the token bucket was empty.
pub const FLAG_TOKEN_BLOCKED: u32 = 1 << 1;
/// At least one entry of `y` was censored (Tobit, seed 004 eq. 2).
pub const FLAG_CENSORED: u32 = 1 << 2;
/// The packet was lost by a random-loss stage (Bernoulli / Gilbert–Elliott).
pub const FLAG_RANDOM_LOSS: u32 = 1 << 3;
/// The packet was dropped because the state was inside an occlusion region (seed 001).
pub const FLAG_OCCLUDED: u32 = 1 << 4;

impl Observation {
    /// A dropped packet at instant `k` from `node` with measurement dimension `ny`.
    pub fn dropped(k: u32, node: u8, ny: u8, flags: u32) -> Self {
        Self {
            k,
            node,
            delivered: false,
            ny,
            y: [0.0; MAX_NY],
            flags,
        }
    }

    /// The valid part of the measurement (`None` when nothing was delivered).
    pub fn measurement(&self) -> Option<&[f64]> {
        self.delivered.then(|| &self.y[..self.ny as usize])
    }
}

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
    /// The true initial state x_0 (k = 0 has no observation).
    fn initial_truth(&self) -> [f64; MAX_NX];
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
    /// Measurement dimension per node.
    fn ny(&self) -> usize;
    /// Number of sensor nodes.
    fn nodes(&self) -> usize;
    /// Starts run `run` of the experiment seeded by `seed`. Runs are independent streams:
    /// the same `(seed, run)` gives the same instants on every machine and thread count.
    fn start(&self, seed: u64, run: u64) -> Box<dyn Simulation>;
    /// For downcasting to the concrete scenario (estimator factories read its parameters).
    fn as_any(&self) -> &dyn std::any::Any;
}
