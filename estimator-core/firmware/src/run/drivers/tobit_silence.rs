//! The seed 004 fusion filter with the silence update (the product's option beside the
//! paper's; docs/tobit-fusion.md, "Silence that speaks") over the three-node Tobit stream: the
//! receiver's mirror of the shared bucket, then every local filter on its node's arrival — a
//! held trigger's silence is the moment-matched truncated Gaussian on the silence set
//! intersected with the censoring region, any other silence the prediction.

use estimator_core::filter::silence::TriggeredPackets;
use estimator_core::filter::tobit::Silence;
use estimator_core::filter::MirroredFusion;
use estimator_core::protocol::shared_token_bucket::SharedTokenBucket;
use estimator_core::{Error, Estimate, Estimator, Packet};
use nalgebra::{Matrix2, Vector2};

use super::super::digest::Fnv1a64;
use super::super::drive::{drive, Digested};
use super::super::models::TobitModel;
use super::super::summary::Summary;
use super::super::vectors::{NodeStream, NODES, NY, TOBIT_NX};
use super::tobit::{Fusion, Tobit};

/// The example's shared bucket: ξ₀ = 10, g = 5, b = 30, c_m = 3.
pub fn paper_bucket() -> Result<SharedTokenBucket<NODES>, Error> {
    SharedTokenBucket::new(10, 5, 30, [3; NODES])
}

/// The silence-reading fusion filter as the firmware runs it.
#[derive(Clone, Debug)]
pub struct TobitSilence {
    /// The example's matrices.
    pub model: TobitModel,
    /// The mirror and the fusion filter.
    pub filter: MirroredFusion<f32, TOBIT_NX, NY, NODES>,
}

impl TobitSilence {
    /// The example's fusion filter with [`Silence::TruncatedGaussian`] local filters.
    pub fn paper_example() -> Result<Self, Error> {
        let cfgs = [0, 1, 2]
            .map(|m| Tobit::node_config(m).map(|c| c.with_silence(Silence::TruncatedGaussian)));
        let [a, b, c] = cfgs;
        let fusion = Fusion::new([a?, b?, c?], Vector2::new(5.0, 0.0), Matrix2::identity())?;
        Ok(Self {
            model: TobitModel::paper_example(),
            filter: MirroredFusion::new(fusion, paper_bucket()?),
        })
    }
}

impl Estimator<f32, TOBIT_NX> for TobitSilence {
    type Measurement = [Packet<f32, NY>; NODES];

    /// The stream has no transport losses and no reported levels: the mirror runs on the
    /// transmissions alone.
    fn step(&mut self, k: usize, y: &[Packet<f32, NY>; NODES]) -> Result<(), Error> {
        let _ = k;
        let m = &self.model;
        self.filter.step_matrices(
            &m.a,
            &m.bqb,
            &m.c,
            &m.r,
            &TriggeredPackets {
                packets: *y,
                level: None,
            },
        )
    }

    fn estimate(&self) -> &Estimate<f32, TOBIT_NX> {
        self.filter.fusion().estimate()
    }
}

/// The same digest as the paper's filter's: x̂^g, P^g, then every node's x̂_m, P̄_m.
impl Digested<TOBIT_NX> for TobitSilence {
    fn censored(y: &Vector2<f32>) -> bool {
        y.iter().any(|&v| v <= 0.0)
    }

    fn digest(&self, h: &mut Fnv1a64) {
        h.estimate(self.estimate().state(), self.estimate().covariance());
        for m in 0..NODES {
            if let Some(e) = self.filter.fusion().local_estimate(m) {
                h.estimate(e.state(), e.covariance());
            }
        }
    }
}

/// The silence-reading fusion filter over the three-node Tobit stream.
pub fn run_tobit_silence(stream: &NodeStream<'_>, steps: usize) -> Summary {
    drive(
        "tobit-silence",
        stream.instants(),
        steps,
        TobitSilence::paper_example,
    )
}
