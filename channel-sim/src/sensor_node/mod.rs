//! Sensor nodes in the loop (docs/sensor-node.md): the publisher's channel is a set of
//! microcontrollers on serial lines instead of the simulated stages.
//!
//! `channel-sim --sensor-node unix:PATH` (one per node, in node order) runs the scenario's
//! plant as usual, feeds each node its raw samples over its line, and publishes the slots the
//! nodes decided ([`gateway::NodeLoop`]); the frames are `estpipe_sensor_node`'s, shared with
//! the firmware. The modules: [`link`] (a line: connect, frames in and out, deadlines),
//! [`config`] (what each node runs, from the scenario's stages), [`gateway`] (the loop, the
//! checks and the comparison with channel-sim's own decisions).

pub mod config;
pub mod gateway;
pub mod link;

pub use gateway::{LoopReport, NodeLoop};
pub use link::Endpoint;
