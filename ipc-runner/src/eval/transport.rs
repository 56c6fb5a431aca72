//! `eval`'s transport stage after the channel (module docs of [`super`]): slots lost
//! (`--transport-loss`) or delayed (`--transport-delay`) on their way to the estimators, and
//! the late ones handed on when they arrive.

use channel_sim::sim::MAX_NODES;
use channel_sim::Observation;
use estpipe_wire::FLAG_IPC_LOST;

use super::{transport_lost, EvalOptions, NodeCounts, RunEstimator};

/// The transport of one run.
pub(super) struct Transport<'o> {
    options: &'o EvalOptions,
    run: u64,
    /// Whether there is a stage at all: without one the channel's slots go through as they are.
    on: bool,
    after: heapless::Vec<Observation, MAX_NODES>,
    /// Late slots in flight: (the instant after whose step it arrives, the slot).
    in_flight: Vec<(u32, Observation)>,
}

impl<'o> Transport<'o> {
    pub(super) fn new(options: &'o EvalOptions, run: u64) -> Self {
        Self {
            options,
            run,
            on: options.transport_loss > 0.0 || options.transport_delay.is_some(),
            after: heapless::Vec::new(),
            in_flight: Vec::new(),
        }
    }

    /// What the estimators receive of instant k's slots `obs`; the losses and delays are
    /// counted in `channel`.
    pub(super) fn pass<'a>(
        &'a mut self,
        obs: &'a [Observation],
        k: u32,
        channel: &mut [NodeCounts],
    ) -> &'a [Observation] {
        if !self.on {
            return obs;
        }
        let options = self.options;
        self.after.clear();
        let nodes = obs.len() as u64;
        for (o, counts) in obs.iter().zip(channel) {
            let seq = u64::from(o.k - 1) * nodes + u64::from(o.node);
            let mut o = *o;
            if options.transport_loss > 0.0
                && transport_lost(options.seed, self.run, seq, options.transport_loss)
            {
                counts.transport_lost += 1;
                let flags = if options.transport_loss_unmarked {
                    0
                } else {
                    FLAG_IPC_LOST
                };
                o = Observation::dropped(o.k, o.node, o.ny, flags);
            } else if let Some(delay) = &options.transport_delay {
                let d = delay.of(options.seed, self.run, seq);
                if d > 0 {
                    counts.transport_late += 1;
                    counts.transport_too_old += u64::from(d > options.lag);
                    self.in_flight.push((k + d - 1, o));
                    o = Observation::dropped(o.k, o.node, o.ny, FLAG_IPC_LOST);
                }
            }
            let _ = self.after.push(o);
        }
        &self.after
    }

    /// The late slots arriving now, after instant k was stepped and scored (delay module
    /// docs): folded in by estimators with a history, the improvement seen from k + 1 on.
    pub(super) fn deliver(
        &mut self,
        k: u32,
        nodes: usize,
        estimators: &mut [Box<dyn crate::Estimator>],
        records: &[RunEstimator],
    ) {
        if !self.in_flight.is_empty() && self.options.lag > 0 {
            fold_arrivals(k, nodes, &mut self.in_flight, estimators, records);
        }
        self.in_flight.retain(|(at, _)| *at > k);
    }
}

/// Hands every slot of `in_flight` arriving after instant `k` to the estimators still running
/// (each slot with the other nodes of its instant lost, [`crate::Estimator::fold_late`]).
fn fold_arrivals(
    k: u32,
    nodes: usize,
    in_flight: &mut [(u32, Observation)],
    estimators: &mut [Box<dyn crate::Estimator>],
    records: &[RunEstimator],
) {
    // Oldest instant first, as a receiver would order what it holds.
    in_flight.sort_by_key(|(at, o)| (*at, o.k, o.node));
    for (_, o) in in_flight.iter().filter(|(at, _)| *at == k) {
        let mut obs: heapless::Vec<Observation, MAX_NODES> = heapless::Vec::new();
        for n in 0..nodes {
            let lost = Observation::dropped(o.k, n as u8, o.ny, FLAG_IPC_LOST);
            let _ = obs.push(if n == usize::from(o.node) { *o } else { lost });
        }
        for (e, rec) in estimators.iter_mut().zip(records) {
            if rec.sq_err.is_some() && !e.full_information() {
                e.fold_late(o.k, &obs);
            }
        }
    }
}
