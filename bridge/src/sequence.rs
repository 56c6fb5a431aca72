//! What the network lost: sequence gaps seen on arrival.
//!
//! Slots carry dense sequence numbers (`docs/wire.md`, Stream rules), so a gap on arrival is
//! exactly the slots the network (or the sensor-side bridge's restart) lost. The estimator
//! side writes each of them into shared memory as a slot without a measurement flagged
//! [`FLAG_NET_LOST`]: the runner reads it as a loss (no information), counted as lost on the
//! network, never as a packet the channel dropped (which may carry information).

use estpipe_wire::{Slot, SLOT_DATA};

pub use estpipe_wire::FLAG_NET_LOST;

/// What an arriving slot is, against what came before.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Arrival {
    /// The next expected slot, or one after a gap of `lost` slots starting at `from`.
    InOrder {
        /// First missing sequence number.
        from: u64,
        /// Slots missing before this one.
        lost: u64,
    },
    /// A sequence number already passed (duplicate or reordered): not forwarded.
    Late,
    /// The first slot of a stream (or of a new one: the publisher restarted).
    NewStream,
}

/// Follows one stream's sequence numbers.
#[derive(Debug, Default)]
pub struct Sequence {
    stream: Option<u64>,
    next: u64,
}

impl Sequence {
    /// Classifies `s` and advances past it. END/ABORT markers carry the count of data slots
    /// sent, so a gap before a marker is the tail the network lost.
    pub fn arrive(&mut self, s: &Slot) -> Arrival {
        if self.stream != Some(s.stream_id) {
            self.stream = Some(s.stream_id);
            self.next = if s.kind == SLOT_DATA {
                s.seq + 1
            } else {
                s.seq
            };
            return Arrival::NewStream;
        }
        if s.seq < self.next {
            return Arrival::Late;
        }
        let from = self.next;
        let lost = s.seq - from;
        self.next = if s.kind == SLOT_DATA {
            s.seq + 1
        } else {
            s.seq
        };
        Arrival::InOrder { from, lost }
    }
}

/// The slot written for sequence number `seq` that the network lost: no measurement,
/// [`FLAG_NET_LOST`], the stream's fields from `like` (a slot of the same stream).
pub fn lost_slot(like: &Slot, seq: u64) -> Slot {
    let (k, node) = Slot::position_of(seq, like.nodes);
    let mut s = Slot::data(k, node, like.nodes, like.stream_id);
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

    fn data(k: u32, node: u8) -> Slot {
        Slot::data(k, node, 2, 7)
    }

    #[test]
    fn gaps_are_counted_once_and_late_slots_refused() {
        let mut q = Sequence::default();
        assert_eq!(q.arrive(&data(1, 0)), Arrival::NewStream);
        assert_eq!(q.arrive(&data(1, 1)), Arrival::InOrder { from: 1, lost: 0 });
        // (2,0), (2,1), (3,0) lost.
        assert_eq!(q.arrive(&data(3, 1)), Arrival::InOrder { from: 2, lost: 3 });
        assert_eq!(q.arrive(&data(2, 1)), Arrival::Late);
        assert_eq!(q.arrive(&data(3, 1)), Arrival::Late);
        // The END after 8 data slots: (4,0) and (4,1) lost.
        let end = Slot::marker(SLOT_END, 8, 4, 2, 7, 0);
        assert_eq!(q.arrive(&end), Arrival::InOrder { from: 6, lost: 2 });
        let restarted = Slot::data(1, 0, 2, 8);
        assert_eq!(q.arrive(&restarted), Arrival::NewStream);
    }

    #[test]
    fn a_lost_slot_is_a_valid_slot_without_measurement() {
        let like = data(5, 1);
        let s = lost_slot(&like, 4);
        assert_eq!(
            (s.k, s.node, s.delivered, s.flags),
            (3, 0, 0, FLAG_NET_LOST)
        );
        assert!(s.validate().is_ok());
    }
}
