//! Seed 004's dynamic event triggers sharing one token bucket (eqs. 11-20), as the estimators
//! know them: each node's trigger parameters (σ, χ, λ, η₀) and initial reference ȳ, the
//! shared bucket (initial tokens, rate, capacity) and each node's cost per transmission.

use estimator_core::protocol::event_trigger::EventTriggerConfig;
use estimator_core::protocol::shared_token_bucket::SharedTokenBucket;

use crate::error::SpecError;
use estpipe_wire::{MAX_NODES, MAX_NY};

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
    ) -> Result<Self, SpecError> {
        let l = params.len();
        if l == 0 || l > MAX_NODES || references.len() != l || costs.len() != l {
            return Err(SpecError::invalid(
                "trigger.nodes",
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
            let cfg = make(p.sigma, p.chi, p.lambda, p.eta0)
                .map_err(|e| SpecError::invalid(format!("trigger.nodes[{m}]"), e.to_string()))?;
            triggers.push(cfg);
            let r = &references[m];
            if r.is_empty() || r.len() > MAX_NY || r.iter().any(|v| !v.is_finite()) {
                return Err(SpecError::invalid(
                    format!("trigger.nodes[{m}].reference"),
                    format!("must have 1..={MAX_NY} finite entries"),
                ));
            }
        }
        // The bucket's own validation (with the true node count).
        // Named by the TOML keys (the core says "initial tokens"); `trigger.` is re-rooted at
        // the table by the spec file and the scenario file alike.
        check_bucket(l, initial_tokens, rate, capacity, &costs).map_err(|e| {
            let key = match &e {
                estimator_core::Error::InvalidConfig { field, .. } => match *field {
                    "initial tokens" => ".initial_tokens",
                    "capacity" => ".capacity",
                    "nodes" => ".nodes",
                    _ => "",
                },
                _ => "",
            };
            SpecError::invalid(format!("trigger{key}"), e.to_string())
        })?;
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

    /// Node `m`'s initial reference measurement ȳ_{m,0}.
    pub fn reference(&self, m: usize) -> &[f64] {
        &self.references[m]
    }
}

pub(crate) fn check_bucket(
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
