//! What one run records while its estimators step: each estimator's squared errors and
//! diagnostics, the channel's counts, and run 0's trajectory for the plots.

use channel_sim::sim::MAX_NX;
use channel_sim::Observation;

use super::{record_estimate, NodeCounts, RunEstimator, RunOutput, Trajectory};

/// One run's records so far.
pub(super) struct Records {
    pub(super) estimators: Vec<RunEstimator>,
    pub(super) channel: Vec<NodeCounts>,
    trajectory: Option<Trajectory>,
    truth_nonfinite: u64,
    /// The estimate being scored (scratch, not allocated per step).
    xhat: [f64; MAX_NX],
}

impl Records {
    /// Empty records of run `run` for the estimators `names` over `horizon` instants.
    pub(super) fn new(
        run: u64,
        names: &[&'static str],
        nx: usize,
        horizon: usize,
        nodes: usize,
    ) -> Self {
        Self {
            estimators: names
                .iter()
                .map(|_| RunEstimator {
                    sq_err: Some(vec![0.0; (horizon + 1) * nx]),
                    ..Default::default()
                })
                .collect(),
            channel: (0..nodes).map(NodeCounts::new).collect(),
            trajectory: (run == 0).then(|| Trajectory::new(names, nx, horizon)),
            truth_nonfinite: 0,
            xhat: [0.0; MAX_NX],
        }
    }

    /// k = 0: the prior against x_0.
    pub(super) fn score_prior(&mut self, estimators: &[Box<dyn crate::Estimator>], truth0: &[f64]) {
        let nx = truth0.len();
        let scored = self.count_truth(truth0);
        for ((e, rec), j) in estimators.iter().zip(&mut self.estimators).zip(0..) {
            let t = truth0;
            record_estimate(
                &**e,
                rec,
                0,
                t,
                scored,
                &mut self.xhat,
                &mut self.trajectory,
                j,
            );
        }
        if let Some(t) = &mut self.trajectory {
            t.truth[..nx].copy_from_slice(truth0);
        }
    }

    /// Steps every estimator still running through instant k and scores it against `truth`;
    /// the full-information ones get the simulation's `raw` slots, the others `received`.
    pub(super) fn step(
        &mut self,
        k: u32,
        estimators: &mut [Box<dyn crate::Estimator>],
        received: &[Observation],
        raw: Option<&[Observation]>,
        truth: &[f64],
    ) {
        let nx = truth.len();
        let scored = self.count_truth(truth);
        if let Some(t) = &mut self.trajectory {
            t.truth[k as usize * nx..][..nx].copy_from_slice(truth);
        }
        for ((e, rec), j) in estimators.iter_mut().zip(&mut self.estimators).zip(0..) {
            if rec.sq_err.is_none() {
                continue;
            }
            let obs: &[Observation] = if e.full_information() {
                match raw {
                    Some(raw) => raw,
                    None => {
                        rec.error = Some("needs the pre-channel observations".into());
                        rec.sq_err = None;
                        continue;
                    }
                }
            } else {
                received
            };
            match e.step(k, obs) {
                Ok(()) => {
                    let (k, xhat, traj) = (k as usize, &mut self.xhat, &mut self.trajectory);
                    record_estimate(&**e, rec, k, truth, scored, xhat, traj, j)
                }
                Err(err) => {
                    rec.error = Some(format!("k = {k}: {err}"));
                    rec.sq_err = None;
                }
            }
        }
    }

    /// Whether `truth` is finite, so a sample of the error; counts it when not.
    fn count_truth(&mut self, truth: &[f64]) -> bool {
        let scored = truth.iter().all(|v| v.is_finite());
        self.truth_nonfinite += u64::from(!scored);
        scored
    }

    pub(super) fn output(self, run: u64) -> RunOutput {
        RunOutput {
            run,
            estimators: self.estimators,
            channel: self.channel,
            trajectory: self.trajectory,
            truth_nonfinite: self.truth_nonfinite,
        }
    }
}
