//! Skipped tests, said where `cargo test` shows them.
//!
//! A test that cannot run here (no Python client, no QEMU, not root, …) returns early and
//! libtest reports it "ok", and libtest captures what a passing test prints. So a test that
//! skips calls [`skipped`]: the line goes straight to the stderr handle (not captured), and is
//! appended to this cargo run's skip log under `target/tmp/skips/`; the last test binary
//! cargo runs, `ipc-runner`'s `zz_skip_summary` (cargo runs the packages' test binaries in
//! name order, `ipc-runner` last), prints every line of the log at the end of the output
//! (README, "Tests").
//!
//! A cargo run is told apart by its process: cargo starts every test binary itself, so the
//! binaries of one run share their parent, whose pid and start time name the log.
//!
//! Included by path (`#[path = …] mod skip_log;`) in every test crate that skips, so that
//! `CARGO_TARGET_TMPDIR` and `CARGO_CRATE_NAME` are that crate's.

#![allow(dead_code)]

use std::io::Write;
use std::path::PathBuf;

/// The directory of the skip logs (`target/tmp/skips`).
pub fn dir() -> PathBuf {
    PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("skips")
}

/// `(pid, start time in clock ticks since boot)` of process `pid`, from `/proc/<pid>/stat`.
fn start_time(pid: u32) -> Option<u64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // The command name (field 2) may hold spaces and parentheses: fields after its last ')'.
    let rest = &stat[stat.rfind(')')? + 1..];
    // Field 22 (starttime) is the 20th after the name.
    rest.split_whitespace().nth(19)?.parse().ok()
}

/// This process's parent, the cargo that runs the tests: the log's name.
pub fn run_name() -> String {
    let ppid = std::os::unix::process::parent_id();
    format!("{ppid}-{}", start_time(ppid).unwrap_or(0))
}

/// Whether the run that wrote log `name` (`<pid>-<start time>`) is still going on.
pub fn run_alive(name: &str) -> bool {
    let Some((pid, start)) = name.split_once('-') else {
        return false;
    };
    match (pid.parse::<u32>(), start.parse::<u64>()) {
        (Ok(pid), Ok(start)) => start_time(pid) == Some(start),
        _ => false,
    }
}

/// The log of this cargo run.
pub fn run_log() -> PathBuf {
    dir().join(format!("{}.log", run_name()))
}

/// Says that test `test` of this test crate skipped and why: on stderr now, and in the
/// run's log for the summary at the end.
pub fn skipped(test: &str, why: &str) {
    let why = why.replace(['\n', '\r'], " ");
    let line = format!("{}::{test}: {why}", env!("CARGO_CRATE_NAME"));
    let _ = writeln!(std::io::stderr(), "SKIPPED {line}");
    let _ = std::fs::create_dir_all(dir());
    // One write of one line, appended: the threads of a test binary may skip at once.
    if let Ok(mut f) = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(run_log())
    {
        let _ = f.write_all(format!("{line}\n").as_bytes());
    }
}

/// The name of the test running on this thread (libtest names a test's thread after it), or
/// `what` where it does not.
pub fn current_test(what: &str) -> String {
    match std::thread::current().name() {
        Some(n) if n != "main" => n.to_string(),
        _ => what.to_string(),
    }
}
