//! `ikf`: the intermittent Kalman filter (Sinopoli et al., 2004), the channel-aware baseline.
//!
//! It predicts at every instant and updates with each node's measurement only when that
//! packet was delivered; a dropped packet is simply missing information (what the drop itself
//! says about the state, as in the occlusion model, is ignored). It sees exactly what crosses
//! the channel, so it runs in evaluation and in the real-time loop alike. Same filter code as
//! [`super::kf`] (estimator-core's `KalmanFilter`, Joseph form), fed the channel's output.
//!
//! Applies to every spec with a linear model. Diagnostics: `trace_p`.

use std::sync::Arc;

use estpipe_spec::EstimatorSpec;

use super::adapter::name;
use super::kf::linear_kf;
use super::{BuildOptions, RunStart};
use crate::Estimator;

/// Builds `ikf` for a spec with a linear model.
pub fn build(
    spec: &Arc<EstimatorSpec>,
    options: &BuildOptions,
    _start: &RunStart<'_>,
) -> anyhow::Result<Vec<Box<dyn Estimator>>> {
    Ok(linear_kf(spec, name!("ikf"), false, options.gate)?
        .into_iter()
        .collect())
}
