//! The window's side of the [`Assembler`]: slots put into their instant, gaps filled with
//! losses, and instants handed on in order once every node's slot is known (arrived, lost,
//! overrun or past its deadline), or given up on at the end of a stream.

use super::*;

impl Assembler {
    /// Node `m`'s slots of instants `next_k..k` (those still pending) were lost in the IPC,
    /// or on the network if the node's relay changed since its last slot
    /// ([`Assembler::relay_changed`]).
    pub(super) fn fill_gap(&mut self, m: usize, k: u64, recv_ns: u64) {
        let net = self.relay_gap & (1 << m) != 0;
        self.relay_gap &= !(1 << m);
        let flags = if net {
            FLAG_IPC_LOST | FLAG_NET_LOST
        } else {
            FLAG_IPC_LOST
        };
        let from = self.node[m].next_k.max(self.base);
        for j in from..k {
            if self.ring[(j as usize) % WINDOW].known & (1 << m) == 0 {
                if net {
                    self.counts.lost_on_network += 1;
                } else {
                    self.counts.lost_in_ipc += 1;
                }
                let o = Observation::dropped(j as u32, m as u8, self.ny[m], flags);
                self.set(j, m, o, recv_ns);
            }
        }
    }

    #[inline]
    pub(super) fn set(&mut self, k: u64, m: usize, o: Observation, recv_ns: u64) {
        let p = &mut self.ring[(k as usize) % WINDOW];
        if p.known == 0 {
            p.first_ns = recv_ns;
        }
        p.known |= 1 << m;
        p.obs[m] = o;
    }

    /// Makes instant `k` fit the window, handing on the oldest instants without their
    /// missing slots; `false` if that would take more than `bound` instants.
    pub(super) fn make_room(
        &mut self,
        k: u64,
        m: usize,
        bound: u64,
        emit: &mut impl FnMut(u32, &[Observation]),
    ) -> bool {
        let top = self.base + WINDOW as u64 - 1;
        if k <= top {
            return true;
        }
        if k - top > bound {
            return false;
        }
        for _ in 0..k - top {
            self.give_up_for(GiveUp::Overrun, Some(m), emit);
            self.advance(emit);
        }
        true
    }

    /// Whether node `n`'s slot of instant `j` is known to be absent after its END/ABORT.
    #[inline]
    pub(super) fn ended_before(&self, n: usize, j: u64) -> bool {
        self.node[n].end.is_some_and(|e| j > e.0)
    }

    /// Hands on the complete instants at the front of the window.
    pub(super) fn advance(&mut self, emit: &mut impl FnMut(u32, &[Observation])) {
        loop {
            let j = self.base;
            let known = self.ring[(j as usize) % WINDOW].known;
            if known == 0 {
                return;
            }
            if known != self.all
                && (0..usize::from(self.nodes))
                    .any(|n| known & (1 << n) == 0 && !self.ended_before(n, j))
            {
                return;
            }
            self.hand_on(emit);
        }
    }

    /// Hands on instant `base`: every node's slot not known is lost (after its END, or for
    /// `why`).
    pub(super) fn give_up(&mut self, why: GiveUp, emit: &mut impl FnMut(u32, &[Observation])) {
        self.give_up_for(why, None, emit);
    }

    pub(super) fn give_up_for(
        &mut self,
        why: GiveUp,
        gap_of: Option<usize>,
        emit: &mut impl FnMut(u32, &[Observation]),
    ) {
        let j = self.base;
        for n in 0..usize::from(self.nodes) {
            if self.ring[(j as usize) % WINDOW].known & (1 << n) != 0 {
                continue;
            }
            if self.ended_before(n, j) {
                self.counts.lost_after_end += 1;
            } else if gap_of == Some(n) && j >= self.node[n].next_k {
                // The node whose slot made room: this is a gap of its own sequence.
                if self.relay_gap & (1 << n) != 0 {
                    self.counts.lost_on_network += 1;
                } else {
                    self.counts.lost_in_ipc += 1;
                }
            } else {
                match why {
                    GiveUp::Deadline => self.counts.lost_deadline += 1,
                    GiveUp::Overrun => self.counts.lost_overrun += 1,
                }
            }
            let p = &mut self.ring[(j as usize) % WINDOW];
            p.obs[n] = Observation::dropped(j as u32, n as u8, self.ny[n], FLAG_IPC_LOST);
            p.known |= 1 << n;
        }
        self.hand_on(emit);
    }

    /// Emits instant `base` (every node's slot known) and moves on.
    pub(super) fn hand_on(&mut self, emit: &mut impl FnMut(u32, &[Observation])) {
        let j = self.base;
        let nodes = usize::from(self.nodes);
        for n in 0..nodes {
            if self.ring[(j as usize) % WINDOW].known & (1 << n) == 0 {
                // After its END: lost, known only now that the instant is handed on.
                self.counts.lost_after_end += 1;
                self.ring[(j as usize) % WINDOW].obs[n] =
                    Observation::dropped(j as u32, n as u8, self.ny[n], FLAG_IPC_LOST);
            }
        }
        let p = &mut self.ring[(j as usize) % WINDOW];
        p.known = 0;
        self.counts.instants += 1;
        self.base = j + 1;
        emit(j as u32, &p.obs[..nodes]);
    }

    /// Hands on every pending instant without the slots that have not come (counted as lost
    /// by the deadline): the publishers are gone or the run ends, and what arrived is still
    /// stepped.
    pub fn flush(&mut self, emit: &mut impl FnMut(u32, &[Observation])) {
        while self.ring[(self.base as usize) % WINDOW].known != 0 {
            self.give_up(GiveUp::Deadline, emit);
            self.advance(emit);
        }
    }

    /// When the oldest pending instant's deadline passes (paced mode), if one is pending.
    pub fn next_expiry(&self) -> Option<u64> {
        let p = &self.ring[(self.base as usize) % WINDOW];
        (self.paced && self.limits.instant_deadline_ns > 0 && p.known != 0)
            .then(|| p.first_ns.saturating_add(self.limits.instant_deadline_ns))
    }

    /// Hands on every pending instant whose deadline passed by `now` (paced mode only),
    /// without the slots that have not come.
    pub fn expire(&mut self, now: u64, emit: &mut impl FnMut(u32, &[Observation])) {
        while self.next_expiry().is_some_and(|t| now >= t) {
            self.give_up(GiveUp::Deadline, emit);
            self.advance(emit);
        }
    }
}
