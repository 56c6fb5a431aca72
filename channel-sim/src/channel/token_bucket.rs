//! The token-bucket channel stage of seed 003 (eqs. 2-3): each sensor node runs
//! `estimator_core::protocol::token_bucket::TokenBucket` (the same state machine a real node
//! would run) and a packet is withheld, flagged [`FLAG_TOKEN_BLOCKED`], when `μ_k < 0`.
//!
//! The bucket takes its first decision, from the level `z0`, at the first instant it is
//! applied to. Behind seed 003's plant, which measures at k = 0, that is k = 0, as in the
//! paper (eq. (2) decides at k = 0: μ₀ = min{z₀ + a, S} − b); behind a plant without a
//! measurement at k = 0 (a TOML scenario's linear plant) it is k = 1. The decision does not
//! depend on the data or on randomness: no random numbers are drawn.

use std::any::Any;

use estimator_core::protocol::token_bucket::{TokenBucket, TokenBucketConfig};

use super::{drop_packet, Stage, StageSpec};
use crate::rng::SimRng;
use crate::sim::{Observation, FLAG_TOKEN_BLOCKED};

pub use estpipe_spec::channel::TokenBucket as TokenBucketStage;

impl StageSpec for TokenBucketStage {
    fn knowledge(&self, k: &mut estpipe_spec::channel::ChannelKnowledge) {
        k.token_bucket = Some(*self);
    }
    fn name(&self) -> &'static str {
        "token-bucket"
    }
    fn build(&self, nodes: usize) -> Box<dyn Stage> {
        // Validated when the scenario was built; an invalid spec here is a programming error
        // upstream, so fall back to a bucket that never transmits rather than panic.
        let cfg = TokenBucketConfig::new(self.a, self.b, self.s, self.z0)
            .or_else(|_| TokenBucketConfig::new(1, u32::MAX, u32::MAX, 0))
            .expect("a = 1, b = S = u32::MAX, z0 = 0 is valid");
        Box::new(TokenBucketRun {
            buckets: vec![TokenBucket::new(cfg); nodes],
        })
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

struct TokenBucketRun {
    buckets: Vec<TokenBucket>,
}

impl Stage for TokenBucketRun {
    fn apply(&mut self, _k: u32, _truth: &[f64], obs: &mut [Observation], _rng: &mut SimRng) {
        for (o, bucket) in obs.iter_mut().zip(&mut self.buckets) {
            // A packet already dropped upstream still consumes the instant's decision: the
            // node does not know what the channel did before it.
            if !bucket.step().transmit {
                drop_packet(o, FLAG_TOKEN_BLOCKED);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::{run_rng, Stream};

    #[test]
    fn withholds_exactly_the_protocol_pattern() {
        let spec = TokenBucketStage {
            a: 2,
            b: 3,
            s: 10,
            z0: 6,
        };
        let mut stage = spec.build(1);
        let mut rng = run_rng(0, 0, Stream::Channel);
        // From eq. (2) by hand (see estimator-core's token_bucket tests): the first six
        // decisions send, then (withheld, sent, sent) repeats — whatever instant the first
        // decision is applied to (here k = 0, as behind seed 003's plant).
        let mut pattern = Vec::new();
        for k in 0..12u32 {
            let mut obs = [Observation {
                k,
                node: 0,
                delivered: true,
                ny: 2,
                y: [1.0, 2.0, 0.0, 0.0],
                flags: 0,
                tokens: None,
            }];
            stage.apply(k, &[0.0; 3], &mut obs, &mut rng);
            assert_eq!(obs[0].flags & FLAG_TOKEN_BLOCKED != 0, !obs[0].delivered);
            pattern.push(obs[0].delivered);
        }
        let t = true;
        let f = false;
        assert_eq!(pattern, [t, t, t, t, t, t, f, t, t, f, t, t]);
    }

    #[test]
    fn invalid_parameters_are_named() {
        let bad = TokenBucketStage {
            a: 3,
            b: 2,
            s: 10,
            z0: 0,
        };
        let e = bad.config("stages[0]").unwrap_err().to_string();
        assert!(e.contains("stages[0].b"), "{e}");
    }
}
