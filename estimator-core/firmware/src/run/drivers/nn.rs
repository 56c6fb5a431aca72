//! The seed 003 NN estimator over the token-bucket stream.

use estimator_core::filter::nn::NnBoundConfig;
use estimator_core::papers::{Seed003Example, Seed003Nn};
use estimator_core::{Estimate, Estimator, OnModel, Packet, Result};

use super::super::drive::{drive, Digested};
use super::super::summary::Summary;
use super::super::vectors::{Link, Stream, NX, NY};

/// The seed 003 NN estimator in `f32` with the paper's configuration (Section IV) on the
/// example's system, as the token-bucket stream drives it: every record is the estimator's
/// next instant. The estimator counts its instants and refuses a step without counting it,
/// so after a refused step it is one instant behind the stream's `k`; it takes the next
/// record as its next instant rather than refusing every later one as out of order.
#[derive(Clone, Debug)]
pub struct Nn(pub OnModel<Seed003Example, Seed003Nn<f32>, NY>);

impl Estimator<f32, NX> for Nn {
    type Measurement = Packet<f32, NY>;

    fn step(&mut self, _k: usize, y: &Packet<f32, NY>) -> Result<()> {
        let next = self.0.filter.instant() + 1;
        self.0.step(next, y)
    }

    fn estimate(&self) -> &Estimate<f32, NX> {
        self.0.estimate()
    }
}

/// The digest covers x̂_k and the bound P̄_k.
impl Digested<NX> for Nn {}

/// The NN estimator over the token-bucket stream.
pub fn run_nn(stream: &Stream<'_>, steps: usize) -> Summary {
    drive("nn", stream.instants(Link::Channel), steps, || {
        let nn = Seed003Nn::seed003(NnBoundConfig::seed003_example())?;
        Ok(Nn(OnModel::new(Seed003Example, nn)))
    })
}
