//! The token-bucket communication protocol of seed 003, eqs. (2)-(3), as the state machine a
//! sensor node runs.
//!
//! ```text
//! μ_k     = min{z_k + a, S} − b                       (transmission judgment variable)
//! z_{k+1} = min{z_k + a, S} − 1{μ_k ≥ 0} b            (bucket level)
//! ȳ_k     = 1{μ_k ≥ 0} y_k                            (what the estimator receives, (3))
//! ```
//!
//! `a` tokens arrive per instant (overflow above the capacity `S` is discarded), a transmission
//! costs `b` tokens and happens iff the bucket, after the arrival, holds at least `b`. The
//! decision does not depend on the data, so the transmission pattern is a deterministic
//! sequence fixed by `(a, b, S, z₀)`; in steady state a fraction `a/b` of the instants transmit.
//!
//! ```
//! use estimator_core::protocol::token_bucket::{TokenBucket, TokenBucketConfig};
//! // Seed 003, section IV: a = 2, b = 3, S = 10, z₀ = 6.
//! let mut tb = TokenBucket::new(TokenBucketConfig::new(2, 3, 10, 6)?);
//! let sent: [bool; 9] = core::array::from_fn(|_| tb.step().transmit);
//! assert_eq!(sent, [true, true, true, true, true, true, false, true, true]);
//! # Ok::<(), estimator_core::Error>(())
//! ```

use crate::{Error, Result};

/// Validated parameters of the token bucket (seed 003, section II-B).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TokenBucketConfig {
    a: u32,
    b: u32,
    s: u32,
    z0: u32,
}

impl TokenBucketConfig {
    /// Token rate `a ≥ 1`, transmission cost `b ≥ a`, capacity `S ≥ b`, initial level
    /// `0 ≤ z₀ ≤ S` (the ranges stated under eq. (2)).
    pub fn new(a: u32, b: u32, s: u32, z0: u32) -> Result<Self> {
        if a < 1 {
            return Err(Error::InvalidConfig {
                field: "a",
                reason: "token rate a must be at least 1 (seed 003, II-B)",
            });
        }
        if b < a {
            return Err(Error::InvalidConfig {
                field: "b",
                reason: "transmission cost b must be at least the token rate a (seed 003, II-B)",
            });
        }
        if s < b {
            return Err(Error::InvalidConfig {
                field: "S",
                reason:
                    "bucket capacity S must be at least the transmission cost b (seed 003, II-B)",
            });
        }
        if z0 > s {
            return Err(Error::InvalidConfig {
                field: "z0",
                reason: "initial bucket level z0 must lie in [0, S] (seed 003, eq. 2)",
            });
        }
        Ok(Self { a, b, s, z0 })
    }

    /// Token rate `a`.
    #[inline]
    pub fn rate(&self) -> u32 {
        self.a
    }
    /// Transmission cost `b`.
    #[inline]
    pub fn cost(&self) -> u32 {
        self.b
    }
    /// Capacity `S`.
    #[inline]
    pub fn capacity(&self) -> u32 {
        self.s
    }
    /// Initial level `z₀`.
    #[inline]
    pub fn initial_level(&self) -> u32 {
        self.z0
    }
}

/// One instant's decision of the bucket.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TokenDecision {
    /// `μ_k = min{z_k + a, S} − b`.
    pub mu: i64,
    /// `1{μ_k ≥ 0}`: the measurement of this instant is transmitted.
    pub transmit: bool,
    /// Bucket level `z_k` before the instant.
    pub level_before: u32,
    /// Bucket level `z_{k+1}` after the instant.
    pub level_after: u32,
}

/// The bucket's running state `z_k`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TokenBucket {
    cfg: TokenBucketConfig,
    z: u32,
}

impl TokenBucket {
    /// A bucket at its initial level `z₀`.
    pub fn new(cfg: TokenBucketConfig) -> Self {
        Self { cfg, z: cfg.z0 }
    }

    /// The configuration.
    #[inline]
    pub fn config(&self) -> &TokenBucketConfig {
        &self.cfg
    }

    /// Current level `z_k`.
    #[inline]
    pub fn level(&self) -> u32 {
        self.z
    }

    /// What instant `k` would decide, without changing the bucket.
    #[must_use]
    pub fn peek(&self) -> TokenDecision {
        // u64 arithmetic: z + a cannot overflow for any u32 inputs.
        let filled = (u64::from(self.z) + u64::from(self.cfg.a)).min(u64::from(self.cfg.s));
        let mu = filled as i64 - i64::from(self.cfg.b);
        let transmit = mu >= 0;
        let after = if transmit {
            filled - u64::from(self.cfg.b)
        } else {
            filled
        };
        TokenDecision {
            mu,
            transmit,
            level_before: self.z,
            // filled ≤ S ≤ u32::MAX.
            level_after: after as u32,
        }
    }

    /// Runs eq. (2) for one instant: decides whether this instant's measurement is sent and
    /// moves the bucket to `z_{k+1}`.
    pub fn step(&mut self) -> TokenDecision {
        let d = self.peek();
        self.z = d.level_after;
        d
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hand_computed_sequence_a2_b3_s10_z6() {
        // Hand computation of eq. (2) with a = 2, b = 3, S = 10, z₀ = 6:
        //  k  z_k  min(z+a,S)  μ_k  sent  z_{k+1}
        //  0   6       8        5    1      5
        //  1   5       7        4    1      4
        //  2   4       6        3    1      3
        //  3   3       5        2    1      2
        //  4   2       4        1    1      1
        //  5   1       3        0    1      0
        //  6   0       2       −1    0      2
        //  7   2       4        1    1      1
        //  8   1       3        0    1      0
        //  9   0       2       −1    0      2
        // and from k = 6 on the pattern (no, yes, yes) repeats with period 3.
        let expected: [(u32, i64, bool, u32); 10] = [
            (6, 5, true, 5),
            (5, 4, true, 4),
            (4, 3, true, 3),
            (3, 2, true, 2),
            (2, 1, true, 1),
            (1, 0, true, 0),
            (0, -1, false, 2),
            (2, 1, true, 1),
            (1, 0, true, 0),
            (0, -1, false, 2),
        ];
        let mut tb = TokenBucket::new(TokenBucketConfig::new(2, 3, 10, 6).unwrap());
        for (k, &(z, mu, sent, z_next)) in expected.iter().enumerate() {
            let d = tb.step();
            assert_eq!(
                (d.level_before, d.mu, d.transmit, d.level_after),
                (z, mu, sent, z_next),
                "instant {k}"
            );
        }
        // Periodic tail: exactly 2 of every 3 instants transmit (rate a/b).
        let sent = (0..300).filter(|_| tb.step().transmit).count();
        assert_eq!(sent, 200);
    }

    #[test]
    fn capacity_discards_overflow() {
        // a = b: every instant transmits and a full bucket stays full.
        let mut tb = TokenBucket::new(TokenBucketConfig::new(4, 4, 10, 10).unwrap());
        for _ in 0..20 {
            let d = tb.step();
            assert!(d.transmit);
            assert_eq!(d.mu, 6);
            assert_eq!(d.level_after, 6);
            assert_eq!(tb.step().level_after, 6);
        }
        // Empty bucket, a < b: first transmission when z + a ≥ b.
        let mut tb = TokenBucket::new(TokenBucketConfig::new(1, 3, 3, 0).unwrap());
        let pattern: [bool; 6] = core::array::from_fn(|_| tb.step().transmit);
        assert_eq!(pattern, [false, false, true, false, false, true]);
    }

    #[test]
    fn peek_does_not_move_the_bucket() {
        let tb = TokenBucket::new(TokenBucketConfig::new(2, 3, 10, 6).unwrap());
        let d = tb.peek();
        assert_eq!(tb.level(), 6);
        assert_eq!(d.level_after, 5);
    }

    #[test]
    fn bad_parameters_rejected_with_named_reason() {
        let field = |r: Result<TokenBucketConfig>| match r {
            Err(Error::InvalidConfig { field, .. }) => field,
            other => panic!("expected InvalidConfig, got {other:?}"),
        };
        assert_eq!(field(TokenBucketConfig::new(0, 3, 10, 6)), "a");
        assert_eq!(field(TokenBucketConfig::new(4, 3, 10, 6)), "b");
        assert_eq!(field(TokenBucketConfig::new(2, 3, 2, 0)), "S");
        assert_eq!(field(TokenBucketConfig::new(2, 3, 10, 11)), "z0");
        assert!(TokenBucketConfig::new(1, 1, 1, 0).is_ok());
    }
}
