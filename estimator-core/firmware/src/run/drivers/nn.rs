//! The seed 003 NN estimator over the token-bucket stream.

use estimator_core::filter::nn::{NnBoundConfig, NnTbcpEstimator};
use estimator_core::papers::{Seed003Example, Seed003Nn};
use estimator_core::Error;
use nalgebra::Vector2;

use super::super::digest::Fnv1a64;
use super::super::drive::{drive, Driven};
use super::super::summary::Summary;
use super::super::vectors::{Link, Stream};

/// The seed 003 NN estimator in `f32` with the paper's configuration (Section IV), on the
/// token-bucket stream.
pub type Nn = Seed003Nn<f32>;

/// Step `i` takes instant `k = i + 1`'s observation (`None` when the bucket withheld it) and
/// yields x̂_k; the digest covers x̂_k and the bound P̄_k.
impl Driven<1> for Nn {
    const LABELS: bool = false;
    fn step(&mut self, _k: usize, [y]: [Option<&Vector2<f32>>; 1]) -> Result<usize, Error> {
        NnTbcpEstimator::step(self, &Seed003Example, y).map(|()| 0)
    }
    fn digest(&self, h: &mut Fnv1a64) {
        h.estimate(self.estimate().state(), self.estimate().covariance());
    }
    fn x(&self) -> &[f32] {
        self.estimate().state().as_slice()
    }
}

/// The NN estimator over the token-bucket stream.
pub fn run_nn(stream: &Stream<'_>, steps: usize) -> Summary {
    drive("nn", stream.instants(Link::Channel), steps, || {
        Nn::seed003(NnBoundConfig::seed003_example())
    })
}
