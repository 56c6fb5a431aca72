//! The seed 001 estimators over the occlusion stream, each the core filter paired with the
//! stream's model ([`OnModel`]): the KF on the lossless link, IKF, CCE, ADF and KF-IO, with
//! their `run_<name>`.

use estimator_core::filter::{
    AssumedDensityFilter, CrossCoupledEstimator, IntermittentKalmanFilter, KalmanFilter,
    KfIo as KfIoFilter,
};
use estimator_core::gsum::GaussSum;
use estimator_core::OnModel;

use super::super::drive::{drive, Digested};
use super::super::models::{model, occlusion, prior, Model};
use super::super::summary::Summary;
use super::super::vectors::{Link, Stream, NX, NY};

/// The Kalman filter on seed 001's model.
pub type Kf = OnModel<Model, KalmanFilter<f32, NX>, NY>;
/// The intermittent Kalman filter on seed 001's model.
pub type Ikf = OnModel<Model, IntermittentKalmanFilter<f32, NX>, NY>;
/// The CCE as configured for the stream (N = 15 Gaussians per region, KL-optimal σ̂) on seed
/// 001's model.
pub type Cce = OnModel<Model, CrossCoupledEstimator<f32, NX, 1, 4, 15>, NY>;
/// The assumed-density filter on seed 001's model.
pub type Adf = OnModel<Model, AssumedDensityFilter<f32, NX, 4>, NY>;
/// The linear MMSE filter with Bernoulli arrivals (KF-IO) on seed 001's model.
pub type KfIo = OnModel<Model, KfIoFilter<f32, NX, 4>, NY>;

impl Digested<NX> for Kf {}
impl Digested<NX> for Ikf {}
impl Digested<NX> for KfIo {}

/// The digest covers the region label, x̂_k and P_k.
impl Digested<NX> for Cce {
    fn label(&self) -> Option<usize> {
        Some(self.filter.label())
    }
}

/// The digest covers the region label, x̂_k and P_k.
impl Digested<NX> for Adf {
    fn label(&self) -> Option<usize> {
        Some(self.filter.label())
    }
}

/// The Kalman filter on a lossless link: every instant's sensor measurement is used,
/// dropped or not (the reference the other estimators are compared with).
pub fn run_kf(stream: &Stream<'_>, steps: usize) -> Summary {
    drive("kf", stream.instants(Link::Lossless), steps, || {
        let (x0, p0) = prior();
        Ok(Kf::new(model()?, KalmanFilter::new(x0, p0)?))
    })
}

/// The intermittent Kalman filter: updates on delivered instants, predicts through dropouts.
pub fn run_ikf(stream: &Stream<'_>, steps: usize) -> Summary {
    drive("ikf", stream.instants(Link::Channel), steps, || {
        let (x0, p0) = prior();
        Ok(Ikf::new(model()?, IntermittentKalmanFilter::new(x0, p0)?))
    })
}

/// The cross-coupled estimator (seed 001, Algorithms 1-2).
pub fn run_cce(stream: &Stream<'_>, steps: usize) -> Summary {
    drive("cce", stream.instants(Link::Channel), steps, || {
        let (x0, p0) = prior();
        let g = GaussSum::<f32, 1, 15>::uniform()?;
        Ok(Cce::new(
            model()?,
            CrossCoupledEstimator::new(x0, p0, occlusion()?, &g)?,
        ))
    })
}

/// The assumed-density filter with exact interval likelihoods (the product's improvement).
pub fn run_adf(stream: &Stream<'_>, steps: usize) -> Summary {
    drive("adf", stream.instants(Link::Channel), steps, || {
        let (x0, p0) = prior();
        Ok(Adf::new(
            model()?,
            AssumedDensityFilter::new(x0, p0, occlusion()?)?,
        ))
    })
}

/// KF-IO (built as in docs/design.md, Seed 001) over the stream.
pub fn run_kf_io(stream: &Stream<'_>, steps: usize) -> Summary {
    drive("kf-io", stream.instants(Link::Channel), steps, || {
        let (x0, p0) = prior();
        Ok(KfIo::new(model()?, KfIoFilter::new(x0, p0, occlusion()?)?))
    })
}
