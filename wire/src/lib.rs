//! The estimation pipeline's shared-memory contract, defined once: what a publisher of sensor
//! slots and a subscriber of estimates must agree on with `ipc-runner`, whatever language
//! they are written in. `docs/wire.md` is the same contract for people (every field's offset,
//! the QoS, the stream rules); a test checks its tables against this crate.
//!
//! Depend on this crate, not on `channel-sim`, to talk to the pipeline from your own Rust
//! process: it knows nothing of plants, channels or estimators.
//!
//! | module | what |
//! |---|---|
//! | [`slot`] | [`Slot`]: one sensor node's observation of one instant, its kinds, flags and validation |
//! | [`header`] | [`StreamHeader`]: the shape of the stream, in the user header of every slot |
//! | [`fingerprint`] | [`Fnv1a64`], the hash behind [`StreamHeader::model`] |
//! | [`observation`] | [`Observation`]: one node's observation of one instant as the estimators read it, and its slot |
//! | [`estimate`] | [`Estimate`]: x̂, the packed covariance, status and timing |
//! | [`truth`] | [`Truth`]: the true state, for evaluation only |
//! | [`services`] | service names, QoS and opening the services with them |
//! | [`qos`] | [`qos::PubSubQos`]: what a publish-subscribe service is created with |
//! | [`explain`] | what a failed open means, in one line |
//! | [`net`] | the byte form of every payload between hosts (the zenoh bridge), decoded with every check |
//! | [`layout`] | every payload's field offsets, sizes and alignments (what the docs and the C header are checked against) |
//! | [`error`] | [`WireError`] (a bad payload) and [`ContractError`] (a peer outside the contract) |
//! | [`clock`] | [`monotonic_ns`], the one clock of every timestamp |
//!
//! Every payload is `#[repr(C)]`, fixed-size and pointer-free, has [`WIRE_VERSION`] as its
//! first field and an explicit iceoryx2 type name (without `#[type_name]` iceoryx2 uses the
//! Rust path and refuses a peer built elsewhere).

pub mod clock;
pub mod error;
pub mod estimate;
pub mod explain;
pub mod fingerprint;
pub mod header;
pub mod layout;
pub mod net;
pub mod observation;
pub mod qos;
pub mod services;
pub mod slot;
pub mod truth;

pub use clock::monotonic_ns;
pub use error::{ContractError, WireError};
pub use estimate::{
    packed_index, Estimate, COV_BOUND, COV_ESTIMATE, COV_LEN, COV_NONE, STATUS_NONE_YET, STATUS_OK,
    STATUS_REFUSED,
};
pub use fingerprint::Fnv1a64;
pub use header::StreamHeader;
pub use observation::Observation;
pub use services::{
    estimate_service, latest_estimates_board, ready_event_service, service_name, slot_service,
    truth_service, DEFAULT_PREFIX, DEFAULT_RATE_HZ, DEFAULT_STEPS, ESTIMATES, ESTIMATE_HISTORY,
    LATEST_ESTIMATES, MAX_SUBSCRIBER_BUFFER, READY_EVENT, SLOTS, SLOTS_READY, TRUTH,
};
pub use slot::{
    Slot, SlotFault, FLAGS_LOST, FLAG_CENSORED, FLAG_IPC_LOST, FLAG_NET_LOST, FLAG_OCCLUDED,
    FLAG_RANDOM_LOSS, FLAG_TOKENS, FLAG_TOKEN_BLOCKED, FLAG_TRIGGERED, SLOT_ABORT, SLOT_DATA,
    SLOT_END,
};
pub use truth::Truth;

/// Version of the contract: the payload layouts, the stream header and the rules of
/// `docs/wire.md`. Bumped on any change to a field's meaning or layout; every payload carries
/// it as its first field and the runner refuses any other.
///
/// Version 2 added the stream header and the estimate's covariance and made the slot service
/// non-overflowing (back-pressure). Version 3 made every sensor node its own stream (its own
/// stream id, `seq = k − 1`, its own END/ABORT marker) and lets the slot service admit one
/// publisher per node ([`MAX_NODES`]).
pub const WIRE_VERSION: u32 = 6;

/// Largest state dimension (fixed so payloads are fixed-size).
pub const MAX_NX: usize = 8;
/// Largest measurement dimension per node.
pub const MAX_NY: usize = 4;
/// Largest number of sensor nodes.
pub const MAX_NODES: usize = 8;
