//! The work of one instant, in latency order: step every estimator, publish its estimate,
//! then — with the estimates out — record the histograms, score against the truth, record
//! the trajectories and loan the next instant's samples.

use crate::latency::Latency;
use crate::transport::Transport;
use crate::Estimator;
use anyhow::Result;
use estpipe_wire::Observation;
use estpipe_wire::MAX_NX;
use estpipe_wire::{self as wire, Estimate, COV_LEN, WIRE_VERSION};

use super::args::RunArgs;
use super::publish::Publisher;
use super::report::EstimatorReport;
use super::trajectories::Trajectories;
use super::truth::Scores;

/// The slot that completed the current instant, as the receive path saw it.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct SlotTimes {
    /// The publisher's send time of the last slot (0: unusable, not a latency).
    pub(super) send_ns: u64,
    /// When this runner received it.
    pub(super) recv_ns: u64,
    /// The stream of the last slot.
    pub(super) stream_id: u64,
}

/// The estimators and everything that happens to their estimates.
pub(super) struct Runner {
    /// Replaced by a fresh set when a new stream starts.
    pub(super) estimators: Vec<Box<dyn Estimator>>,
    nx: usize,
    /// The latest estimate of every estimator.
    xhat: Vec<[f64; MAX_NX]>,
    /// The covariance an estimator wrote (row-major), before it is packed on the wire.
    p_full: [f64; MAX_NX * MAX_NX],
    /// Per estimator, the diagonal of its latest covariance (recorded for the plot's bands).
    var: Vec<[f64; MAX_NX]>,
    /// Per estimator, what its latest covariance is (the estimate message's `cov_kind`).
    cov_kind: Vec<u32>,
    rejected: Vec<u64>,
    names: Vec<[u8; 16]>,
    /// Per estimator, when its step of the current instant started and ended (recorded in the
    /// histogram after publishing).
    step_ns: Vec<(u64, u64)>,
    est_seq: u64,
    pub(super) out: Publisher,
    pub(super) latency: Latency,
    pub(super) scores: Scores,
    pub(super) traj: Trajectories,
    record_cap: usize,
    /// Streams followed so far (1 + restarts).
    pub(super) session: u32,
    /// Set per slot by the receive path.
    pub(super) slot: SlotTimes,
    /// The latest instant processed.
    pub(super) last_k: u32,
    /// Per estimator, the late slots folded in since its last estimate and the oldest instant
    /// they belonged to (the estimate message's `late_folded`, `revised_from`).
    revised: Vec<(u32, u32)>,
    /// Per estimator, what it made of every late slot of the run (the report's `late`).
    late: Vec<super::report::LateCount>,
    /// The live view's tap (docs/view.md).
    tap: crate::view::ViewTap,
}

impl Runner {
    /// For `estimators` on a scenario with `nx` states and `nodes` nodes, publishing and
    /// recording as `args` asks.
    pub(super) fn new(
        t: &Transport,
        args: &RunArgs,
        estimators: Vec<Box<dyn Estimator>>,
        nx: usize,
        nodes: u8,
    ) -> Result<Self> {
        let n_est = estimators.len();
        let record_cap = args.steps as usize;
        let names: Vec<[u8; 16]> = estimators
            .iter()
            .map(|e| Estimate::encode_name(e.name()))
            .collect();
        let traj = Trajectories::with_capacity(
            record_cap,
            nx,
            estimators.iter().map(|e| e.name().to_string()).collect(),
            if args.slots_csv.is_some() {
                record_cap
            } else {
                0
            },
            usize::from(nodes),
            args.mcap.is_some(),
        );
        let out = Publisher::new(t, args, &names)?;
        Ok(Self {
            estimators,
            nx,
            xhat: vec![[0.0; MAX_NX]; n_est],
            p_full: [0.0; MAX_NX * MAX_NX],
            var: vec![[f64::NAN; MAX_NX]; n_est],
            cov_kind: vec![0; n_est],
            rejected: vec![0; n_est],
            names,
            step_ns: vec![(0, 0); n_est],
            est_seq: 0,
            out,
            latency: Latency::new(),
            scores: Scores::new(n_est),
            traj,
            record_cap,
            session: 1,
            slot: SlotTimes::default(),
            last_k: 0,
            revised: vec![(0, 0); n_est],
            late: vec![Default::default(); n_est],
            tap: args.view_tap.clone(),
        })
    }

    /// Steps every estimator on instant `k` and publishes the estimates; the evaluation
    /// against truth (MSE, recording) runs after publishing, off the latency path.
    #[inline]
    pub(super) fn on_instant(&mut self, t: &Transport, k: u32, obs: &[Observation]) {
        let done_ns = self.step_and_publish(t, k, obs);
        // Statistics after the estimates are out: a histogram bucket can be a cache miss.
        for &(t0, t1) in &self.step_ns {
            Latency::record(&mut self.latency.step, t0, t1);
        }
        // A slot's unusable send time (0, or in the future) is not a latency.
        if self.slot.send_ns != 0 {
            Latency::record(&mut self.latency.end_to_end, self.slot.send_ns, done_ns);
        }
        self.last_k = k;
        // The slot log (for `replay`) in instant order, whatever order the nodes' slots
        // came in; a slot the runner lost is missing from it, which `replay` reads as lost.
        for o in obs {
            if o.flags & wire::FLAG_IPC_LOST == 0
                && self.traj.slots.len() < self.traj.slots.capacity()
            {
                self.traj.slots.push(*o);
            }
        }
        self.evaluate(t, k, done_ns, obs);
        self.out.loan_ahead(t);
    }

    /// The latency path of instant `k`: every estimator stepped and its estimate published;
    /// returns when the last was out. Never inlined, so that an instruction count can tell
    /// it from what follows it (BENCHMARKS.md, "The live view's cost to the loop").
    #[inline(never)]
    fn step_and_publish(&mut self, t: &Transport, k: u32, obs: &[Observation]) -> u64 {
        let nx = self.nx;
        for (e, est) in self.estimators.iter_mut().enumerate() {
            let t0 = wire::monotonic_ns();
            let status = match est.step(k, obs) {
                Ok(()) => 0,
                Err(_) => {
                    self.rejected[e] += 1;
                    1
                }
            };
            let xhat = &mut self.xhat[e];
            est.estimate(&mut xhat[..nx]);
            let cov_kind = est.covariance(&mut self.p_full[..nx * nx]);
            let t1 = wire::monotonic_ns();
            for (i, v) in self.var[e][..nx].iter_mut().enumerate() {
                *v = self.p_full[i * nx + i];
            }
            self.cov_kind[e] = cov_kind.wire();
            self.step_ns[e] = (t0, t1);
            let seq = self.est_seq;
            self.est_seq += 1;
            let (late_folded, revised_from) = std::mem::take(&mut self.revised[e]);
            if !self.out.is_on() {
                continue;
            }
            let mut msg = Estimate {
                version: WIRE_VERSION,
                k,
                stream_id: self.slot.stream_id,
                seq,
                estimator: e as u32,
                nx: nx as u32,
                name: self.names[e],
                status,
                cov_kind: cov_kind.wire(),
                x: *xhat,
                p: [0.0; COV_LEN],
                slot_send_ns: self.slot.send_ns,
                receive_ns: self.slot.recv_ns,
                step_done_ns: t1,
                late_folded,
                revised_from,
            };
            Estimate::pack_covariance(nx, &self.p_full[..nx * nx], &mut msg.p);
            self.out.send(t, e, msg);
        }
        wire::monotonic_ns()
    }

    /// A slot of instant `k` that arrived after `k` was handed on, within `--lag`: every
    /// estimator folds it into its history (docs/pipeline.md, "Late packets"); the next
    /// estimates carry the revision. `obs` is the instant's observations, the other nodes lost.
    pub(super) fn on_late(&mut self, k: u32, obs: &[Observation]) {
        let each = self.estimators.iter_mut().zip(&mut self.revised);
        for ((est, revised), count) in each.zip(&mut self.late) {
            let r = est.fold_late(k, obs);
            count.add(r);
            if r == crate::LateFold::Folded {
                revised.1 = if revised.0 == 0 { k } else { revised.1.min(k) };
                revised.0 += 1;
            }
        }
        // The slot log keeps the slot, with when it came, so that `replay --lag` folds it in
        // where this run did.
        if let Some(o) = obs.iter().find(|o| o.flags & wire::FLAG_IPC_LOST == 0) {
            self.tap.late(k, o.node);
            self.traj.mark_late((self.session, k), o.node);
            if self.traj.slots.len() < self.traj.slots.capacity() {
                self.traj.slots.push(*o);
                self.traj
                    .late_after
                    .push((self.traj.slots.len() - 1, self.last_k));
            }
        }
    }

    /// Errors against truth and the recorded trajectories of instant `k`, whose estimates
    /// were published at `done_ns`.
    fn evaluate(&mut self, t: &Transport, k: u32, done_ns: u64, obs: &[Observation]) {
        let truth = self.scores.truth(t, k, self.slot.stream_id);
        if self.traj.keys.len() < self.record_cap {
            if self.traj.full {
                // `--mcap`: the covariance again, off the latency path (the loop packed it
                // for the wire only).
                let nx = self.nx;
                // Exactly `nodes` per instant (the assembler hands every node on).
                for n in 0..self.traj.nodes {
                    let o = obs.get(n).copied().unwrap_or_else(|| {
                        Observation::dropped(k, n as u8, 0, wire::FLAG_IPC_LOST)
                    });
                    self.traj.obs.push(o);
                }
                for est in &self.estimators {
                    let kind = est.covariance(&mut self.p_full[..nx * nx]);
                    self.traj.cov.extend_from_slice(&self.p_full[..nx * nx]);
                    self.traj.cov_kind.push(kind.wire());
                }
            }
            self.traj.record(
                (self.session, k),
                [self.slot.send_ns, self.slot.recv_ns, done_ns],
                truth.as_ref(),
                &self.xhat,
                &self.var,
                obs,
            );
        }
        if let Some(x) = &truth {
            self.scores.score(x, &self.xhat, self.nx);
        }
        // The view gets the estimates here, after they are out, from the loop's own copy: a
        // subscriber of its own on `<prefix>/estimates` would make every send deliver to one
        // more queue, on the latency path (docs/view.md, "Cost to the loop").
        if self.tap.is_on() {
            let latency_us = if self.slot.send_ns != 0 && done_ns >= self.slot.send_ns {
                (done_ns - self.slot.send_ns) as f64 * 1e-3
            } else {
                f64::NAN
            };
            for e in 0..self.xhat.len() {
                self.tap.estimate(crate::view::EstimateEvent {
                    k,
                    name: self.names[e],
                    nx: self.nx as u8,
                    x: self.xhat[e],
                    var: self.var[e],
                    cov_kind: self.cov_kind[e],
                    latency_us,
                });
            }
        }
        self.tap.instant(self.session, k, obs, truth.as_ref());
    }

    /// Per-estimator results so far.
    pub(super) fn estimator_reports(&self) -> Vec<EstimatorReport> {
        self.estimators
            .iter()
            .enumerate()
            .map(|(e, est)| EstimatorReport {
                name: est.name().to_string(),
                mse: self.scores.mse(e),
                mse_instants: self.scores.err_n[e],
                rejected: self.rejected[e],
                gate: crate::estimators::gate_counts(&**est)
                    .map(|(tested, rejected)| super::report::GateCount { tested, rejected }),
                late: Some(self.late[e]).filter(|c| *c != Default::default()),
            })
            .collect()
    }
}
