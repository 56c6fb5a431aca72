//! Running other programs, and telling on stderr what is being run.

use anyhow::{bail, Context, Result};
use serde_json::Value;
use std::path::Path;
use std::process::Command;

/// A note printed to stderr as the run goes.
pub fn say(msg: &str) {
    eprintln!("report: {msg}");
}

/// The trimmed stdout of `cmd args`, or `None` if it cannot run or fails.
pub fn sh(cmd: &str, args: &[&str]) -> Option<String> {
    let o = Command::new(cmd).args(args).output().ok()?;
    o.status
        .success()
        .then(|| String::from_utf8_lossy(&o.stdout).trim().to_string())
}

/// Runs one of the benchmark binaries with `args` and `--json`, and parses its stdout.
pub fn run_json(bin: &Path, args: &[&str]) -> Result<Value> {
    say(&format!("{} {} --json", bin.display(), args.join(" ")));
    let out = Command::new(bin)
        .args(args)
        .arg("--json")
        .env("IOX2_LOG_LEVEL", "Error")
        .output()
        .with_context(|| format!("{bin:?}"))?;
    if !out.status.success() {
        bail!("{}", String::from_utf8_lossy(&out.stderr).trim());
    }
    serde_json::from_slice(&out.stdout).with_context(|| format!("{bin:?}: JSON on stdout"))
}
