//! How far a node's `k` may jump: `--max-gap`, or as far as the stream's own clock vouches
//! for (issue #39).
//!
//! `--max-gap` bounds the work one slot can cause (every instant of a gap is stepped), so
//! that a forged `k = u32::MAX` cannot keep the runner busy. But a runner stopped for 0.8 s
//! (`kill -STOP`, a debugger, a VM pause) at 2 kHz comes back to a real gap of 1 600
//! instants, and refusing it abandoned the stream for good (every later slot was a jump too,
//! counted as `skipped.gap`, and the run ended "publisher lost"). docs/security.md promises
//! that a stop and continue changes nothing but the slots it cost.
//!
//! So a paced node's jump is followed when the time between its sends says that many
//! instants passed: the bound is `--max-gap` plus the node's send-time advance over its
//! period. Both come from the node's own stream, but they cannot buy more work than real
//! time: the send time counts only when it is not after the slot's receipt, and the period
//! is the stream's first one (a later slot cannot shrink it), at least [`MIN_PERIOD_NS`].
//! A gap followed so is filled with lost slots like any other (`lost_in_ipc`).

use estpipe_wire::Slot;

/// Shortest period for which the clock extends the bound (100 kHz): faster streams are
/// followed within `--max-gap` only, so a gap costs at most 10⁵ stepped instants per second
/// of the stream's real time.
pub const MIN_PERIOD_NS: u64 = 10_000;

/// A node's send clock: its last accepted slot's send time and its stream's period.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct StreamClock {
    last_send_ns: u64,
    period_ns: u64,
}

impl StreamClock {
    /// The clock after accepting `slot` (received at `recv_ns`) on a node whose clock was
    /// `old`: `None` for an unpaced stream or one faster than [`MIN_PERIOD_NS`].
    pub(super) fn after(old: Option<Self>, slot: &Slot, recv_ns: u64) -> Option<Self> {
        let period_ns = old.map_or(slot.period_ns, |c| c.period_ns);
        if !(MIN_PERIOD_NS..=super::MAX_PERIOD_NS).contains(&period_ns) {
            return None;
        }
        match super::usable_send_ns(slot, recv_ns) {
            Some(t) => Some(Self {
                last_send_ns: t.max(old.map_or(0, |c| c.last_send_ns)),
                period_ns,
            }),
            None => old,
        }
    }
}

/// The farthest node `k` may advance with `slot` (received at `recv_ns`): `max_gap`, plus
/// the periods between the node's last send and this one's.
pub(super) fn gap_bound(
    max_gap: u32,
    clock: Option<StreamClock>,
    slot: &Slot,
    recv_ns: u64,
) -> u64 {
    let base = u64::from(max_gap);
    match (clock, super::usable_send_ns(slot, recv_ns)) {
        (Some(c), Some(now)) => {
            base.saturating_add(now.saturating_sub(c.last_send_ns) / c.period_ns)
        }
        _ => base,
    }
}
