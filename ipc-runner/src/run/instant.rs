//! The work of one instant, in latency order: step every estimator, publish its estimate,
//! then — with the estimates out — record the histograms, score against the truth, record
//! the trajectories and loan the next instant's samples.

use crate::latency::Latency;
use crate::transport::Transport;
use crate::Estimator;
use anyhow::{ensure, Result};
use estpipe_wire::Observation;
use estpipe_wire::MAX_NX;
use estpipe_wire::{self as wire, Estimate, COV_LEN, WIRE_VERSION};

use super::args::RunArgs;
use super::assemble::{Instant, SlotTimes};
use super::lane::Lane;
use super::publish::Publisher;
use super::report::EstimatorReport;
use super::trajectories::Trajectories;
use super::truth::Scores;

/// The estimators (one [`Lane`] each) and everything that happens to their estimates.
pub(super) struct Runner {
    lanes: Vec<Lane>,
    nx: usize,
    /// The covariance an estimator wrote (row-major), before it is packed on the wire.
    p_full: [f64; MAX_NX * MAX_NX],
    est_seq: u64,
    pub(super) out: Publisher,
    pub(super) latency: Latency,
    pub(super) scores: Scores,
    pub(super) traj: Trajectories,
    record_cap: usize,
    /// Streams followed so far (1 + restarts).
    pub(super) session: u32,
    /// The latest instant processed.
    pub(super) last_k: u32,
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
        let record_cap = args.steps as usize;
        let lanes: Vec<Lane> = estimators.into_iter().map(Lane::new).collect();
        let traj = Trajectories::with_capacity(
            record_cap,
            nx,
            lanes
                .iter()
                .map(|l| l.estimator.name().to_string())
                .collect(),
            if args.slots_csv.is_some() {
                record_cap
            } else {
                0
            },
            usize::from(nodes),
            args.mcap.is_some(),
        );
        let names: Vec<[u8; 16]> = lanes.iter().map(|l| l.name).collect();
        let out = Publisher::new(t, args, &names)?;
        Ok(Self {
            lanes,
            nx,
            p_full: [0.0; MAX_NX * MAX_NX],
            est_seq: 0,
            out,
            latency: Latency::new(),
            scores: Scores::new(),
            traj,
            record_cap,
            session: 1,
            last_k: 0,
            tap: args.view_tap.clone(),
        })
    }

    /// A new session (channel-sim restarted): fresh `estimators`, one per lane, in the same
    /// order; the lanes' counts and errors go on.
    pub(super) fn renew(&mut self, estimators: Vec<Box<dyn Estimator>>) -> Result<()> {
        ensure!(
            estimators.len() == self.lanes.len(),
            "{} estimators for a new stream, {} before",
            estimators.len(),
            self.lanes.len()
        );
        for (lane, est) in self.lanes.iter_mut().zip(estimators) {
            lane.renew(est);
        }
        Ok(())
    }

    /// Steps every estimator on the instant and publishes the estimates; the evaluation
    /// against truth (MSE, recording) runs after publishing, off the latency path.
    #[inline]
    pub(super) fn on_instant(&mut self, t: &Transport, i: &Instant<'_>) {
        let done_ns = self.step_and_publish(t, i);
        // Statistics after the estimates are out: a histogram bucket can be a cache miss.
        for lane in &self.lanes {
            Latency::record(&mut self.latency.step, lane.step_ns.0, lane.step_ns.1);
        }
        // A slot's unusable send time (0, or in the future) is not a latency.
        if i.slot.send_ns != 0 {
            Latency::record(&mut self.latency.end_to_end, i.slot.send_ns, done_ns);
        }
        self.last_k = i.k;
        // The slot log (for `replay`) in instant order, whatever order the nodes' slots
        // came in; a slot the runner lost is missing from it, which `replay` reads as lost.
        for o in i.obs {
            if o.flags & wire::FLAG_IPC_LOST == 0
                && self.traj.slots.len() < self.traj.slots.capacity()
            {
                self.traj.slots.push(*o);
            }
        }
        self.evaluate(t, i, done_ns);
        self.out.loan_ahead(t);
    }

    /// The latency path of the instant: every estimator stepped and its estimate published;
    /// returns when the last was out. Never inlined, so that an instruction count can tell
    /// it from what follows it (BENCHMARKS.md, "The live view's cost to the loop").
    #[inline(never)]
    fn step_and_publish(&mut self, t: &Transport, i: &Instant<'_>) -> u64 {
        let nx = self.nx;
        for (e, lane) in self.lanes.iter_mut().enumerate() {
            let t0 = wire::monotonic_ns();
            let est = &mut lane.estimator;
            let status = match est.step(i.k, i.obs) {
                Ok(()) => 0,
                Err(_) => {
                    lane.rejected += 1;
                    1
                }
            };
            est.estimate(&mut lane.xhat[..nx]);
            let cov_kind = est.covariance(&mut self.p_full[..nx * nx]);
            let t1 = wire::monotonic_ns();
            for (j, v) in lane.var[..nx].iter_mut().enumerate() {
                *v = self.p_full[j * nx + j];
            }
            lane.cov_kind = cov_kind.wire();
            lane.step_ns = (t0, t1);
            let seq = self.est_seq;
            self.est_seq += 1;
            let (late_folded, revised_from) = std::mem::take(&mut lane.revised);
            if !self.out.is_on() {
                continue;
            }
            let mut msg = Estimate {
                version: WIRE_VERSION,
                k: i.k,
                stream_id: i.slot.stream_id,
                seq,
                estimator: e as u32,
                nx: nx as u32,
                name: lane.name,
                status,
                cov_kind: lane.cov_kind,
                x: lane.xhat,
                p: [0.0; COV_LEN],
                slot_send_ns: i.slot.send_ns,
                receive_ns: i.slot.recv_ns,
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
        for lane in &mut self.lanes {
            lane.fold_late(k, obs);
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

    /// Errors against truth, the recorded trajectories and the live view of the instant,
    /// whose estimates were published at `done_ns`.
    fn evaluate(&mut self, t: &Transport, i: &Instant<'_>, done_ns: u64) {
        let truth = self.scores.truth(t, i.k, i.slot.stream_id);
        if self.traj.keys.len() < self.record_cap {
            self.record(i, done_ns, truth.as_ref());
        }
        if let Some(x) = &truth {
            if self.scores.usable(x, self.nx) {
                for lane in &mut self.lanes {
                    lane.score(x, self.nx);
                }
            }
        }
        self.view(i, done_ns, truth.as_ref());
    }

    /// Records the instant's trajectories (and with `--mcap` its observations and
    /// covariances).
    fn record(&mut self, i: &Instant<'_>, done_ns: u64, truth: Option<&[f64; MAX_NX]>) {
        if self.traj.full {
            // `--mcap`: the covariance again, off the latency path (the loop packed it for
            // the wire only).
            let nx = self.nx;
            // Exactly `nodes` per instant (the assembler hands every node on).
            for n in 0..self.traj.nodes {
                let o =
                    i.obs.get(n).copied().unwrap_or_else(|| {
                        Observation::dropped(i.k, n as u8, 0, wire::FLAG_IPC_LOST)
                    });
                self.traj.obs.push(o);
            }
            for lane in &self.lanes {
                let kind = lane.estimator.covariance(&mut self.p_full[..nx * nx]);
                self.traj.cov.extend_from_slice(&self.p_full[..nx * nx]);
                self.traj.cov_kind.push(kind.wire());
            }
        }
        let SlotTimes {
            send_ns, recv_ns, ..
        } = i.slot;
        self.traj.record(
            (self.session, i.k),
            [send_ns, recv_ns, done_ns],
            truth,
            self.lanes.iter().map(|l| (&l.xhat, &l.var)),
            i.obs,
        );
    }

    /// The view gets the estimates here, after they are out, from the loop's own copy: a
    /// subscriber of its own on `<prefix>/estimates` would make every send deliver to one
    /// more queue, on the latency path (docs/view.md, "Cost to the loop").
    fn view(&mut self, i: &Instant<'_>, done_ns: u64, truth: Option<&[f64; MAX_NX]>) {
        if self.tap.is_on() {
            let send_ns = i.slot.send_ns;
            let latency_us = if send_ns != 0 && done_ns >= send_ns {
                (done_ns - send_ns) as f64 * 1e-3
            } else {
                f64::NAN
            };
            for lane in &self.lanes {
                self.tap.estimate(crate::view::EstimateEvent {
                    k: i.k,
                    name: lane.name,
                    nx: self.nx as u8,
                    x: lane.xhat,
                    var: lane.var,
                    cov_kind: lane.cov_kind,
                    latency_us,
                });
            }
        }
        self.tap.instant(self.session, i.k, i.obs, truth);
    }

    /// Per-estimator results so far.
    pub(super) fn estimator_reports(&self) -> Vec<EstimatorReport> {
        self.lanes.iter().map(Lane::report).collect()
    }
}
