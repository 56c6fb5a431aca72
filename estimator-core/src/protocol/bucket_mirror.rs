//! The receiver's mirror of the shared token bucket (seed 004, eqs. 16-18): which silences
//! are "the trigger held" and which are "the bucket had no token for it"
//! (docs/tobit-fusion.md, "Silence that speaks").
//!
//! The bucket's level changes only with transmissions (17), and the receiver sees every
//! transmission that is not lost on the way, so it can run the bucket itself: at instant t
//! every node's grant β_{m,t} (18) follows from the level ξ_{t−1}, and a node that sent nothing
//! although granted did not fire (α_{m,t} = 0, eq. 15): its measurement lies in the trigger's
//! silence set. A silent node without a grant may have fired: its silence says nothing.
//!
//! Where the mirror cannot follow, it knows it: a packet lost in transport may have been a
//! transmission that spent tokens, so after a lost packet the level is *unknown* and no
//! silence counts as held, until a delivered packet reports the level its grant used (wire
//! version 6: the slot's `tokens`, docs/wire.md). A reported level resynchronises the mirror;
//! one that differs from a known mirror level is counted (a mismatch: the mirror had been
//! wrong), and one that is impossible (above the capacity, or too low for the grant of a node
//! that sent) is counted and ignored. A delivered packet the mirror's level would not have
//! granted is a mismatch too: the level becomes unknown.

use super::shared_token_bucket::SharedTokenBucket;

/// What one node's packet of an instant says about the bucket.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sent {
    /// Delivered: the node transmitted (α β = 1).
    Yes,
    /// Nothing arrived and nothing was lost in transport: the node did not transmit.
    No,
    /// Lost in transport: it may or may not have transmitted.
    Unknown,
}

/// Counts of what the mirror met.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MirrorCounts {
    /// Instants whose level was unknown (no silence was read as held).
    pub unknown: u32,
    /// Reported levels that moved an unknown mirror back to a known level.
    pub resyncs: u32,
    /// A reported level that differed from the mirror's known one, or a delivered packet the
    /// mirror would not have granted.
    pub mismatches: u32,
    /// Reported levels refused as impossible (above the capacity, or below a sender's grant).
    pub refused: u32,
}

/// The receiver's copy of the shared bucket; `None` while its level is unknown.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BucketMirror<const L: usize> {
    bucket: SharedTokenBucket<L>,
    known: bool,
    counts: MirrorCounts,
}

impl<const L: usize> BucketMirror<L> {
    /// Starts from the bucket's configuration and initial level ξ₀ (known: the receiver
    /// starts with the nodes).
    pub fn new(bucket: SharedTokenBucket<L>) -> Self {
        Self {
            bucket,
            known: true,
            counts: MirrorCounts::default(),
        }
    }

    /// The level ξ_{t−1} the next instant's grants use, if known.
    #[inline]
    pub fn level(&self) -> Option<u32> {
        self.known.then(|| self.bucket.level())
    }

    /// What the mirror met so far.
    #[inline]
    pub fn counts(&self) -> MirrorCounts {
        self.counts
    }

    /// One instant: every node's packet (`sent`) and the level a delivered packet of this
    /// instant reported (`reported`, ξ_{t−1}; every sender of an instant reports the same).
    /// Returns, per node, whether its silence is the trigger holding (granted and silent).
    /// Advances the level by (17), or makes it unknown when a packet was lost.
    pub fn step(&mut self, sent: &[Sent; L], reported: Option<u32>) -> [bool; L] {
        if let Some(level) = reported {
            let granted_all = |b: &SharedTokenBucket<L>| {
                let g = b.grants();
                (0..L).all(|m| sent[m] != Sent::Yes || g[m])
            };
            let mut b = self.bucket;
            if b.set_level(level).is_ok() && granted_all(&b) {
                if !self.known {
                    self.counts.resyncs += 1;
                } else if level != self.bucket.level() {
                    self.counts.mismatches += 1;
                }
                self.bucket = b;
                self.known = true;
            } else {
                self.counts.refused += 1;
            }
        }
        let mut held = [false; L];
        if !self.known {
            self.counts.unknown += 1;
            return held;
        }
        let grants = self.bucket.grants();
        if (0..L).any(|m| sent[m] == Sent::Yes && !grants[m]) {
            // A transmission the mirror's level forbids: the mirror was wrong.
            self.counts.mismatches += 1;
            self.counts.unknown += 1;
            self.known = false;
            return held;
        }
        for m in 0..L {
            held[m] = sent[m] == Sent::No && grants[m];
        }
        if sent.contains(&Sent::Unknown) {
            self.known = false;
        } else {
            let s = sent.map(|s| s == Sent::Yes);
            // Cannot fail: every sender was granted (checked above).
            self.known = self.bucket.update(&s).is_ok();
        }
        held
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::event_trigger::{EventTrigger, EventTriggerConfig};
    use crate::protocol::shared_token_bucket::TriggeredBucketScheduler;
    use nalgebra::vector;

    #[test]
    fn mirror_follows_the_bucket_and_tells_held_from_blocked() {
        // The paper's bucket and three nodes with always-firing or never-firing triggers:
        // replay the scheduler and check the mirror's verdict against the truth at every
        // instant.
        let fire = EventTriggerConfig::new(0.0, 5.0, 0.5, 0.0).unwrap();
        let quiet = EventTriggerConfig::new(1e9, 5.0, 0.5, 0.0).unwrap();
        let bucket = SharedTokenBucket::<3>::new(10, 5, 30, [3, 3, 3]).unwrap();
        let mut mirror = BucketMirror::new(bucket);
        let mut truth = TriggeredBucketScheduler::new(
            [
                EventTrigger::new(fire, vector![0.0]).unwrap(),
                EventTrigger::new(fire, vector![0.0]).unwrap(),
                EventTrigger::new(quiet, vector![0.0]).unwrap(),
            ],
            bucket,
        );
        let (mut held_seen, mut blocked_seen) = (0, 0);
        for t in 0..40 {
            let y = t as f64 + 1.0;
            let d = truth.step(&[vector![y], vector![-y], vector![y]]).unwrap();
            let sent = d.map(|d| if d.sent { Sent::Yes } else { Sent::No });
            let held = mirror.step(&sent, None);
            for m in 0..3 {
                // Held iff silent and granted; then the trigger did not fire (19).
                assert_eq!(held[m], !d[m].sent && d[m].granted, "t = {t}, node {m}");
                assert!(!held[m] || !d[m].triggered);
                held_seen += u32::from(held[m]);
                blocked_seen += u32::from(d[m].blocked());
            }
            assert_eq!(mirror.level(), Some(truth.bucket().level()));
        }
        assert!(held_seen > 0 && blocked_seen > 0);
        assert_eq!(mirror.counts(), MirrorCounts::default());
    }

    #[test]
    fn a_lost_packet_makes_the_level_unknown_until_a_report() {
        let bucket = SharedTokenBucket::<2>::new(10, 5, 30, [3, 3]).unwrap();
        let mut m = BucketMirror::new(bucket);
        assert_eq!(m.step(&[Sent::No, Sent::Unknown], None), [true, false]);
        assert_eq!(m.level(), None);
        // Unknown: no silence is held.
        assert_eq!(m.step(&[Sent::No, Sent::No], None), [false, false]);
        assert_eq!(m.counts().unknown, 1);
        // A delivered packet reports ξ = 12 (granted: 2·3 ≤ 12): resynchronised, and the
        // other node's silence is held again.
        assert_eq!(m.step(&[Sent::Yes, Sent::No], Some(12)), [false, true]);
        assert_eq!(m.level(), Some(14));
        assert_eq!(m.counts().resyncs, 1);
        // A report that differs from a known level is a mismatch; one above the capacity or
        // too low for the sender's grant is refused and changes nothing.
        m.step(&[Sent::Yes, Sent::No], Some(20));
        assert_eq!(m.counts().mismatches, 1);
        assert_eq!(m.level(), Some(22));
        let before = m.level();
        m.step(&[Sent::No, Sent::No], Some(31));
        assert_eq!(m.counts().refused, 1);
        assert_eq!(m.level(), before.map(|l| (l + 5).min(30)));
        m.step(&[Sent::Yes, Sent::No], Some(5));
        assert_eq!(m.counts().refused, 2);
    }

    #[test]
    fn a_send_the_mirror_forbids_makes_it_unknown() {
        let bucket = SharedTokenBucket::<2>::new(4, 1, 30, [3, 3]).unwrap();
        let mut m = BucketMirror::new(bucket);
        // Grants need ξ ≥ 6; a delivered packet at ξ = 4 means the mirror is wrong.
        assert_eq!(m.step(&[Sent::Yes, Sent::No], None), [false, false]);
        assert_eq!(m.level(), None);
        assert_eq!(m.counts().mismatches, 1);
    }
}
