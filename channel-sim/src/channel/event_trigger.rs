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

use estimator_core::protocol::event_trigger::{EventTrigger, EventTriggerConfig};
use estimator_core::protocol::shared_token_bucket::{
    NodeDecision, SharedTokenBucket, TriggeredBucketScheduler,
};
use estpipe_wire::Fnv1a64;
use nalgebra::SVector;

use super::{drop_packet, Stage, StageSpec};
use crate::error::ScenarioError;
use crate::rng::SimRng;
use crate::sim::{Observation, FLAG_TOKEN_BLOCKED, FLAG_TRIGGERED, MAX_NODES, MAX_NY};

/// Parameters of the dynamic event triggers (one per node) and the shared token bucket.
#[derive(Clone, Debug, PartialEq)]
pub struct TriggeredTokenBucket {
    triggers: Vec<EventTriggerConfig<f64>>,
    references: Vec<Vec<f64>>,
    initial_tokens: u32,
    rate: u32,
    capacity: u32,
    costs: Vec<u32>,
    allow_paper_violation: bool,
}

/// Per-node trigger parameters as the paper writes them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriggerParams {
    /// σ_m.
    pub sigma: f64,
    /// χ_m (the example's "θ_m").
    pub chi: f64,
    /// λ_m.
    pub lambda: f64,
    /// η_{m,0}.
    pub eta0: f64,
}

impl TriggeredTokenBucket {
    /// Validates everything through estimator-core: the triggers (`λχ > 1` is required unless
    /// `allow_paper_violation`), the bucket (`ξ₀ ≤ b`, integer tokens), and one reference
    /// (the initial ȳ, the censoring threshold τ_m in seed 004) and one cost per node.
    pub fn new(
        params: &[TriggerParams],
        references: Vec<Vec<f64>>,
        initial_tokens: u32,
        rate: u32,
        capacity: u32,
        costs: Vec<u32>,
        allow_paper_violation: bool,
    ) -> Result<Self, ScenarioError> {
        let l = params.len();
        if l == 0 || l > MAX_NODES || references.len() != l || costs.len() != l {
            return Err(ScenarioError::invalid(
                "trigger",
                format!(
                    "need 1..={MAX_NODES} nodes with one parameter set, reference and cost \
                     each; got {l}, {}, {}",
                    references.len(),
                    costs.len()
                ),
            ));
        }
        let mut triggers = Vec::with_capacity(l);
        for (m, p) in params.iter().enumerate() {
            let make = if allow_paper_violation {
                EventTriggerConfig::new_allowing_paper_violation
            } else {
                EventTriggerConfig::new
            };
            let cfg = make(p.sigma, p.chi, p.lambda, p.eta0).map_err(|e| {
                ScenarioError::invalid(format!("trigger.nodes[{m}]"), e.to_string())
            })?;
            triggers.push(cfg);
            let r = &references[m];
            if r.is_empty() || r.len() > MAX_NY || r.iter().any(|v| !v.is_finite()) {
                return Err(ScenarioError::invalid(
                    format!("trigger.references[{m}]"),
                    format!("must have 1..={MAX_NY} finite entries"),
                ));
            }
        }
        // The bucket's own validation (with the true node count).
        check_bucket(l, initial_tokens, rate, capacity, &costs)
            .map_err(|e| ScenarioError::invalid("bucket", e.to_string()))?;
        Ok(Self {
            triggers,
            references,
            initial_tokens,
            rate,
            capacity,
            costs,
            allow_paper_violation,
        })
    }

    /// The node's trigger configuration.
    pub fn trigger(&self, m: usize) -> &EventTriggerConfig<f64> {
        &self.triggers[m]
    }

    /// Number of nodes.
    pub fn nodes(&self) -> usize {
        self.triggers.len()
    }

    /// Bucket parameters `(ξ₀, g, b)`.
    pub fn bucket(&self) -> (u32, u32, u32) {
        (self.initial_tokens, self.rate, self.capacity)
    }

    /// Per-node costs c_m.
    pub fn costs(&self) -> &[u32] {
        &self.costs
    }

    /// Whether the configuration was built with the explicit opt-in.
    pub fn allows_paper_violation(&self) -> bool {
        self.allow_paper_violation
    }

    /// One line per node whose parameters violate the paper's `λχ > 1` (accepted only with
    /// the opt-in): what a report must print.
    pub fn warnings(&self) -> Vec<String> {
        self.triggers
            .iter()
            .enumerate()
            .filter_map(|(m, t)| {
                t.paper_violation().map(|why| {
                    format!(
                        "node {}: lambda*chi = {} * {} = {:.3} <= 1 accepted by explicit opt-in; \
                         {why}; eta can go negative",
                        m + 1,
                        t.lambda(),
                        t.chi(),
                        t.lambda() * t.chi()
                    )
                })
            })
            .collect()
    }

    /// A fresh concrete stage (for callers that want the token level, e.g. plots).
    pub fn build_stage(&self) -> TriggeredTokenBucketStage {
        TriggeredTokenBucketStage {
            sched: build_scheduler(self),
            last: [None; MAX_NODES],
        }
    }
}

fn check_bucket(
    l: usize,
    initial: u32,
    rate: u32,
    capacity: u32,
    costs: &[u32],
) -> estimator_core::Result<()> {
    macro_rules! check {
        ($($n:literal)*) => {
            match l {
                $($n => {
                    let mut c = [0u32; $n];
                    c.copy_from_slice(costs);
                    SharedTokenBucket::<$n>::new(initial, rate, capacity, c).map(|_| ())
                })*
                _ => Err(estimator_core::Error::InvalidConfig {
                    field: "nodes",
                    reason: "between 1 and MAX_NODES",
                }),
            }
        };
    }
    check!(1 2 3 4 5 6 7 8)
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
            r.as_mut_slice()[..spec.references[m].len()].copy_from_slice(&spec.references[m]);
            EventTrigger::new(spec.triggers[m], r).expect("validated in TriggeredTokenBucket::new")
        });
        let costs: [u32; L] = core::array::from_fn(|m| spec.costs[m]);
        let bucket =
            SharedTokenBucket::<L>::new(spec.initial_tokens, spec.rate, spec.capacity, costs)
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
    fn name(&self) -> &'static str {
        "event-trigger-token-bucket"
    }
    fn warnings(&self) -> Vec<String> {
        TriggeredTokenBucket::warnings(self)
    }
    fn build(&self, _nodes: usize) -> Box<dyn Stage> {
        Box::new(self.build_stage())
    }
    fn fingerprint(&self, h: &mut Fnv1a64) {
        h.u64(self.triggers.len() as u64);
        for (t, r) in self.triggers.iter().zip(&self.references) {
            h.f64(t.sigma()).f64(t.chi()).f64(t.lambda()).f64(t.eta0());
            h.u64(r.len() as u64).f64s(r);
        }
        h.u64(self.initial_tokens.into())
            .u64(self.rate.into())
            .u64(self.capacity.into());
        for &c in &self.costs {
            h.u64(c.into());
        }
        h.u64(self.allow_paper_violation.into());
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
                    if !d.sent {
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
        let mut st = spec.build_stage();
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
