//! The hand-on work a call to the [`Assembler`](super::Assembler) left for
//! [`next_ready`](super::Assembler::next_ready): a pushed slot decides at once what it is
//! ([`Pushed`](super::Pushed), the counts), and the instants it completes or gives up are
//! handed on one at a time as the caller asks for them, in the order below. An instant is
//! handed on only when asked for, so the window never overwrites an instant the caller has
//! not taken yet, and nothing is allocated whatever one slot sets off.

use estpipe_wire::Observation;

/// A slot accepted into the window once there is room for it (after [`Work::room`]).
#[derive(Clone, Copy, Debug)]
pub(super) struct Place {
    /// The node.
    pub(super) m: usize,
    /// The node's slots missing before this instant were lost.
    pub(super) gap_to: u64,
    /// The slot's observation (its instant is `o.k`); `None` for an END/ABORT marker.
    pub(super) obs: Option<Observation>,
    /// The node's next instant after it.
    pub(super) next_k: u64,
    /// When it was received.
    pub(super) recv_ns: u64,
    /// The marker's last instant and whether it was an ABORT.
    pub(super) end: Option<(u64, bool)>,
}

/// What is left to hand on, in this order.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Work {
    /// Instants `missed.0 .. missed.1` before a joined stream's first slot, every slot lost.
    pub(super) missed: (u64, u64),
    /// After giving an instant up (or placing a slot): hand on the complete instants at the
    /// front of the window before anything else.
    pub(super) advance: bool,
    /// Instants to give up from the front to make room for the slot of node `room_for`,
    /// each followed by [`Work::advance`].
    pub(super) room: u64,
    pub(super) room_for: usize,
    /// The slot, put into the window once there is room (then [`Work::advance`]).
    pub(super) place: Option<Place>,
    /// Every stream is over: give up every instant up to this one.
    pub(super) end_at: Option<u64>,
    /// Give up the instants whose deadline passed by this time (each followed by
    /// [`Work::advance`]).
    pub(super) expire_at: Option<u64>,
    /// Give up every pending instant (each followed by [`Work::advance`]).
    pub(super) flush: bool,
}

impl Work {
    /// Nothing left.
    pub(super) fn is_done(&self) -> bool {
        self.missed.0 >= self.missed.1
            && !self.advance
            && self.room == 0
            && self.place.is_none()
            && self.end_at.is_none()
            && self.expire_at.is_none()
            && !self.flush
    }
}
