//! The estimator interface shared by `eval` (in-process Monte Carlo), `run` (the real-time
//! loop over shared memory) and `replay`: one dispatch, so the three can never disagree.

use channel_sim::Observation;

/// An estimator as the application drives it (f64, dynamic dimensions at this level; the
/// const-generic core types live inside each implementation).
pub trait Estimator: Send {
    /// Stable lower-case name (`kf`, `ikf`, `cce`, …): the key in JSON, CSV and plots.
    fn name(&self) -> &'static str;
    /// Processes instant `k ≥ 1` given every node's observation of that instant (dropped
    /// packets included). On error the estimator keeps its previous state.
    fn step(&mut self, k: u32, obs: &[Observation]) -> Result<(), estimator_core::Error>;
    /// Writes the current estimate x̂_k into `out[..nx]`.
    fn estimate(&self, out: &mut [f64]);
}
