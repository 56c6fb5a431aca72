//! Running `ipc-runner demo`: the pipeline end to end, from its own processes.

use crate::command::say;
use crate::opts::Opts;
use anyhow::{bail, Context, Result};
use serde_json::Value;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Instant;

/// The scenario of the pipeline runs: `linear` (stable plant, cheap KF/IKF), so that the
/// figures measure the pipeline rather than an estimator. Seed 001's plant is unstable: over
/// 10⁵ instants its state overflows and the steps turn into rejections.
pub fn demo_scenario() -> &'static str {
    "linear"
}

/// A demo's report JSON, the process's wall time, and its per-instant end-to-end latencies
/// (`latency.csv`: seconds since the first send, transport µs, end to end µs).
pub struct DemoRun {
    pub report: Value,
    pub secs: f64,
    pub trace: Vec<ipc_runner::plot_trace::Point>,
}

/// Reads `latency.csv` as written by `ipc-runner demo`.
fn read_trace(path: &Path) -> Result<Vec<ipc_runner::plot_trace::Point>> {
    let text = std::fs::read_to_string(path).with_context(|| format!("{path:?}"))?;
    text.lines()
        .skip(1)
        .map(|l| {
            let f: Vec<f64> = l
                .split(',')
                .skip(2)
                .map(str::parse)
                .collect::<Result<_, _>>()
                .with_context(|| format!("{path:?}: {l:?}"))?;
            anyhow::ensure!(f.len() == 3, "{path:?}: {l:?}");
            Ok((f[0], f[1], f[2]))
        })
        .collect()
}

/// Runs `ipc-runner demo`. `latest` adds `--latest-estimates` (estimates on the blackboard
/// instead of the queue).
pub fn demo(o: &Opts, wait: &str, rate: f64, steps: u32, latest: bool) -> Result<DemoRun> {
    let bin = o.target.join("release/ipc-runner");
    let out = std::env::temp_dir().join(format!(
        "benches-report-demo-{}-{wait}-{rate}",
        std::process::id()
    ));
    say(&format!(
        "ipc-runner demo --wait {wait} --rate {rate} --steps {steps}"
    ));
    let t = Instant::now();
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
        .args(latest.then_some("--latest-estimates"))
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
    let secs = t.elapsed().as_secs_f64();
    let read = || -> Result<DemoRun> {
        let st = res?;
        if !st.success() {
            bail!("ipc-runner demo --wait {wait} --rate {rate} failed ({st})");
        }
        Ok(DemoRun {
            report: serde_json::from_str(&std::fs::read_to_string(out.join("report.json"))?)?,
            secs,
            trace: read_trace(&out.join("latency.csv"))?,
        })
    };
    let v = read();
    let _ = std::fs::remove_dir_all(&out);
    v
}
