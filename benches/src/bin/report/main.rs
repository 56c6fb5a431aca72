//! Regenerates `BENCHMARKS.md`: runs every benchmark of the product on this machine and writes
//! the tables. Run through `benches/run.sh` (which builds what it needs first).
//!
//! Parts, in order (each can be skipped with `--skip PART,…`), each in a module of its own:
//!
//! - `criterion` ([`kf_comparison`]): `cargo bench -p benches` (every criterion bench file),
//!   medians with their 95 % confidence intervals, our KF against `adskalman` as ratios of the
//!   same run, and interleaved in one process ([`kf_interleaved`]);
//! - `icount` ([`icount`]): host instructions per step under valgrind/callgrind,
//!   `(I(2N) − I(N)) / N`, each 2N run done twice to show the count is deterministic;
//! - `firmware` ([`firmware`]): Cortex-M4 instructions per step from `.ci/firmware` (QEMU TCG
//!   plugin);
//! - `ipc` ([`raw_transports`]): `ipc_latency` (raw iceoryx2 and Unix socket ping-pong);
//! - `pipeline` ([`pipeline`]): `ipc-runner demo` end to end (slot sent → estimates
//!   published), spin ([`spin_verdict`], [`tail_breakdown`]) and blocking, and a sustained
//!   100 000 slots/s run ([`sustained`]);
//! - `idle` ([`idle_penalty`]): the same small works back to back and paced;
//! - `eval` ([`eval_throughput`]): Monte-Carlo throughput of `ipc-runner eval` per scenario
//!   preset.
//!
//! `--quick` shortens every part (for trying the script; the committed file uses the full run).
//!
//! The prose of the report is in `prose/*.md` ([`prose`]).

mod command;
mod criterion;
mod demo;
mod eval_throughput;
mod firmware;
mod format;
mod header;
mod icount;
mod idle_penalty;
mod ipc_latency;
mod kf_comparison;
mod kf_forms;
mod kf_interleaved;
mod opts;
mod pct;
mod pipeline;
mod plots;
mod prose;
mod rate;
mod raw_transports;
mod spin_verdict;
mod sustained;
mod tail_breakdown;

use anyhow::{Context, Result};
use command::say;
use opts::Opts;
use std::fmt::Write as _;

/// The parts' text, and the parts that failed.
#[derive(Default)]
struct Body {
    md: String,
    failures: Vec<String>,
}

impl Body {
    /// Runs part `name` unless skipped. It writes into a buffer of its own, kept only if the
    /// part completed: a failed part is listed at the end instead.
    fn part<T>(
        &mut self,
        o: &Opts,
        name: &str,
        f: impl FnOnce(&Opts, &mut String) -> Result<T>,
    ) -> Option<T> {
        if !o.runs(name) {
            return None;
        }
        let mut part = String::new();
        match f(o, &mut part) {
            Ok(v) => {
                self.md.push_str(&part);
                Some(v)
            }
            Err(e) => {
                say(&format!("{name}: {e:#}"));
                self.failures.push(format!("{name}: {e:#}"));
                None
            }
        }
    }
}

fn run() -> Result<()> {
    let Some(o) = Opts::from_args()? else {
        return Ok(());
    };
    let machine = header::Machine::now(&o);
    let mut body = Body::default();
    body.part(&o, "criterion", kf_comparison::part);
    body.part(&o, "icount", icount::part);
    body.part(&o, "firmware", firmware::part);
    let raw = body
        .part(&o, "ipc", raw_transports::part)
        .unwrap_or_default();
    body.part(&o, "pipeline", |o, md| pipeline::part(o, md, &raw));
    body.part(&o, "idle", idle_penalty::part);
    body.part(&o, "eval", eval_throughput::part);

    let mut md = machine.header(&o);
    md.push_str(&body.md);
    if !body.failures.is_empty() {
        md.push_str("## Parts that did not run\n\n");
        for f in &body.failures {
            let _ = writeln!(md, "- {f}");
        }
        md.push('\n');
    }
    std::fs::write(&o.out, md).with_context(|| format!("write {:?}", o.out))?;
    say(&format!("wrote {:?}", o.out));
    Ok(())
}

fn main() {
    if let Err(e) = run() {
        eprintln!("report: {e:#}");
        std::process::exit(1);
    }
}
