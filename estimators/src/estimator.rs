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

/// What [`Estimator::fold_late`] made of a late slot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LateFold {
    /// Folded in: the estimate is the one the slot would have given on time.
    Folded,
    /// Nothing new (the instant's slot of that node was already known).
    Unchanged,
    /// Older than the estimator's history (`--lag`), or an estimator without one: dropped.
    TooOld,
    /// The estimator refused the re-step; it kept its estimate.
    Refused,
}

/// An estimator as the application drives it (f64, dynamic dimensions at this level; the
/// const-generic core types live inside each implementation).
pub trait Estimator: Send {
    /// Stable lower-case name (`kf`, `ikf`, `cce`, …): the key in JSON, CSV and plots.
    fn name(&self) -> &'static str;
    /// Processes instant `k ≥ 1` given every node's observation of that instant (dropped
    /// packets included). On error the estimator keeps its previous state.
    fn step(&mut self, k: u32, obs: &[Observation]) -> Result<(), estimator_core::Error>;
    /// Keeps the history of `--lag lag` from now on (called once, before the first step;
    /// docs/pipeline.md "Late packets"); `false` for an estimator that keeps none (its late
    /// slots are then [`LateFold::TooOld`]). Default: none.
    fn set_lag(&mut self, _lag: u32) -> bool {
        false
    }
    /// Folds slots of instant `k` that arrived after `k` was stepped into the estimate, as if
    /// they had come on time (the core's fixed-lag layer, docs/pipeline.md "Late packets"):
    /// `obs` is every node's observation of `k`, lost (`FLAG_IPC_LOST`) except the late ones.
    /// Default: [`LateFold::TooOld`], for an estimator that keeps no history.
    fn fold_late(&mut self, _k: u32, _obs: &[Observation]) -> LateFold {
        LateFold::TooOld
    }
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
