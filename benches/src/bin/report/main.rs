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
//!   plugin); with `icount`, what a late packet costs ([`late`]);
//! - `pipeline` ([`pipeline`]): `ipc-runner demo` end to end (slot sent → estimates
//!   published), one spinning and one sleeping runner, one table;
//! - `bridge` ([`bridge`]): the bridge hop over loopback (`demo --via zenoh`) against raw
//!   zenoh pub/sub of the same payload (`zenoh_latency`) and the one-host pipeline, the three
//!   alternating over rounds;
//! - `eval-baseline` ([`eval_baseline`]): issue #23's Monte-Carlo command against commit
//!   `b7a974e`, CPU time and instructions side by side, the JSON compared, where the
//!   instructions go;
//! - `eval` ([`eval_throughput`]): Monte-Carlo throughput of `ipc-runner eval` per scenario
//!   preset;
//! - `view` ([`view`]): the live view's cost to the loop, short runs with and without a
//!   reading page in alternating pairs, and the tap's instructions per instant.
//!
//! Retired (issue #23): the raw transports' ping-pong (`ipc`, with its `ipc_latency` binary)
//! and the idling penalty (`idle_penalty`), which measured the p99 tails of a shared 2-core
//! VM more than the transports; their last figures are in the git history of `BENCHMARKS.md`.
//!
//! `--quick` shortens every part (for trying the script; the committed file uses the full run).
//! A part that is skipped keeps its section of the existing output file, if it has one, marked
//! as not rerun ([`carried`]): the deterministic parts can be regenerated on their own.
//!
//! The prose of the report is in `prose/*.md` ([`prose`]).

mod bridge;
mod command;
mod criterion;
mod demo;
mod eval_baseline;
mod eval_throughput;
mod firmware;
mod firmware_heavy;
mod firmware_speed;
mod format;
mod header;
mod icount;
mod kf_comparison;
mod kf_forms;
mod kf_interleaved;
mod late;
mod opts;
mod pct;
mod pipeline;
mod prose;
mod rate;
mod view;

use anyhow::{Context, Result};
use command::say;
use opts::Opts;
use std::fmt::Write as _;

/// The parts' text, and the parts that failed.
#[derive(Default)]
struct Body {
    md: String,
    failures: Vec<String>,
    /// The output file as it was before this run (empty if there was none).
    old: String,
}

/// The headings each part's section starts with, in the order of the file.
const SECTIONS: &[(&str, &str)] = &[
    ("criterion", "## Kalman step: ours against `adskalman`"),
    ("icount", "## Instructions per step on the host"),
    ("firmware", "## The Cortex-M4F on QEMU"),
    // Retired (issue #23), like "idle" below.
    ("ipc", "## IPC latency: raw transports"),
    ("pipeline", "## IPC latency: the full pipeline end to end"),
    ("bridge", "## Across hosts: the bridge hop over loopback"),
    // Retired (issue #23): it only ends the section before it in an older file.
    ("idle", "## What idling costs here"),
    (
        "eval-baseline",
        "## Monte-Carlo evaluation: issue #23's command",
    ),
    ("eval", "## Monte-Carlo evaluation throughput"),
    ("view", "## The live view's cost to the loop"),
];

/// Part `name`'s section of the previous file `old` (from its heading up to the next part's
/// or a "## Parts that did not run"), with a line saying it was not rerun; `None` if `old`
/// has none.
fn carried(old: &str, name: &str) -> Option<String> {
    let (_, head) = SECTIONS.iter().find(|(n, _)| *n == name)?;
    let start = old.find(&format!("\n{head}"))? + 1;
    let rest = &old[start..];
    let end = SECTIONS
        .iter()
        .filter_map(|(_, h)| rest[1..].find(&format!("\n{h}")).map(|i| i + 2))
        .chain(rest[1..].find("\n## Parts that did not run").map(|i| i + 2))
        .min()
        .unwrap_or(rest.len());
    let section = rest[..end].trim_end();
    // Carried before: its note already names the run it is from.
    if section.lines().last().is_some_and(|l| l.starts_with(NOTE)) {
        return Some(format!("{section}\n\n"));
    }
    // The head of this file describes this run: the machine and date the section was
    // measured on go into its note.
    let field = |name: &str| {
        old.lines()
            .find_map(|l| l.strip_prefix(&format!("| {name} | ")))
            .and_then(|l| l.strip_suffix(" |"))
    };
    let commit = field("commit").unwrap_or("?");
    let on = match (field("date"), field("CPU")) {
        (Some(d), Some(c)) => format!(" (run on {d}, CPU {c})"),
        _ => String::new(),
    };
    Some(format!(
        "{section}\n\n{NOTE} carried over from the `BENCHMARKS.md` of commit {commit}{on}.)*\n\n"
    ))
}

/// How a carried section's last line starts.
const NOTE: &str = "*(Not rerun in this regeneration:";

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
            if let Some(old) = carried(&self.old, name) {
                self.md.push_str(&old);
            }
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
    let mut body = Body {
        old: std::fs::read_to_string(&o.out).unwrap_or_default(),
        ..Body::default()
    };
    body.part(&o, "criterion", kf_comparison::part);
    body.part(&o, "icount", icount::part);
    body.part(&o, "firmware", firmware::part);
    body.part(&o, "pipeline", pipeline::part);
    body.part(&o, "bridge", bridge::part);
    body.part(&o, "eval-baseline", eval_baseline::part);
    body.part(&o, "eval", eval_throughput::part);
    body.part(&o, "view", view::part);

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

#[cfg(test)]
mod tests {
    use super::carried;

    #[test]
    fn a_skipped_part_keeps_its_old_section() {
        let old = "# B\n\n| date | d |\n| commit | abc |\n| CPU | c |\n\n## Instructions per step on the host (x)\n\nt1\n\n### sub\n\nt2\n\n## The Cortex-M4F on QEMU: y\n\nf\n\n## Parts that did not run\n\n- z\n";
        let icount = carried(old, "icount").unwrap();
        assert_eq!(
            icount,
            "## Instructions per step on the host (x)\n\nt1\n\n### sub\n\nt2\n\n*(Not rerun in \
             this regeneration: carried over from the `BENCHMARKS.md` of commit abc (run on d, CPU \
             c).)*\n\n"
        );
        let fw = carried(old, "firmware").unwrap();
        assert!(fw.starts_with("## The Cortex-M4F on QEMU: y\n\nf\n\n*(Not rerun"));
        // Carried twice, still one note.
        assert_eq!(carried(&format!("x\n{fw}"), "firmware").unwrap(), fw);
        assert!(carried(old, "criterion").is_none());
    }
}
