//! The evaluation's results: reduction over runs (in run order), JSON, CSV and the summary
//! table.
//!
//! JSON shape (fields beyond the issue's are additions):
//! ```text
//! { "scenario", "runs", ["runs_requested",] "horizon", "seed", "ending", ["error",]
//!   "truth_nonfinite",
//!   ["transport_loss", "transport_loss_unmarked", "transport_delay", "lag", "loss_rate",
//!    "gate",]   (only when set)
//!   "estimators": { NAME: { "role", "mse": [MSE(k), k = 0..=T], "avg_mse", "avg_mse_se",
//!                           "median_run_avg", "diverged_runs", "valid_runs",
//!                           "first_error", "mse_per_state": [[MSE_i(k)]…],
//!                           ["gate": { "tested", "rejected", "rejection_rate" },]  (`+gate`)
//!                           <diagnostic name>: [mean over runs per k]… } },
//!   "channel": { "delivery_rate", "nodes": [ { "node", "instants", "delivered", "dropped",
//!                "sent", "triggered", "blocked", "censored", "random_loss", "occluded",
//!                ["transport_lost", "transport_late", "transport_too_old",]
//!                "delivery_rate" }… ] } }
//! ```
//! MSE(k) is the mean over valid runs of ‖x_k − x̂_k‖²; `avg_mse` the mean of MSE(k) over
//! k = 1..=T (equivalently the mean of the valid runs' averages), `avg_mse_se` its Monte-Carlo
//! standard error (sample standard deviation of the run averages / √valid_runs),
//! `median_run_avg` the median of the run averages. Non-finite values are written as `null`.
//!
//! `ending` is `completed`, `interrupted` (SIGINT/SIGTERM/SIGHUP) or `failed` (with `error`): then
//! `runs` are the runs done before the first one not done, of `runs_requested`, and every
//! number is over those. `truth_nonfinite` counts the (run, k) instants whose truth had a
//! non-finite component; they are left out of every MSE (MSE(k) is then the mean over the
//! runs whose truth at k was finite, and `avg_mse` the mean of MSE(k) over the k that have
//! any), so one such sample cannot turn the report into `null`s.

use std::fmt::Write as _;

use channel_sim::Scenario;
use serde::Serialize;

use super::RunOutput;
use crate::estimators::role::Role;
use crate::eval::EvalOptions;
use reduce::EstimatorAcc;

mod channel;
mod consistency;
mod json;
mod reduce;
mod summary;

/// Everything an evaluation produced.
#[derive(Debug, Serialize)]
pub struct EvalResult {
    /// Scenario name.
    pub scenario: String,
    /// Runs done and in the means (fewer than asked when the evaluation was interrupted or
    /// failed).
    pub runs: u64,
    /// Runs asked for (`--runs`; written only when not all were done).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub runs_requested: Option<u64>,
    /// Horizon T.
    pub horizon: u32,
    /// Experiment seed.
    pub seed: u64,
    /// How the evaluation ended.
    pub ending: super::EvalEnding,
    /// Why it failed ([`super::EvalEnding::Failed`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// (run, k) instants whose truth was not finite, left out of every MSE.
    pub truth_nonfinite: u64,
    /// `--transport-loss` (not written when 0).
    #[serde(skip_serializing_if = "json::is_zero_f64")]
    pub transport_loss: f64,
    /// `--transport-loss-unmarked` (not written when false).
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub transport_loss_unmarked: bool,
    /// `--transport-delay` (not written when every slot is on time).
    #[serde(
        skip_serializing_if = "Option::is_none",
        serialize_with = "json::display_opt"
    )]
    pub transport_delay: Option<super::delay::Delay>,
    /// `--lag` (not written when 0).
    #[serde(skip_serializing_if = "json::is_zero_u32")]
    pub lag: u32,
    /// `--loss-rate` of the `-mix` estimators (not written when 0).
    #[serde(skip_serializing_if = "json::is_zero_f64")]
    pub loss_rate: f64,
    /// `--gate P`, the innovation gate's probability (not written when off; docs/gate.md).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gate: Option<f64>,
    /// Per estimator, in registry order.
    #[serde(serialize_with = "json::ordered_map")]
    pub estimators: Vec<(String, EstimatorResult)>,
    /// Channel statistics over all runs.
    pub channel: ChannelSummary,
    /// Run 0's trajectories (plots only).
    #[serde(skip)]
    pub trajectory: Trajectory,
    /// The scenario's warnings (parameters accepted against the paper's own conditions).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
}

/// One estimator's results.
#[derive(Debug, Serialize)]
pub struct EstimatorResult {
    /// Whose it is: "paper", "product", "baseline", "reference" or "oracle" (README.md's
    /// role legend), in the table and the JSON.
    #[serde(serialize_with = "json::role_str")]
    pub role: Role,
    /// MSE(k), k = 0..=T.
    pub mse: Vec<f64>,
    /// Mean of MSE(k) over k = 1..=T.
    pub avg_mse: f64,
    /// Monte-Carlo standard error of `avg_mse`.
    pub avg_mse_se: f64,
    /// Median over valid runs of the run's mean squared error over k = 1..=T.
    pub median_run_avg: f64,
    /// Runs excluded because the estimate became non-finite or a step failed.
    pub diverged_runs: u64,
    /// Runs included in the means.
    pub valid_runs: u64,
    /// The first failure message (lowest run index), if any run diverged.
    pub first_error: Option<String>,
    /// Per-state MSE: `mse_per_state[i][k]`.
    pub mse_per_state: Vec<Vec<f64>>,
    /// The innovation gate's totals over the valid runs (gated estimators only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gate: Option<GateTotals>,
    /// Named diagnostics, mean over valid runs per k.
    #[serde(flatten, serialize_with = "json::ordered_map")]
    pub diagnostics: Vec<(String, Vec<f64>)>,
    /// Every valid run's index and its mean squared error over k = 1..=T, in run order (not
    /// written: for paired comparisons of evaluations with the same seed).
    #[serde(skip)]
    pub run_averages: Vec<(u64, f64)>,
}

/// What a gated estimator's innovation gate did over the valid runs (docs/gate.md).
#[derive(Clone, Copy, Debug, Serialize)]
pub struct GateTotals {
    /// Delivered measurements tested.
    pub tested: u64,
    /// Of those, rejected (not used).
    pub rejected: u64,
    /// `rejected / tested`.
    pub rejection_rate: f64,
}

impl GateTotals {
    /// From the diagnostics `gate_tested`, `gate_rejected` (mean over the valid runs per k of
    /// the counts so far): their value at `k = T` times the valid runs.
    fn of(diagnostics: &[(String, Vec<f64>)], valid_runs: u64) -> Option<Self> {
        let last = |n: &str| {
            let v = &diagnostics.iter().find(|(d, _)| d == n)?.1;
            let m = *v.last()?;
            m.is_finite()
                .then(|| (m * valid_runs as f64).round() as u64)
        };
        let (tested, rejected) = (last("gate_tested")?, last("gate_rejected")?);
        Some(Self {
            tested,
            rejected,
            rejection_rate: rejected as f64 / tested.max(1) as f64,
        })
    }
}

/// Channel statistics.
#[derive(Debug, Serialize)]
pub struct ChannelSummary {
    /// Delivered / instants over all nodes.
    pub delivery_rate: f64,
    /// Per node.
    pub nodes: Vec<NodeCounts>,
}

/// Counts of one node's observations over all runs and instants k = 1..=T.
#[derive(Clone, Debug, Default, Serialize)]
pub struct NodeCounts {
    /// Node index.
    pub node: usize,
    /// Observations (runs × T).
    pub instants: u64,
    /// Delivered measurements.
    pub delivered: u64,
    /// Dropped (not delivered) for any reason.
    pub dropped: u64,
    /// Packets put on the wire: delivered, or lost in transit by a random-loss stage.
    pub sent: u64,
    /// `FLAG_TRIGGERED` set.
    pub triggered: u64,
    /// `FLAG_TOKEN_BLOCKED` set.
    pub blocked: u64,
    /// `FLAG_CENSORED` set.
    pub censored: u64,
    /// `FLAG_RANDOM_LOSS` set.
    pub random_loss: u64,
    /// `FLAG_OCCLUDED` set.
    pub occluded: u64,
    /// Slots lost by `eval`'s transport stage after the channel (`--transport-loss`; not
    /// written when 0). The counts above are the channel's, before that stage.
    #[serde(skip_serializing_if = "json::is_zero")]
    pub transport_lost: u64,
    /// Slots `eval`'s delaying transport made late (`--transport-delay`; not written when 0):
    /// missing at their instant, then folded in by the estimators with `--lag`.
    #[serde(skip_serializing_if = "json::is_zero")]
    pub transport_late: u64,
    /// Of those, the ones later than `--lag`: lost for good (not written when 0).
    #[serde(skip_serializing_if = "json::is_zero")]
    pub transport_too_old: u64,
    /// delivered / instants.
    pub delivery_rate: f64,
}

/// One run's true and estimated trajectories, `[k * nx + i]`.
#[derive(Clone, Debug, Default)]
pub struct Trajectory {
    /// State dimension.
    pub nx: usize,
    /// x_k.
    pub truth: Vec<f64>,
    /// Estimator names.
    pub names: Vec<&'static str>,
    /// x̂_k per estimator (NaN after a divergence).
    pub estimates: Vec<Vec<f64>>,
}

impl Trajectory {
    pub(super) fn new(names: &[&'static str], nx: usize, horizon: usize) -> Self {
        let len = (horizon + 1) * nx;
        Self {
            nx,
            truth: vec![f64::NAN; len],
            names: names.to_vec(),
            estimates: vec![vec![f64::NAN; len]; names.len()],
        }
    }
}

/// Sums over runs, fed in run order.
pub(super) struct Accumulator {
    scenario: String,
    options: EvalOptions,
    nx: usize,
    names: Vec<&'static str>,
    roles: Vec<Role>,
    estimators: Vec<EstimatorAcc>,
    channel: Vec<NodeCounts>,
    trajectory: Option<Trajectory>,
    next_run: u64,
    truth_nonfinite: u64,
}

impl Accumulator {
    pub(super) fn new(
        scenario: &dyn Scenario,
        options: &EvalOptions,
        names: &[&'static str],
        roles: &[Role],
    ) -> Self {
        let nx = scenario.nx();
        let len = (options.horizon as usize + 1) * nx;
        Self {
            scenario: scenario.name().to_owned(),
            options: options.clone(),
            nx,
            names: names.to_vec(),
            roles: roles.to_vec(),
            estimators: names
                .iter()
                .map(|_| EstimatorAcc::new(len, options.horizon as usize))
                .collect(),
            channel: (0..scenario.nodes())
                .map(|node| NodeCounts {
                    node,
                    ..Default::default()
                })
                .collect(),
            trajectory: None,
            next_run: 0,
            truth_nonfinite: 0,
        }
    }

    pub(super) fn add(&mut self, out: RunOutput) {
        assert_eq!(out.run, self.next_run, "runs must be reduced in order");
        self.next_run += 1;
        self.truth_nonfinite += out.truth_nonfinite;
        let (nx, t) = (self.nx, self.options.horizon as usize);
        for (acc, rec) in self.estimators.iter_mut().zip(out.estimators) {
            acc.absorb(rec, out.run, nx, t);
        }
        for (total, c) in self.channel.iter_mut().zip(out.channel) {
            total.absorb(&c);
        }
        if out.trajectory.is_some() {
            self.trajectory = out.trajectory;
        }
    }

    pub(super) fn finish(self) -> EvalResult {
        let (nx, t) = (self.nx, self.options.horizon as usize);
        let estimators = self
            .names
            .iter()
            .zip(self.roles)
            .zip(self.estimators)
            .map(|((name, role), acc)| ((*name).to_owned(), acc.result(role, nx, t)))
            .collect();
        let mut channel = self.channel;
        for c in &mut channel {
            c.delivery_rate = c.delivered as f64 / c.instants.max(1) as f64;
        }
        let (delivered, instants) = channel
            .iter()
            .fold((0, 0), |(d, i), c| (d + c.delivered, i + c.instants));
        EvalResult {
            scenario: self.scenario,
            runs: self.next_run,
            runs_requested: (self.next_run != self.options.runs).then_some(self.options.runs),
            horizon: self.options.horizon,
            seed: self.options.seed,
            ending: super::EvalEnding::Completed,
            error: None,
            truth_nonfinite: self.truth_nonfinite,
            transport_loss: self.options.transport_loss,
            transport_loss_unmarked: self.options.transport_loss_unmarked,
            transport_delay: self.options.transport_delay,
            lag: self.options.lag,
            loss_rate: self.options.loss_rate,
            gate: self.options.gate,
            estimators,
            channel: ChannelSummary {
                delivery_rate: delivered as f64 / instants.max(1) as f64,
                nodes: channel,
            },
            trajectory: self.trajectory.unwrap_or_default(),
            warnings: Vec::new(),
        }
    }
}

impl EvalResult {
    /// The JSON document (pretty-printed, trailing newline).
    pub fn to_json(&self) -> String {
        let mut s = serde_json::to_string_pretty(self).expect("plain data serialises");
        s.push('\n');
        s
    }

    /// CSV: one row per k, column `k` then one MSE(k) column per estimator.
    pub fn to_csv(&self) -> String {
        let mut s = String::from("k");
        for (name, _) in &self.estimators {
            let _ = write!(s, ",{name}");
        }
        s.push('\n');
        for k in 0..=self.horizon as usize {
            let _ = write!(s, "{k}");
            for (_, r) in &self.estimators {
                let _ = write!(s, ",{}", r.mse[k]);
            }
            s.push('\n');
        }
        s
    }

    /// The human-readable summary table.
    pub fn summary(&self) -> String {
        let mut s = String::new();
        summary::heading(self, &mut s);
        summary::table(self, &mut s);
        consistency::covariance_lines(self, &mut s);
        consistency::gate_lines(self, &mut s);
        for w in &self.warnings {
            let _ = writeln!(s, "WARNING: {w}");
        }
        channel::transport_lines(self, &mut s);
        channel::node_lines(self, &mut s);
        s
    }
}
