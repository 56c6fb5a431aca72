//! Turns the slot stream back into sampling instants.
//!
//! Sequence numbers are dense (`seq = (k − 1)·nodes + node`, see [`Slot::seq_of`]), so every
//! missing slot is known exactly: a gap is a slot lost inside the IPC (the subscriber queue
//! overflowed and the oldest sample was overwritten). It becomes an observation without a
//! measurement marked [`FLAG_IPC_LOST`] — the estimator sees the instant, as a loss (no
//! information, `Packet::Lost`), not as a packet the channel dropped — and is counted
//! separately. An instant is handed on when its last node's slot (received or
//! lost) has been seen. A runner that joins a stream in the middle (restarted after a crash)
//! steps through the instants it missed as lost ones, counted as *missed before join*.

use channel_sim::sim::MAX_NODES;
use channel_sim::Observation;
use estpipe_wire::{Slot, WireError, FLAG_IPC_LOST, SLOT_ABORT, SLOT_DATA, SLOT_END};
use serde::Serialize;

/// Slot accounting of one runner.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Counts {
    /// Data slots received.
    pub received: u64,
    /// Received slots carrying a measurement.
    pub delivered: u64,
    /// Received slots whose packet the channel dropped (occlusion, token bucket, loss, …).
    pub dropped_by_channel: u64,
    /// Slots lost inside the IPC (sequence gaps), handed on as lost.
    pub lost_in_ipc: u64,
    /// Slots a bridge wrote for what the network lost (`FLAG_NET_LOST`, docs/bridge.md):
    /// received, but without information.
    pub lost_on_network: u64,
    /// Slots before the first one this runner saw of a stream (joined mid-stream).
    pub missed_before_join: u64,
    /// Slots that arrived out of order or duplicated (ignored; never expected).
    pub out_of_order: u64,
    /// Instants handed to the estimators.
    pub instants: u64,
}

/// What a pushed slot meant.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pushed {
    /// Data slot consumed.
    Data,
    /// The slot belongs to another stream than the current one (channel-sim restarted). Not
    /// consumed: call [`Assembler::reset`] and push it again.
    NewStream,
    /// END marker: the stream is complete (tail gaps have been filled).
    End,
    /// ABORT marker: the publisher was stopped early.
    Abort,
}

/// Reassembles instants from slots without allocating.
#[derive(Debug)]
pub struct Assembler {
    nodes: u8,
    ny: u8,
    stream: Option<u64>,
    joined_at: u64,
    subscribed_ns: u64,
    next_seq: u64,
    obs: [Observation; MAX_NODES],
    /// Running counts (over all streams).
    pub counts: Counts,
}

impl Assembler {
    /// For a scenario with `nodes` nodes and measurement dimension `ny`.
    pub fn new(nodes: u8, ny: u8) -> Self {
        Self {
            nodes,
            ny,
            stream: None,
            joined_at: 0,
            subscribed_ns: 0,
            next_seq: 0,
            obs: [Observation::dropped(0, 0, ny, 0); MAX_NODES],
            counts: Counts::default(),
        }
    }

    /// When the runner's subscriber was created (`CLOCK_MONOTONIC`): slots missing before the
    /// first one seen of a stream that started later were lost in the IPC; of a stream that
    /// started earlier, they were sent before this runner joined.
    pub fn set_subscribed_ns(&mut self, ns: u64) {
        self.subscribed_ns = ns;
    }

    /// The stream currently followed.
    pub fn stream(&self) -> Option<u64> {
        self.stream
    }

    /// Forgets the current stream (the next slot starts a new one); counts are kept.
    pub fn reset(&mut self) {
        self.stream = None;
        self.next_seq = 0;
    }

    fn lost(&mut self, seq: u64, emit: &mut impl FnMut(u32, &[Observation])) {
        let (k, node) = Slot::position_of(seq, self.nodes);
        if seq < self.joined_at {
            self.counts.missed_before_join += 1;
        } else {
            self.counts.lost_in_ipc += 1;
        }
        self.obs[usize::from(node)] = Observation::dropped(k, node, self.ny, FLAG_IPC_LOST);
        if node + 1 == self.nodes {
            self.counts.instants += 1;
            emit(k, &self.obs[..usize::from(self.nodes)]);
        }
    }

    fn fill_to(&mut self, seq: u64, emit: &mut impl FnMut(u32, &[Observation])) {
        while self.next_seq < seq {
            self.lost(self.next_seq, emit);
            self.next_seq += 1;
        }
    }

    /// Consumes one slot; calls `emit(k, observations)` for every instant it completes (gap
    /// instants included), in order.
    pub fn push(
        &mut self,
        slot: &Slot,
        emit: &mut impl FnMut(u32, &[Observation]),
    ) -> Result<Pushed, WireError> {
        slot.validate()?;
        match self.stream {
            Some(s) if s != slot.stream_id => return Ok(Pushed::NewStream),
            Some(_) => {}
            None => {
                self.stream = Some(slot.stream_id);
                self.next_seq = 0;
                // A stream that started before we subscribed was joined in the middle: what
                // precedes the first instant we see was sent before we existed.
                self.joined_at = if slot.stream_start_ns >= self.subscribed_ns {
                    0
                } else if slot.kind == SLOT_DATA {
                    Slot::seq_of(slot.k, 0, slot.nodes)
                } else {
                    slot.seq
                };
            }
        }
        if slot.kind != SLOT_DATA {
            if slot.nodes == self.nodes {
                self.fill_to(slot.seq, emit);
            }
            return Ok(match slot.kind {
                SLOT_END => Pushed::End,
                SLOT_ABORT => Pushed::Abort,
                _ => unreachable!("validated"),
            });
        }
        if slot.nodes != self.nodes {
            return Err(WireError::Invalid(
                "node count differs from the scenario the runner was started with",
            ));
        }
        // Estimators read `ny` entries: a measurement of another size is refused, not read.
        if slot.delivered == 1 && slot.ny != self.ny {
            return Err(WireError::Invalid(
                "ny differs from the scenario the runner was started with",
            ));
        }
        if slot.seq < self.next_seq {
            self.counts.out_of_order += 1;
            return Ok(Pushed::Data);
        }
        self.fill_to(slot.seq, emit);
        let mut obs = channel_sim::wire::observation_of(slot)?;
        obs.ny = self.ny;
        if obs.flags & estpipe_wire::FLAG_NET_LOST != 0 {
            self.counts.lost_on_network += 1;
        } else {
            self.counts.received += 1;
            if obs.delivered {
                self.counts.delivered += 1;
            } else {
                self.counts.dropped_by_channel += 1;
            }
        }
        self.obs[usize::from(obs.node)] = obs;
        self.next_seq = slot.seq + 1;
        if obs.node + 1 == self.nodes {
            self.counts.instants += 1;
            emit(obs.k, &self.obs[..usize::from(self.nodes)]);
        }
        Ok(Pushed::Data)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use channel_sim::sim::MAX_NY;
    use estpipe_wire::SLOT_END;

    fn slot(k: u32, node: u8, nodes: u8, stream: u64) -> Slot {
        let mut y = [0.0; MAX_NY];
        y[0] = f64::from(k) + f64::from(node) / 10.0;
        let o = Observation {
            k,
            node,
            delivered: node != 1,
            ny: 1,
            y: if node != 1 { y } else { [0.0; MAX_NY] },
            flags: 0,
        };
        channel_sim::wire::slot_of(&o, nodes, stream, 0, 0, 100)
    }

    fn collect(a: &mut Assembler, slots: &[Slot]) -> Vec<(u32, Vec<Observation>)> {
        let mut out = Vec::new();
        for s in slots {
            a.push(s, &mut |k, o: &[Observation]| out.push((k, o.to_vec())))
                .unwrap();
        }
        out
    }

    #[test]
    fn complete_stream_yields_every_instant_once() {
        let mut a = Assembler::new(3, 1);
        let slots: Vec<Slot> = (1..=4)
            .flat_map(|k| (0..3).map(move |n| slot(k, n, 3, 7)))
            .collect();
        let out = collect(&mut a, &slots);
        assert_eq!(out.iter().map(|o| o.0).collect::<Vec<_>>(), [1, 2, 3, 4]);
        assert!(out
            .iter()
            .all(|(k, o)| o.len() == 3 && o.iter().all(|x| x.k == *k)));
        assert_eq!(a.counts.received, 12);
        assert_eq!(a.counts.delivered, 8);
        assert_eq!(a.counts.dropped_by_channel, 4);
        assert_eq!(a.counts.lost_in_ipc, 0);
    }

    #[test]
    fn gaps_become_counted_ipc_drops_at_the_right_instant_and_node() {
        let mut a = Assembler::new(2, 1);
        // Lose (2,1), (3,0), (3,1), (4,0).
        let slots = [
            slot(1, 0, 2, 1),
            slot(1, 1, 2, 1),
            slot(2, 0, 2, 1),
            slot(4, 1, 2, 1),
        ];
        let out = collect(&mut a, &slots);
        assert_eq!(out.iter().map(|o| o.0).collect::<Vec<_>>(), [1, 2, 3, 4]);
        assert_eq!(a.counts.lost_in_ipc, 4);
        let lost = |k: usize, n: usize| {
            let o = &out[k - 1].1[n];
            !o.delivered && o.flags & FLAG_IPC_LOST != 0 && o.k == k as u32 && o.node == n as u8
        };
        assert!(lost(2, 1) && lost(3, 0) && lost(3, 1) && lost(4, 0));
        assert!(out[1].1[0].delivered && out[3].1[1].flags & FLAG_IPC_LOST == 0);
    }

    #[test]
    fn end_marker_fills_the_tail() {
        let mut a = Assembler::new(2, 1);
        let mut out = 0;
        let mut emit = |_k: u32, _o: &[Observation]| out += 1;
        a.push(&slot(1, 0, 2, 5), &mut emit).unwrap();
        let end = Slot::marker(SLOT_END, 6, 3, 2, 5, 0);
        assert_eq!(a.push(&end, &mut emit).unwrap(), Pushed::End);
        assert_eq!(out, 3);
        assert_eq!(a.counts.lost_in_ipc, 5);
    }

    #[test]
    fn joining_mid_stream_and_restarts() {
        let mut a = Assembler::new(1, 1);
        // Subscribed after the stream started (at 100): a join.
        a.set_subscribed_ns(200);
        let out = collect(&mut a, &[slot(3, 0, 1, 9), slot(4, 0, 1, 9)]);
        assert_eq!(out.iter().map(|o| o.0).collect::<Vec<_>>(), [1, 2, 3, 4]);
        assert_eq!(a.counts.missed_before_join, 2);
        assert_eq!(a.counts.lost_in_ipc, 0);
        let mut n = 0;
        let restarted = slot(1, 0, 1, 10);
        assert_eq!(
            a.push(&restarted, &mut |_, _: &[Observation]| n += 1)
                .unwrap(),
            Pushed::NewStream
        );
        a.reset();
        assert_eq!(
            a.push(&restarted, &mut |_, _: &[Observation]| n += 1)
                .unwrap(),
            Pushed::Data
        );
        assert_eq!(n, 1);
    }

    #[test]
    fn losses_before_the_first_slot_of_a_stream_we_saw_start_are_ipc_losses() {
        let mut a = Assembler::new(1, 1);
        a.set_subscribed_ns(50); // before the stream started at 100
        let out = collect(&mut a, &[slot(3, 0, 1, 9)]);
        assert_eq!(out.len(), 3);
        assert_eq!(a.counts.lost_in_ipc, 2);
        assert_eq!(a.counts.missed_before_join, 0);
    }

    #[test]
    fn wrong_version_and_node_count_are_errors() {
        let mut a = Assembler::new(2, 1);
        let mut s = slot(1, 0, 2, 1);
        s.version += 1;
        assert!(matches!(
            a.push(&s, &mut |_, _: &[Observation]| {}),
            Err(WireError::Version { .. })
        ));
        let s = slot(1, 0, 3, 1);
        assert!(a.push(&s, &mut |_, _: &[Observation]| {}).is_err());
    }
}
