//! The token bucket shared by `L` sensor nodes (seed 004, eqs. 16-18) and its combination
//! with each node's dynamic event trigger (eqs. 19-20).
//!
//! ```text
//! ξ_{m,t} = ξ_t / L                                          (16)
//! ξ_t     = min{ ξ_{t−1} + g − Σ_m β_{m,t} α_{m,t} c_m, b }   (17)
//! β_{m,t} = 1 if c_m ≤ ξ_{m,t}                                (18)
//! ȳ_{m,t} = y_{m,t} if α_{m,t} β_{m,t} = 1, else ȳ_{m,t−1}    (19)-(20)
//! ```
//!
//! Order within an instant (Algorithm 1, docs/design.md "Seed 004"): every node's grant β uses the
//! per-node allocation left by the *previous* instant's bucket update; the nodes decide;
//! then the bucket is updated once with everything that was sent. Tokens, rate, capacity and
//! costs are integers (the paper's `g`, `c_m`, `b` are), and `c_m ≤ ξ/L` is tested exactly as
//! `L c_m ≤ ξ`, so no rounding enters the protocol. Because every granted node costs at most
//! `ξ/L`, the level never goes below `g`.

use nalgebra::SVector;

use crate::protocol::event_trigger::{EventTrigger, TriggerOutcome};
use crate::{Error, Real, Result};

/// The shared bucket: level ξ, rate g, capacity b and the per-node costs c_m.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SharedTokenBucket<const L: usize> {
    level: u32,
    rate: u32,
    capacity: u32,
    costs: [u32; L],
}

impl<const L: usize> SharedTokenBucket<L> {
    /// `initial` tokens ξ₀ (≤ capacity), generation rate `g` per instant, capacity `b ≥ 1`,
    /// per-node transmission costs `c_m`. `L ≥ 1`.
    pub fn new(initial: u32, rate: u32, capacity: u32, costs: [u32; L]) -> Result<Self> {
        if L == 0 {
            return Err(Error::InvalidConfig {
                field: "nodes",
                reason: "a shared bucket needs at least one node",
            });
        }
        if capacity == 0 {
            return Err(Error::InvalidConfig {
                field: "capacity",
                reason: "must be at least one token",
            });
        }
        if initial > capacity {
            return Err(Error::InvalidConfig {
                field: "initial tokens",
                reason: "exceed the bucket capacity",
            });
        }
        // L·c_m and ξ + g must fit: keep everything far from u32::MAX.
        if costs.iter().any(|&c| c as u64 * L as u64 > u32::MAX as u64)
            || capacity as u64 + rate as u64 > u32::MAX as u64
        {
            return Err(Error::InvalidConfig {
                field: "token counts",
                reason: "too large for 32-bit token arithmetic",
            });
        }
        Ok(Self {
            level: initial,
            rate,
            capacity,
            costs,
        })
    }

    /// Current level ξ_t.
    #[inline]
    pub fn level(&self) -> u32 {
        self.level
    }

    /// Capacity b.
    #[inline]
    pub fn capacity(&self) -> u32 {
        self.capacity
    }

    /// The same bucket at level `level` (≤ capacity): what a receiver that learns the level
    /// from a packet ([`crate::protocol::bucket_mirror`]) resynchronises to. Unchanged on error.
    pub fn set_level(&mut self, level: u32) -> Result<()> {
        if level > self.capacity {
            return Err(Error::InvalidConfig {
                field: "token level",
                reason: "exceeds the bucket capacity",
            });
        }
        self.level = level;
        Ok(())
    }

    /// Per-node allocation ξ_t / L (eq. 16).
    #[inline]
    pub fn allocation<T: Real>(&self) -> T {
        T::lit(self.level as f64) / T::lit(L as f64)
    }

    /// β_m for every node (eq. 18) from the current allocation.
    #[must_use]
    pub fn grants(&self) -> [bool; L] {
        let mut g = [false; L];
        for m in 0..L {
            g[m] = share_covers(self.level, L, self.costs[m]);
        }
        g
    }

    /// Eq. (17) with the nodes that transmitted (`α β = 1`). Refuses a node that sent without
    /// a grant (the protocol was bypassed); nothing changes on error. Returns the new level.
    pub fn update(&mut self, sent: &[bool; L]) -> Result<u32> {
        let grants = self.grants();
        let mut spent: u64 = 0;
        for m in 0..L {
            if sent[m] {
                if !grants[m] {
                    return Err(Error::InvalidConfig {
                        field: "sent",
                        reason: "a node transmitted without a token grant",
                    });
                }
                spent += self.costs[m] as u64;
            }
        }
        // spent ≤ ξ because each granted cost is ≤ ξ/L.
        let next = (self.level as u64 + self.rate as u64 - spent).min(self.capacity as u64);
        self.level = next as u32;
        Ok(self.level)
    }
}

/// β_m (eq. 18) of one node of `nodes` sharing a bucket at `level` tokens: its share
/// ξ/L (eq. 16) covers its cost c_m, tested exactly as `L c_m ≤ ξ`. What a sensor node that
/// is told the shared level (and not the other nodes' decisions) decides by itself.
#[inline]
#[must_use]
pub fn share_covers(level: u32, nodes: usize, cost: u32) -> bool {
    u64::from(cost) * nodes as u64 <= u64::from(level)
}

/// One node's decision at one instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NodeDecision<T: Real> {
    /// α (eq. 15): the event-trigger condition held.
    pub triggered: bool,
    /// β (eq. 18): the node's allocation covered its cost.
    pub granted: bool,
    /// α β: the measurement was transmitted.
    pub sent: bool,
    /// η used in the condition.
    pub eta: T,
}

impl<T: Real> NodeDecision<T> {
    /// Fired but refused for lack of tokens.
    #[inline]
    pub fn blocked(&self) -> bool {
        self.triggered && !self.granted
    }
}

/// `L` event-triggered nodes sharing one token bucket (eqs. 11-20), run one instant at a time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriggeredBucketScheduler<T: Real, const NY: usize, const L: usize> {
    nodes: [EventTrigger<T, NY>; L],
    bucket: SharedTokenBucket<L>,
}

impl<T: Real, const NY: usize, const L: usize> TriggeredBucketScheduler<T, NY, L> {
    /// Combines the nodes' triggers with the shared bucket.
    pub fn new(nodes: [EventTrigger<T, NY>; L], bucket: SharedTokenBucket<L>) -> Self {
        Self { nodes, bucket }
    }

    /// The bucket.
    #[inline]
    pub fn bucket(&self) -> &SharedTokenBucket<L> {
        &self.bucket
    }

    /// Node `m`'s trigger.
    #[inline]
    pub fn node(&self, m: usize) -> Option<&EventTrigger<T, NY>> {
        self.nodes.get(m)
    }

    /// ȳ_m (eq. 19): the last measurement node `m` transmitted (τ before the first).
    #[inline]
    pub fn received(&self, m: usize) -> Option<&SVector<T, NY>> {
        self.nodes.get(m).map(|n| n.reference())
    }

    /// One instant: grants from the previous bucket level, every node's trigger, then the
    /// bucket update (17). All-or-nothing: on error nothing changes.
    pub fn step(&mut self, ys: &[SVector<T, NY>; L]) -> Result<[NodeDecision<T>; L]> {
        let grants = self.bucket.grants();
        let mut nodes = self.nodes;
        let mut sent = [false; L];
        let mut out = [NodeDecision {
            triggered: false,
            granted: false,
            sent: false,
            eta: T::zero(),
        }; L];
        for m in 0..L {
            let TriggerOutcome {
                triggered,
                sent: s,
                eta,
                ..
            } = nodes[m].step(&ys[m], grants[m])?;
            sent[m] = s;
            out[m] = NodeDecision {
                triggered,
                granted: grants[m],
                sent: s,
                eta,
            };
        }
        let mut bucket = self.bucket;
        bucket.update(&sent)?;
        self.nodes = nodes;
        self.bucket = bucket;
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::event_trigger::EventTriggerConfig;
    use nalgebra::vector;

    #[test]
    fn bucket_sequence_by_hand() {
        // The paper's bucket: ξ₀ = 10, g = 5, b = 30, c = 3 for 3 nodes (grant iff ξ ≥ 9).
        let mut b = SharedTokenBucket::<3>::new(10, 5, 30, [3, 3, 3]).unwrap();
        assert_eq!(b.grants(), [true; 3]);
        assert!((b.allocation::<f64>() - 10.0 / 3.0).abs() < 1e-15);
        // All three send: 10 + 5 − 9 = 6.
        assert_eq!(b.update(&[true, true, true]).unwrap(), 6);
        assert_eq!(b.grants(), [false; 3]);
        // Nobody may send: 6 + 5 = 11.
        assert_eq!(b.update(&[false; 3]).unwrap(), 11);
        assert_eq!(b.grants(), [true; 3]);
        // One sends: 11 + 5 − 3 = 13; then idle: 18, 23, 28, 30 (capped), 30.
        assert_eq!(b.update(&[false, true, false]).unwrap(), 13);
        for want in [18, 23, 28, 30, 30] {
            assert_eq!(b.update(&[false; 3]).unwrap(), want);
        }
        // Sending without a grant is refused and changes nothing.
        let mut low = SharedTokenBucket::<3>::new(8, 5, 30, [3, 3, 3]).unwrap();
        assert_eq!(
            low.update(&[true, false, false]),
            Err(Error::InvalidConfig {
                field: "sent",
                reason: "a node transmitted without a token grant"
            })
        );
        assert_eq!(low.level(), 8);
        // Unequal costs: c = [1, 4] with L = 2 and ξ = 5: β = [2 ≤ 5, 8 ≤ 5] = [1, 0].
        let b2 = SharedTokenBucket::<2>::new(5, 1, 10, [1, 4]).unwrap();
        assert_eq!(b2.grants(), [true, false]);
    }

    #[test]
    fn bad_bucket_configs() {
        assert!(SharedTokenBucket::<3>::new(31, 5, 30, [3; 3]).is_err());
        assert!(SharedTokenBucket::<3>::new(0, 5, 0, [3; 3]).is_err());
        assert!(SharedTokenBucket::<0>::new(0, 5, 10, []).is_err());
        assert!(SharedTokenBucket::<2>::new(0, 5, 10, [u32::MAX, 1]).is_err());
    }

    #[test]
    fn scheduler_follows_algorithm_order() {
        // Triggers that always fire (σ = 0, η₀ = 0 → condition −‖ε‖ ≤ 0), bucket as in the
        // paper: the grant at t uses the level after t − 1, the update uses all nodes.
        let cfg = EventTriggerConfig::new(0.0, 5.0, 0.5, 0.0).unwrap();
        let node = EventTrigger::<f64, 1>::new(cfg, vector![0.0]).unwrap();
        let bucket = SharedTokenBucket::<3>::new(10, 5, 30, [3, 3, 3]).unwrap();
        let mut s = TriggeredBucketScheduler::new([node; 3], bucket);
        let ys = [vector![1.0], vector![2.0], vector![3.0]];
        let d = s.step(&ys).unwrap();
        assert!(d.iter().all(|d| d.triggered && d.granted && d.sent));
        assert_eq!(s.bucket().level(), 6);
        assert_eq!(s.received(2), Some(&vector![3.0]));
        let ys2 = [vector![1.5], vector![2.5], vector![3.5]];
        let d = s.step(&ys2).unwrap();
        assert!(d.iter().all(|d| d.blocked() && !d.sent));
        assert_eq!(s.bucket().level(), 11);
        // Blocked: the receivers still hold the first measurements.
        assert_eq!(s.received(0), Some(&vector![1.0]));
        // A NaN at one node rolls back the whole instant.
        let before = s;
        assert!(s
            .step(&[vector![0.0], vector![f64::NAN], vector![0.0]])
            .is_err());
        assert_eq!(s, before);
    }
}
