//! One estimator's lane through the loop: the estimator, its latest estimate and covariance
//! diagonal, its counters, its step times of the current instant and its error against the
//! truth. The loop holds one [`Lane`] per estimator, in the order the estimators were
//! selected (the estimate message's `estimator` index).

use crate::Estimator;
use estpipe_wire::{Estimate, MAX_NX};

use super::report::{EstimatorReport, GateCount, LateCount};

/// One estimator and everything the loop keeps of it.
pub(super) struct Lane {
    /// Replaced by a fresh one when a new stream starts ([`Lane::renew`]).
    pub(super) estimator: Box<dyn Estimator>,
    /// Its name as the wire carries it.
    pub(super) name: [u8; 16],
    /// Its latest estimate.
    pub(super) xhat: [f64; MAX_NX],
    /// The diagonal of its latest covariance (recorded for the plot's bands).
    pub(super) var: [f64; MAX_NX],
    /// What its latest covariance is (the estimate message's `cov_kind`).
    pub(super) cov_kind: u32,
    /// Steps that returned an error (the estimate message's `status` 1).
    pub(super) rejected: u64,
    /// When its step of the current instant started and ended (recorded in the step
    /// histogram after publishing).
    pub(super) step_ns: (u64, u64),
    /// The late slots folded in since its last estimate and the oldest instant they belonged
    /// to (the estimate message's `late_folded`, `revised_from`).
    pub(super) revised: (u32, u32),
    /// What it made of every late slot of the run (the report's `late`).
    pub(super) late: LateCount,
    /// The sum of ‖x_k − x̂_k‖² over the instants scored against the truth.
    pub(super) sq_err: f64,
    /// The instants in [`Lane::sq_err`].
    pub(super) err_n: u64,
}

impl Lane {
    /// A lane for `estimator`, nothing estimated yet.
    pub(super) fn new(estimator: Box<dyn Estimator>) -> Self {
        Self {
            name: Estimate::encode_name(estimator.name()),
            estimator,
            xhat: [0.0; MAX_NX],
            var: [f64::NAN; MAX_NX],
            cov_kind: 0,
            rejected: 0,
            step_ns: (0, 0),
            revised: (0, 0),
            late: LateCount::default(),
            sq_err: 0.0,
            err_n: 0,
        }
    }

    /// A new session: a fresh estimator, the lane's counts and errors go on.
    pub(super) fn renew(&mut self, estimator: Box<dyn Estimator>) {
        self.estimator = estimator;
    }

    /// A late slot of instant `k` (`obs`, the other nodes lost) folded into the estimator's
    /// history, counted; the next estimate carries the revision.
    pub(super) fn fold_late(&mut self, k: u32, obs: &[estpipe_wire::Observation]) {
        let r = self.estimator.fold_late(k, obs);
        self.late.add(r);
        if r == crate::LateFold::Folded {
            let revised = &mut self.revised;
            revised.1 = if revised.0 == 0 { k } else { revised.1.min(k) };
            revised.0 += 1;
        }
    }

    /// Adds the squared error of the first `nx` values of the latest estimate against
    /// `truth` (a finite one).
    pub(super) fn score(&mut self, truth: &[f64; MAX_NX], nx: usize) {
        let d: f64 = (0..nx).map(|j| (truth[j] - self.xhat[j]).powi(2)).sum();
        self.sq_err += d;
        self.err_n += 1;
    }

    /// Mean squared error (NaN before its first scored instant).
    pub(super) fn mse(&self) -> f64 {
        if self.err_n > 0 {
            self.sq_err / self.err_n as f64
        } else {
            f64::NAN
        }
    }

    /// Its results so far.
    pub(super) fn report(&self) -> EstimatorReport {
        EstimatorReport {
            name: self.estimator.name().to_string(),
            mse: self.mse(),
            mse_instants: self.err_n,
            rejected: self.rejected,
            gate: crate::estimators::gate_counts(&*self.estimator)
                .map(|(tested, rejected)| GateCount { tested, rejected }),
            late: Some(self.late).filter(|c| *c != LateCount::default()),
        }
    }
}
