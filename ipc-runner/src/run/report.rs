//! What a run reports: the [`RunReport`] (the summary a person reads, the `--json` file),
//! the output files at the end and the process's exit code.

use crate::latency::LatencySummary;
use anyhow::{Context, Result};
use serde::Serialize;

use super::args::{RunArgs, WaitMode};
use super::assemble::Counts;
use super::trajectories::Trajectories;

/// Exit code when the publisher was lost (deadline passed) and no restart was awaited.
pub const EXIT_PUBLISHER_LOST: i32 = 3;

/// Per-estimator results.
#[derive(Clone, Debug, Serialize)]
pub struct EstimatorReport {
    /// Estimator name.
    pub name: String,
    /// Mean over instants of ‖x_k − x̂_k‖² (instants whose truth was received).
    pub mse: f64,
    /// Instants in the MSE.
    pub mse_instants: u64,
    /// Steps the estimator refused (e.g. non-finite measurement); its state was kept.
    pub rejected: u64,
    /// `--gate P`: measurements its innovation gate tested and rejected (docs/gate.md;
    /// not written for an ungated estimator).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gate: Option<GateCount>,
}

/// What an estimator's innovation gate did in a run.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct GateCount {
    /// Delivered measurements tested.
    pub tested: u64,
    /// Of those, rejected (not used).
    pub rejected: u64,
}

/// How the run ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Ending {
    /// The publisher sent its END marker.
    Completed,
    /// The publisher was stopped early (ABORT marker).
    PublisherStopped,
    /// The runner got SIGINT/SIGTERM.
    Interrupted,
    /// The data deadline passed and no restart was awaited.
    PublisherLost,
}

/// What a run did.
#[derive(Clone, Debug, Serialize)]
pub struct RunReport {
    /// Scenario name.
    pub scenario: String,
    /// Wait mode.
    pub wait: WaitMode,
    /// Slot accounting.
    pub counts: Counts,
    /// Per-estimator results.
    pub estimators: Vec<EstimatorReport>,
    /// Latency percentiles.
    pub latency: LatencySummary,
    /// Streams followed (1 + publisher restarts).
    pub sessions: u32,
    /// Times the data deadline passed.
    pub publisher_losses: u32,
    /// Truth messages missing for processed instants.
    pub truth_missing: u64,
    /// Allocations after warm-up (only with an allocation probe).
    pub allocations_after_warmup: Option<usize>,
    /// Slots received after warm-up (denominator of the above).
    pub slots_after_warmup: u64,
    /// Estimates published after warm-up (iceoryx2 0.10's `loan_uninit` allocates one
    /// reference count per sample, inside the library).
    pub published_after_warmup: u64,
    /// Outcome of `--cpu` / `--mlock` (`None` if not requested).
    pub cpu_pinning: Option<String>,
    /// Outcome of `--mlock`.
    pub memory_lock: Option<String>,
    /// Set-up conditions that will show in the latency (e.g. spinning under RT throttling).
    pub warnings: Vec<String>,
    /// How the run ended.
    pub ending: Ending,
}

impl RunReport {
    /// The summary a person reads at the end of a run.
    pub fn summary(&self) -> String {
        let c = &self.counts;
        let mut s = format!(
            "scenario {} · {} instants · {} wait · ended: {:?}\n\
             slots: {} received ({} delivered, {} dropped by the channel), {} lost in IPC, {} missed before join\n",
            self.scenario,
            c.instants,
            self.wait.as_str(),
            self.ending,
            c.received,
            c.delivered,
            c.dropped_by_channel,
            c.lost_in_ipc,
            c.missed_before_join,
        );
        if self.sessions > 1 || self.publisher_losses > 0 {
            s.push_str(&format!(
                "publisher lost {} time(s); {} session(s)\n",
                self.publisher_losses, self.sessions
            ));
        }
        s.push_str("estimator         MSE vs truth   instants   rejected\n");
        for e in &self.estimators {
            s.push_str(&format!(
                "{:<16} {:>13.6} {:>10} {:>10}\n",
                e.name, e.mse, e.mse_instants, e.rejected
            ));
        }
        for e in &self.estimators {
            if let Some(g) = e.gate {
                s.push_str(&format!(
                    "{}: innovation gate rejected {} of {} measurements\n",
                    e.name, g.rejected, g.tested
                ));
            }
        }
        s.push_str(&self.latency.table());
        if let Some(a) = self.allocations_after_warmup {
            s.push_str(&format!(
                "allocations after warm-up: {a} over {} slots ({} estimates published)\n",
                self.slots_after_warmup, self.published_after_warmup
            ));
        }
        for w in &self.warnings {
            s.push_str(w);
            s.push('\n');
        }
        s
    }
}

/// Writes the requested output files.
pub fn finish(args: &RunArgs, report: &RunReport, traj: &Trajectories, ny: usize) -> Result<()> {
    if let Some(p) = &args.estimates_csv {
        traj.write_estimates_csv(p)?;
    }
    if let Some(p) = &args.slots_csv {
        traj.write_slots_csv(p, ny)?;
    }
    if let Some(p) = &args.latency_csv {
        traj.write_latency_csv(p)?;
    }
    if let Some(p) = &args.json {
        std::fs::write(p, serde_json::to_string_pretty(report)?)
            .with_context(|| format!("cannot write {p:?}"))?;
    }
    Ok(())
}

/// 0 for a completed (or cleanly stopped) run, [`EXIT_PUBLISHER_LOST`] when the publisher was
/// lost, 130 when interrupted.
pub fn exit_code(r: &RunReport) -> i32 {
    match r.ending {
        Ending::Completed | Ending::PublisherStopped => 0,
        Ending::PublisherLost => EXIT_PUBLISHER_LOST,
        Ending::Interrupted => 130,
    }
}
