//! Which restarts the loop believes: a new stream at `k = 1` on a node resets every
//! estimator (docs/wire.md, "Restarts"), so one well-formed slot from any local process
//! ended a healthy run (docs/security.md, "What the runner assumes"). A real restart comes
//! from the publisher that owns the node's stream (a relay forwarding its sensor's restart),
//! after that publisher is gone (a crashed process replaced), or after the stream went
//! silent (a stopped publisher replaced). A new stream from another publisher while the
//! owner is registered on the slot service and its stream still flowing is a second
//! publisher on the node, forged or misconfigured: it is counted instead
//! ([`Skipped::foreign_restart`](super::assemble::Skipped::foreign_restart)) and the stream
//! goes on.

use crate::transport::Transport;
use estpipe_wire::MAX_NODES;
use iceoryx2::prelude::*;

/// Dead nodes are cleaned up for a restart check at most this often: a flood of forged
/// restarts costs one directory scan per interval, not one per slot.
const CLEANUP_EVERY_NS: u64 = 10_000_000;

/// The owner of one node's stream.
#[derive(Clone, Copy, Debug)]
struct Owner {
    /// The stream id.
    sid: u64,
    /// `UniquePublisherId` value of the publisher of the stream's first slot.
    publisher: u128,
    /// When the stream's last slot arrived.
    last_ns: u64,
}

/// Per node, the stream the loop follows and the publisher whose slot started it.
#[derive(Debug, Default)]
pub(super) struct StreamOwners {
    owner: [Option<Owner>; MAX_NODES],
    /// When dead nodes were last cleaned up for a check.
    last_cleanup_ns: Option<u64>,
}

impl StreamOwners {
    /// A slot of stream `slot_sid` from publisher `origin` arrived at `recv_ns` on node `m`,
    /// whose stream is now `current` (the assembler's): a stream with no owner yet is owned
    /// by `origin`, the publisher of the slot that made it the node's stream.
    #[inline]
    pub(super) fn note(
        &mut self,
        m: usize,
        current: Option<u64>,
        slot_sid: u64,
        origin: u128,
        recv_ns: u64,
    ) {
        let (Some(sid), Some(o)) = (current, self.owner.get_mut(m)) else {
            return;
        };
        match o {
            Some(o) if o.sid == sid => {
                if slot_sid == sid {
                    o.last_ns = recv_ns;
                }
            }
            _ => {
                *o = Some(Owner {
                    sid,
                    publisher: origin,
                    last_ns: recv_ns,
                })
            }
        }
    }

    /// Whether a new stream on node `m` (following `current`) from publisher `origin`,
    /// arriving at `now`, is a restart: the node has no stream (the run waits for a
    /// restart), the stream's owner sent it, the stream was silent for more than `quiet_ns`
    /// (the run's data deadline), or its owner is no longer registered on the slot service
    /// once dead nodes are cleaned up.
    #[cold]
    pub(super) fn believe(
        &mut self,
        m: usize,
        current: Option<u64>,
        origin: u128,
        t: &Transport,
        now: u64,
        quiet_ns: u64,
    ) -> bool {
        let Some(o) = self.owner.get(m).copied().flatten() else {
            return true;
        };
        if current != Some(o.sid)
            || o.publisher == origin
            || now.saturating_sub(o.last_ns) > quiet_ns
            || !registered(t, o.publisher)
        {
            return true;
        }
        // Registered: alive, or dead and not yet cleaned up (a SIGKILLed publisher's port
        // stays until someone cleans up its node).
        if self
            .last_cleanup_ns
            .is_some_and(|t0| now.saturating_sub(t0) < CLEANUP_EVERY_NS)
        {
            return false;
        }
        self.last_cleanup_ns = Some(now);
        let _ = t.node.try_cleanup_dead_nodes();
        !registered(t, o.publisher)
    }
}

/// Whether publisher `id` is registered on the slot service.
fn registered(t: &Transport, id: u128) -> bool {
    let mut found = false;
    t.slots.dynamic_config().list_publishers(|p| {
        if p.publisher_id.value() == id {
            found = true;
            CallbackProgression::Stop
        } else {
            CallbackProgression::Continue
        }
    });
    found
}
