//! The head of `BENCHMARKS.md`: the machine and the run, and how noisy its figures are.

use crate::command::sh;
use crate::opts::Opts;
use crate::prose;
use std::fmt::Write as _;
use std::time::Instant;

/// What is known of the machine and the run at its start.
pub struct Machine {
    started: Instant,
    load0: String,
    cpu: String,
    nproc: usize,
    rustc: String,
    date: String,
    commit: String,
    valgrind: String,
}

impl Machine {
    pub fn now(o: &Opts) -> Self {
        let started = Instant::now();
        let load0 = loadavg();
        let cpu = std::fs::read_to_string("/proc/cpuinfo")
            .ok()
            .and_then(|s| {
                s.lines()
                    .find(|l| l.starts_with("model name"))
                    .and_then(|l| l.split(':').nth(1))
                    .map(|m| m.trim().to_string())
            })
            .unwrap_or_else(|| "?".into());
        let nproc = std::thread::available_parallelism().map_or(0, |n| n.get());
        let rustc = sh("rustc", &["-V"]).unwrap_or_else(|| "?".into());
        let date = sh("date", &["-u", "+%Y-%m-%d %H:%M UTC"]).unwrap_or_else(|| "?".into());
        let commit = sh(
            "git",
            &[
                "-C",
                o.root.to_str().unwrap_or("."),
                "rev-parse",
                "--short",
                "HEAD",
            ],
        )
        .unwrap_or_else(|| "?".into());
        let valgrind = sh("valgrind", &["--version"]).unwrap_or_else(|| "not installed".into());
        Self {
            started,
            load0,
            cpu,
            nproc,
            rustc,
            date,
            commit,
            valgrind,
        }
    }

    /// The head, written once the parts have run (it gives the load at the end and the
    /// duration).
    pub fn header(&self, o: &Opts) -> String {
        let load1 = loadavg();
        let Self {
            started,
            load0,
            cpu,
            nproc,
            rustc,
            date,
            commit,
            valgrind,
        } = self;
        let mut md = String::new();
        prose::push(&mut md, include_str!("prose/header.md"));
        let _ = writeln!(md, "| | |\n|---|---|");
        let _ = writeln!(md, "| date | {date} |");
        let _ = writeln!(md, "| commit | {commit} |");
        let _ = writeln!(md, "| CPU | {cpu} |");
        let _ = writeln!(md, "| nproc | {nproc} |");
        let _ = writeln!(md, "| rustc | {rustc} |");
        let _ = writeln!(md, "| valgrind | {valgrind} |");
        let _ = writeln!(
            md,
            "| benchmark binaries | {} |",
            if o.plain_release {
                "plain `cargo build --release` (`--plain-release`)"
            } else {
                "`profile.bench` (thin LTO, one codegen unit)"
            }
        );
        let _ = writeln!(
            md,
            "| load average (1/5/15 min) at start / end | {load0} / {load1} |"
        );
        let _ = writeln!(
            md,
            "| mode | {} |",
            if o.quick {
                "`--quick` (short runs: indicative only)"
            } else {
                "full"
            }
        );
        let _ = writeln!(
            md,
            "| duration | {:.0} s |\n",
            started.elapsed().as_secs_f64()
        );
        prose::push(&mut md, &noise(load0));
        md
    }
}

/// The noise paragraph. The 1-minute load average at the start, against the core count: above
/// ~1 per core, other processes competed for the cores while the figures were taken.
fn noise(load0: &str) -> String {
    let load_start: f64 = load0
        .split_whitespace()
        .next()
        .and_then(|v| v.parse().ok())
        .unwrap_or(f64::NAN);
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get()) as f64;
    let busy = load_start.is_nan() || load_start >= cores;
    let machine = if busy {
        format!(
            "The machine was busy (1-minute load average {load_start:.1} on {cores:.0} \
             cores at the start): absolute times are inflated and noisy."
        )
    } else {
        format!(
            "The machine was otherwise idle (1-minute load average {load_start:.1} on \
             {cores:.0} cores at the start; the run itself keeps one to two cores busy)."
        )
    };
    prose::fill(
        include_str!("prose/noise.md"),
        &[("machine", &machine), ("cores", &format!("{cores:.0}"))],
    )
}

fn loadavg() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|_| "?".into())
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_prose_fills() {
        assert!(
            super::noise("0.10 0.20 0.30").contains("otherwise idle (1-minute load average 0.1 on")
        );
        assert!(super::noise("?").contains("The machine was busy (1-minute load average NaN"));
    }
}
