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
/// Added by the runner, never written on the wire: the slot was lost inside the IPC,
/// detected by a gap in sequence numbers. Above every channel-side flag.
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
/// Sequence numbers are dense per stream: `seq = (k − 1)·nodes + node`, so the runner can tell
/// exactly which `(k, node)` a gap corresponds to. Every slot of the service carries a
/// [`StreamHeader`](crate::StreamHeader) as its iceoryx2 user header.
#[derive(Clone, Copy, Debug, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("estpipe::wire::Slot")]
pub struct Slot {
    /// [`WIRE_VERSION`] of the writer. Always the first field.
    pub version: u32,
    /// [`SLOT_DATA`], [`SLOT_END`] or [`SLOT_ABORT`].
    pub kind: u32,
    /// Identifies one publisher run; a new value means the publisher was restarted.
    pub stream_id: u64,
    /// Dense sequence number within the stream (for END/ABORT: data slots sent).
    pub seq: u64,
    /// Sampling instant k ≥ 1 (END/ABORT: the last instant sent).
    pub k: u32,
    /// Sensor node, 0-based.
    pub node: u8,
    /// Number of nodes in the scenario.
    pub nodes: u8,
    /// Valid entries of `y`.
    pub ny: u8,
    /// 1 if the channel delivered a measurement, 0 if the packet was dropped.
    pub delivered: u8,
    /// Channel-side flags (`FLAG_*`).
    pub flags: u32,
    /// Reserved, 0.
    pub reserved: u32,
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
    /// Data slot `(k, node)` of stream `stream_id` with its dense `seq`; no measurement yet
    /// (`delivered = 0`, `ny = 0`, times 0): the writer fills in the rest.
    pub fn data(k: u32, node: u8, nodes: u8, stream_id: u64) -> Self {
        Self {
            version: WIRE_VERSION,
            kind: SLOT_DATA,
            stream_id,
            seq: Self::seq_of(k, node, nodes),
            k,
            node,
            nodes,
            ny: 0,
            delivered: 0,
            flags: 0,
            reserved: 0,
            send_ns: 0,
            period_ns: 0,
            stream_start_ns: 0,
            y: [0.0; MAX_NY],
        }
    }

    /// An END ([`SLOT_END`]) or ABORT ([`SLOT_ABORT`]) marker after `sent` data slots.
    pub fn marker(kind: u32, sent: u64, last_k: u32, nodes: u8, stream_id: u64, now: u64) -> Self {
        Self {
            kind,
            seq: sent,
            k: last_k,
            node: 0,
            send_ns: now,
            ..Self::data(0, 0, nodes, stream_id)
        }
    }

    /// The dense sequence number of `(k, node)`: `(k − 1)·nodes + node`.
    pub fn seq_of(k: u32, node: u8, nodes: u8) -> u64 {
        (u64::from(k).saturating_sub(1)) * u64::from(nodes) + u64::from(node)
    }

    /// `(k, node)` of sequence number `seq` (inverse of [`Slot::seq_of`]).
    pub fn position_of(seq: u64, nodes: u8) -> (u32, u8) {
        let n = u64::from(nodes.max(1));
        ((seq / n + 1) as u32, (seq % n) as u8)
    }

    /// Checks the version and the ranges of the fields (not the stream's shape: that is
    /// [`StreamHeader::check`](crate::StreamHeader::check)).
    pub fn validate(&self) -> Result<(), WireError> {
        if self.version != WIRE_VERSION {
            return Err(WireError::Version {
                found: self.version,
            });
        }
        if self.kind > SLOT_ABORT {
            return Err(WireError::Invalid("kind"));
        }
        if self.kind != SLOT_DATA {
            return Ok(());
        }
        if self.nodes == 0 || usize::from(self.nodes) > MAX_NODES {
            return Err(WireError::Invalid("nodes out of range"));
        }
        if self.node >= self.nodes {
            return Err(WireError::Invalid("node ≥ nodes"));
        }
        if usize::from(self.ny) > MAX_NY {
            return Err(WireError::Invalid("ny > MAX_NY"));
        }
        if self.k == 0 {
            return Err(WireError::Invalid("k = 0 (the prior has no slot)"));
        }
        if self.seq != Self::seq_of(self.k, self.node, self.nodes) {
            return Err(WireError::Invalid("seq ≠ (k − 1)·nodes + node"));
        }
        if self.delivered > 1 {
            return Err(WireError::Invalid("delivered is not 0/1"));
        }
        Ok(())
    }

    /// The valid part of the measurement, `None` when the packet was dropped.
    pub fn measurement(&self) -> Option<&[f64]> {
        (self.delivered == 1).then(|| &self.y[..usize::from(self.ny).min(MAX_NY)])
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
    fn sequence_numbers_are_dense_and_invertible() {
        for (k, node, nodes) in [(1, 0, 1), (7, 2, 3), (300, 1, 2)] {
            let s = slot(k, node, nodes);
            assert_eq!(s.seq, u64::from(k - 1) * u64::from(nodes) + u64::from(node));
            assert_eq!(Slot::position_of(s.seq, nodes), (k, node));
            assert!(s.validate().is_ok());
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
        let bad: [fn(&mut Slot); 6] = [
            |s| s.node = 2,
            |s| s.ny = MAX_NY as u8 + 1,
            |s| s.seq += 1,
            |s| s.k = 0,
            |s| s.delivered = 2,
            |s| s.kind = 3,
        ];
        for f in bad {
            let mut s = good;
            f(&mut s);
            assert!(s.validate().is_err(), "{s:?}");
        }
    }

    #[test]
    fn markers_skip_the_data_checks() {
        let m = Slot::marker(SLOT_END, 6, 3, 2, 5, 0);
        assert_eq!((m.kind, m.seq, m.k), (SLOT_END, 6, 3));
        assert!(m.validate().is_ok());
        assert_eq!(m.measurement(), None);
    }
}
