//! Plants, sensors and channel models that turn the papers' numerical examples into sample
//! streams, and the publisher that puts them on shared memory for `ipc-runner`.
//!
//! The data path reads top to bottom, and so do the modules:
//!
//! | step | module | what |
//! |---|---|---|
//! | plant | [`plant`] | the true state x_k and every node's raw measurement z_{m,k} |
//! | channel | [`channel`] | what happens to a packet between sensor and estimator: occlusion, token buckets, Tobit censoring, event triggers, random loss |
//! | instant | [`sim`] | the contract: one [`Instant`] per k, one [`Observation`] per node |
//! | shared memory | [`wire`], [`publisher`], [`backpressure`] | observations as the contract's slots (`estpipe_wire`), the `channel-sim` process that publishes them on iceoryx2, and what it does when a queue is full |
//!
//! [`scenario`] puts a plant, its channel stages and the initial distribution under a name
//! (presets or TOML); [`scenario::resolve`] is what both processes call to get one. Beneath
//! everything: [`error`] (the one error type of scenario construction, and what counts as
//! bad input), [`rng`] (the run's random streams) and [`validate`] (parameter checks naming
//! the field). The process plumbing (console lines, the signal flag, checked flags, the
//! iceoryx2 node) is `estpipe_process`'s, shared with `ipc-runner` and the bridge.

pub mod backpressure;
pub mod channel;
pub mod error;
pub mod plant;
pub mod publisher;
pub mod rng;
pub mod scenario;
pub mod sensor_node;
pub mod sim;
pub mod slot_sender;
pub mod validate;
pub mod wire;

pub use error::ScenarioError;
pub use sim::{Instant, Observation, Scenario, Simulation};
