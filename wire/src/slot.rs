//! [`Slot`]: one sensor node's observation of one sampling instant, the payload of
//! `<prefix>/slots`.

use crate::error::WireError;
use crate::{MAX_NODES, MAX_NY, WIRE_VERSION};
use iceoryx2::prelude::*;

/// [`Slot::kind`]: one node's observation of one instant.
pub const SLOT_DATA: u32 = 0;
/// [`Slot::kind`]: the stream is complete; `seq` is the number of data slots sent.
pub const SLOT_END: u32 = 1;
/// [`Slot::kind`]: the publisher was stopped (SIGINT/SIGTERM) before the last instant; `seq`
/// is the number of data slots sent.
pub const SLOT_ABORT: u32 = 2;

/// [`Slot::flags`]: the sensor's event trigger fired at this instant (seed 004 eq. 13).
pub const FLAG_TRIGGERED: u32 = 1 << 0;
/// [`Slot::flags`]: a trigger (or scheduled send) was blocked because the token bucket was
/// empty.
pub const FLAG_TOKEN_BLOCKED: u32 = 1 << 1;
/// [`Slot::flags`]: at least one entry of `y` was censored (Tobit, seed 004 eq. 2).
pub const FLAG_CENSORED: u32 = 1 << 2;
/// [`Slot::flags`]: the packet was lost by a random-loss stage (Bernoulli / Gilbert–Elliott).
pub const FLAG_RANDOM_LOSS: u32 = 1 << 3;
/// [`Slot::flags`]: the packet was dropped because the state was inside an occlusion region
/// (seed 001).
pub const FLAG_OCCLUDED: u32 = 1 << 4;
/// [`Slot::flags`]: [`Slot::tokens`] holds the shared token bucket's level ξ_{t−1} that this
/// node's grant used (seed 004, eq. 18): a delivered packet tells the receiver the bucket's
/// level, so the receiver's mirror of the bucket can resynchronise after a lost packet
/// (docs/tobit-fusion.md, "Silence that speaks"). Since wire version 6.
pub const FLAG_TOKENS: u32 = 1 << 5;
/// Added by the runner, never written on the wire: the node's slot of this instant never
/// reached the estimators — lost inside the IPC (a gap in the node's sequence numbers),
/// skipped as malformed, or not there when the instant was handed on (its deadline, or the
/// window of pending instants). The estimators read it as a loss, not as a channel dropout.
/// Above every channel-side flag.
pub const FLAG_IPC_LOST: u32 = 1 << 31;
/// Written by the estimator side of a bridge (`ipc-runner bridge`, docs/bridge.md) for a slot
/// the network lost, detected by a gap in sequence numbers on arrival: no measurement, no
/// information (a loss, never a channel dropout).
pub const FLAG_NET_LOST: u32 = 1 << 30;
/// The flags of a slot that was lost on its way ([`FLAG_IPC_LOST`], [`FLAG_NET_LOST`]): it
/// carries no information about the state, unlike a packet the channel dropped.
pub const FLAGS_LOST: u32 = FLAG_IPC_LOST | FLAG_NET_LOST;

/// One node's observation of one sampling instant (a *slot*).
///
/// Every sensor node is its own stream (wire version 3, `docs/wire.md`, Stream rules): its
/// own `stream_id`, and its own dense sequence `seq = k − 1` (one slot per instant, a dropped
/// packet included), so the runner can tell exactly which of the node's instants a gap
/// corresponds to, whatever order the nodes' slots arrive in. Every slot of the service
/// carries a [`StreamHeader`](crate::StreamHeader) as its iceoryx2 user header.
#[derive(Clone, Copy, Debug, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("estpipe::wire::Slot")]
pub struct Slot {
    /// [`WIRE_VERSION`] of the writer. Always the first field.
    pub version: u32,
    /// [`SLOT_DATA`], [`SLOT_END`] or [`SLOT_ABORT`].
    pub kind: u32,
    /// Identifies one run of the node's publisher; a new value starting again at k = 1 means
    /// the publisher was restarted.
    pub stream_id: u64,
    /// The node's data slots sent before this one in its stream, `k − 1` (END/ABORT: the
    /// node's data slots sent).
    pub seq: u64,
    /// Sampling instant k ≥ 1 (END/ABORT: the last instant sent).
    pub k: u32,
    /// Sensor node, 0-based (END/ABORT: the node whose stream ends).
    pub node: u8,
    /// Number of nodes in the scenario.
    pub nodes: u8,
    /// Valid entries of `y`.
    pub ny: u8,
    /// 1 if the channel delivered a measurement, 0 if the packet was dropped.
    pub delivered: u8,
    /// Channel-side flags (`FLAG_*`).
    pub flags: u32,
    /// With [`FLAG_TOKENS`]: the shared bucket's level ξ_{t−1} the node's grant used (a
    /// delivered packet of a node behind seed 004's shared bucket); 0 otherwise.
    pub tokens: u32,
    /// `CLOCK_MONOTONIC` time (ns) at which the slot was written, just before `send()`.
    pub send_ns: u64,
    /// The publisher's sampling period in ns (0 = as fast as possible).
    pub period_ns: u64,
    /// `CLOCK_MONOTONIC` when the stream started (after a subscriber had connected): a
    /// subscriber older than this saw the whole stream, so any slot it misses before its
    /// first one was lost in the IPC rather than sent before it joined.
    pub stream_start_ns: u64,
    /// The measurement (entries ≥ `ny` are 0; meaningful iff `delivered == 1`).
    pub y: [f64; MAX_NY],
}

impl Slot {
    /// Data slot `(k, node)` of stream `stream_id` with its dense `seq` (`k − 1`); no
    /// measurement yet (`delivered = 0`, `ny = 0`, times 0): the writer fills in the rest.
    pub fn data(k: u32, node: u8, nodes: u8, stream_id: u64) -> Self {
        Self {
            version: WIRE_VERSION,
            kind: SLOT_DATA,
            stream_id,
            seq: Self::seq_of(k),
            k,
            node,
            nodes,
            ny: 0,
            delivered: 0,
            flags: 0,
            tokens: 0,
            send_ns: 0,
            period_ns: 0,
            stream_start_ns: 0,
            y: [0.0; MAX_NY],
        }
    }

    /// An END ([`SLOT_END`]) or ABORT ([`SLOT_ABORT`]) marker of `node`'s stream after its
    /// data slots of instants 1..=`last_k` (`seq = last_k`, the node's data slots sent).
    pub fn marker(kind: u32, last_k: u32, node: u8, nodes: u8, stream_id: u64, now: u64) -> Self {
        Self {
            kind,
            seq: u64::from(last_k),
            k: last_k,
            node,
            send_ns: now,
            ..Self::data(0, node, nodes, stream_id)
        }
    }

    /// The node's sequence number of its slot of instant `k`: `k − 1` (0 for k = 0).
    pub fn seq_of(k: u32) -> u64 {
        u64::from(k).saturating_sub(1)
    }

    /// The first thing wrong with this slot for a stream of `nodes` nodes whose node m
    /// announced `ny[m]` measurements (the header's), or `None`: the checks that need
    /// nothing but the slot and the header. The stream's own rules (stream id, gaps, late
    /// slots) are the receiver's (`docs/wire.md`, What the runner does with a bad slot).
    pub fn fault(&self, nodes: u8, ny: &[u8]) -> Option<SlotFault> {
        if self.version != WIRE_VERSION {
            return Some(SlotFault::Version);
        }
        if self.kind > SLOT_ABORT {
            return Some(SlotFault::Kind);
        }
        if self.nodes != nodes {
            return Some(SlotFault::Nodes);
        }
        if self.node >= nodes || usize::from(self.node) >= ny.len() {
            return Some(SlotFault::Node);
        }
        if self.kind != SLOT_DATA {
            // The last instant and the count of data slots sent say the same (dense).
            return (self.seq != u64::from(self.k)).then_some(SlotFault::MarkerSeq);
        }
        if self.k == 0 {
            return Some(SlotFault::KZero);
        }
        if self.seq != Self::seq_of(self.k) {
            return Some(SlotFault::Seq);
        }
        if self.delivered > 1 {
            return Some(SlotFault::Delivered);
        }
        let want = ny[usize::from(self.node)];
        if self.delivered == 1 {
            if self.ny == 0 {
                return Some(SlotFault::NyZero);
            }
            if self.ny != want {
                return Some(SlotFault::Ny);
            }
            let n = usize::from(want).min(MAX_NY);
            if !self.y[..n].iter().all(|v| v.is_finite()) {
                return Some(SlotFault::NonFinite);
            }
        } else if self.ny != 0 && self.ny != want {
            return Some(SlotFault::Ny);
        }
        None
    }

    /// Checks the version and the ranges of the fields against the slot's own `nodes` (not
    /// the stream's shape: that is [`Slot::fault`] with the header's).
    pub fn validate(&self) -> Result<(), WireError> {
        if self.version != WIRE_VERSION {
            return Err(WireError::Version {
                found: self.version,
            });
        }
        if self.nodes == 0 || usize::from(self.nodes) > MAX_NODES {
            return Err(WireError::Invalid("nodes out of range"));
        }
        if usize::from(self.ny) > MAX_NY {
            return Err(WireError::Invalid("ny > MAX_NY"));
        }
        let ny = [self.ny; MAX_NODES];
        match self.fault(self.nodes, &ny[..usize::from(self.nodes)]) {
            None => Ok(()),
            Some(f) => Err(WireError::Invalid(f.describe())),
        }
    }

    /// The valid part of the measurement, `None` when the packet was dropped.
    pub fn measurement(&self) -> Option<&[f64]> {
        (self.delivered == 1).then(|| &self.y[..usize::from(self.ny).min(MAX_NY)])
    }
}

/// What is wrong with a slot ([`Slot::fault`]); the receiver counts it by this reason and
/// skips the slot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SlotFault {
    /// `version` ≠ [`WIRE_VERSION`].
    Version,
    /// `kind` is not data, END or ABORT.
    Kind,
    /// `nodes` ≠ the header's.
    Nodes,
    /// `node` ≥ `nodes`.
    Node,
    /// A data slot with `k = 0` (the prior has no slot).
    KZero,
    /// A data slot with `seq ≠ k − 1`.
    Seq,
    /// An END/ABORT marker with `seq ≠ k`.
    MarkerSeq,
    /// `delivered` is neither 0 nor 1.
    Delivered,
    /// `ny` is not the header's `ny[node]` (0 is allowed when nothing was delivered).
    Ny,
    /// `delivered = 1` with `ny = 0`.
    NyZero,
    /// A delivered measurement with a NaN or infinite entry.
    NonFinite,
}

impl SlotFault {
    /// Every fault, in the order of the declaration.
    pub const ALL: [SlotFault; 11] = [
        Self::Version,
        Self::Kind,
        Self::Nodes,
        Self::Node,
        Self::KZero,
        Self::Seq,
        Self::MarkerSeq,
        Self::Delivered,
        Self::Ny,
        Self::NyZero,
        Self::NonFinite,
    ];

    /// What is wrong, in a few words.
    pub fn describe(self) -> &'static str {
        match self {
            Self::Version => "another wire version",
            Self::Kind => "kind is not 0 (data), 1 (END) or 2 (ABORT)",
            Self::Nodes => "nodes differs from the stream header's",
            Self::Node => "node ≥ nodes",
            Self::KZero => "k = 0 (the prior has no slot)",
            Self::Seq => "seq ≠ k − 1",
            Self::MarkerSeq => "END/ABORT with seq ≠ k",
            Self::Delivered => "delivered is not 0/1",
            Self::Ny => "ny is not the stream header's ny of the node",
            Self::NyZero => "delivered = 1 with ny = 0",
            Self::NonFinite => "a non-finite measurement entry",
        }
    }

    /// Whether the slot still names its instant and node reliably (only its content is
    /// unusable): the receiver then hands that node's observation on as lost rather than
    /// leaving a gap.
    pub fn content_only(self) -> bool {
        matches!(
            self,
            Self::Delivered | Self::Ny | Self::NyZero | Self::NonFinite
        )
    }
}

impl core::fmt::Display for SlotFault {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.describe())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn slot(k: u32, node: u8, nodes: u8) -> Slot {
        let mut s = Slot::data(k, node, nodes, 1);
        s.ny = 2;
        s.delivered = 1;
        s.y[..2].copy_from_slice(&[1.5, -2.25]);
        s
    }

    #[test]
    fn sequence_numbers_are_dense_per_node() {
        for (k, node, nodes) in [(1, 0, 1), (7, 2, 3), (300, 1, 2)] {
            let s = slot(k, node, nodes);
            assert_eq!(s.seq, u64::from(k - 1));
            assert!(s.validate().is_ok());
            assert_eq!(s.fault(nodes, &[2; 3][..usize::from(nodes)]), None);
        }
    }

    #[test]
    fn wrong_version_and_bad_fields_are_refused() {
        let mut s = slot(2, 1, 2);
        s.version = 99;
        let e = s.validate().unwrap_err();
        assert_eq!(e, WireError::Version { found: 99 });
        assert!(e.to_string().contains("version 99"));
        assert!(e.to_string().contains(&format!("version {WIRE_VERSION}")));
        assert!(e.to_string().contains("docs/wire.md"));

        let good = slot(2, 1, 2);
        type Edit = fn(&mut Slot);
        let bad: [(Edit, SlotFault); 10] = [
            (|s| s.version = 2, SlotFault::Version),
            (|s| s.node = 2, SlotFault::Node),
            (|s| s.nodes = 3, SlotFault::Nodes),
            (|s| s.ny = 1, SlotFault::Ny),
            (|s| s.ny = 0, SlotFault::NyZero),
            (|s| s.seq += 1, SlotFault::Seq),
            (|s| s.k = 0, SlotFault::KZero),
            (|s| s.delivered = 0xAB, SlotFault::Delivered),
            (|s| s.kind = 3, SlotFault::Kind),
            (|s| s.y[1] = f64::INFINITY, SlotFault::NonFinite),
        ];
        for (f, fault) in bad {
            let mut s = good;
            f(&mut s);
            assert_eq!(s.fault(2, &[2, 2]), Some(fault), "{s:?}");
        }
        // A dropped packet may leave ny at 0.
        let mut s = good;
        s.delivered = 0;
        s.ny = 0;
        assert_eq!(s.fault(2, &[2, 2]), None);
    }

    #[test]
    fn markers_are_per_node_and_dense() {
        let m = Slot::marker(SLOT_END, 3, 1, 2, 5, 0);
        assert_eq!((m.kind, m.seq, m.k, m.node), (SLOT_END, 3, 3, 1));
        assert!(m.validate().is_ok());
        assert_eq!(m.measurement(), None);
        let mut bad = m;
        bad.seq = u64::MAX;
        assert_eq!(bad.fault(2, &[1, 1]), Some(SlotFault::MarkerSeq));
    }
}
