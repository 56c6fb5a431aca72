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
    /// Reports named per-step diagnostics of the current step (e.g. `"trace_p"`, the nn
    /// estimator's `"bound_trace"`) by calling `sink(name, value)`; called at k = 0 and after
    /// every successful step. `eval` averages each name over runs per k and writes it as an
    /// array into the estimator's JSON entry. Default: none.
    fn diagnostics(&self, _sink: &mut dyn FnMut(&'static str, f64)) {}
    /// Evaluation only: diagnostics that need the true state x_k (e.g. the normalised
    /// estimation error squared against the estimator's own covariance), reported like
    /// [`Estimator::diagnostics`] and averaged over runs per k. Takes `&self`, so the truth
    /// can never influence an estimate; a real-time loop never calls it. Default: none.
    fn diagnostics_vs_truth(&self, _truth: &[f64], _sink: &mut dyn FnMut(&'static str, f64)) {}
    /// True for oracle baselines that must be fed the observations *before* the channel
    /// (`Simulation::raw_observations`, every packet delivered) instead of what the channel
    /// delivered, such as the full-information `kf`. Only offline evaluation can do that; a
    /// real-time loop must not offer such an estimator. Default: false.
    fn full_information(&self) -> bool {
        false
    }
}
