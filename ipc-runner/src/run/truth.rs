//! The evaluation beside the loop, never inside an estimator: channel-sim's truth messages
//! kept in a ring by instant, and every estimator's squared error against them.

use crate::transport::Transport;
use estpipe_wire::MAX_NX;
use estpipe_wire::WIRE_VERSION;

/// Instants of truth kept: the truth of k must still be there when k's estimates are out.
const TRUTH_RING: usize = 1024;

/// Truth by instant and the errors against it.
pub(super) struct Scores {
    truth_k: Box<[u32; TRUTH_RING]>,
    truth_x: Box<[[f64; MAX_NX]; TRUTH_RING]>,
    truth_stream: u64,
    /// Per estimator: the sum of ‖x_k − x̂_k‖² and the instants in it.
    pub(super) sq_err: Vec<f64>,
    pub(super) err_n: Vec<u64>,
    /// Processed instants whose truth was missing.
    pub(super) truth_missing: u64,
    /// Received truths with a non-finite component (not scored).
    pub(super) truth_nonfinite: u64,
}

impl Scores {
    /// For `n_est` estimators.
    pub(super) fn new(n_est: usize) -> Self {
        Self {
            truth_k: Box::new([u32::MAX; TRUTH_RING]),
            truth_x: Box::new([[0.0; MAX_NX]; TRUTH_RING]),
            truth_stream: 0,
            sq_err: vec![0.0; n_est],
            err_n: vec![0; n_est],
            truth_missing: 0,
            truth_nonfinite: 0,
        }
    }

    fn drain(&mut self, t: &Transport) {
        while let Ok(Some(s)) = t.truth_sub.receive() {
            let m = s.payload();
            if m.version != WIRE_VERSION {
                continue;
            }
            let i = m.k as usize % TRUTH_RING;
            self.truth_k[i] = m.k;
            self.truth_x[i] = m.x;
            self.truth_stream = m.stream_id;
        }
    }

    /// The truth of instant `k` of `stream` (after taking in what the truth service has
    /// sent), counted as missing when it is not there.
    pub(super) fn truth(&mut self, t: &Transport, k: u32, stream: u64) -> Option<[f64; MAX_NX]> {
        self.drain(t);
        let i = k as usize % TRUTH_RING;
        let truth =
            (self.truth_k[i] == k && self.truth_stream == stream).then_some(self.truth_x[i]);
        if truth.is_none() {
            self.truth_missing += 1;
        }
        truth
    }

    /// Adds the squared errors of the estimates `xhat` (first `nx` values each) against
    /// `truth`. A truth with a non-finite component (a publisher's bug, or a plant that
    /// overflowed) is no sample: counted and left out, so it cannot turn every MSE into NaN.
    pub(super) fn score(&mut self, truth: &[f64; MAX_NX], xhat: &[[f64; MAX_NX]], nx: usize) {
        if truth[..nx].iter().any(|v| !v.is_finite()) {
            self.truth_nonfinite += 1;
            return;
        }
        for (e, xhat) in xhat.iter().enumerate() {
            let d: f64 = (0..nx).map(|j| (truth[j] - xhat[j]).powi(2)).sum();
            self.sq_err[e] += d;
            self.err_n[e] += 1;
        }
    }

    /// Mean squared error of estimator `e` (NaN before its first scored instant).
    pub(super) fn mse(&self, e: usize) -> f64 {
        if self.err_n[e] > 0 {
            self.sq_err[e] / self.err_n[e] as f64
        } else {
            f64::NAN
        }
    }
}
