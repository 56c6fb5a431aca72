//! What the bridge does to a stream whatever carries it between the hosts. Nothing here names
//! a zenoh type: these are the contract's rules across a link (docs/bridge.md), and this
//! host's shared memory, which another transport would keep as they are.
//!
//! | module | what |
//! |---|---|
//! | [`sequence`] | per-node sequence tracking: what the network lost, as lost slots |
//! | [`markers`] | the sensor side's END/ABORT markers, repeated until acknowledged |
//! | [`report`] | counts by reason and the bridge's latency histograms |
//! | `forward` | a message from the far side checked, then written into shared memory |
//! | `shm` | this host's iceoryx2 services of the prefix, and a sample written into one |
//! | `linger` | when a `--once` bridge ends |
//! | `wait` | waiting for the other end within `--connect-timeout` |

pub(crate) mod forward;
pub(crate) mod linger;
pub mod markers;
pub mod report;
pub mod sequence;
pub(crate) mod shm;
pub(crate) mod wait;
