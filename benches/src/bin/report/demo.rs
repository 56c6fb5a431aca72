//! Running `ipc-runner demo`: the pipeline end to end, from its own processes.

use crate::command::say;
use crate::opts::Opts;
use anyhow::{bail, Context, Result};
use serde_json::Value;
use std::process::{Command, Stdio};

/// The scenario of the pipeline runs: `linear` (stable plant, cheap KF/IKF), so that the
/// figures measure the pipeline rather than an estimator. Seed 001's plant is unstable: over
/// 10⁵ instants its state overflows and the steps turn into rejections.
pub fn demo_scenario() -> &'static str {
    "linear"
}

/// Runs `ipc-runner demo` and reads its `report.json`.
pub fn demo(o: &Opts, wait: &str, rate: f64, steps: u32) -> Result<Value> {
    let bin = o.target.join("release/ipc-runner");
    let out = std::env::temp_dir().join(format!(
        "benches-report-demo-{}-{wait}-{rate}",
        std::process::id()
    ));
    say(&format!(
        "ipc-runner demo --wait {wait} --rate {rate} --steps {steps}"
    ));
    let res = Command::new("timeout")
        .arg("300")
        .arg(&bin)
        .args([
            "demo",
            "--quiet",
            "--wait",
            wait,
            "--scenario",
            demo_scenario(),
        ])
        .args(["--rate", &rate.to_string(), "--steps", &steps.to_string()])
        .args([
            "--prefix",
            &format!("benches-report-{}-{wait}", std::process::id()),
        ])
        .arg("--out")
        .arg(&out)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .context("ipc-runner demo");
    let read = || -> Result<Value> {
        let st = res?;
        if !st.success() {
            bail!("ipc-runner demo --wait {wait} --rate {rate} failed ({st})");
        }
        Ok(serde_json::from_str(&std::fs::read_to_string(
            out.join("report.json"),
        )?)?)
    };
    let v = read();
    let _ = std::fs::remove_dir_all(&out);
    v
}
