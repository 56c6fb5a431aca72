//! Turns the slot streams back into sampling instants, trusting nothing in a slot.
//!
//! Wire version 3 (`docs/wire.md`, Stream rules): every sensor node is its own stream, with
//! its own `stream_id` and its own dense sequence (`seq = k − 1`), so its slots may come from
//! its own process and the nodes' slots of an instant may arrive in any order. The
//! [`Assembler`] keeps a window of [`WINDOW`] pending instants (allocated once, nothing per
//! slot) and hands instant k on, strictly in order, when every node's slot k is *known*:
//!
//! * it arrived;
//! * it is known lost: a gap in that node's sequence (lost inside the IPC) or after that
//!   node's END/ABORT marker; a malformed slot that still names its instant and node
//!   reliably (only its content is bad) is such a loss too;
//! * in paced mode (a stream with `period_ns > 0`), the instant's deadline passed
//!   ([`Limits::instant_deadline_ns`] after its first slot arrived): the node's slot is
//!   *lost* by the deadline, counted apart from channel drops and IPC gaps;
//! * a slot of an instant [`WINDOW`] instants later arrived: the node is that far behind,
//!   its slot counted as lost by overrun (the only way blocking mode loses a slot).
//!
//! A lost slot becomes an observation without a measurement marked [`FLAG_IPC_LOST`]: the
//! estimators see the instant, as a loss (no information, `Packet::Lost`), not as a packet
//! the channel dropped. A slot that arrives after its instant was handed on is counted as
//! late and skipped.
//!
//! Hostile input (issue #20): every slot is counted exactly once — accepted (delivered or
//! dropped by the channel), a marker, a duplicate, late, or skipped for one [`Skipped`]
//! reason — and no slot can make the assembler do more than a bounded amount of work: a
//! node's `k` may advance at most [`Limits::max_gap`] past its last instant (a larger jump is
//! a counted stream error, never a fill of fake instants), and so may an END/ABORT marker.
//! A restart is a new stream id on a node starting again at its first slot (k = 1); any other
//! slot with another stream id is counted and skipped, so a stream id flipping on every other
//! slot never resets the estimators.

//!
//! The caller pulls (no callback): [`Assembler::push_slot`] says at once what a slot was
//! ([`Pushed`]) and counts it; then [`Assembler::next_ready`] hands on, one [`Instant`] per
//! call and strictly in order, every instant that slot completed or gave up, until `None`.
//! [`Assembler::expire_due`] and [`Assembler::flush`] work the same way. The parts, one file
//! each: `window` (the pending instants), `work` (what a call left to hand on), `instant`
//! (what is handed on), `counts`, `clock` (how far a node may jump), `late` (a late slot).

use estpipe_wire::Observation;
use estpipe_wire::{
    Slot, SlotFault, StreamHeader, FLAG_IPC_LOST, FLAG_NET_LOST, SLOT_ABORT, SLOT_DATA,
};
use estpipe_wire::{MAX_NODES, MAX_NY};

mod clock;
mod counts;
mod instant;
mod late;
mod window;
mod work;

pub use counts::{Anomalies, Counts, Reason, Skipped};
pub use instant::{Instant, SlotTimes};
use window::Window;
use work::{Place, Work};

/// Pending instants the assembler holds: how far one node may run ahead of the slowest
/// before the slowest node's slot of the oldest instant is given up (counted as
/// [`Counts::lost_overrun`]). As many as a subscriber queue can hold.
pub const WINDOW: usize = 4096;

/// Default of `--max-gap`: instants a node's `k` may advance past its last one.
pub const DEFAULT_MAX_GAP: u32 = 1000;

/// Default of `--instant-deadline-ms`.
pub const DEFAULT_INSTANT_DEADLINE_MS: f64 = 20.0;

/// The longest sampling period a slot may announce (10 s); a longer one is ignored for loss
/// detection and counted ([`Anomalies::period_ns`]): `period_ns = 2⁶²` would otherwise
/// switch the data deadline off.
pub const MAX_PERIOD_NS: u64 = 10_000_000_000;

/// How far the assembler follows a stream.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limits {
    /// Instants a node's `k` (or its END/ABORT's) may advance past its last instant; the
    /// gap is filled with lost slots. A larger jump is counted ([`Skipped::gap`],
    /// [`Skipped::marker`]) and the slot skipped.
    pub max_gap: u32,
    /// In paced mode, how long after its first slot arrived an instant waits for the other
    /// nodes' slots (0: for ever). Blocking mode (`period_ns = 0`) never loses a slot by a
    /// deadline.
    pub instant_deadline_ns: u64,
    /// `--lag`: a slot at most this many instants late (its instant and those after it handed
    /// on) is handed on by itself ([`Pushed::Late`]) instead of skipped as late.
    pub lag: u32,
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            max_gap: DEFAULT_MAX_GAP,
            instant_deadline_ns: (DEFAULT_INSTANT_DEADLINE_MS * 1e6) as u64,
            lag: 0,
        }
    }
}

/// What a pushed slot meant.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pushed {
    /// Data slot accepted.
    Data,
    /// A data slot whose content is malformed ([`SlotFault::content_only`]): the node's slot
    /// of that instant is handed on as lost.
    Refused(SlotFault),
    /// The slot starts a new stream of its node (the node's publisher restarted). Not
    /// consumed (nothing to hand on): start a new session, call [`Assembler::reset`] and
    /// push it again.
    NewStream,
    /// A node's END/ABORT; other nodes' streams go on.
    Marker,
    /// A data slot of an instant already handed on, at most [`Limits::lag`] instants late:
    /// [`Assembler::take_late`] gives it, for the estimators' fixed-lag history.
    Late,
    /// The last node's END marker: every stream is complete, every instant handed on.
    End,
    /// The last node's marker, and some node's was an ABORT (its publisher stopped early).
    Abort,
    /// Skipped, counted ([`Counts`]).
    Ignored,
}

/// One node's stream as far as it was followed.
#[derive(Clone, Copy, Debug, Default)]
struct NodeStream {
    sid: Option<u64>,
    /// The stream a restart replaced: its slots still in the queue are skipped.
    stale: Option<u64>,
    /// The next instant expected from the node (every earlier one is known).
    next_k: u64,
    /// The node's END/ABORT: its last instant and whether it was an ABORT.
    end: Option<(u64, bool)>,
    /// Its send clock, which may vouch for a jump past `--max-gap` ([`clock`]).
    clock: Option<clock::StreamClock>,
}

/// Why a node's slot is given up when its instant is handed on without it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum GiveUp {
    Deadline,
    Overrun,
}

/// Reassembles instants from per-node slot streams; allocates only when built.
#[derive(Debug)]
pub struct Assembler {
    nodes: u8,
    all: u16,
    ny: [u8; MAX_NODES],
    expected: StreamHeader,
    limits: Limits,
    subscribed_ns: u64,
    session_started: bool,
    /// The streams were given up (publisher lost): the next stream starts a new session.
    restart_pending: bool,
    paced: bool,
    window: Window,
    node: [NodeStream; MAX_NODES],
    first_seen: Option<Reason>,
    /// Bit m: node m's stream goes on from another publisher (a relay that restarted), so
    /// the slots missing before its next one were lost while nothing forwarded them.
    relay_gap: u16,
    /// The slot of the last [`Pushed::Late`].
    late: Option<Observation>,
    /// The slot pushed last (every [`Instant`] handed on carries it).
    last: SlotTimes,
    /// What is left to hand on ([`Assembler::next_ready`]).
    work: Work,
    /// Running counts (over all sessions).
    pub counts: Counts,
}

/// Whether `h` announces the stream `expected` describes (the fields
/// [`StreamHeader::check`] compares, and the version).
pub fn same_stream_shape(h: &StreamHeader, expected: &StreamHeader) -> bool {
    h.version == expected.version
        && h.nodes == expected.nodes
        && h.nx == expected.nx
        && h.ny == expected.ny
        && h.model == expected.model
}

/// The bucket level a delivered packet reports with `FLAG_TOKENS` (docs/wire.md), late or not.
fn reported_level(slot: &Slot, delivered: bool) -> Option<u32> {
    (slot.flags & estpipe_wire::FLAG_TOKENS != 0 && delivered).then_some(slot.tokens)
}

/// The slot's `send_ns` if it can be used for latency: not 0 and not after `recv_ns`.
#[inline]
pub fn usable_send_ns(slot: &Slot, recv_ns: u64) -> Option<u64> {
    (slot.send_ns != 0 && slot.send_ns <= recv_ns).then_some(slot.send_ns)
}

impl Assembler {
    /// For streams announcing `expected` (its nodes and every node's ny).
    pub fn new(expected: &StreamHeader, limits: Limits) -> Self {
        let nodes = expected.nodes.min(MAX_NODES as u8);
        let mut ny = [0; MAX_NODES];
        for (d, &s) in ny.iter_mut().zip(expected.ny_per_node()) {
            *d = s.min(MAX_NY as u8);
        }
        let mut a = Self {
            nodes,
            all: (1u16 << nodes) - 1,
            ny,
            expected: *expected,
            limits,
            subscribed_ns: 0,
            session_started: false,
            restart_pending: false,
            paced: false,
            window: Window::new(usize::from(nodes), ny),
            node: [NodeStream::default(); MAX_NODES],
            first_seen: None,
            relay_gap: 0,
            late: None,
            last: SlotTimes::default(),
            work: Work::default(),
            counts: Counts::default(),
        };
        a.reset();
        a
    }

    /// When the runner's subscriber was created (`CLOCK_MONOTONIC`): slots missing before the
    /// first one seen of a stream that started later were lost in the IPC; of a stream that
    /// started earlier, they were sent before this runner joined.
    pub fn set_subscribed_ns(&mut self, ns: u64) {
        self.subscribed_ns = ns;
    }

    /// The stream node `m` is followed on (node 0's is the truth's: its process publishes
    /// the truth).
    pub fn stream_of(&self, m: u8) -> Option<u64> {
        self.node.get(usize::from(m)).and_then(|n| n.sid)
    }

    /// The next instant to hand on.
    pub fn next_instant(&self) -> u64 {
        self.window.base()
    }

    /// Whether every stream of the session was paced (`period_ns > 0`) so far.
    pub fn paced(&self) -> bool {
        self.paced
    }

    /// A reason counted for the first time since the last call (to say it once).
    pub fn take_first_seen(&mut self) -> Option<Reason> {
        self.first_seen.take()
    }

    /// Starts a new session: every node's current stream becomes stale (its slots still in
    /// the queue are skipped), pending instants are dropped; counts are kept.
    pub fn reset(&mut self) {
        for n in &mut self.node {
            if n.sid.is_some() {
                n.stale = n.sid;
            }
            n.sid = None;
            n.end = None;
            n.next_k = 1;
            n.clock = None;
        }
        self.window.clear();
        self.work = Work::default();
        self.session_started = false;
        self.restart_pending = false;
        self.paced = false;
        self.relay_gap = 0;
    }

    /// Node `m`'s stream goes on from another publisher than its last slot's: a relay
    /// between the stream's publisher and this runner (`ipc-runner bridge`, docs/bridge.md)
    /// went away and another took over. The slots of `m` missing before its next one were
    /// lost while no relay forwarded them: counted as [`Counts::lost_on_network`], not as lost
    /// in the IPC.
    pub fn relay_changed(&mut self, m: u8) {
        if usize::from(m) < MAX_NODES {
            self.relay_gap |= 1 << m;
        }
    }

    /// The publishers were lost (`--wait-for-restart`): their streams become stale and the
    /// next stream, starting at any k (its first slot may have been lost too), is pushed as
    /// [`Pushed::NewStream`] (a new session).
    pub fn lose_streams(&mut self) {
        self.reset();
        self.restart_pending = true;
    }

    /// The slot that was pushed as [`Pushed::NewStream`] is not a restart (the loop knows
    /// the publisher of the node's stream is alive, and another one sent it): counted and
    /// skipped, the node's stream goes on.
    pub fn refuse_restart(&mut self) -> Pushed {
        self.skip(Reason::ForeignRestart)
    }

    fn note(&mut self, r: Reason, first: bool) {
        if first && self.first_seen.is_none() {
            self.first_seen = Some(r);
        }
    }

    fn skip(&mut self, r: Reason) -> Pushed {
        let s = &mut self.counts.skipped;
        let c = match r {
            Reason::Fault(f) => s.fault(f),
            Reason::Header => &mut s.header,
            Reason::Stream => &mut s.stream,
            Reason::Stale => &mut s.stale_stream,
            Reason::ForeignRestart => &mut s.foreign_restart,
            Reason::Gap => &mut s.gap,
            Reason::Marker => &mut s.marker,
            Reason::AfterMarker => &mut s.after_marker,
            Reason::Late => &mut self.counts.late,
            Reason::Period | Reason::SendNs => unreachable!("anomalies are not skips"),
        };
        *c += 1;
        let first = *c == 1;
        self.note(r, first);
        Pushed::Ignored
    }

    /// Consumes one slot (with the stream header it came with, received at `recv_ns`) and
    /// says what it was; the instants it completes are then taken with
    /// [`Assembler::next_ready`] (every one, before the next slot is pushed).
    #[inline]
    pub fn push_slot(&mut self, slot: &Slot, header: &StreamHeader, recv_ns: u64) -> Pushed {
        debug_assert!(
            self.work.is_done(),
            "a slot pushed before every instant was taken"
        );
        self.last = SlotTimes {
            send_ns: usable_send_ns(slot, recv_ns).unwrap_or(0),
            recv_ns,
            stream_id: self.stream_of(0).unwrap_or(slot.stream_id),
        };
        if !same_stream_shape(header, &self.expected) {
            return self.skip(Reason::Header);
        }
        let fault = slot.fault(self.nodes, &self.ny[..usize::from(self.nodes)]);
        if let Some(f) = fault.filter(|f| !f.content_only()) {
            return self.skip(Reason::Fault(f));
        }
        if let Some(pushed) = self.follow(slot, fault) {
            return pushed;
        }
        if self.node[usize::from(slot.node)].end.is_some() {
            return self.skip(Reason::AfterMarker);
        }
        if slot.kind != SLOT_DATA {
            return self.marker(slot, recv_ns);
        }
        self.data(slot, fault, recv_ns)
    }

    /// The slot's stream: `Some` when that settles what the slot is (skipped, or a new
    /// stream); the first slot of a session starts it.
    fn follow(&mut self, slot: &Slot, fault: Option<SlotFault>) -> Option<Pushed> {
        let m = usize::from(slot.node);
        let ns = self.node[m];
        if ns.stale == Some(slot.stream_id) && ns.sid != Some(slot.stream_id) {
            return Some(self.skip(Reason::Stale));
        }
        match ns.sid {
            // A restart starts again at the node's first slot; anything else with another
            // stream id is a stray (or a flipped field), never a reason to reset.
            Some(s) if s != slot.stream_id => Some(
                if slot.kind == SLOT_DATA && slot.k == 1 && fault.is_none() {
                    Pushed::NewStream
                } else {
                    self.skip(Reason::Stream)
                },
            ),
            Some(_) => None,
            None if self.restart_pending => Some(Pushed::NewStream),
            None => {
                if !self.session_started {
                    self.start_session(slot);
                }
                self.node[m].sid = Some(slot.stream_id);
                None
            }
        }
    }

    /// The first slot of a session: whether this runner saw the stream start, and where the
    /// session's instants begin.
    fn start_session(&mut self, slot: &Slot) {
        self.session_started = true;
        if slot.stream_start_ns >= self.subscribed_ns {
            return; // base 1: anything missing before the first slot was lost in the IPC
        }
        // Joined mid-stream: what precedes the first instant seen was sent before we existed.
        let first = if slot.kind == SLOT_DATA {
            u64::from(slot.k)
        } else {
            u64::from(slot.k) + 1
        }
        .max(1);
        let missed = first - 1;
        self.counts.missed_before_join += missed * u64::from(self.nodes);
        if missed <= u64::from(self.limits.max_gap) {
            // Within the gap bound the estimators step through the missed instants as lost
            // ones (the instant count then matches the publisher's).
            self.work.missed = (1, first);
        }
        self.window.start_at(first);
        for n in &mut self.node {
            n.next_k = first;
        }
    }

    /// A data slot of the node's stream.
    fn data(&mut self, slot: &Slot, fault: Option<SlotFault>, recv_ns: u64) -> Pushed {
        let m = usize::from(slot.node);
        let k = u64::from(slot.k);
        let next = self.node[m].next_k;
        if k < next {
            self.counts.out_of_order += 1;
            return Pushed::Ignored;
        }
        if k < self.window.base() {
            return self.late_slot(slot, fault);
        }
        // From what is still pending: a node that fell behind (its slots given up) may come
        // back.
        let bound = clock::gap_bound(self.limits.max_gap, self.node[m].clock, slot, recv_ns);
        if k - next.max(self.window.base()) > bound || !self.make_room(k, m, bound) {
            return self.skip(Reason::Gap);
        }
        self.note_fields(slot, recv_ns);
        let (obs, pushed) = match fault {
            Some(f) => {
                self.skip(Reason::Fault(f));
                let o = Observation::dropped(slot.k, slot.node, self.ny[m], FLAG_IPC_LOST);
                (o, Pushed::Refused(f))
            }
            None => (self.accept(slot), Pushed::Data),
        };
        self.node[m].clock = clock::StreamClock::after(self.node[m].clock, slot, recv_ns);
        self.work.place = Some(Place {
            m,
            gap_to: k,
            obs: Some(obs),
            next_k: k + 1,
            recv_ns,
            end: None,
        });
        self.work.expire_at = Some(recv_ns);
        pushed
    }

    /// Counts the fields of an accepted data slot that are not used.
    fn note_fields(&mut self, slot: &Slot, recv_ns: u64) {
        if slot.period_ns > MAX_PERIOD_NS {
            self.counts.anomalies.period_ns += 1;
            let first = self.counts.anomalies.period_ns == 1;
            self.note(Reason::Period, first);
        } else if slot.period_ns > 0 {
            self.paced = true;
        }
        if usable_send_ns(slot, recv_ns).is_none() {
            self.counts.anomalies.send_ns += 1;
            let first = self.counts.anomalies.send_ns == 1;
            self.note(Reason::SendNs, first);
        }
    }

    /// A well-formed data slot, counted, as the observation handed on.
    fn accept(&mut self, slot: &Slot) -> Observation {
        let net_lost = slot.flags & FLAG_NET_LOST != 0;
        if net_lost {
            // A bridge's stand-in for a slot the network lost (docs/bridge.md). Its count
            // says lost, so it is handed on as lost: a foreign publisher that sets the bit on
            // a measurement does not get it used behind the count.
            self.counts.lost_on_network += 1;
        } else {
            self.counts.received += 1;
            if slot.delivered == 1 {
                self.counts.delivered += 1;
            } else {
                self.counts.dropped_by_channel += 1;
            }
        }
        Observation {
            k: slot.k,
            node: slot.node,
            delivered: slot.delivered == 1 && !net_lost,
            ny: self.ny[usize::from(slot.node)],
            y: if net_lost {
                [0.0; MAX_NY]
            } else {
                late::measurement(slot)
            },
            flags: slot.flags & !FLAG_IPC_LOST,
            tokens: reported_level(slot, slot.delivered == 1 && !net_lost),
        }
    }

    /// A data slot of an instant already handed on without it (deadline or overrun); what
    /// lies between was given up with it. Within the lag it is still information (its
    /// lateness: the instants handed on from its own to the newest).
    fn late_slot(&mut self, slot: &Slot, fault: Option<SlotFault>) -> Pushed {
        let m = usize::from(slot.node);
        let k = u64::from(slot.k);
        self.node[m].next_k = k + 1;
        let lateness = self.window.base() - k;
        if lateness <= u64::from(self.limits.lag)
            && fault.is_none()
            && slot.flags & FLAG_NET_LOST == 0
        {
            self.counts.late_folded += 1;
            self.late = Some(Observation {
                k: slot.k,
                node: slot.node,
                delivered: slot.delivered == 1,
                ny: self.ny[m],
                y: late::measurement(slot),
                flags: slot.flags & !FLAG_IPC_LOST,
                tokens: reported_level(slot, slot.delivered == 1),
            });
            return Pushed::Late;
        }
        self.skip(Reason::Late)
    }

    /// The slot of the last [`Pushed::Late`], as its instant's observations: every other node
    /// lost (`FLAG_IPC_LOST`), what the estimators' `fold_late` takes. `None` after the first
    /// call.
    pub fn take_late(&mut self, out: &mut [Observation; MAX_NODES]) -> Option<(u32, usize)> {
        let o = self.late.take()?;
        Some(late::as_instant(
            o,
            &self.ny[..usize::from(self.nodes)],
            out,
        ))
    }

    /// A node's END/ABORT.
    fn marker(&mut self, slot: &Slot, recv_ns: u64) -> Pushed {
        let m = usize::from(slot.node);
        let k = u64::from(slot.k);
        let next = self.node[m].next_k;
        let last = next.max(self.window.base()) - 1;
        let bound = clock::gap_bound(self.limits.max_gap, self.node[m].clock, slot, recv_ns);
        if k + 1 < next || k.saturating_sub(last) > bound || !self.make_room(k, m, bound) {
            return self.skip(Reason::Marker);
        }
        let abort = slot.kind == SLOT_ABORT;
        self.counts.markers += 1;
        self.work.place = Some(Place {
            m,
            gap_to: k + 1,
            obs: None,
            next_k: k + 1,
            recv_ns,
            end: Some((k, abort)),
        });
        let others = self.node[..usize::from(self.nodes)]
            .iter()
            .enumerate()
            .filter(|&(n, _)| n != m)
            .map(|(_, s)| s.end);
        if others.clone().any(|e| e.is_none()) {
            return Pushed::Marker;
        }
        // Every stream is over: what is left is handed on (the other nodes' instants after
        // an early END are complete with this node's slots lost).
        let ends = others.flatten();
        self.work.end_at = Some(ends.clone().map(|e| e.0).fold(k, u64::max));
        if abort || ends.clone().any(|e| e.1) {
            Pushed::Abort
        } else {
            Pushed::End
        }
    }

    /// Whether instant `k` fits the window; if it takes handing on the oldest instants
    /// without their missing slots, that is left to do first ([`Work::room`]). `false` if
    /// it would take more than `bound` instants.
    fn make_room(&mut self, k: u64, m: usize, bound: u64) -> bool {
        let top = self.window.top();
        if k <= top {
            return true;
        }
        if k - top > bound {
            return false;
        }
        self.work.room = k - top;
        self.work.room_for = m;
        true
    }

    /// The next instant ready, strictly in order: those the last pushed slot (or
    /// [`Assembler::expire_due`], [`Assembler::flush`]) completed or gave up. `None` once
    /// every one was taken.
    #[inline]
    pub fn next_ready(&mut self) -> Option<Instant<'_>> {
        let (next, end) = self.work.missed;
        if next < end {
            self.work.missed.0 += 1;
            self.counts.instants += 1;
            let slot = self.last;
            let obs = self.window.lost_instant(next);
            return Some(Instant {
                k: next as u32,
                obs,
                slot,
            });
        }
        loop {
            if self.work.advance {
                if self.front_complete() {
                    return Some(self.complete_front());
                }
                self.work.advance = false;
            }
            if self.work.room > 0 {
                self.work.room -= 1;
                self.work.advance = true;
                let m = self.work.room_for;
                return Some(self.give_up(GiveUp::Overrun, Some(m)));
            }
            if let Some(p) = self.work.place.take() {
                self.place(p);
                self.work.advance = true;
                continue;
            }
            return self.give_up_due();
        }
    }

    /// The instants [`Work::end_at`], [`Work::expire_at`] and [`Work::flush`] give up, in
    /// that order.
    fn give_up_due(&mut self) -> Option<Instant<'_>> {
        if let Some(last) = self.work.end_at {
            if self.window.base() <= last {
                return Some(self.give_up(GiveUp::Overrun, None));
            }
            self.work.end_at = None;
        }
        if let Some(now) = self.work.expire_at {
            if self.next_expiry().is_some_and(|t| now >= t) {
                self.work.advance = true;
                return Some(self.give_up(GiveUp::Deadline, None));
            }
            self.work.expire_at = None;
        }
        if self.work.flush {
            if self.window.front_known() != 0 {
                self.work.advance = true;
                return Some(self.give_up(GiveUp::Deadline, None));
            }
            self.work.flush = false;
        }
        None
    }

    /// Puts a pushed slot into the window (there is room now).
    fn place(&mut self, p: Place) {
        self.fill_gap(p.m, p.gap_to, p.recv_ns);
        if let Some(o) = p.obs {
            self.window.set(u64::from(o.k), p.m, o, p.recv_ns);
        }
        self.node[p.m].next_k = p.next_k;
        if p.end.is_some() {
            self.node[p.m].end = p.end;
        }
    }

    /// Node `m`'s slots of instants `next_k..k` (those still pending) were lost in the IPC,
    /// or on the network if the node's relay changed since its last slot
    /// ([`Assembler::relay_changed`]).
    fn fill_gap(&mut self, m: usize, k: u64, recv_ns: u64) {
        let net = self.relay_gap & (1 << m) != 0;
        self.relay_gap &= !(1 << m);
        let flags = if net {
            FLAG_IPC_LOST | FLAG_NET_LOST
        } else {
            FLAG_IPC_LOST
        };
        let from = self.node[m].next_k.max(self.window.base());
        for j in from..k {
            if !self.window.is_known(j, m) {
                if net {
                    self.counts.lost_on_network += 1;
                } else {
                    self.counts.lost_in_ipc += 1;
                }
                let o = Observation::dropped(j as u32, m as u8, self.ny[m], flags);
                self.window.set(j, m, o, recv_ns);
            }
        }
    }

    /// Whether node `n`'s slot of instant `j` is known to be absent after its END/ABORT.
    #[inline]
    fn ended_before(&self, n: usize, j: u64) -> bool {
        self.node[n].end.is_some_and(|e| j > e.0)
    }

    /// Whether the front instant is complete: every node's slot known, or absent after the
    /// node's END/ABORT.
    #[inline]
    fn front_complete(&self) -> bool {
        let known = self.window.front_known();
        let j = self.window.base();
        known != 0
            && (known == self.all
                || (0..usize::from(self.nodes))
                    .all(|n| known & (1 << n) != 0 || self.ended_before(n, j)))
    }

    /// Hands on the complete front instant (a slot not known is after its node's END: lost,
    /// known only now that the instant is handed on).
    #[inline]
    fn complete_front(&mut self) -> Instant<'_> {
        let known = self.window.front_known();
        for n in 0..usize::from(self.nodes) {
            if known & (1 << n) == 0 {
                self.counts.lost_after_end += 1;
            }
        }
        self.take_front()
    }

    /// Hands on the front instant: every node's slot not known is lost, after its END or
    /// for `why`; a slot of `gap_of`, the node whose slot made room, is a gap of its own
    /// sequence.
    fn give_up(&mut self, why: GiveUp, gap_of: Option<usize>) -> Instant<'_> {
        let j = self.window.base();
        let known = self.window.front_known();
        for n in (0..usize::from(self.nodes)).filter(|n| known & (1 << n) == 0) {
            let c = &mut self.counts;
            if self.node[n].end.is_some_and(|e| j > e.0) {
                c.lost_after_end += 1;
            } else if gap_of == Some(n) && j >= self.node[n].next_k {
                if self.relay_gap & (1 << n) != 0 {
                    c.lost_on_network += 1;
                } else {
                    c.lost_in_ipc += 1;
                }
            } else {
                match why {
                    GiveUp::Deadline => c.lost_deadline += 1,
                    GiveUp::Overrun => c.lost_overrun += 1,
                }
            }
        }
        self.take_front()
    }

    #[inline]
    fn take_front(&mut self) -> Instant<'_> {
        self.counts.instants += 1;
        let slot = self.last;
        let (k, obs) = self.window.hand_on();
        Instant { k, obs, slot }
    }

    /// When the oldest pending instant's deadline passes (paced mode), if one is pending.
    pub fn next_expiry(&self) -> Option<u64> {
        let deadline = self.limits.instant_deadline_ns;
        self.window
            .front_first_ns()
            .filter(|_| self.paced && deadline > 0)
            .map(|t| t.saturating_add(deadline))
    }

    /// The pending instants whose deadline passed by `now` (paced mode only) are to be
    /// handed on without the slots that have not come: taken with
    /// [`Assembler::next_ready`].
    #[inline]
    pub fn expire_due(&mut self, now: u64) {
        self.work.expire_at = Some(now);
    }

    /// Every pending instant is to be handed on without the slots that have not come
    /// (counted as lost by the deadline): the publishers are gone or the run ends, and what
    /// arrived is still stepped. Taken with [`Assembler::next_ready`].
    pub fn flush(&mut self) {
        self.work.flush = true;
    }

    /// [`Assembler::push_slot`], then every instant it made ready to `emit(k, observations)`:
    /// the callback form, for a caller that wants nothing but the observations
    /// (`tests/assemble_prop.rs`).
    pub fn push(
        &mut self,
        slot: &Slot,
        header: &StreamHeader,
        recv_ns: u64,
        emit: &mut impl FnMut(u32, &[Observation]),
    ) -> Pushed {
        let pushed = self.push_slot(slot, header, recv_ns);
        self.hand_on_to(emit);
        pushed
    }

    /// [`Assembler::expire_due`] in the callback form of [`Assembler::push`].
    pub fn expire(&mut self, now: u64, emit: &mut impl FnMut(u32, &[Observation])) {
        self.expire_due(now);
        self.hand_on_to(emit);
    }

    fn hand_on_to(&mut self, emit: &mut impl FnMut(u32, &[Observation])) {
        while let Some(i) = self.next_ready() {
            emit(i.k, i.obs);
        }
    }
}

#[cfg(test)]
mod tests;
