//! Running `ipc_latency`, the raw transports' ping-pong.

use crate::command::say;
use crate::opts::Opts;
use crate::pct::Pct;
use anyhow::{bail, Context, Result};
use serde_json::Value;
use std::collections::BTreeMap;
use std::process::{Command, Stdio};

/// `(one-way, round trip)` per mode.
pub type Raw = BTreeMap<String, (Pct, Pct)>;

/// Runs `ipc_latency` (`rate` 0: back to back) on the comma-separated `modes`.
pub fn run(o: &Opts, samples: u32, rate: f64, modes: &str) -> Result<Raw> {
    let bin = o.target.join("release/ipc_latency");
    let json = std::env::temp_dir().join(format!(
        "benches-report-ipc-{}-{rate}.json",
        std::process::id()
    ));
    say(&format!(
        "ipc_latency --samples {samples} --rate {rate} --modes {modes}"
    ));
    let st = Command::new(&bin)
        .args(["--samples", &samples.to_string(), "--warmup", "5000"])
        .args(["--rate", &rate.to_string(), "--modes", modes, "--json"])
        .arg(&json)
        .stdout(Stdio::null())
        .status()
        .context("ipc_latency")?;
    if !st.success() {
        bail!("ipc_latency failed ({st})");
    }
    let v: Value = serde_json::from_str(&std::fs::read_to_string(&json)?)?;
    let _ = std::fs::remove_file(&json);
    let mut res = BTreeMap::new();
    for (mode, m) in v.as_object().context("ipc_latency JSON")? {
        res.insert(
            mode.clone(),
            (
                Pct::from_json(&m["one_way"]).with_context(|| format!("{mode} one-way"))?,
                Pct::from_json(&m["round_trip"]).with_context(|| format!("{mode} round trip"))?,
            ),
        );
    }
    Ok(res)
}
