//! Plants, sensors and channel models that turn the papers' numerical examples into sample
//! streams, plus the wire format shared with `ipc-runner`.
//!
//! The data path reads top to bottom: plant → sensor → channel stages → [`sim::Instant`]
//! (→ shared memory in the pipeline) → estimator.

pub mod publisher;
pub mod signal;
pub mod sim;
pub mod wire;

pub use sim::{Instant, Observation, Scenario, Simulation};
pub mod loss;
pub mod nn_plant;
pub mod occlusion;
pub mod plant;
pub mod scenario;
pub mod stage;
pub mod tobit_channel;
pub mod token_bucket;
