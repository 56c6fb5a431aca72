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
//! A (run, k) whose *truth* is not finite is no sample: counted (`truth_nonfinite`) and left
//! out of every MSE, never turning the report into NaN.
//!
//! **Bounds and endings** ([`evaluate_with`], [`Control`]): what the evaluation holds
//! ([`memory_need`]) is checked against a budget before the first run, and the chunk of
//! finished runs shrinks to fit it (results unchanged); a stop request (SIGINT/SIGTERM/SIGHUP in
//! `ipc-runner eval`) or a run that fails ends the evaluation with the runs done before the
//! first one not done ([`EvalEnding`]), whose results are exactly those of an evaluation of
//! that many runs (docs/pipeline.md, "Exit codes and limits").
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
//! use ipc_runner::estimators::FACTORIES;
//! use ipc_runner::eval::EvalOptions;
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
pub mod delay;
pub mod nn_bound;
mod options;
pub mod paired;
mod plan;
pub mod report;
mod scoring;
mod transport;

use anyhow::Context as _;
use channel_sim::sim::{FLAG_CENSORED, FLAG_OCCLUDED, FLAG_RANDOM_LOSS, FLAG_TOKEN_BLOCKED};
use channel_sim::sim::{FLAG_TRIGGERED, MAX_NX};
use channel_sim::{Observation, Scenario};
use rayon::prelude::*;

use crate::estimators::role::Role;
use crate::estimators::{build_all, Factory, RunStart};
use crate::limits::{product, Budget, Progress};
pub use options::EvalOptions;
pub use report::{ChannelSummary, EstimatorResult, EvalResult, NodeCounts, Trajectory};
use std::time::Duration;

/// How to run an evaluation (beyond what estimators see in [`EvalOptions`]).
#[derive(Clone, Debug, Default)]
pub struct RunConfig {
    /// Worker threads (`None`: one per core; `ipc-runner eval` reads `RAYON_NUM_THREADS`
    /// itself, [`cli::default_threads`]).
    pub threads: Option<usize>,
    /// Show progress on stderr (a bar on a terminal, else a line every few seconds).
    pub progress: bool,
}

/// The bounds and the stop request of an evaluation ([`evaluate_with`]).
pub struct Control<'a> {
    /// What the evaluation may hold in memory ([`memory_need`]).
    pub budget: Budget,
    /// Interval of the progress lines when stderr is not a terminal.
    pub progress_every: Duration,
    /// Polled by the workers before each run: `true` stops the evaluation, which then
    /// reports the runs done before the first one not done.
    pub stop: Option<&'a (dyn Fn() -> bool + Sync)>,
}

impl Default for Control<'_> {
    fn default() -> Self {
        Self {
            budget: Budget::mib(crate::limits::DEFAULT_MAX_MEMORY_MIB),
            progress_every: crate::limits::PROGRESS_LINE_EVERY,
            stop: None,
        }
    }
}

impl std::fmt::Debug for Control<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Control")
            .field("budget", &self.budget)
            .field("progress_every", &self.progress_every)
            .field("stop", &self.stop.is_some())
            .finish()
    }
}

/// Diagnostics an estimator may report per k, assumed by [`memory_need`] (the most any
/// estimator of this product reports is 6: `p11`, `p12`, `p22`, `trace_p`, `nees`,
/// `inside_95`).
pub const DIAGNOSTICS_ALLOWANCE: u64 = 8;

/// Most runs finished but not yet reduced: the results of a chunk are reduced in run order.
const CHUNK: u64 = 256;

/// What an evaluation holds in memory, in bytes: `(fixed, per_run)`. `fixed` are the
/// reductions (per-k sums and counts of every estimator, the per-run averages the median
/// needs, run 0's trajectories), `per_run` one run's record (squared errors and
/// diagnostics per k) while it waits in a chunk, or is being computed.
pub fn memory_need(nx: usize, n_est: usize, horizon: u32, runs: u64) -> (u64, u64) {
    let (nx, n_est, k) = (nx as u64, n_est as u64, u64::from(horizon) + 1);
    let per_run = product(&[8, k, n_est, nx + DIAGNOSTICS_ALLOWANCE]);
    let reductions = product(&[8, k, n_est, nx + 2 * DIAGNOSTICS_ALLOWANCE + 1]);
    let run_avgs = product(&[8, runs, n_est]);
    let trajectories = product(&[2 * 8, k, nx, n_est + 1]);
    (
        reductions
            .saturating_add(run_avgs)
            .saturating_add(trajectories),
        per_run,
    )
}

/// How an evaluation ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum EvalEnding {
    /// Every requested run was done.
    Completed,
    /// Stopped by SIGINT/SIGTERM/SIGHUP ([`Control::stop`]); the runs done before are reported.
    Interrupted,
    /// A run failed (its estimators could not be built); the runs before it are reported.
    Failed,
}

/// Runs the Monte Carlo of `scenario` with the estimators of `factories`; a run that fails
/// is an error (what [`evaluate_with`] reports as [`EvalEnding::Failed`]).
pub fn evaluate(
    scenario: &dyn Scenario,
    options: &EvalOptions,
    factories: &[Factory],
    config: &RunConfig,
) -> anyhow::Result<EvalResult> {
    let r = evaluate_with(scenario, options, factories, config, &Control::default())?;
    match (&r.ending, &r.error) {
        (EvalEnding::Failed, Some(e)) => anyhow::bail!("{e}"),
        _ => Ok(r),
    }
}

/// [`evaluate`] within `control`'s bounds. `Err` only before the first run (bad options,
/// memory budget, worker threads); afterwards the result always comes back, with what ended
/// it in [`EvalResult::ending`] and the runs done before that in [`EvalResult::runs`].
pub fn evaluate_with(
    scenario: &dyn Scenario,
    options: &EvalOptions,
    factories: &[Factory],
    config: &RunConfig,
    control: &Control<'_>,
) -> anyhow::Result<EvalResult> {
    let plan::Plan {
        threads,
        names,
        roles,
        chunk,
    } = plan::Plan::check(scenario, options, factories, config, control)?;
    let progress = Progress::new(
        format!("eval {}", scenario.name()),
        "runs",
        options.runs,
        !config.progress,
        control.progress_every,
    );

    let mut acc = report::Accumulator::new(scenario, options, &names, &roles);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads.max(1))
        .build()
        .context("cannot start the worker threads")?;
    let stopped = std::sync::atomic::AtomicBool::new(false);
    let stop_now = || {
        use std::sync::atomic::Ordering::Relaxed;
        stopped.load(Relaxed)
            || control.stop.is_some_and(|f| f()) && {
                stopped.store(true, Relaxed);
                true
            }
    };
    // Chunks bound the memory held by finished runs; within a chunk, results are collected in
    // run order and reduced in that order. A run not done (stop) or failed ends the
    // reduction: what is reported are always the runs 0..n, as if only n had been asked.
    let mut ending = EvalEnding::Completed;
    let mut error = None;
    let mut start = 0;
    'chunks: while start < options.runs {
        let end = (start + chunk).min(options.runs);
        let outputs: Vec<Option<anyhow::Result<RunOutput>>> = pool.install(|| {
            (start..end)
                .into_par_iter()
                .map(|run| {
                    if stop_now() {
                        return None;
                    }
                    let out = run_one(scenario, options, factories, run, &names);
                    progress.inc(1);
                    Some(out)
                })
                .collect()
        });
        for out in outputs {
            match out {
                Some(Ok(out)) => acc.add(out),
                Some(Err(e)) => {
                    ending = EvalEnding::Failed;
                    error = Some(format!("{e:#}"));
                    break 'chunks;
                }
                None => {
                    ending = EvalEnding::Interrupted;
                    break 'chunks;
                }
            }
        }
        start = end;
    }
    progress.finish();
    let mut result = acc.finish();
    result.ending = ending;
    result.error = error;
    Ok(result)
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
    /// Instants k = 0..=T whose truth had a non-finite component: left out of every
    /// estimator's squared errors.
    pub truth_nonfinite: u64,
}

/// One estimator's record of one run.
#[derive(Debug, Default)]
pub struct RunEstimator {
    /// Squared error per k and state, `sq_err[k * nx + i]` (NaN at an instant whose truth is
    /// not finite: not a sample); `None` when the run diverged.
    pub sq_err: Option<Vec<f64>>,
    /// The step error that ended the run, if any.
    pub error: Option<String>,
    /// Named diagnostics per k (NaN where not reported), in first-reported order.
    pub diagnostics: Vec<(&'static str, Vec<f64>)>,
}

impl RunEstimator {
    /// Records the estimator's diagnostics at `k`. An estimator reports the same names in the
    /// same order at every k, so the n-th name of this call is looked up at index n first
    /// (the same `&'static str` compares by address), and searched for only when it is not
    /// there.
    fn record_diagnostics(
        &mut self,
        e: &dyn crate::Estimator,
        k: usize,
        len: usize,
        truth: &[f64],
    ) {
        let diags = &mut self.diagnostics;
        let mut next = 0;
        let mut sink = |name: &'static str, value| {
            let slot = match diags.get_mut(next) {
                Some((n, values)) if core::ptr::eq(*n, name) => {
                    // The common case: no search, no second bounds check.
                    if let Some(v) = values.get_mut(k) {
                        *v = value;
                    }
                    next += 1;
                    return;
                }
                Some((n, _)) if *n == name => next,
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
    let start = RunStart {
        seed: options.seed,
        run,
        initial: sim.initial_observations(),
    };
    let mut estimators = build_all(factories, &scenario.estimator_spec(), options, &start)?;
    let built: Vec<&str> = estimators.iter().map(|e| e.name()).collect();
    anyhow::ensure!(
        built == names,
        "run {run} built estimators {built:?}, run 0 built {names:?}"
    );
    let nodes = scenario.nodes();
    let mut records = scoring::Records::new(run, names, nx, horizon, nodes);
    records.score_prior(&estimators, &sim.initial_truth()[..nx]);
    let mut transport = transport::Transport::new(options, run);
    for k in 1..=options.horizon {
        let instant = sim.next_instant();
        for (o, counts) in instant.obs.iter().zip(&mut records.channel) {
            counts.count(o);
        }
        let received = transport.pass(&instant.obs, k, &mut records.channel);
        let raw = sim.raw_observations();
        records.step(k, &mut estimators, received, raw, &instant.truth[..nx]);
        transport.deliver(k, nodes, &mut estimators, &records.estimators);
    }
    Ok(records.output(run))
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
/// not finite), its diagnostics and, for the plotted run, the trajectory. A non-finite truth
/// is no sample of the error (`scored` false): NaN is recorded there, which the reduction
/// leaves out (one such instant would otherwise make every MSE of the report NaN, issue #20).
#[inline]
fn record_estimate(
    e: &dyn crate::Estimator,
    rec: &mut RunEstimator,
    k: usize,
    truth: &[f64],
    scored: bool,
    xhat: &mut [f64; MAX_NX],
    trajectory: &mut Option<Trajectory>,
    j: usize,
) {
    let nx = truth.len();
    xhat[..nx].fill(f64::NAN);
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
        if let Some(sq_k) = sq.get_mut(k * nx..(k + 1) * nx) {
            for ((s, t), x) in sq_k.iter_mut().zip(truth).zip(xhat) {
                *s = if scored { (t - x).powi(2) } else { f64::NAN };
            }
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
