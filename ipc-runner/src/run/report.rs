//! What a run reports: the [`RunReport`] (the summary a person reads, the `--json` file),
//! the output files at the end and the process's exit code.
//!
//! Whatever ends a run that stepped any instant — the END marker, a signal, a lost
//! publisher, a transport failure or a refused slot in the middle of the stream — the
//! summary is printed and every requested file written, with the ending (and the error) in
//! both ([`conclude`]); the files' paths were checked writable before the loop started
//! ([`super::RunArgs::check_outputs`]). A run that fails before its first instant has
//! computed nothing and writes nothing.

use crate::latency::LatencySummary;
use anyhow::{Context, Result};
use serde::Serialize;

use super::args::{RunArgs, WaitMode};
use super::assemble::Counts;
use super::trajectories::Trajectories;

mod summary;

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
    /// What the estimator made of the late slots it was offered (`--lag`; docs/pipeline.md,
    /// "Late packets"; not written when none came).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub late: Option<LateCount>,
}

/// What one estimator made of the late slots of a run ([`crate::LateFold`], one count each).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct LateCount {
    /// Folded in: its estimates since are those of the slot on time.
    pub folded: u64,
    /// Nothing new (the instant's slot of that node was already known).
    pub unchanged: u64,
    /// Older than its history (or it keeps none): lost for it.
    pub too_old: u64,
    /// It refused the re-step and kept its estimate.
    pub refused: u64,
}

impl LateCount {
    /// Counts one fold's outcome.
    pub fn add(&mut self, r: crate::LateFold) {
        match r {
            crate::LateFold::Folded => self.folded += 1,
            crate::LateFold::Unchanged => self.unchanged += 1,
            crate::LateFold::TooOld => self.too_old += 1,
            crate::LateFold::Refused => self.refused += 1,
        }
    }
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
    /// The runner got SIGINT/SIGTERM/SIGHUP.
    Interrupted,
    /// The data deadline passed and no restart was awaited.
    PublisherLost,
    /// The loop failed after it had processed instants (transport failure, a refused slot);
    /// [`RunReport::error`] says why.
    Failed,
}

/// Silences of a publisher that was alive (its iceoryx2 node was) past the data deadline:
/// stalled, not lost (docs/pipeline.md, "Stalled or lost").
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Stalls {
    /// Stalls.
    pub count: u32,
    /// The longest silence in ms: from the last slot before it to the first one after it (or
    /// to the end of the run).
    pub longest_ms: f64,
    /// All stalls' silences together, ms.
    pub total_ms: f64,
}

impl Stalls {
    /// Records a stall that was `silence_ns` long.
    pub fn record(&mut self, silence_ns: u64) {
        let ms = silence_ns as f64 / 1e6;
        self.count += 1;
        self.longest_ms = self.longest_ms.max(ms);
        self.total_ms += ms;
    }
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
    /// Times the publisher was lost (dead, or stalled past `--stall-limit`).
    pub publisher_losses: u32,
    /// Times the publisher was alive but silent past the data deadline, and for how long.
    pub stalls: Stalls,
    /// Truth messages missing for processed instants.
    pub truth_missing: u64,
    /// Truth messages with a non-finite component: those instants are left out of every
    /// estimator's MSE (one would otherwise make them all NaN).
    pub truth_nonfinite: u64,
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
    /// Why the run failed ([`Ending::Failed`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// The exit code of that failure ([`crate::exit_code_of`]).
    #[serde(skip)]
    pub error_code: i32,
}

/// Writes the requested output files, each on its own: one that fails does not keep the
/// others from being written; the errors come back together.
pub fn finish(args: &RunArgs, report: &RunReport, traj: &Trajectories, ny: usize) -> Result<()> {
    let mut failures: Vec<String> = Vec::new();
    let mut note = |r: Result<()>| {
        if let Err(e) = r {
            failures.push(format!("{e:#}"));
        }
    };
    if let Some(p) = &args.estimates_csv {
        note(traj.write_estimates_csv(p));
    }
    if let Some(p) = &args.slots_csv {
        note(traj.write_slots_csv(p, ny));
    }
    if let Some(p) = &args.latency_csv {
        note(traj.write_latency_csv(p));
    }
    if let Some(p) = &args.mcap {
        note(traj.write_mcap(p, &report.scenario));
    }
    if let Some(p) = &args.json {
        note(
            serde_json::to_string_pretty(report)
                .map_err(anyhow::Error::from)
                .and_then(|j| write_whole(p, &(j + "\n"))),
        );
    }
    if failures.is_empty() {
        Ok(())
    } else {
        anyhow::bail!("{}", failures.join("; "))
    }
}

/// The end of `ipc-runner run`: prints the summary, then writes the files (so a file that
/// cannot be written loses nothing the summary shows). Returns the exit code
/// ([`exit_code`]), or the error of a run that failed or of a file that was not written.
pub fn conclude(args: &RunArgs, report: &RunReport, traj: &Trajectories, ny: usize) -> Result<i32> {
    // A run that never got a slot ended with its one-line reason on stderr; a summary of
    // zeros after it would only bury that line.
    if !(report.counts.received == 0 && report.ending == Ending::PublisherLost) {
        estpipe_process::outln!("{}", report.summary());
    }
    let written = finish(args, report, traj, ny);
    if report.ending == Ending::Failed {
        let e = report.error.as_deref().unwrap_or("the loop failed");
        let n = report.counts.instants;
        let msg = match written {
            Ok(()) => format!("{e} (after {n} instants; the summary and files were written)"),
            Err(w) => format!("{e} (after {n} instants); also: {w:#}"),
        };
        return Err(ExitWith(report.error_code, msg).into());
    }
    written?;
    Ok(exit_code(report))
}

/// An error that carries its exit code (a failed run's: that of its cause).
#[derive(Debug)]
pub struct ExitWith(pub i32, pub String);

impl std::fmt::Display for ExitWith {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.1)
    }
}

impl std::error::Error for ExitWith {}

/// 0 for a completed (or cleanly stopped) run, [`EXIT_PUBLISHER_LOST`] when the publisher was
/// lost, 130 when interrupted, the cause's code when the loop failed.
pub fn exit_code(r: &RunReport) -> i32 {
    match r.ending {
        Ending::Completed | Ending::PublisherStopped => 0,
        Ending::PublisherLost => EXIT_PUBLISHER_LOST,
        Ending::Interrupted => 130,
        Ending::Failed => r.error_code.max(1),
    }
}

/// Writes `text` to `path` whole or not at all (a full disk left a 0-byte `--json` behind).
fn write_whole(path: &std::path::Path, text: &str) -> Result<()> {
    estpipe_process::whole_file::write(path, text).with_context(|| format!("cannot write {path:?}"))
}
