//! The serial link between a sensor node and the estimation pipeline (docs/sensor-node.md).
//!
//! A sensor node (the firmware in `estimator-core/firmware`, `src/node/`) reads each instant's
//! raw sample from its UART, decides with estimator-core's sensor-side protocols whether to
//! transmit it, and writes the decision back; a gateway on the host (`channel-sim
//! --sensor-node`) feeds the samples, checks every answer against the contract and
//! publishes the slots. Both sides use this crate, so they agree on the bytes:
//!
//! - [`frame`]: the messages and their frames (postcard, CRC-32, COBS);
//! - [`deframe`]: cutting a byte stream into frames in a fixed buffer;
//! - [`node`]: the node's state machine, target-independent, so the host tests it too.
//!
//! `no_std`, no allocation, no `unsafe`, and no panic on any input bytes.
#![no_std]
#![forbid(unsafe_code)]

pub mod deframe;
pub mod frame;
pub mod node;

pub use deframe::{Deframer, Push};
pub use frame::{
    decode, encode, Decision, FrameError, FromNode, NodeConfig, NodeStats, Refusal, Sample,
    Schedule, ToNode, DELIMITER, LINK_VERSION, MAX_FRAME, MAX_NY,
};
pub use node::{Phase, Reply, SensorNode};
