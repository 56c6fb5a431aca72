//! Channel stages: what happens to the sensors' measurements between the plant and the
//! estimator.
//!
//! A scenario holds a list of [`StageSpec`]s (configuration). Each run builds a fresh,
//! stateful [`Stage`] from every spec and applies them in list order to all nodes'
//! observations of an instant at once, so that resources shared by nodes (a token bucket
//! shared by sensors, seed 004 eqs. 16-18) fit the same interface as per-node effects.
//!
//! Before the first stage every observation holds the raw measurement z_{m,k} and
//! `delivered == true`. A stage may censor `y`, drop the packet ([`drop_packet`]) and set
//! `FLAG_*` bits; it never resurrects a dropped packet. Stages should draw the same random
//! numbers whatever happened upstream, so that runs stay comparable across channel settings.
//!
//! The stages: [`occlusion`] (seed 001, eqs. 2-3), [`token_bucket`] (one bucket per node,
//! seed 003 eqs. 2-3), [`tobit`] censoring (seed 004 eq. 2), [`event_trigger`] (seed 004's
//! triggers sharing one token bucket, eqs. 11-20) and random [`loss`] (Bernoulli,
//! Gilbert–Elliott). Random numbers come from the run's channel stream
//! ([`crate::rng::Stream::Channel`]), never from the plant's.

pub mod event_trigger;
pub mod loss;
pub mod occlusion;
pub mod tobit;
pub mod token_bucket;

use std::any::Any;
use std::fmt::Debug;

use crate::rng::SimRng;
use crate::sim::{Observation, MAX_NY};

/// Configuration of one channel stage; builds the per-run state.
pub trait StageSpec: Send + Sync + Debug {
    /// Short stable name (`bernoulli`, `gilbert-elliott`, `occlusion`, …).
    fn name(&self) -> &'static str;
    /// A fresh stage for one run over `nodes` sensor nodes.
    fn build(&self, nodes: usize) -> Box<dyn Stage>;
    /// For downcasting to the concrete spec (estimators read channel parameters this way).
    fn as_any(&self) -> &dyn Any;
    /// Writes what an estimator may know of this stage into `k` (the occlusion regions, the
    /// buckets, the triggers, the censoring thresholds): the stage's part of the scenario's
    /// [`EstimatorSpec`](estpipe_spec::EstimatorSpec). Default: nothing, for a stage whose
    /// outcome an estimator cannot predict (a random loss).
    fn knowledge(&self, _k: &mut estpipe_spec::channel::ChannelKnowledge) {}
    /// Parameters accepted although they violate the source paper's own conditions (accepted
    /// only by an explicit opt-in), one line each: the evaluation prints them. Default: none.
    fn warnings(&self) -> Vec<String> {
        Vec::new()
    }
}

/// A channel stage's state within one run.
pub trait Stage: Send {
    /// Acts on every node's observation of instant `k`; `truth` is x_k (state-dependent
    /// channels such as occlusion need it).
    fn apply(&mut self, k: u32, truth: &[f64], obs: &mut [Observation], rng: &mut SimRng);
}

/// Marks `obs` as not delivered (measurement cleared) and adds `flag`.
pub fn drop_packet(obs: &mut Observation, flag: u32) {
    obs.delivered = false;
    obs.y = [0.0; MAX_NY];
    obs.flags |= flag;
    obs.tokens = None;
}
