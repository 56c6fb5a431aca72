//! The estimator interface shared by `eval` (in-process Monte Carlo), `run` (the real-time
//! loop over shared memory) and `replay`: one dispatch, so the three can never disagree.

use estpipe_wire::Observation;

/// What [`Estimator::covariance`] wrote.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CovarianceKind {
    /// Nothing (NaN): the estimator keeps no covariance.
    None,
    /// The estimator's error covariance P_k.
    Estimate,
    /// An upper bound on the error covariance (the NN estimator, the Tobit filters).
    Bound,
}

impl CovarianceKind {
    /// The wire encoding, [`Estimate::cov_kind`](estpipe_wire::Estimate::cov_kind).
    pub fn wire(self) -> u32 {
        match self {
            Self::None => estpipe_wire::COV_NONE,
            Self::Estimate => estpipe_wire::COV_ESTIMATE,
            Self::Bound => estpipe_wire::COV_BOUND,
        }
    }
}

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
    /// Writes the covariance of the current estimate, row-major, into `out[..nx·nx]` and
    /// says what it is (the error covariance, or the bound the estimator's paper propagates).
    /// Default: NaN and [`CovarianceKind::None`], for an estimator that has none.
    fn covariance(&self, out: &mut [f64]) -> CovarianceKind {
        out.fill(f64::NAN);
        CovarianceKind::None
    }
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
