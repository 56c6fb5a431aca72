//! `ipc-runner replay`: runs the estimators over a recorded slot log ([`crate::slot_log`])
//! instead of live shared memory — for sensor logs recorded elsewhere, or to re-examine a run
//! offline.

use crate::estimator_args::EstimatorArgs;
use crate::limits::{check_outputs, given, product, BadInput, Budget};
use crate::run::select;
use crate::slot_log::{read_slots_within, Interrupted, LoggedInstant};
use crate::source::Source;
use crate::Estimator;
use anyhow::{Context, Result};
use estpipe_wire::Observation;
use estpipe_wire::MAX_NX;
use estpipe_wire::{FLAG_IPC_LOST, FLAG_NET_LOST};
use std::io::Write;
use std::path::PathBuf;

/// Options of `ipc-runner replay`.
#[derive(Clone, Debug, clap::Args)]
pub struct ReplayArgs {
    /// The slot log (CSV, see the column list in `docs/replay.md`).
    #[arg(long)]
    pub input: PathBuf,
    /// Scenario whose model the estimators use.
    #[arg(long, default_value = "occlusion", conflicts_with = "config")]
    pub scenario: String,
    /// Scenario TOML file (instead of a preset).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Estimator spec TOML file (as `run --estimator-spec`), instead of a scenario.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["config", "scenario"])]
    pub estimator_spec: Option<PathBuf>,
    /// The estimators and their options (as in `run`).
    #[command(flatten)]
    pub estimator: EstimatorArgs,
    /// Experiment seed the estimators are built for (as `eval --seed`).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Run index the estimators are built for.
    #[arg(long, default_value_t = 0)]
    pub run: u64,
    /// Write `k,<est>_0..` rows here (default: print the last estimates only).
    #[arg(long)]
    pub output: Option<PathBuf>,
    /// Also write the replay as an MCAP file (docs/mcap.md): the slots and the estimates with
    /// their covariance; the log has no clock, so instant k is at k ms.
    #[arg(long, value_name = "FILE")]
    pub mcap: Option<PathBuf>,
    /// Memory the replay may hold, in MiB: every instant from k = 1 to the log's last k (gaps
    /// filled as lost) and its estimates. A log whose k goes beyond is refused at that row,
    /// with the numbers.
    #[arg(long, value_name = "MIB", default_value_t = crate::limits::DEFAULT_MAX_MEMORY_MIB,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub max_memory: u64,
}

/// Steps `estimators` over `instants`, and folds in each slot of `late` after the instant it
/// came after (what `run --lag` did live; an estimator without the lag leaves it lost);
/// returns per-instant estimates (`nx` per estimator, as published at each instant: before
/// the slots that came after it) and the rejected counts.
///
/// With `cov`, also every estimator's covariance (`nx · nx` row-major) and its wire kind per
/// instant (for `--mcap`).
///
/// Stops after the instant during which SIGINT/SIGTERM/SIGHUP arrived
/// (`estpipe_process::signal`, when installed): the estimates cover the instants stepped,
/// `len / (nx · estimators)` of them.
pub fn run_estimators(
    estimators: &mut [Box<dyn Estimator>],
    instants: &[LoggedInstant],
    late: &[(u32, Observation)],
    nx: usize,
    mut cov: Option<&mut Covariances>,
) -> (Vec<f64>, Vec<u64>) {
    let mut p = [0.0; MAX_NX * MAX_NX];
    let mut out = Vec::with_capacity(instants.len() * nx * estimators.len());
    let mut rejected = vec![0; estimators.len()];
    let mut x = [0.0; MAX_NX];
    // By the instant each came after (stable: the log's order within one instant).
    let mut by_arrival: Vec<&(u32, Observation)> = late.iter().collect();
    by_arrival.sort_by_key(|(after, _)| *after);
    let mut next = by_arrival.into_iter().peekable();
    for (i, (k, obs)) in instants.iter().enumerate() {
        if i % 1024 == 1023 && estpipe_process::signal::termination_requested() {
            break;
        }
        for (e, est) in estimators.iter_mut().enumerate() {
            if est.step(*k, obs).is_err() {
                rejected[e] += 1;
            }
            est.estimate(&mut x[..nx]);
            out.extend_from_slice(&x[..nx]);
            if let Some(c) = cov.as_deref_mut() {
                let kind = est.covariance(&mut p[..nx * nx]);
                c.p.extend_from_slice(&p[..nx * nx]);
                c.kind.push(kind.wire());
            }
        }
        // The live run folded each late slot in when it came, after the instant `after`.
        while let Some((_, o)) = next.next_if(|(after, _)| *after <= *k) {
            let mut all: heapless::Vec<Observation, { estpipe_wire::MAX_NODES }> =
                heapless::Vec::new();
            for n in 0..obs.len() {
                let lost = Observation::dropped(o.k, n as u8, o.ny, FLAG_IPC_LOST);
                let _ = all.push(if n == usize::from(o.node) { *o } else { lost });
            }
            for est in estimators.iter_mut() {
                est.fold_late(o.k, &all);
            }
        }
    }
    (out, rejected)
}

/// Per instant and estimator, the covariance (`nx · nx` row-major) and its wire kind.
#[derive(Debug, Default)]
pub struct Covariances {
    /// The matrices.
    pub p: Vec<f64>,
    /// The wire's `cov_kind` of each.
    pub kind: Vec<u32>,
}

/// Exit code of a replay SIGINT/SIGTERM/SIGHUP stopped (as `run`'s).
pub const EXIT_INTERRUPTED: i32 = 130;

/// `ipc-runner replay`: checks `--output` and the memory budget, reads the log (bounded),
/// steps the estimators, prints and writes the estimates. Bad input (flags, scenario, the
/// log's content, an unwritable output) is an error of [`BadInput`] (exit code 2).
pub fn main(args: &ReplayArgs) -> Result<i32> {
    // SIGINT/SIGTERM/SIGHUP set a flag from here on: a replay stops between rows or instants
    // and writes whole rows of what it computed (issue #39: it was killed mid-row).
    estpipe_process::signal::install();
    check_replay_outputs(args)?;
    let source = std::sync::Arc::new(Source::resolve(
        &args.scenario,
        args.config.as_deref(),
        args.estimator_spec.as_deref(),
        args.seed,
        args.run,
    )?);
    let spec = &source.spec;
    let (nx, ny, nodes) = (spec.nx(), spec.ny(), spec.nodes());
    let particles = ParticleBudget::check(args, spec)?;
    let factory = |horizon: u32| {
        select::estimators_with(
            source.clone(),
            &args.estimator,
            select::Experiment {
                seed: args.seed,
                run: args.run,
                horizon,
            },
        )
        .map_err(|e| BadInput(format!("{e:#}")))
    };
    // The estimators' count, for the bytes per instant (the log gives the horizon).
    let n_est = factory(1)?()?.len() as u64;
    let max_instants = particles.instants(args, nx, n_est)?;
    let Some(log) = read_log(args, nodes, ny, max_instants)? else {
        return Ok(EXIT_INTERRUPTED);
    };
    let make = factory(u32::try_from(log.instants.len()).unwrap_or(u32::MAX))?;
    let mut estimators = make()?;
    let mut cov = args.mcap.as_ref().map(|_| Covariances::default());
    let (est, rejected) =
        run_estimators(&mut estimators, &log.instants, &log.late, nx, cov.as_mut());
    let stepped = if estimators.is_empty() || nx == 0 {
        log.instants.len()
    } else {
        est.len() / (nx * estimators.len())
    };
    let interrupted = stepped < log.instants.len();
    let instants = &log.instants[..stepped];
    if interrupted {
        estpipe_process::errln!(
            "ipc-runner: replay stopped by {} after {stepped} instants; the estimates so far \
             follow",
            estpipe_process::signal::termination_signal().unwrap_or("a signal")
        );
    }
    print_slot_counts(args, nodes, instants, &log.late);
    print_final_estimates(&estimators, &rejected, nx, instants.is_empty());
    if let Some(p) = &args.output {
        write_estimates(p, &estimators, nx, instants, &est)?;
        estpipe_process::outln!("estimates written to {p:?}");
    }
    if let (Some(p), Some(cov)) = (&args.mcap, &cov) {
        let names: Vec<String> = estimators.iter().map(|e| e.name().to_string()).collect();
        let scenario = args
            .estimator_spec
            .as_ref()
            .map_or_else(|| spec_name(args), |p| p.display().to_string());
        write_mcap(p, &scenario, nx, &names, instants, &est, cov)?;
        estpipe_process::outln!("MCAP written to {p:?}");
    }
    Ok(exit_code(interrupted, instants.len()))
}

/// The log, or `None` when a signal stopped the reading (said on stderr).
fn read_log(
    args: &ReplayArgs,
    nodes: usize,
    ny: usize,
    max_instants: u64,
) -> Result<Option<crate::slot_log::SlotLog>> {
    match read_slots_within(&args.input, nodes, ny, max_instants) {
        Err(e) if e.downcast_ref::<Interrupted>().is_some() => {
            estpipe_process::errln!(
                "ipc-runner: replay stopped by {} ({e}); nothing stepped, nothing written",
                estpipe_process::signal::termination_signal().unwrap_or("a signal")
            );
            Ok(None)
        }
        r => r.map(Some),
    }
}

/// 130 when a signal came, whether it cut the stepping short (`interrupted`) or came after
/// all `stepped` instants; else 0.
fn exit_code(interrupted: bool, stepped: usize) -> i32 {
    if !interrupted && estpipe_process::signal::termination_requested() {
        // The signal came after the last instant was stepped: nothing was left out, but the
        // user asked to stop and a script must see it (exit 130, as when stepping stopped).
        estpipe_process::errln!(
            "ipc-runner: replay stopped by {} after all {} instants were stepped; every \
             estimate was written",
            estpipe_process::signal::termination_signal().unwrap_or("a signal"),
            stepped
        );
        return EXIT_INTERRUPTED;
    }
    if interrupted {
        EXIT_INTERRUPTED
    } else {
        0
    }
}

/// `--output` and `--mcap` must not overwrite an input or each other.
fn check_replay_outputs(args: &ReplayArgs) -> Result<()> {
    let outputs = given(&[
        ("--output", args.output.as_deref()),
        ("--mcap", args.mcap.as_deref()),
    ]);
    if !outputs.is_empty() {
        let inputs = given(&[
            ("--input", Some(args.input.as_path())),
            ("--config", args.config.as_deref()),
            ("--estimator-spec", args.estimator_spec.as_deref()),
        ]);
        check_outputs(&outputs, &inputs)?;
    }
    Ok(())
}

/// `--max-memory` and the particles' share of it, checked before the log is read.
struct ParticleBudget {
    budget: Budget,
    particles: usize,
    /// The particle filters' bytes.
    pf: u64,
}

impl ParticleBudget {
    fn check(args: &ReplayArgs, spec: &estpipe_spec::EstimatorSpec) -> Result<Self> {
        let particles = args.estimator.particle_count();
        let budget = Budget::mib(args.max_memory);
        let pf = product(&[
            particles as u64,
            crate::estimators::pf_bytes_per_particle_for(spec),
        ]);
        budget.check(&format!("--particles {}", particles), pf)?;
        Ok(Self {
            budget,
            particles,
            pf,
        })
    }

    /// The instants the log may span in what the particles of `n_est` estimators leave.
    fn instants(&self, args: &ReplayArgs, nx: usize, n_est: u64) -> Result<u64> {
        // The instants' vector is held while it grows (the old and the new block at once: at
        // most 1.5 times its final size, `slot_log::read_slots_within`), then the estimates.
        let mut per_instant =
            size_of::<LoggedInstant>() as u64 * 3 / 2 + product(&[8, n_est, nx as u64]);
        if args.mcap.is_some() {
            per_instant = per_instant.saturating_add(product(&[n_est, 8 * (nx * nx) as u64 + 4]));
        }
        // The particles must leave room for at least one instant, or the log's first row
        // would be refused as "beyond the row limit" without a word about the particles.
        self.budget.check(
            &format!("--particles {} and one instant", self.particles),
            self.pf.saturating_add(per_instant),
        )?;
        Ok(self.budget.bytes.saturating_sub(self.pf) / per_instant)
    }
}

/// The slots replayed, by what became of them, and the late ones.
fn print_slot_counts(
    args: &ReplayArgs,
    nodes: usize,
    instants: &[LoggedInstant],
    late: &[(u32, Observation)],
) {
    let count = |f: &dyn Fn(&Observation) -> bool| -> usize {
        instants
            .iter()
            .map(|(_, o)| o.iter().filter(|o| f(o)).count())
            .sum()
    };
    let delivered = count(&|o| o.delivered);
    // Lost on the network (a bridge's FLAG_NET_LOST) apart from lost in the IPC: both are
    // stepped as losses, neither is the channel's dropout.
    let net_lost = count(&|o| !o.delivered && o.flags & FLAG_NET_LOST != 0);
    let ipc_lost =
        count(&|o| !o.delivered && o.flags & FLAG_IPC_LOST != 0 && o.flags & FLAG_NET_LOST == 0);
    estpipe_process::outln!(
        "replayed {} instants × {nodes} node(s) from {:?}: {delivered} measurements delivered, \
         {} dropped by the channel, {ipc_lost} lost in the IPC (flagged or missing), \
         {net_lost} lost on the network",
        instants.len(),
        args.input,
        instants.len() * nodes - delivered - ipc_lost - net_lost
    );
    if !late.is_empty() {
        estpipe_process::outln!(
            "{} slot(s) arrived late: {}",
            late.len(),
            if args.estimator.lag > 0 {
                format!(
                    "folded in where at most --lag {} instants late, lost otherwise",
                    args.estimator.lag
                )
            } else {
                "lost (no --lag)".to_string()
            }
        );
    }
}

/// Each estimator's rejections, final estimate and gate counts.
fn print_final_estimates(
    estimators: &[Box<dyn Estimator>],
    rejected: &[u64],
    nx: usize,
    none_stepped: bool,
) {
    for (e, est_e) in estimators.iter().enumerate() {
        // After the last instant and every late slot folded in after it.
        let mut last = [0.0; MAX_NX];
        est_e.estimate(&mut last[..nx]);
        estpipe_process::outln!(
            "{:<12} rejected {:>5}   final estimate {:?}",
            est_e.name(),
            rejected[e],
            if none_stepped { &[][..] } else { &last[..nx] }
        );
        if let Some((tested, rejected)) = crate::estimators::gate_counts(&**est_e) {
            estpipe_process::outln!(
                "{:<12} innovation gate rejected {rejected} of {tested} measurements",
                est_e.name()
            );
        }
    }
}

/// Writes `k,<est>_0..` rows of the instants stepped to `p`.
fn write_estimates(
    p: &std::path::Path,
    estimators: &[Box<dyn Estimator>],
    nx: usize,
    instants: &[LoggedInstant],
    est: &[f64],
) -> Result<()> {
    let ne = estimators.len();
    let mut w = std::io::BufWriter::new(
        std::fs::File::create(p).with_context(|| format!("cannot create {p:?}"))?,
    );
    write!(w, "k").with_context(|| format!("cannot write {p:?}"))?;
    for e in estimators {
        for j in 0..nx {
            write!(w, ",{}_{j}", e.name()).with_context(|| format!("cannot write {p:?}"))?;
        }
    }
    writeln!(w).with_context(|| format!("cannot write {p:?}"))?;
    for (i, (k, _)) in instants.iter().enumerate() {
        // Whole rows only; after the signal the rows computed are still written.
        write!(w, "{k}").with_context(|| format!("cannot write {p:?}"))?;
        for v in &est[i * nx * ne..(i + 1) * nx * ne] {
            write!(w, ",{v:e}").with_context(|| format!("cannot write {p:?}"))?;
        }
        writeln!(w).with_context(|| format!("cannot write {p:?}"))?;
    }
    // Dropping a BufWriter loses its last error: a full disk must fail the command.
    w.flush().with_context(|| format!("cannot write {p:?}"))?;
    Ok(())
}

/// The scenario's name for the MCAP metadata: the preset, or the TOML file.
fn spec_name(args: &ReplayArgs) -> String {
    args.config
        .as_ref()
        .map_or_else(|| args.scenario.clone(), |p| p.display().to_string())
}

/// Writes the replayed instants as an MCAP file ([`crate::mcap_file`]); instant k at k ms.
fn write_mcap(
    path: &std::path::Path,
    scenario: &str,
    nx: usize,
    names: &[String],
    instants: &[LoggedInstant],
    est: &[f64],
    cov: &Covariances,
) -> Result<()> {
    let ne = names.len();
    let mut w = crate::mcap_file::McapWriter::create(path, scenario, nx, names)?;
    for (i, (k, obs)) in instants.iter().enumerate() {
        let t = u64::from(*k) * 1_000_000;
        w.instant(&crate::mcap_file::InstantRecord {
            session: 1,
            k: *k,
            times: crate::mcap_file::Times {
                sent: t,
                received: t,
                published: t,
            },
            truth: None,
            obs,
            xhat: est.get(i * nx * ne..(i + 1) * nx * ne).unwrap_or(&[]),
            cov: cov
                .p
                .get(i * nx * nx * ne..(i + 1) * nx * nx * ne)
                .unwrap_or(&[]),
            cov_kind: cov.kind.get(i * ne..(i + 1) * ne).unwrap_or(&[]),
        })?;
    }
    w.finish()?;
    Ok(())
}
