//! What the network lost: sequence gaps seen on arrival.
//!
//! Every node's slots form their own stream with dense sequence numbers, `seq = k − 1`, and
//! the node's END/ABORT marker carries its last instant (`docs/wire.md`, Stream rules). So a
//! gap on arrival is exactly the slots the network (or the sensor-side bridge's restart) lost.
//! The estimator side writes each of them into shared memory as a slot without a measurement
//! flagged [`FLAG_NET_LOST`]: the runner reads it as a loss (no information), counted as lost
//! on the network, never as a packet the channel dropped (which may carry information).

use estpipe_wire::{Slot, MAX_NODES, SLOT_DATA};

pub use estpipe_wire::FLAG_NET_LOST;

/// What an arriving slot is, against what came before from its node.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Arrival {
    /// The node's next instant, or one after `lost` missing instants starting at `from`.
    InOrder {
        /// First missing instant.
        from: u32,
        /// Instants of this node missing before this slot.
        lost: u32,
    },
    /// An instant of this node already passed (duplicate or reordered): not forwarded.
    Late,
    /// The first slot of the node's stream (or of a new one: the publisher restarted), after
    /// `lost` missing instants `1..=lost` when it is not instant 1 (see [`LEADING_LOSS_MAX`]).
    NewStream {
        /// Instants `1..=lost` of the stream missing before this slot.
        lost: u32,
    },
    /// A copy of the marker the node's stream already ended with (the sensor side sends
    /// each marker several times): expected, not forwarded.
    RepeatedMarker,
}

/// The most leading instants a new stream's first slot may be missing and still have them
/// counted as lost on the network. A stream starts at instant 1 (`docs/wire.md`, Stream
/// rules) and the sensor side forwards from the first slot once this side is there, so a
/// first slot at instant k > 1 means 1..k − 1 were lost on the way. Beyond this many, the
/// likelier cause is a bridge that started mid-stream (a restart), whose runner already had
/// those instants: they are not filled (a run of 16 losses at p = 0.1 has probability 1e-16).
pub const LEADING_LOSS_MAX: u32 = 16;

/// Follows every node's stream.
#[derive(Debug, Default)]
pub struct Sequence {
    /// Per node: its stream id and the next instant expected.
    node: [Option<(u64, u32)>; MAX_NODES],
    /// Per node: the stream id and instant of the last END/ABORT marker taken.
    marker: [Option<(u64, u32)>; MAX_NODES],
}

impl Sequence {
    /// Classifies `s` (checked: `node < MAX_NODES`) and advances its node past it.
    pub fn arrive(&mut self, s: &Slot) -> Arrival {
        let m = usize::from(s.node).min(MAX_NODES - 1);
        // A data slot is instant k; a marker covers its node's instants up to and including
        // k. Either way the node's next instant is k + 1, and what is missing lies before
        // `upto`.
        let after = s.k.saturating_add(1);
        let upto = if s.kind == SLOT_DATA { s.k } else { after };
        if self.is_last_marker(s) {
            return Arrival::RepeatedMarker;
        }
        let arrival = self.classify(m, s, upto, after);
        if s.kind != SLOT_DATA && arrival != Arrival::Late {
            self.marker[m] = Some((s.stream_id, s.k));
        }
        arrival
    }

    /// Whether `s` is a copy of the marker its node's stream last ended with.
    pub fn is_last_marker(&self, s: &Slot) -> bool {
        let m = usize::from(s.node).min(MAX_NODES - 1);
        s.kind != SLOT_DATA && self.marker[m] == Some((s.stream_id, s.k))
    }

    fn classify(&mut self, m: usize, s: &Slot, upto: u32, after: u32) -> Arrival {
        match self.node[m] {
            Some((stream, next)) if stream == s.stream_id => {
                if upto < next {
                    return Arrival::Late;
                }
                self.node[m] = Some((stream, after));
                Arrival::InOrder {
                    from: next,
                    lost: upto - next,
                }
            }
            _ => {
                self.node[m] = Some((s.stream_id, after));
                let missing = upto.saturating_sub(1);
                Arrival::NewStream {
                    lost: if missing <= LEADING_LOSS_MAX {
                        missing
                    } else {
                        0
                    },
                }
            }
        }
    }
}

/// The slot written for instant `k` of `like`'s node that the network lost: no measurement,
/// [`FLAG_NET_LOST`], the stream's fields from `like` (a slot of the same node's stream).
pub fn lost_slot(like: &Slot, k: u32) -> Slot {
    let mut s = Slot::data(k, like.node, like.nodes, like.stream_id);
    s.flags = FLAG_NET_LOST;
    s.period_ns = like.period_ns;
    s.stream_start_ns = like.stream_start_ns;
    s.send_ns = like.send_ns;
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use estpipe_wire::SLOT_END;

    fn data(k: u32, node: u8, stream: u64) -> Slot {
        Slot::data(k, node, 2, stream)
    }

    #[test]
    fn gaps_are_per_node_and_late_slots_refused() {
        let mut q = Sequence::default();
        assert_eq!(q.arrive(&data(1, 0, 7)), Arrival::NewStream { lost: 0 });
        assert_eq!(q.arrive(&data(1, 1, 8)), Arrival::NewStream { lost: 0 });
        assert_eq!(
            q.arrive(&data(2, 0, 7)),
            Arrival::InOrder { from: 2, lost: 0 }
        );
        // Node 1 lost instants 2 and 3; node 0 is not affected.
        assert_eq!(
            q.arrive(&data(4, 1, 8)),
            Arrival::InOrder { from: 2, lost: 2 }
        );
        assert_eq!(q.arrive(&data(3, 1, 8)), Arrival::Late);
        assert_eq!(q.arrive(&data(4, 1, 8)), Arrival::Late);
        assert_eq!(
            q.arrive(&data(3, 0, 7)),
            Arrival::InOrder { from: 3, lost: 0 }
        );
        // Node 0's END after instant 5: its instants 4 and 5 were lost.
        let end = Slot::marker(SLOT_END, 5, 0, 2, 7, 0);
        assert_eq!(q.arrive(&end), Arrival::InOrder { from: 4, lost: 2 });
        // Node 1's END right after its last slot: nothing lost.
        let end = Slot::marker(SLOT_END, 4, 1, 2, 8, 0);
        assert_eq!(q.arrive(&end), Arrival::InOrder { from: 5, lost: 0 });
        assert_eq!(q.arrive(&data(1, 0, 9)), Arrival::NewStream { lost: 0 });
    }

    /// A stream whose first slots the network lost: they are counted from instant 1 (a
    /// marker covers its own instant too); a first slot far into the stream (a bridge that
    /// joined mid-stream) fills nothing.
    #[test]
    fn a_stream_missing_its_first_slots_counts_them() {
        let mut q = Sequence::default();
        assert_eq!(q.arrive(&data(3, 0, 7)), Arrival::NewStream { lost: 2 });
        assert_eq!(
            q.arrive(&data(4, 0, 7)),
            Arrival::InOrder { from: 4, lost: 0 }
        );
        let end = Slot::marker(SLOT_END, 2, 1, 2, 8, 0);
        assert_eq!(q.arrive(&end), Arrival::NewStream { lost: 2 });
        let far = data(LEADING_LOSS_MAX + 2, 0, 9);
        assert_eq!(q.arrive(&far), Arrival::NewStream { lost: 0 });
        let edge = data(LEADING_LOSS_MAX + 1, 1, 10);
        assert_eq!(
            q.arrive(&edge),
            Arrival::NewStream {
                lost: LEADING_LOSS_MAX
            }
        );
    }

    #[test]
    fn a_repeated_marker_is_known_as_a_copy() {
        let mut q = Sequence::default();
        assert_eq!(q.arrive(&data(1, 0, 7)), Arrival::NewStream { lost: 0 });
        let end = Slot::marker(SLOT_END, 3, 0, 2, 7, 0);
        assert!(!q.is_last_marker(&end));
        assert_eq!(q.arrive(&end), Arrival::InOrder { from: 2, lost: 2 });
        // The second and third copies are known as copies; a late data slot or another
        // node's marker is not.
        assert!(q.is_last_marker(&end));
        assert_eq!(q.arrive(&end), Arrival::RepeatedMarker);
        assert_eq!(q.arrive(&end), Arrival::RepeatedMarker);
        assert_eq!(q.arrive(&data(3, 0, 7)), Arrival::Late);
        assert!(!q.is_last_marker(&data(3, 0, 7)));
        assert!(!q.is_last_marker(&Slot::marker(SLOT_END, 3, 1, 2, 7, 0)));
        assert!(!q.is_last_marker(&Slot::marker(SLOT_END, 2, 0, 2, 7, 0)));
    }

    #[test]
    fn a_lost_slot_is_a_valid_slot_without_measurement() {
        let like = data(5, 1, 3);
        let s = lost_slot(&like, 4);
        assert_eq!(
            (s.k, s.node, s.delivered, s.flags),
            (4, 1, 0, FLAG_NET_LOST)
        );
        assert!(s.validate().is_ok());
    }
}
