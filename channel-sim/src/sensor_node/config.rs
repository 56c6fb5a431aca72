//! What each node of a scenario runs, read from the scenario's channel stages: the nodes'
//! configurations ([`NodeConfig`]) and the shared bucket the gateway keeps (seed 004).
//!
//! The node firmware runs the stages that are a sensor's own: Tobit censoring, then either
//! seed 003's token bucket or seed 004's event trigger on its share of the shared bucket, in
//! the order channel-sim applies them. A scenario with any other stage (occlusion, random
//! losses: what happens to a packet after the node, or needs the true state) is refused with
//! the stage's name.

use estimator_core::protocol::shared_token_bucket::SharedTokenBucket;
use estpipe_sensor_node::{NodeConfig, Schedule, LINK_VERSION, MAX_NY};

use crate::channel::event_trigger::TriggeredTokenBucket;
use crate::channel::tobit::TobitCensoring;
use crate::channel::token_bucket::TokenBucketStage;
use crate::scenario::composed::ComposedScenario;
use crate::sim::Scenario;

/// The shared token bucket of seed 004 (eqs. 16-18) for any number of nodes, as the gateway
/// keeps it: the level the nodes are told, and the update with what they sent.
pub trait Bucket: Send + std::fmt::Debug {
    /// ξ_k.
    fn level(&self) -> u32;
    /// Eq. (17) with the nodes that sent; refuses a node that sent without its share.
    fn update(&mut self, sent: &[bool]) -> estimator_core::Result<u32>;
}

impl<const L: usize> Bucket for SharedTokenBucket<L> {
    fn level(&self) -> u32 {
        SharedTokenBucket::level(self)
    }
    fn update(&mut self, sent: &[bool]) -> estimator_core::Result<u32> {
        let s: [bool; L] = core::array::from_fn(|m| sent.get(m).copied().unwrap_or(false));
        SharedTokenBucket::update(self, &s)
    }
}

fn bucket_of(spec: &TriggeredTokenBucket) -> Result<Box<dyn Bucket>, String> {
    fn make<const L: usize>(spec: &TriggeredTokenBucket) -> Result<Box<dyn Bucket>, String> {
        let (initial, rate, capacity) = spec.bucket();
        let costs: [u32; L] = core::array::from_fn(|m| spec.costs()[m]);
        SharedTokenBucket::<L>::new(initial, rate, capacity, costs)
            .map(|b| Box::new(b) as Box<dyn Bucket>)
            .map_err(|e| format!("shared token bucket: {e}"))
    }
    match spec.nodes() {
        1 => make::<1>(spec),
        2 => make::<2>(spec),
        3 => make::<3>(spec),
        4 => make::<4>(spec),
        5 => make::<5>(spec),
        6 => make::<6>(spec),
        7 => make::<7>(spec),
        8 => make::<8>(spec),
        n => Err(format!("{n} nodes share the bucket; at most 8")),
    }
}

/// Every node's configuration and, for seed 004's shared bucket, the bucket.
#[derive(Debug)]
pub struct LoopConfig {
    /// Node m's configuration.
    pub nodes: Vec<NodeConfig>,
    /// The shared bucket, whose level goes with every sample.
    pub bucket: Option<Box<dyn Bucket>>,
    /// Node m's cost c_m in the shared bucket (its grant is checked on every decision).
    pub costs: Vec<u32>,
}

fn padded(v: &[f64], pad: f64) -> [f64; MAX_NY] {
    let mut a = [pad; MAX_NY];
    a[..v.len().min(MAX_NY)].copy_from_slice(&v[..v.len().min(MAX_NY)]);
    a
}

/// The nodes' configurations of `scenario`, or why its channel cannot run on sensor nodes.
pub fn loop_config(scenario: &dyn Scenario) -> Result<LoopConfig, String> {
    let composed = scenario
        .as_any()
        .downcast_ref::<ComposedScenario>()
        .ok_or_else(|| format!("scenario {} is not a composed scenario", scenario.name()))?;
    let stages = NodeStages::of(scenario, composed)?;
    let n = scenario.nodes();
    stages.check_nodes(n)?;
    let nodes = (0..n)
        .map(|m| NodeConfig {
            version: LINK_VERSION,
            node: m as u8,
            ny: scenario.node_ny(m) as u8,
            censor: stages.censoring.map(|c| c.padded(m).into()),
            schedule: stages.schedule(m, n),
        })
        .collect();
    Ok(LoopConfig {
        nodes,
        bucket: stages.trigger.map(bucket_of).transpose()?,
        costs: stages
            .trigger
            .map_or_else(|| vec![0; n], |t| t.costs().to_vec()),
    })
}

/// The channel stages a sensor node runs, each at most once, in the node's order.
#[derive(Clone, Copy)]
struct NodeStages<'a> {
    censoring: Option<&'a TobitCensoring>,
    bucket: Option<&'a TokenBucketStage>,
    trigger: Option<&'a TriggeredTokenBucket>,
}

impl<'a> NodeStages<'a> {
    /// The stages of `composed`, or why they cannot run on a node (a stage a node does not
    /// run, or one out of order).
    fn of(scenario: &dyn Scenario, composed: &'a ComposedScenario) -> Result<Self, String> {
        let mut censoring: Option<&TobitCensoring> = None;
        let mut bucket: Option<&TokenBucketStage> = None;
        let mut trigger: Option<&TriggeredTokenBucket> = None;
        let order =
            "the node runs tobit-censoring, then token-bucket or event-trigger-token-bucket";
        for s in composed.stages() {
            let a = s.as_any();
            let scheduled = bucket.is_some() || trigger.is_some();
            if let Some(t) = a.downcast_ref::<TobitCensoring>() {
                if censoring.is_some() || scheduled {
                    return Err(format!("stage {} out of order: {order}", s.name()));
                }
                censoring = Some(t);
            } else if let Some(b) = a.downcast_ref::<TokenBucketStage>() {
                if scheduled {
                    return Err(format!("stage {} out of order: {order}", s.name()));
                }
                bucket = Some(b);
            } else if let Some(t) = a.downcast_ref::<TriggeredTokenBucket>() {
                if scheduled {
                    return Err(format!("stage {} out of order: {order}", s.name()));
                }
                trigger = Some(t);
            } else {
                return Err(format!(
                    "scenario {}: stage {} does not run on a sensor node ({order})",
                    scenario.name(),
                    s.name()
                ));
            }
        }
        Ok(Self {
            censoring,
            bucket,
            trigger,
        })
    }

    /// The trigger and the censoring cover the plant's `n` nodes.
    fn check_nodes(&self, n: usize) -> Result<(), String> {
        if let Some(t) = self.trigger {
            if t.nodes() != n {
                return Err(format!(
                    "the event trigger has {} nodes, the plant {n}",
                    t.nodes()
                ));
            }
        }
        if let Some(c) = self.censoring {
            if c.nodes() < n {
                return Err(format!(
                    "censoring thresholds for {} nodes, the plant has {n}",
                    c.nodes()
                ));
            }
        }
        Ok(())
    }

    /// Node `m`'s schedule (of `n` nodes): its bucket, its trigger, or every sample.
    fn schedule(&self, m: usize, n: usize) -> Schedule {
        if let Some(b) = self.bucket {
            Schedule::TokenBucket {
                a: b.a,
                b: b.b,
                s: b.s,
                z0: b.z0,
            }
        } else if let Some(t) = self.trigger {
            let c = t.trigger(m);
            Schedule::EventTrigger {
                sigma: c.sigma(),
                chi: c.chi(),
                lambda: c.lambda(),
                eta0: c.eta0(),
                allow_paper_violation: c.paper_violation().is_some(),
                // channel-sim's stage pads the reference with 0.
                reference: padded(t.reference(m), 0.0),
                cost: t.costs()[m],
                nodes: n as u8,
            }
        } else {
            Schedule::Always
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::preset;

    #[test]
    fn the_presets_nodes() {
        let c = loop_config(&*preset("nn-token-bucket").unwrap()).unwrap();
        assert_eq!(c.nodes.len(), 1);
        assert!(c.bucket.is_none());
        assert_eq!(
            c.nodes[0].schedule,
            Schedule::TokenBucket {
                a: 2,
                b: 3,
                s: 10,
                z0: 6
            }
        );
        let c = loop_config(&*preset("tobit-fusion").unwrap()).unwrap();
        assert_eq!(c.nodes.len(), 3);
        assert_eq!(c.bucket.as_ref().unwrap().level(), 10);
        let Schedule::EventTrigger { sigma, cost, .. } = c.nodes[2].schedule else {
            panic!()
        };
        assert_eq!((sigma, cost), (0.3, 3));
        assert_eq!(c.nodes[1].censor.unwrap()[..2], [0.0, 0.0]);
        let e = loop_config(&*preset("occlusion").unwrap()).unwrap_err();
        assert!(
            e.contains("stage occlusion does not run on a sensor node"),
            "{e}"
        );
    }
}
