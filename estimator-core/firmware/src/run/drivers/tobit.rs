//! The seed 004 federated Tobit fusion filter over the three-node Tobit stream.

use estimator_core::filter::tobit::{BoundScalars, TobitFilterConfig};
use estimator_core::filter::TobitFusion;
use estimator_core::protocol::event_trigger::EventTriggerConfig;
use estimator_core::{Error, Estimate, Estimator, Packet};
use nalgebra::{Matrix2, Vector2};

use super::super::digest::Fnv1a64;
use super::super::drive::{drive, Digested};
use super::super::models::{TobitModel, TOBIT_CHI, TOBIT_ETA0, TOBIT_LAMBDA, TOBIT_SIGMA};
use super::super::summary::Summary;
use super::super::vectors::{NodeStream, NODES, NY, TOBIT_NX};

/// The federated Tobit fusion filter of the stream: 3 local Tobit filters on (n_x, n_y) = (2, 2).
pub type Fusion = TobitFusion<f32, TOBIT_NX, NY, NODES>;

/// Seed 004's estimator side as the firmware runs it: the fusion filter and the example's
/// matrices. A core estimator of its own rather than the fusion filter's
/// [`OnModel`](estimator_core::OnModel) pairing: that pairing takes every node's model as a
/// [`LinearSystem`](estimator_core::model::LinearSystem) and derives the variances R_m,j from
/// R_m at every step, which the time-invariant example has stored once.
#[derive(Clone, Debug)]
pub struct Tobit {
    /// The example's matrices.
    pub model: TobitModel,
    /// The three local filters and the fusion centre.
    pub fusion: Fusion,
}

impl Tobit {
    /// Node `m`'s local filter: τ_m = 0, ε as in section 4, the trigger's σ, χ, λ, η₀ (λχ ≤ 1
    /// is accepted, as the example needs), d = 1.5, e = 2.
    pub fn node_config(m: usize) -> Result<TobitFilterConfig<f32, NY>, Error> {
        let trigger = EventTriggerConfig::new_allowing_paper_violation(
            TOBIT_SIGMA[m],
            TOBIT_CHI,
            TOBIT_LAMBDA[m],
            TOBIT_ETA0,
        )?;
        TobitFilterConfig::new(
            Vector2::zeros(),
            BoundScalars::paper_example(),
            trigger,
            1.5,
            2.0,
        )
    }

    /// The example's fusion filter: α_m = 1/3, x̂₀ = [5 0]ᵀ, P₀ = I₂.
    pub fn paper_example() -> Result<Self, Error> {
        let cfgs = [
            Self::node_config(0)?,
            Self::node_config(1)?,
            Self::node_config(2)?,
        ];
        Ok(Self {
            model: TobitModel::paper_example(),
            fusion: Fusion::new(cfgs, Vector2::new(5.0, 0.0), Matrix2::identity())?,
        })
    }
}

/// One instant of Algorithm 1 on the estimator side: every local filter on what its node
/// delivered (θ = 1 holds the last received measurement), fusion (50), reset (51).
impl Estimator<f32, TOBIT_NX> for Tobit {
    type Measurement = [Packet<f32, NY>; NODES];

    fn step(&mut self, _k: usize, y: &[Packet<f32, NY>; NODES]) -> Result<(), Error> {
        let m = &self.model;
        let received = core::array::from_fn(|i| y[i].delivered());
        self.fusion.step(&m.a, &m.bqb, &m.c, &m.r, received)
    }

    fn estimate(&self) -> &Estimate<f32, TOBIT_NX> {
        self.fusion.estimate()
    }
}

/// The digest covers x̂^g and P^g, then every node's x̂_m and P̄_m before the reset. A delivered
/// measurement is censored where a component is at the threshold τ_m = 0 (eq. 2: the node sends
/// τ for a value below it).
impl Digested<TOBIT_NX> for Tobit {
    fn censored(y: &Vector2<f32>) -> bool {
        y.iter().any(|&v| v <= 0.0)
    }

    fn digest(&self, h: &mut Fnv1a64) {
        h.estimate(self.estimate().state(), self.estimate().covariance());
        for m in 0..NODES {
            if let Some(e) = self.fusion.local_estimate(m) {
                h.estimate(e.state(), e.covariance());
            }
        }
    }
}

/// The seed 004 fusion filter over the three-node Tobit stream.
pub fn run_tobit(stream: &NodeStream<'_>, steps: usize) -> Summary {
    drive("tobit", stream.instants(), steps, Tobit::paper_example)
}
