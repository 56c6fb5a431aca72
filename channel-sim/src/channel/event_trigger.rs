//! The dynamic event triggers of all seed 004 nodes sharing one token bucket (eqs. 11-20), as
//! one channel stage: resources shared by nodes are why a stage sees every node's observation
//! of an instant at once.
//!
//! The stage runs estimator-core's sensor-side state machine
//! ([`estimator_core::protocol::shared_token_bucket::TriggeredBucketScheduler`]), so the
//! simulation and a sensor node execute the same code. It draws no random numbers.
//!
//! Flags: [`FLAG_TRIGGERED`] when the node's trigger fired (α = 1); [`FLAG_TOKEN_BLOCKED`] when
//! it fired but its share of the bucket did not cover its cost (β = 0). A node that did not
//! transmit (α β = 0) is a dropped packet: the estimator then holds its last received
//! measurement (eq. 19).

use std::any::Any;

use estimator_core::protocol::event_trigger::EventTrigger;
use estimator_core::protocol::shared_token_bucket::{
    NodeDecision, SharedTokenBucket, TriggeredBucketScheduler,
};
use nalgebra::SVector;

use super::{drop_packet, Stage, StageSpec};
use crate::rng::SimRng;
use crate::sim::{Observation, FLAG_TOKEN_BLOCKED, FLAG_TRIGGERED, MAX_NODES, MAX_NY};

pub use estpipe_spec::channel::{TriggerParams, TriggeredTokenBucket};

/// The stage of a [`TriggeredTokenBucket`] (a fresh scheduler per run).
pub fn build_stage(spec: &TriggeredTokenBucket) -> TriggeredTokenBucketStage {
    TriggeredTokenBucketStage {
        sched: build_scheduler(spec),
        last: [None; MAX_NODES],
    }
}

/// The const-generic scheduler behind a node-count-erased interface.
trait ErasedScheduler: Send + std::fmt::Debug {
    fn step(
        &mut self,
        ys: &[SVector<f64, MAX_NY>; MAX_NODES],
    ) -> estimator_core::Result<[Option<NodeDecision<f64>>; MAX_NODES]>;
    fn level(&self) -> u32;
}

impl<const L: usize> ErasedScheduler for TriggeredBucketScheduler<f64, MAX_NY, L> {
    fn step(
        &mut self,
        ys: &[SVector<f64, MAX_NY>; MAX_NODES],
    ) -> estimator_core::Result<[Option<NodeDecision<f64>>; MAX_NODES]> {
        let mine: [SVector<f64, MAX_NY>; L] = core::array::from_fn(|m| ys[m]);
        let d = TriggeredBucketScheduler::step(self, &mine)?;
        let mut out = [None; MAX_NODES];
        for m in 0..L {
            out[m] = Some(d[m]);
        }
        Ok(out)
    }
    fn level(&self) -> u32 {
        self.bucket().level()
    }
}

fn build_scheduler(spec: &TriggeredTokenBucket) -> Box<dyn ErasedScheduler> {
    fn make<const L: usize>(spec: &TriggeredTokenBucket) -> Box<dyn ErasedScheduler> {
        let nodes: [EventTrigger<f64, MAX_NY>; L] = core::array::from_fn(|m| {
            let mut r = SVector::<f64, MAX_NY>::zeros();
            r.as_mut_slice()[..spec.reference(m).len()].copy_from_slice(spec.reference(m));
            EventTrigger::new(*spec.trigger(m), r).expect("validated in TriggeredTokenBucket::new")
        });
        let costs: [u32; L] = core::array::from_fn(|m| spec.costs()[m]);
        let bucket = {
            let (initial, rate, capacity) = spec.bucket();
            SharedTokenBucket::<L>::new(initial, rate, capacity, costs)
        }
        .expect("validated in TriggeredTokenBucket::new");
        Box::new(TriggeredBucketScheduler::new(nodes, bucket))
    }
    match spec.nodes() {
        1 => make::<1>(spec),
        2 => make::<2>(spec),
        3 => make::<3>(spec),
        4 => make::<4>(spec),
        5 => make::<5>(spec),
        6 => make::<6>(spec),
        7 => make::<7>(spec),
        _ => make::<8>(spec),
    }
}

/// One run's triggers and bucket.
#[derive(Debug)]
pub struct TriggeredTokenBucketStage {
    sched: Box<dyn ErasedScheduler>,
    last: [Option<NodeDecision<f64>>; MAX_NODES],
}

impl TriggeredTokenBucketStage {
    /// The bucket level ξ_k after the last instant's update (eq. 17).
    pub fn level(&self) -> u32 {
        self.sched.level()
    }

    /// Node `m`'s decision at the last instant.
    pub fn decision(&self, m: usize) -> Option<NodeDecision<f64>> {
        self.last.get(m).copied().flatten()
    }
}

impl StageSpec for TriggeredTokenBucket {
    fn knowledge(&self, k: &mut estpipe_spec::channel::ChannelKnowledge) {
        k.event_trigger = Some(self.clone());
    }
    fn name(&self) -> &'static str {
        "event-trigger-token-bucket"
    }
    fn warnings(&self) -> Vec<String> {
        TriggeredTokenBucket::warnings(self)
    }
    fn build(&self, _nodes: usize) -> Box<dyn Stage> {
        Box::new(build_stage(self))
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

impl Stage for TriggeredTokenBucketStage {
    fn apply(&mut self, _k: u32, _truth: &[f64], obs: &mut [Observation], _rng: &mut SimRng) {
        let mut ys = [SVector::<f64, MAX_NY>::zeros(); MAX_NODES];
        for o in obs.iter() {
            if let Some(slot) = ys.get_mut(o.node as usize) {
                // Padded entries are 0 in y and in the reference: they add nothing to ‖ε‖.
                *slot = SVector::from_column_slice(&o.y);
                slot.as_mut_slice()[o.ny as usize..].fill(0.0);
            }
        }
        // ξ_{t−1}, what every grant of this instant uses: a sent packet reports it (docs/wire.md,
        // "The bucket level on a delivered packet").
        let level = self.sched.level();
        match self.sched.step(&ys) {
            Ok(decisions) => {
                self.last = decisions;
                for o in obs.iter_mut() {
                    let Some(Some(d)) = decisions.get(o.node as usize) else {
                        continue;
                    };
                    let mut flags = 0;
                    if d.triggered {
                        flags |= FLAG_TRIGGERED;
                    }
                    if d.blocked() {
                        flags |= FLAG_TOKEN_BLOCKED;
                    }
                    o.flags |= flags;
                    if d.sent {
                        o.tokens = Some(level);
                    } else {
                        drop_packet(o, 0);
                    }
                }
            }
            // Only a non-finite measurement gets here (the plant's bug): nothing is sent and
            // the protocol state stays as it was.
            Err(_) => {
                self.last = [None; MAX_NODES];
                for o in obs.iter_mut() {
                    drop_packet(o, 0);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn obs(node: u8, y: [f64; 2]) -> Observation {
        let mut o = Observation::dropped(1, node, 2, 0);
        o.delivered = true;
        o.y[..2].copy_from_slice(&y);
        o
    }

    #[test]
    fn trigger_stage_flags_and_drops() {
        let p = TriggerParams {
            sigma: 0.0,
            chi: 5.0,
            lambda: 0.5,
            eta0: 0.0,
        };
        // Every node fires every instant; ξ₀ = 10, g = 5, c = 3, L = 3.
        let spec = TriggeredTokenBucket::new(
            &[p; 3],
            vec![vec![0.0, 0.0]; 3],
            10,
            5,
            30,
            vec![3; 3],
            false,
        )
        .unwrap();
        assert!(spec.warnings().is_empty());
        let mut st = build_stage(&spec);
        let mut rng = crate::rng::run_rng(0, 0, crate::rng::Stream::Channel);
        let mut o = [obs(0, [1.0, 0.0]), obs(1, [2.0, 0.0]), obs(2, [3.0, 0.0])];
        st.apply(1, &[], &mut o, &mut rng);
        assert!(o.iter().all(|o| o.delivered && o.flags == FLAG_TRIGGERED));
        assert_eq!(st.level(), 6);
        let mut o = [obs(0, [1.5, 0.0]), obs(1, [2.5, 0.0]), obs(2, [3.5, 0.0])];
        st.apply(2, &[], &mut o, &mut rng);
        assert!(o
            .iter()
            .all(|o| !o.delivered && o.flags == FLAG_TRIGGERED | FLAG_TOKEN_BLOCKED));
        assert_eq!(st.level(), 11);
    }

    #[test]
    fn violation_needs_opt_in_and_warns() {
        let p = TriggerParams {
            sigma: 0.1,
            chi: 5.0,
            lambda: 0.1,
            eta0: 1.5,
        };
        let e = TriggeredTokenBucket::new(&[p], vec![vec![0.0]], 10, 5, 30, vec![3], false)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("trigger.nodes[0]") && e.contains("lambda*chi"),
            "{e}"
        );
        let ok =
            TriggeredTokenBucket::new(&[p], vec![vec![0.0]], 10, 5, 30, vec![3], true).unwrap();
        assert_eq!(ok.warnings().len(), 1);
        assert!(ok.warnings()[0].contains("0.500"), "{}", ok.warnings()[0]);
        assert!(
            TriggeredTokenBucket::new(&[p], vec![vec![0.0]], 40, 5, 30, vec![3], true).is_err()
        );
    }
}
