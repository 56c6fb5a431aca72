//! The product's seed 004 estimator at the information bound, `tobit-cmm-held`
//! (docs/tobit-fusion.md, "At the information bound"), over the three-node Tobit stream: one
//! centralised moment-matched filter behind the receiver's mirror of the shared bucket, every
//! delivered packet read component by component (observed: the Kalman update; censored: the
//! exact truncated moments) and every held trigger's silence read as the truncated Gaussian
//! on its silence box.
//!
//! Every item here is `#[inline]`, so that it is compiled into the one binary that runs it
//! rather than into the firmware library every binary links: otherwise the library's shared
//! generic code (the truncated moments, the Kalman prediction) gains callers, and LLVM
//! compiles the other Tobit binaries' steps differently (their counts would move with a
//! binary they do not contain).

use estimator_core::filter::silence::TriggeredPackets;
use estimator_core::filter::MomentMatchedTobit;
use estimator_core::protocol::event_trigger::EventTriggerConfig;
use estimator_core::protocol::trigger_knowledge::TriggerKnowledge;
use estimator_core::{Error, Estimate, Estimator, Packet};
use nalgebra::{Matrix2, Vector2};

use super::super::digest::Fnv1a64;
use super::super::drive::{drive, Digested};
use super::super::mark::HELD;
use super::super::models::{TobitModel, TOBIT_CHI, TOBIT_ETA0, TOBIT_LAMBDA, TOBIT_SIGMA};
use super::super::summary::Summary;
use super::super::vectors::{NodeStream, NODES, NY, TOBIT_NX};
use super::tobit_silence::paper_bucket;

/// The moment-matched filter of the stream: (n_x, n_y) = (2, 2), three nodes.
pub type Cmm = MomentMatchedTobit<f32, TOBIT_NX, NY, NODES>;

/// `tobit-cmm-held` as the firmware runs it: the filter and the example's matrices, stored
/// once in the form [`MomentMatchedTobit::step_matrices`] takes them (the model is
/// time-invariant).
#[derive(Clone, Debug)]
pub struct TobitCmm {
    /// A.
    pub a: Matrix2<f32>,
    /// B Q Bᵀ.
    pub bqb: Matrix2<f32>,
    /// Every node's C_m and the variances of R_m.
    pub nodes: [(Matrix2<f32>, Vector2<f32>); NODES],
    /// The filter, its bucket mirror and its knowledge of every trigger.
    pub filter: Cmm,
}

impl TobitCmm {
    /// The example's filter: x̂₀ = [5 0]ᵀ, P₀ = I₂, τ_m = 0, every node's trigger (σ_m, χ, λ_m,
    /// η₀) with its initial reference at τ_m as the node starts, the shared bucket at ξ₀;
    /// `reads_silence` as the product's flagship sets it (`tobit-cmm-held`) or not
    /// (`tobit-cmm`).
    #[inline]
    pub fn paper_example(reads_silence: bool) -> Result<Self, Error> {
        let tau = Vector2::zeros();
        let knowledge = |m: usize| {
            let trigger = EventTriggerConfig::new_allowing_paper_violation(
                TOBIT_SIGMA[m],
                TOBIT_CHI,
                TOBIT_LAMBDA[m],
                TOBIT_ETA0,
            )?;
            TriggerKnowledge::new(trigger, tau)
        };
        let nodes = [knowledge(0)?, knowledge(1)?, knowledge(2)?];
        let prior = Estimate::new(Vector2::new(5.0, 0.0), Matrix2::identity())?;
        let m = TobitModel::paper_example();
        Ok(Self {
            a: m.a,
            bqb: m.bqb,
            nodes: core::array::from_fn(|i| (m.c[i], m.r[i])),
            filter: Cmm::new(prior, [tau; NODES], nodes, paper_bucket()?, reads_silence)?,
        })
    }

    /// The flagship, `tobit-cmm-held`.
    #[inline]
    pub fn silence() -> Result<Self, Error> {
        Self::paper_example(true)
    }
}

impl Estimator<f32, TOBIT_NX> for TobitCmm {
    type Measurement = [Packet<f32, NY>; NODES];

    /// The stream has no transport losses and no reported levels: the mirror runs on the
    /// transmissions alone.
    #[inline]
    fn step(&mut self, _k: usize, y: &[Packet<f32, NY>; NODES]) -> Result<(), Error> {
        let packets = TriggeredPackets {
            packets: *y,
            level: None,
        };
        self.filter
            .step_matrices(&self.a, &self.bqb, &self.nodes, &packets)
    }

    #[inline]
    fn estimate(&self) -> &Estimate<f32, TOBIT_NX> {
        self.filter.estimate()
    }
}

/// The digest covers x̂ and P, then the silence counts (held, blocked, without a usable set),
/// which pin the mirror's reading of every silence.
impl Digested<TOBIT_NX> for TobitCmm {
    #[inline]
    fn censored(y: &Vector2<f32>) -> bool {
        y.iter().any(|&v| v <= 0.0)
    }

    /// The silent nodes whose silence the mirror will call held (a copy of the mirror stepped
    /// ahead): the step's work depends on them.
    fn held<const L: usize>(&self, y: &[Option<Vector2<f32>>; L]) -> u8 {
        let packets = TriggeredPackets::<f32, NY, NODES> {
            packets: core::array::from_fn(|m| Packet::from(y.get(m).copied().flatten())),
            level: None,
        };
        let mut mirror = *self.filter.mirror();
        let held = mirror.step(&packets.sent(), None);
        let mut code = 0;
        for (m, &h) in held.iter().enumerate() {
            if h {
                code |= HELD << m;
            }
        }
        code
    }

    #[inline]
    fn digest(&self, h: &mut Fnv1a64) {
        h.estimate(self.estimate().state(), self.estimate().covariance());
        let c = self.filter.counts();
        for n in [c.held, c.blocked, c.unusable] {
            h.bytes(&n.to_le_bytes());
        }
    }
}

/// `tobit-cmm-held` over the three-node Tobit stream.
#[inline]
pub fn run_tobit_cmm(stream: &NodeStream<'_>, steps: usize) -> Summary {
    drive("tobit-cmm", stream.instants(), steps, TobitCmm::silence)
}
