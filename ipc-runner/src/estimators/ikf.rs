//! `ikf`: the intermittent Kalman filter (Sinopoli et al., 2004), the channel-aware baseline.
//!
//! It predicts at every instant and updates with each node's measurement only when that
//! packet was delivered; a dropped packet is simply missing information (what the drop itself
//! says about the state, as in the occlusion model, is ignored). It sees exactly what crosses
//! the channel, so it runs in evaluation and in the real-time loop alike. Same filter code as
//! [`super::kf`] (estimator-core's `KalmanFilter`, Joseph form), fed the channel's output.
//!
//! Applies to every scenario whose plant offers a linear description. Diagnostics: `trace_p`.

use channel_sim::Scenario;

use super::kf::linear_kf;
use super::EvalOptions;
use crate::Estimator;

/// Builds `ikf` for a composed scenario with a linear description.
pub fn build(
    scenario: &dyn Scenario,
    options: &EvalOptions,
    _seed: u64,
    _run: u64,
) -> anyhow::Result<Vec<Box<dyn Estimator>>> {
    Ok(linear_kf(scenario, "ikf", false, options.gate)?
        .into_iter()
        .collect())
}
