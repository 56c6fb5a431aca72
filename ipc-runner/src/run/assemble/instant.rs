//! What the assembler hands on: an [`Instant`], every node's observation of one sampling
//! instant, with the times of the slot that was pushed last when it became ready
//! ([`SlotTimes`]).

use estpipe_wire::Observation;

/// The slot pushed last before an instant was handed on, as the receive path saw it: the
/// slot that completed the instant, or for an instant handed on by its deadline, a flush or
/// an overrun, the last slot before that.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SlotTimes {
    /// The publisher's send time of the slot (0: unusable, not a latency; see
    /// [`usable_send_ns`](super::usable_send_ns)).
    pub send_ns: u64,
    /// When this runner received it.
    pub recv_ns: u64,
    /// The stream the estimates and the truth belong to: node 0's (its process publishes the
    /// truth), or before node 0's stream is known, the slot's own.
    pub stream_id: u64,
}

/// One sampling instant handed on, strictly in order: exactly one observation per node, a
/// node's lost slot as an observation without a measurement marked `FLAG_IPC_LOST`. The
/// observations are borrowed from the assembler until the next call to it.
#[derive(Clone, Copy, Debug)]
pub struct Instant<'a> {
    /// The instant.
    pub k: u32,
    /// Node n's observation at index n.
    pub obs: &'a [Observation],
    /// The slot pushed last when the instant became ready.
    pub slot: SlotTimes,
}
