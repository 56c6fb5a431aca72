//! Part `eval`: Monte-Carlo throughput of `ipc-runner eval` per scenario preset.

use crate::command::say;
use crate::opts::Opts;
use crate::prose;
use anyhow::{Context, Result};
use serde_json::Value;
use std::fmt::Write as _;
use std::process::{Command, Stdio};
use std::time::Instant;

pub fn part(o: &Opts, md: &mut String) -> Result<()> {
    let bin = o.target.join("release/ipc-runner");
    let (runs, horizon) = if o.quick {
        (100u64, 100u32)
    } else {
        (1000, 100)
    };
    prose::push(md, &intro(runs, horizon));
    md.push_str("| scenario | estimators | threads | wall s | runs × steps / s |\n|---|---|---:|---:|---:|\n");
    for sc in channel_sim::scenario::preset_names() {
        for threads in [Some(1u32), None] {
            let json = std::env::temp_dir().join(format!(
                "benches-report-eval-{}-{sc}.json",
                std::process::id()
            ));
            // At most 5 minutes per scenario (a slow estimator must not stall the report).
            let mut cmd = Command::new("timeout");
            cmd.arg("300")
                .arg(&bin)
                .args(["eval", "--scenario", sc, "--quiet", "--seed", "1"])
                .args(["--runs", &runs.to_string(), "--steps", &horizon.to_string()])
                .arg("--json")
                .arg(&json)
                .stdout(Stdio::null())
                .stderr(Stdio::null());
            if let Some(t) = threads {
                cmd.args(["--threads", &t.to_string()]);
            }
            say(&format!("eval {sc} threads {threads:?}"));
            let t = Instant::now();
            let st = cmd.status().context("ipc-runner eval")?;
            let secs = t.elapsed().as_secs_f64();
            if !st.success() {
                let _ = writeln!(md, "| {sc} | (eval failed: {st}) | | | |");
                continue;
            }
            let names = std::fs::read_to_string(&json)
                .ok()
                .and_then(|s| serde_json::from_str::<Value>(&s).ok())
                .and_then(|v| {
                    v["estimators"]
                        .as_object()
                        .map(|m| m.keys().cloned().collect::<Vec<_>>().join(", "))
                })
                .unwrap_or_default();
            let _ = std::fs::remove_file(&json);
            let _ = writeln!(
                md,
                "| {sc} | {names} | {} | {secs:.2} | {:.0} |",
                threads.map_or_else(
                    || std::thread::available_parallelism()
                        .map_or(0, |n| n.get())
                        .to_string(),
                    |t| t.to_string()
                ),
                (runs * horizon as u64) as f64 / secs
            );
        }
    }
    md.push('\n');
    Ok(())
}

fn intro(runs: u64, horizon: u32) -> String {
    prose::fill(
        include_str!("prose/eval_throughput.md"),
        &[("runs", &runs), ("horizon", &horizon)],
    )
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_prose_fills() {
        assert!(super::intro(1000, 100).contains("with 1000 runs × horizon 100,"));
    }
}
