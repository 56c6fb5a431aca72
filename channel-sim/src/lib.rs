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
//! everything: [`error`] (the one error type of scenario construction), [`rng`] (the run's
//! random streams), [`validate`] (parameter checks naming the field) and [`flags`] (the
//! command-line values of both binaries, and what counts as bad input). [`signal`] lets the
//! publisher and `ipc-runner` ask for Ctrl-C without sleeping (and makes every other signal
//! harmless); [`node`] creates their iceoryx2 node and says what to do when the iceoryx2
//! directories belong to another user.

pub mod backpressure;
pub mod channel;
pub mod console;
pub mod error;
pub mod flags;
pub mod node;
pub mod plant;
pub mod publisher;
pub mod rng;
pub mod scenario;
pub mod signal;
pub mod sim;
pub mod validate;
pub mod wire;

pub use error::ScenarioError;
pub use sim::{Instant, Observation, Scenario, Simulation};
