//! Monte-Carlo evaluation: every estimator that applies to a scenario, over independent runs.
//!
//! One run reads top to bottom in [`run_one`]: start the simulation, build the estimators,
//! then per instant k: the simulation yields the truth and the channel's observations, every
//! estimator steps, and its squared error is recorded. Runs execute in parallel (rayon) and
//! are reduced strictly in run order, so the same seed gives bit-identical results whatever
//! the thread count.
//!
//! A run is *diverged* for an estimator when its estimate becomes non-finite or a step returns
//! an error (the estimator then no longer tracks instant k). Such runs are counted and left
//! out of that estimator's means; the evaluation never stops for them.
//!
//! What a scenario adds to its evaluation lives here too, not in its estimators:
//! [`nn_bound`] (seed 003's assumption check, bound check and bound plot).
//!
//! **Transport losses** (`--transport-loss P`, [`EvalOptions::transport_loss`]): a stage after
//! the channel, outside the scenario, that loses every slot independently with probability
//! `P` before the estimators see it — what a lossy network between sensor and estimator
//! does. Slot `(k, node)` is lost iff `U < P`, `U` uniform from its own SplitMix64 stream of
//! `(seed, run)` indexed by the slot's sequence number ([`transport_lost`]), so the plant's
//! and the channel's random numbers, and the slots lost, are the same whatever the
//! estimators or `P`'s other uses. A lost slot reaches the estimators marked
//! `FLAG_IPC_LOST` (a [`Packet::Lost`](estimator_core::Packet::Lost): no information), or with
//! `--transport-loss-unmarked` as an unflagged dropout (the receiver sees only "no packet").
//! The channel counts are the channel's (before the transport); `transport_lost` counts the
//! slots the transport lost.
//!
//! ```
//! use ipc_runner::estimators::{EvalOptions, FACTORIES};
//! use ipc_runner::eval::{evaluate, RunConfig};
//!
//! let scenario = channel_sim::scenario::preset("linear")?;
//! let options = EvalOptions { runs: 20, horizon: 10, seed: 1, ..EvalOptions::default() };
//! let result = evaluate(&*scenario, &options, FACTORIES, &RunConfig::default())?;
//! let (name, kf) = &result.estimators[0];
//! assert_eq!(name, "kf");
//! assert_eq!(kf.mse.len(), 11);
//! # Ok::<(), anyhow::Error>(())
//! ```

pub mod cli;
pub mod nn_bound;
pub mod report;

use anyhow::Context as _;
use channel_sim::sim::{FLAG_CENSORED, FLAG_OCCLUDED, FLAG_RANDOM_LOSS, FLAG_TOKEN_BLOCKED};
use channel_sim::sim::{FLAG_TRIGGERED, MAX_NODES, MAX_NX};
use channel_sim::{Observation, Scenario};
use estpipe_wire::FLAG_IPC_LOST;
use rayon::prelude::*;

use crate::estimators::{build_all, EvalOptions, Factory};
pub use report::{ChannelSummary, EstimatorResult, EvalResult, NodeCounts, Trajectory};

/// How to run an evaluation (beyond what estimators see in [`EvalOptions`]).
#[derive(Clone, Debug, Default)]
pub struct RunConfig {
    /// Worker threads (`None`: rayon's default, one per core).
    pub threads: Option<usize>,
    /// Show a progress bar on stderr.
    pub progress: bool,
}

/// Runs the Monte Carlo of `scenario` with the estimators of `factories`.
pub fn evaluate(
    scenario: &dyn Scenario,
    options: &EvalOptions,
    factories: &[Factory],
    config: &RunConfig,
) -> anyhow::Result<EvalResult> {
    anyhow::ensure!(options.runs >= 1, "--runs must be at least 1");
    anyhow::ensure!(options.horizon >= 1, "--horizon must be at least 1");
    let names: Vec<&'static str> = build_all(factories, scenario, options, options.seed, 0)?
        .iter()
        .map(|e| e.name())
        .collect();
    anyhow::ensure!(
        !names.is_empty(),
        "no estimator applies to scenario '{}'",
        scenario.name()
    );

    let progress = if config.progress {
        indicatif::ProgressBar::new(options.runs).with_style(
            indicatif::ProgressStyle::with_template(
                "{msg} [{bar:40}] {pos}/{len} runs, {elapsed} (eta {eta})",
            )
            .expect("static template")
            .progress_chars("=> "),
        )
    } else {
        indicatif::ProgressBar::hidden()
    };
    progress.set_message(format!("eval {}", scenario.name()));

    let mut acc = report::Accumulator::new(scenario, options, &names);
    let mut pool = rayon::ThreadPoolBuilder::new();
    if let Some(t) = config.threads {
        pool = pool.num_threads(t);
    }
    let pool = pool.build().context("cannot start the worker threads")?;
    // Chunks bound the memory held by finished runs; within a chunk, results are collected in
    // run order and reduced in that order.
    const CHUNK: u64 = 256;
    let mut start = 0;
    while start < options.runs {
        let end = (start + CHUNK).min(options.runs);
        let outputs: Vec<anyhow::Result<RunOutput>> = pool.install(|| {
            (start..end)
                .into_par_iter()
                .map(|run| {
                    let out = run_one(scenario, options, factories, run, &names);
                    progress.inc(1);
                    out
                })
                .collect()
        });
        for out in outputs {
            acc.add(out?);
        }
        start = end;
    }
    progress.finish_and_clear();
    Ok(acc.finish())
}

/// What one run produced.
#[derive(Debug)]
pub struct RunOutput {
    /// Run index.
    pub run: u64,
    /// Per estimator, in registry order.
    pub estimators: Vec<RunEstimator>,
    /// Per node.
    pub channel: Vec<NodeCounts>,
    /// Truth and estimates over k = 0..=T (kept for run 0 only, for plots).
    pub trajectory: Option<Trajectory>,
}

/// One estimator's record of one run.
#[derive(Debug, Default)]
pub struct RunEstimator {
    /// Squared error per k and state, `sq_err[k * nx + i]`; `None` when the run diverged.
    pub sq_err: Option<Vec<f64>>,
    /// The step error that ended the run, if any.
    pub error: Option<String>,
    /// Named diagnostics per k (NaN where not reported), in first-reported order.
    pub diagnostics: Vec<(&'static str, Vec<f64>)>,
}

impl RunEstimator {
    fn record_diagnostics(
        &mut self,
        e: &dyn crate::Estimator,
        k: usize,
        len: usize,
        truth: &[f64],
    ) {
        let diags = &mut self.diagnostics;
        // An estimator reports the same names in the same order at every k: the n-th name of
        // this call is looked up at index n first (the same `&'static str` compares by
        // address), and searched for only when it is not there.
        let mut next = 0;
        let mut sink = |name: &'static str, value| {
            let slot = match diags.get(next) {
                Some((n, _)) if core::ptr::eq(*n, name) || *n == name => next,
                _ => match diags.iter().position(|(n, _)| *n == name) {
                    Some(i) => i,
                    None => {
                        diags.push((name, vec![f64::NAN; len]));
                        diags.len() - 1
                    }
                },
            };
            next = slot + 1;
            diags[slot].1[k] = value;
        };
        e.diagnostics(&mut sink);
        e.diagnostics_vs_truth(truth, &mut sink);
    }
}

/// Simulates run `run` and steps every estimator through it.
pub fn run_one(
    scenario: &dyn Scenario,
    options: &EvalOptions,
    factories: &[Factory],
    run: u64,
    names: &[&'static str],
) -> anyhow::Result<RunOutput> {
    let (nx, horizon) = (scenario.nx(), options.horizon as usize);
    let mut sim = scenario.start(options.seed, run);
    let mut estimators = build_all(factories, scenario, options, options.seed, run)?;
    let built: Vec<&str> = estimators.iter().map(|e| e.name()).collect();
    anyhow::ensure!(
        built == names,
        "run {run} built estimators {built:?}, run 0 built {names:?}"
    );

    let mut records: Vec<RunEstimator> = estimators
        .iter()
        .map(|_| RunEstimator {
            sq_err: Some(vec![0.0; (horizon + 1) * nx]),
            ..Default::default()
        })
        .collect();
    let mut channel: Vec<NodeCounts> = (0..scenario.nodes()).map(NodeCounts::new).collect();
    let mut trajectory = (run == 0).then(|| Trajectory::new(names, nx, horizon));
    let mut xhat = [0.0; MAX_NX];

    // k = 0: the prior against x_0.
    let truth0 = sim.initial_truth();
    for ((e, rec), j) in estimators.iter().zip(&mut records).zip(0..) {
        record_estimate(&**e, rec, 0, &truth0[..nx], &mut xhat, &mut trajectory, j);
    }
    if let Some(t) = &mut trajectory {
        t.truth[..nx].copy_from_slice(&truth0[..nx]);
    }

    let transport = options.transport_loss > 0.0;
    let mut after_transport: heapless::Vec<Observation, MAX_NODES> = heapless::Vec::new();
    for k in 1..=options.horizon {
        let instant = sim.next_instant();
        let truth = &instant.truth[..nx];
        for (o, counts) in instant.obs.iter().zip(&mut channel) {
            counts.count(o);
        }
        // The transport after the channel (module docs): what the estimators receive.
        let received: &[Observation] = if !transport {
            &instant.obs
        } else {
            after_transport.clear();
            let nodes = instant.obs.len() as u64;
            for (o, counts) in instant.obs.iter().zip(&mut channel) {
                let seq = u64::from(o.k - 1) * nodes + u64::from(o.node);
                let mut o = *o;
                if transport_lost(options.seed, run, seq, options.transport_loss) {
                    counts.transport_lost += 1;
                    let flags = if options.transport_loss_unmarked {
                        0
                    } else {
                        FLAG_IPC_LOST
                    };
                    o = Observation::dropped(o.k, o.node, o.ny, flags);
                }
                let _ = after_transport.push(o);
            }
            &after_transport
        };
        if let Some(t) = &mut trajectory {
            t.truth[k as usize * nx..][..nx].copy_from_slice(truth);
        }
        for ((e, rec), j) in estimators.iter_mut().zip(&mut records).zip(0..) {
            if rec.sq_err.is_none() {
                continue;
            }
            let obs: &[Observation] = if e.full_information() {
                match sim.raw_observations() {
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
                    record_estimate(&**e, rec, k as usize, truth, &mut xhat, &mut trajectory, j)
                }
                Err(err) => {
                    rec.error = Some(format!("k = {k}: {err}"));
                    rec.sq_err = None;
                }
            }
        }
    }
    Ok(RunOutput {
        run,
        estimators: records,
        channel,
        trajectory,
    })
}

/// Whether `eval`'s transport stage loses slot `seq` (`(k − 1)·nodes + node`) of run `run`:
/// `U < p`, with `U` uniform in `[0, 1)` from the slot's own SplitMix64 output in a stream of
/// `(seed, run)` with a tag of its own, apart from the simulation's plant and channel streams
/// (`channel_sim::rng`).
pub fn transport_lost(seed: u64, run: u64, seq: u64, p: f64) -> bool {
    use channel_sim::rng::splitmix64;
    // "transpor": the stream's tag.
    let stream = splitmix64(splitmix64(splitmix64(seed ^ 0x7472_616e_7370_6f72) ^ run));
    let bits = splitmix64(stream.wrapping_add(seq.wrapping_mul(0x9E37_79B9_7F4A_7C15)));
    ((bits >> 11) as f64) * (1.0 / (1u64 << 53) as f64) < p
}

/// Reads the estimate at `k`, records its squared error (or marks the run diverged when it is
/// not finite), its diagnostics and, for the plotted run, the trajectory.
fn record_estimate(
    e: &dyn crate::Estimator,
    rec: &mut RunEstimator,
    k: usize,
    truth: &[f64],
    xhat: &mut [f64; MAX_NX],
    trajectory: &mut Option<Trajectory>,
    j: usize,
) {
    let nx = truth.len();
    xhat.fill(f64::NAN);
    e.estimate(&mut xhat[..]);
    let xhat = &xhat[..nx];
    if let Some(t) = trajectory {
        t.estimates[j][k * nx..][..nx].copy_from_slice(xhat);
    }
    if xhat.iter().any(|v| !v.is_finite()) {
        rec.error = Some(format!("k = {k}: non-finite estimate"));
        rec.sq_err = None;
        return;
    }
    if let Some(sq) = &mut rec.sq_err {
        let len = sq.len() / nx;
        for i in 0..nx {
            sq[k * nx + i] = (truth[i] - xhat[i]).powi(2);
        }
        rec.record_diagnostics(e, k, len, truth);
    }
}

/// Per-node channel counters.
impl NodeCounts {
    fn new(node: usize) -> Self {
        Self {
            node,
            ..Default::default()
        }
    }

    fn count(&mut self, o: &Observation) {
        self.instants += 1;
        let flag = |f: u32| u64::from(o.flags & f != 0);
        if o.delivered {
            self.delivered += 1;
        } else {
            self.dropped += 1;
        }
        // On the wire: arrived, or lost in transit by a random-loss stage.
        self.sent += u64::from(o.delivered || o.flags & FLAG_RANDOM_LOSS != 0);
        self.triggered += flag(FLAG_TRIGGERED);
        self.blocked += flag(FLAG_TOKEN_BLOCKED);
        self.censored += flag(FLAG_CENSORED);
        self.random_loss += flag(FLAG_RANDOM_LOSS);
        self.occluded += flag(FLAG_OCCLUDED);
    }
}

#[cfg(test)]
mod tests;
