//! The seed 001 estimators over the occlusion stream: what an occlusion-stream estimator is
//! ([`OcclusionEstimator`]), how the driver runs one with its model ([`OnModel`]), and the five
//! of them (KF on the lossless link, IKF, CCE, ADF, KF-IO) with their `run_<name>`.

use estimator_core::filter::{
    AssumedDensityFilter, CrossCoupledEstimator, IntermittentKalmanFilter, KalmanFilter, KfIo,
};
use estimator_core::gsum::GaussSum;
use estimator_core::Error;
use nalgebra::{Matrix3, Vector2, Vector3};

use super::super::digest::Fnv1a64;
use super::super::drive::{drive, Driven};
use super::super::models::{model, occlusion, prior, Model};
use super::super::summary::Summary;
use super::super::vectors::{Link, Stream, NX};

/// An estimator of the occlusion stream: one instant `k` with the measurement or `None` on a
/// dropout; returns the region-label estimate (0 for estimators that have none).
pub trait OcclusionEstimator {
    /// One instant.
    fn step(&mut self, m: &Model, k: usize, y: Option<&Vector2<f32>>) -> Result<usize, Error>;
    /// Current x̂_k.
    fn state(&self) -> &Vector3<f32>;
    /// Current P_k.
    fn covariance(&self) -> &Matrix3<f32>;
}

/// An occlusion-stream estimator with its model, as the driver runs it; the digest covers
/// the label, x̂_k and P_k.
#[derive(Clone, Debug)]
pub struct OnModel<E> {
    /// Seed 001's model.
    pub model: Model,
    /// The estimator.
    pub est: E,
}

impl<E: OcclusionEstimator> OnModel<E> {
    /// `est` on seed 001's model.
    pub fn new(est: E) -> Result<Self, Error> {
        Ok(Self {
            model: model()?,
            est,
        })
    }
}

impl<E: OcclusionEstimator> Driven<1> for OnModel<E> {
    const LABELS: bool = true;
    // Not inlined into the driver's loop: the step's temporaries then live only while it
    // runs (measured: adf 4 152 -> 4 048 B peak stack, the others equal or lower).
    #[inline(never)]
    fn step(&mut self, k: usize, [y]: [Option<&Vector2<f32>>; 1]) -> Result<usize, Error> {
        self.est.step(&self.model, k, y)
    }
    fn digest(&self, h: &mut Fnv1a64) {
        h.estimate(self.est.state(), self.est.covariance());
    }
    fn x(&self) -> &[f32] {
        self.est.state().as_slice()
    }
}

impl OcclusionEstimator for KalmanFilter<f32, NX> {
    fn step(&mut self, m: &Model, k: usize, y: Option<&Vector2<f32>>) -> Result<usize, Error> {
        match y {
            Some(y) => KalmanFilter::step(self, m, k, y),
            None => self.predict(m, k.saturating_sub(1)),
        }
        .map(|()| 0)
    }
    fn state(&self) -> &Vector3<f32> {
        self.estimate().state()
    }
    fn covariance(&self) -> &Matrix3<f32> {
        self.estimate().covariance()
    }
}

impl OcclusionEstimator for IntermittentKalmanFilter<f32, NX> {
    fn step(&mut self, m: &Model, k: usize, y: Option<&Vector2<f32>>) -> Result<usize, Error> {
        IntermittentKalmanFilter::step(self, m, k, y).map(|()| 0)
    }
    fn state(&self) -> &Vector3<f32> {
        self.estimate().state()
    }
    fn covariance(&self) -> &Matrix3<f32> {
        self.estimate().covariance()
    }
}

/// The Kalman filter on a lossless link: every instant's sensor measurement is used,
/// dropped or not (the reference the other estimators are compared with).
pub fn run_kf(stream: &Stream<'_>, steps: usize) -> Summary {
    drive("kf", stream.instants(Link::Lossless), steps, || {
        let (x0, p0) = prior();
        OnModel::new(KalmanFilter::new(x0, p0)?)
    })
}

/// The intermittent Kalman filter: updates on delivered instants, predicts through dropouts.
pub fn run_ikf(stream: &Stream<'_>, steps: usize) -> Summary {
    drive("ikf", stream.instants(Link::Channel), steps, || {
        let (x0, p0) = prior();
        OnModel::new(IntermittentKalmanFilter::new(x0, p0)?)
    })
}

/// The CCE as configured for the stream: N = 15 Gaussians per region, KL-optimal σ̂.
pub type Cce = CrossCoupledEstimator<f32, NX, 1, 4, 15>;

impl OcclusionEstimator for Cce {
    fn step(&mut self, m: &Model, k: usize, y: Option<&Vector2<f32>>) -> Result<usize, Error> {
        Cce::step(self, m, k, y)
    }
    fn state(&self) -> &Vector3<f32> {
        self.estimate().state()
    }
    fn covariance(&self) -> &Matrix3<f32> {
        self.estimate().covariance()
    }
}

/// The cross-coupled estimator (seed 001, Algorithms 1-2).
pub fn run_cce(stream: &Stream<'_>, steps: usize) -> Summary {
    drive("cce", stream.instants(Link::Channel), steps, || {
        let (x0, p0) = prior();
        let g = GaussSum::<f32, 1, 15>::uniform()?;
        OnModel::new(Cce::new(x0, p0, occlusion()?, &g)?)
    })
}

/// The assumed-density filter with exact interval likelihoods (the product's improvement).
pub type Adf = AssumedDensityFilter<f32, NX, 4>;

impl OcclusionEstimator for Adf {
    fn step(&mut self, m: &Model, k: usize, y: Option<&Vector2<f32>>) -> Result<usize, Error> {
        Adf::step(self, m, k, y)
    }
    fn state(&self) -> &Vector3<f32> {
        self.estimate().state()
    }
    fn covariance(&self) -> &Matrix3<f32> {
        self.estimate().covariance()
    }
}

/// The assumed-density filter over the stream.
pub fn run_adf(stream: &Stream<'_>, steps: usize) -> Summary {
    drive("adf", stream.instants(Link::Channel), steps, || {
        let (x0, p0) = prior();
        OnModel::new(Adf::new(x0, p0, occlusion()?)?)
    })
}

/// The linear MMSE filter with Bernoulli arrivals (KF-IO, built as in docs/design.md, Seed 001).
pub type KfIoF32 = KfIo<f32, NX, 4>;

impl OcclusionEstimator for KfIoF32 {
    fn step(&mut self, m: &Model, k: usize, y: Option<&Vector2<f32>>) -> Result<usize, Error> {
        KfIoF32::step(self, m, k, y).map(|()| 0)
    }
    fn state(&self) -> &Vector3<f32> {
        self.estimate().state()
    }
    fn covariance(&self) -> &Matrix3<f32> {
        self.estimate().covariance()
    }
}

/// KF-IO over the stream.
pub fn run_kf_io(stream: &Stream<'_>, steps: usize) -> Summary {
    drive("kf-io", stream.instants(Link::Channel), steps, || {
        let (x0, p0) = prior();
        OnModel::new(KfIoF32::new(x0, p0, occlusion()?)?)
    })
}
