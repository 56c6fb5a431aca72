//! The evaluation beside the loop, never inside an estimator: channel-sim's truth messages
//! kept in a ring by instant (every estimator's squared error against them is its
//! [`Lane`](super::lane::Lane)'s).

use crate::transport::Transport;
use estpipe_wire::MAX_NX;
use estpipe_wire::WIRE_VERSION;

/// Instants of truth kept: the truth of k must still be there when k's estimates are out.
const TRUTH_RING: usize = 1024;

/// Truth by instant, and the truths that were missing or not usable.
pub(super) struct Scores {
    truth_k: Box<[u32; TRUTH_RING]>,
    truth_x: Box<[[f64; MAX_NX]; TRUTH_RING]>,
    truth_stream: u64,
    /// Processed instants whose truth was missing.
    pub(super) truth_missing: u64,
    /// Received truths with a non-finite component (not scored).
    pub(super) truth_nonfinite: u64,
}

impl Scores {
    /// No truth yet.
    pub(super) fn new() -> Self {
        Self {
            truth_k: Box::new([u32::MAX; TRUTH_RING]),
            truth_x: Box::new([[0.0; MAX_NX]; TRUTH_RING]),
            truth_stream: 0,
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

    /// Whether `truth` (its first `nx` values) can score the estimates. A truth with a
    /// non-finite component (a publisher's bug, or a plant that overflowed) is no sample:
    /// counted and left out, so it cannot turn every MSE into NaN.
    pub(super) fn usable(&mut self, truth: &[f64; MAX_NX], nx: usize) -> bool {
        if truth[..nx].iter().any(|v| !v.is_finite()) {
            self.truth_nonfinite += 1;
            return false;
        }
        true
    }
}
