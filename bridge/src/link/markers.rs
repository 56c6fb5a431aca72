//! The sensor side's END/ABORT markers, put on the network again until the estimator side
//! acknowledges them (docs/bridge.md, "The END of a stream").
//!
//! A node's marker is the only message that tells the far side its stream is over: lost, the
//! runner waits `--stall-limit` for instants that never come. Copies put back to back do not
//! help on a link that reorders: zenoh's UDP transport drops a frame that arrives after a
//! later one, and a later node's marker can overtake every copy of an earlier one. So each
//! marker is repeated, one at a time and spaced apart, until the estimator side echoes it on
//! `<key>/acks` or [`RESEND_FOR`] has passed since it was first put.

use estpipe_wire::{net, Slot, MAX_NODES, SLOT_DATA};
use std::time::{Duration, Instant};

/// Spacing of the re-sends (of any marker): a re-send alone in its window is overtaken only
/// by a link whose delays spread more than this, and then the next round may get through.
pub const RESEND_EVERY: Duration = Duration::from_millis(20);

/// How long a marker is repeated when no acknowledgement comes (an estimator side of an
/// older version, or a link that takes nothing back): the sensor side gives up and counts it.
pub const RESEND_FOR: Duration = Duration::from_secs(5);

/// One node's marker, waiting for its acknowledgement.
#[derive(Clone, Copy, Debug)]
struct Pending {
    stream_id: u64,
    k: u32,
    kind: u32,
    msg: [u8; net::SLOT_MESSAGE_LEN],
    first: Instant,
    last: Instant,
}

/// What a message on `<key>/acks` was.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ack {
    /// It acknowledged a marker still being repeated: the repeats stop.
    Taken,
    /// A well-formed acknowledgement of nothing pending (a second ack of the same marker, or
    /// one naming a marker not put, or not yet put): nothing changes, not even for a marker
    /// of the same name put later. Counted in [`Markers::stale`].
    Stale,
}

/// The markers put on the network and not yet acknowledged: at most one per node (a node's
/// newer marker replaces its older one), so the state is bounded by `MAX_NODES`.
#[derive(Debug)]
pub struct Markers {
    pending: [Option<Pending>; MAX_NODES],
    last_resend: Option<Instant>,
    /// Markers acknowledged.
    pub acked: u64,
    /// Markers given up on after [`RESEND_FOR`] without an acknowledgement.
    pub unacked: u64,
    /// Well-formed acknowledgements of no pending marker ([`Ack::Stale`]).
    pub stale: u64,
}

impl Default for Markers {
    fn default() -> Self {
        Self {
            pending: [None; MAX_NODES],
            last_resend: None,
            acked: 0,
            unacked: 0,
            stale: 0,
        }
    }
}

impl Markers {
    /// `s` (a checked END/ABORT slot, encoded as `msg`) was put on the network at `now`.
    pub fn put(&mut self, s: &Slot, msg: &[u8; net::SLOT_MESSAGE_LEN], now: Instant) {
        debug_assert!(s.kind != SLOT_DATA);
        let m = usize::from(s.node).min(MAX_NODES - 1);
        if self.pending[m].is_some() {
            // A newer marker of the same node: the older one's stream is over for the far
            // side either way.
            self.unacked += 1;
        }
        self.pending[m] = Some(Pending {
            stream_id: s.stream_id,
            k: s.k,
            kind: s.kind,
            msg: *msg,
            first: now,
            last: now,
        });
    }

    /// A message that came on `<key>/acks`: the estimator side echoes each marker it took (or
    /// recognised as a repeat) as the same bytes. Anything else is refused with the wire
    /// contract's reason (or `ack_not_marker`), never trusted.
    pub fn ack(&mut self, bytes: &[u8]) -> Result<Ack, &'static str> {
        let (_, s) = net::decode_slot(bytes).map_err(|e| e.reason())?;
        if s.kind == SLOT_DATA {
            return Err("ack_not_marker");
        }
        let m = usize::from(s.node).min(MAX_NODES - 1);
        match self.pending[m] {
            Some(p) if p.stream_id == s.stream_id && p.k == s.k && p.kind == s.kind => {
                self.pending[m] = None;
                self.acked += 1;
                Ok(Ack::Taken)
            }
            _ => {
                self.stale += 1;
                Ok(Ack::Stale)
            }
        }
    }

    /// The marker to put again now, if one is due: at most one per [`RESEND_EVERY`], the one
    /// repeated longest ago, so that each node's marker is in turn the last message on the
    /// link. Markers past [`RESEND_FOR`] are dropped and counted in [`Self::unacked`].
    pub fn due(&mut self, now: Instant) -> Option<[u8; net::SLOT_MESSAGE_LEN]> {
        for p in &mut self.pending {
            if p.is_some_and(|p| now.duration_since(p.first) > RESEND_FOR) {
                *p = None;
                self.unacked += 1;
            }
        }
        if self
            .last_resend
            .is_some_and(|t| now.duration_since(t) < RESEND_EVERY)
        {
            return None;
        }
        let next = self
            .pending
            .iter_mut()
            .flatten()
            .filter(|p| now.duration_since(p.last) >= RESEND_EVERY)
            .min_by_key(|p| p.last)?;
        next.last = now;
        self.last_resend = Some(now);
        Some(next.msg)
    }

    /// Whether every marker put was acknowledged or given up on.
    pub fn settled(&self) -> bool {
        self.pending.iter().all(Option::is_none)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use estpipe_wire::{StreamHeader, SLOT_ABORT, SLOT_END};

    fn header() -> StreamHeader {
        StreamHeader::new("tobit-fusion", 3, 2, &[1, 1, 1], 0x1234_5678_9abc_def0)
    }

    fn marker(node: u8, k: u32, kind: u32) -> (Slot, [u8; net::SLOT_MESSAGE_LEN]) {
        let s = if kind == SLOT_DATA {
            Slot::data(k, node, 3, 7)
        } else {
            Slot::marker(kind, k, node, 3, 7, 0)
        };
        (s, net::encode_slot(&header(), &s))
    }

    #[test]
    fn each_pending_marker_is_repeated_in_turn_until_acknowledged() {
        let t0 = Instant::now();
        let mut m = Markers::default();
        let (a, ma) = marker(0, 200, SLOT_END);
        let (b, mb) = marker(1, 200, SLOT_END);
        m.put(&a, &ma, t0);
        m.put(&b, &mb, t0);
        assert_eq!(m.due(t0), None, "nothing before RESEND_EVERY");
        let t1 = t0 + RESEND_EVERY;
        let first = m.due(t1).unwrap();
        assert_eq!(m.due(t1), None, "one re-send per RESEND_EVERY");
        let second = m.due(t1 + RESEND_EVERY).unwrap();
        assert_ne!(first, second, "the other node's marker comes next");
        assert_eq!(m.ack(&ma), Ok(Ack::Taken));
        assert_eq!(m.ack(&ma), Ok(Ack::Stale));
        for i in 2..6 {
            assert_eq!(m.due(t1 + RESEND_EVERY * i), Some(mb));
        }
        assert_eq!(m.ack(&mb), Ok(Ack::Taken));
        assert!(m.settled());
        assert_eq!(m.due(t1 + RESEND_EVERY * 7), None);
        assert_eq!((m.acked, m.unacked), (2, 0));
    }

    #[test]
    fn an_ack_must_name_the_same_marker() {
        let t0 = Instant::now();
        let mut m = Markers::default();
        let (a, ma) = marker(2, 50, SLOT_END);
        m.put(&a, &ma, t0);
        // Another instant, another kind, another stream, a data slot, garbage: none stops it.
        assert_eq!(m.ack(&marker(2, 49, SLOT_END).1), Ok(Ack::Stale));
        assert_eq!(m.ack(&marker(2, 50, SLOT_ABORT).1), Ok(Ack::Stale));
        let mut other = a;
        other.stream_id = 8;
        assert_eq!(m.ack(&net::encode_slot(&header(), &other)), Ok(Ack::Stale));
        assert_eq!(m.ack(&marker(2, 50, SLOT_DATA).1), Err("ack_not_marker"));
        assert!(m.ack(&ma[..10]).is_err());
        assert!(!m.settled());
        assert_eq!(m.ack(&ma), Ok(Ack::Taken));
    }

    #[test]
    fn an_ack_that_comes_before_its_marker_does_not_cancel_it() {
        // A peer that read the stream id off `<key>/slots` can forge the echo of a node's
        // END before the END is put: it acknowledges nothing, and the END, once put, is
        // repeated until its own echo comes.
        let t0 = Instant::now();
        let mut m = Markers::default();
        let (a, ma) = marker(1, 300, SLOT_END);
        for _ in 0..1000 {
            assert_eq!(m.ack(&ma), Ok(Ack::Stale));
        }
        assert!(m.settled());
        m.put(&a, &ma, t0);
        assert!(!m.settled());
        for i in 1..5 {
            assert_eq!(m.due(t0 + RESEND_EVERY * i), Some(ma), "repeat {i}");
        }
        assert_eq!(m.ack(&ma), Ok(Ack::Taken));
        assert!(m.settled());
        assert_eq!((m.acked, m.unacked, m.stale), (1, 0, 1000));
    }

    #[test]
    fn an_unacknowledged_marker_is_given_up_after_resend_for() {
        let t0 = Instant::now();
        let mut m = Markers::default();
        let (a, ma) = marker(0, 10, SLOT_ABORT);
        m.put(&a, &ma, t0);
        let mut puts = 0;
        let mut t = t0;
        while t <= t0 + RESEND_FOR + RESEND_EVERY * 2 {
            puts += usize::from(m.due(t).is_some());
            t += Duration::from_millis(1);
        }
        assert!(m.settled());
        assert_eq!(m.unacked, 1);
        let most = (RESEND_FOR.as_millis() / RESEND_EVERY.as_millis()) as usize;
        assert!(puts <= most && puts >= most - 1, "{puts} re-sends");
    }
}
