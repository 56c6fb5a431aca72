//! Late packets on the occlusion stream: IKF and ADF under the fixed-lag layer with a lag of
//! [`LAG`] instants ([`drive_lag`]), the model borrowed (the layer keeps `LAG + 1` copies of
//! the estimator, which then hold a reference each instead of the model).

use estimator_core::filter::{AssumedDensityFilter, IntermittentKalmanFilter};
use estimator_core::{LagCounts, OnModel};

use super::super::drive::Digested;
use super::super::lag::{drive_lag, LAG};
use super::super::models::{model, occlusion, prior, Model};
use super::super::summary::Summary;
use super::super::vectors::{Link, Stream, NX, NY};

/// The intermittent Kalman filter on a borrowed seed 001 model.
pub type IkfOn<'m> = OnModel<&'m Model, IntermittentKalmanFilter<f32, NX>, NY>;
/// The assumed-density filter on a borrowed seed 001 model.
pub type AdfOn<'m> = OnModel<&'m Model, AssumedDensityFilter<f32, NX, 4>, NY>;

impl Digested<NX> for IkfOn<'_> {}

/// The digest covers the region label, x̂_k and P_k (as `adf`'s).
impl Digested<NX> for AdfOn<'_> {
    fn label(&self) -> Option<usize> {
        Some(self.filter.label())
    }
}

/// IKF under `FixedLag<_, _, 8>` over the occlusion stream with packets late by the pattern
/// of [`lateness`](super::super::lateness); its summary and the layer's counts.
pub fn run_ikf_lag8_counts(stream: &Stream<'_>, steps: usize) -> (Summary, LagCounts) {
    let m = model();
    let n = stream.steps as usize;
    drive_lag::<1, NX, LAG, _>("ikf-lag8", stream.instants(Link::Channel), n, steps, || {
        let (x0, p0) = prior();
        Ok(IkfOn::new(
            m.as_ref().map_err(|e| *e)?,
            IntermittentKalmanFilter::new(x0, p0)?,
        ))
    })
}

/// ADF under `FixedLag<_, _, 8>` over the occlusion stream, as [`run_ikf_lag8_counts`].
pub fn run_adf_lag8_counts(stream: &Stream<'_>, steps: usize) -> (Summary, LagCounts) {
    let m = model();
    let n = stream.steps as usize;
    drive_lag::<1, NX, LAG, _>("adf-lag8", stream.instants(Link::Channel), n, steps, || {
        let (x0, p0) = prior();
        Ok(AdfOn::new(
            m.as_ref().map_err(|e| *e)?,
            AssumedDensityFilter::new(x0, p0, occlusion()?)?,
        ))
    })
}
