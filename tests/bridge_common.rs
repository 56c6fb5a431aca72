//! Shared helpers of the bridge tests (`pipeline_bridge.rs`, `hostile_bridge.rs`): a
//! publisher on prefix A, a runner on prefix B, and two `bridge` processes joined over zenoh
//! on a free loopback port. Include after `pipeline_common.rs` as `mod common`:
//!
//! ```ignore
//! #[path = "pipeline_common.rs"]
//! mod common;
//! #[path = "bridge_common.rs"]
//! mod bridge_common;
//! ```

#![allow(dead_code)]

use crate::common::{self, Proc};
use std::path::{Path, PathBuf};

/// A loopback TCP port nobody listens on now.
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// One bridged chain's names: publisher prefix `a`, runner prefix `b`, zenoh `key` and the
/// sensor side's `endpoint`, all unique to this test; outputs in `dir`.
pub struct Chain {
    pub dir: PathBuf,
    pub a: String,
    pub b: String,
    pub key: String,
    pub endpoint: String,
}

impl Chain {
    pub fn new(test: &str) -> Self {
        Self::in_dir(common::scratch(test), test)
    }

    /// A chain whose outputs go to `dir` (several chains of one test may share it).
    pub fn in_dir(dir: PathBuf, test: &str) -> Self {
        Self {
            a: common::prefix(&format!("{test}-a")),
            b: common::prefix(&format!("{test}-b")),
            key: format!("estpipe-test/{}", common::prefix("key")),
            endpoint: format!("tcp/127.0.0.1:{}", free_port()),
            dir,
        }
    }

    /// `bridge --side estimator --once` on `b` (report `dir/bridge-<name>.json`).
    pub fn estimator(&self, name: &str, extra: &[&str]) -> Proc {
        bridge(
            &self.dir,
            name,
            &self.b,
            &self.key,
            &self.endpoint,
            true,
            extra,
        )
    }

    /// `bridge --side sensor --once` on `a` (report `dir/bridge-<name>.json`).
    pub fn sensor(&self, name: &str, extra: &[&str]) -> Proc {
        bridge(
            &self.dir,
            name,
            &self.a,
            &self.key,
            &self.endpoint,
            true,
            extra,
        )
    }

    /// `run` on `b` (outputs `dir/<name>.csv`, `dir/<name>.json`).
    pub fn runner(&self, name: &str, steps: u32, extra: &[&str]) -> Proc {
        runner(&self.dir, name, &self.b, steps, extra)
    }

    /// [`Chain::runner`] that says what it does on stderr (stalls, a bridge gone).
    pub fn loud_runner(&self, name: &str, steps: u32, extra: &[&str]) -> Proc {
        runner_with(&self.dir, name, &self.b, steps, false, extra)
    }

    /// `channel-sim` on `a`.
    pub fn publisher(&self, name: &str, steps: u32, rate: u32) -> Proc {
        publisher(&self.dir, name, &self.a, steps, rate)
    }

    /// `dir/<name>`'s JSON report.
    pub fn report(&self, file: &str) -> serde_json::Value {
        common::report(&self.dir.join(file))
    }
}

/// `bridge --side <side>` on `prefix`, joined to the other side through `endpoint` (the
/// sensor side listens, the estimator side connects); the side is `name` without trailing
/// digits (`sensor2` is a sensor side). Its report is `dir/bridge-<name>.json`, its output
/// `dir/bridge-<name>.err`. With `once`, it exits after the stream ended.
pub fn bridge(
    dir: &Path,
    name: &str,
    prefix: &str,
    key: &str,
    endpoint: &str,
    once: bool,
    extra: &[&str],
) -> Proc {
    let side = name.trim_end_matches(char::is_numeric);
    let report = dir.join(format!("bridge-{name}.json"));
    let role = if side == "sensor" {
        "--listen"
    } else {
        "--connect"
    };
    let mut args = vec![
        "bridge",
        "--side",
        side,
        "--prefix",
        prefix,
        "--key",
        key,
        role,
        endpoint,
        "--connect-timeout",
        "20",
        "--report",
        report.to_str().unwrap(),
    ];
    if once {
        args.push("--once");
    }
    args.extend_from_slice(extra);
    Proc::start(dir, &format!("bridge-{name}"), &args)
}

/// `run --scenario occlusion --quiet` on `prefix` writing estimates and report into
/// `dir/<name>.*` (`--wait block --buffer 4096` unless `extra` gives them).
pub fn runner(dir: &Path, name: &str, prefix: &str, steps: u32, extra: &[&str]) -> Proc {
    runner_with(dir, name, prefix, steps, true, extra)
}

/// [`runner`], saying what it does on stderr unless `quiet`.
pub fn runner_with(
    dir: &Path,
    name: &str,
    prefix: &str,
    steps: u32,
    quiet: bool,
    extra: &[&str],
) -> Proc {
    let csv = dir.join(format!("{name}.csv"));
    let json = dir.join(format!("{name}.json"));
    let steps = steps.to_string();
    let mut args = vec![
        "run",
        "--scenario",
        "occlusion",
        "--prefix",
        prefix,
        "--steps",
        &steps,
        "--estimates-csv",
        csv.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ];
    if quiet {
        args.push("--quiet");
    }
    for (flag, value) in [("--wait", "block"), ("--buffer", "4096")] {
        if !extra.contains(&flag) {
            args.extend([flag, value]);
        }
    }
    args.extend_from_slice(extra);
    Proc::start(dir, name, &args)
}

/// `channel-sim --scenario occlusion` on `prefix`: `steps` instants at `rate` Hz.
pub fn publisher(dir: &Path, name: &str, prefix: &str, steps: u32, rate: u32) -> Proc {
    let (steps, rate) = (steps.to_string(), rate.to_string());
    Proc::start(
        dir,
        name,
        &[
            "channel-sim",
            "--scenario",
            "occlusion",
            "--prefix",
            prefix,
            "--rate",
            &rate,
            "--steps",
            &steps,
            "--quiet",
        ],
    )
}

/// Waits for `p` to exit 0 (within `secs`) without a panic.
pub fn assert_ok(p: &mut Proc, secs: u64) {
    let st = p.wait(secs);
    assert!(st.success(), "{} exited {st}: {}", p.name, p.err());
    assert!(!p.err().contains("panicked"), "{}: {}", p.name, p.err());
}

/// The estimates CSV without its timing columns (those differ between any two runs).
pub fn estimates(path: &Path) -> Vec<String> {
    let s = std::fs::read_to_string(path).unwrap();
    let mut lines = s.lines();
    let head: Vec<&str> = lines.next().unwrap().split(',').collect();
    let keep: Vec<usize> = (0..head.len())
        .filter(|&i| !head[i].ends_with("_ns") && !head[i].contains("latency"))
        .collect();
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            keep.iter().map(|&i| f[i]).collect::<Vec<_>>().join(",")
        })
        .collect()
}

/// Every instant of a run report accounted for: received, or lost for one of the counted
/// reasons (on the network, in the IPC, by the deadline, by overrun, after an END, before the
/// runner joined). Returns (received, lost).
pub fn accounted(run: &serde_json::Value, steps: u32) -> (u64, u64) {
    let c = &run["counts"];
    let n = |f: &str| {
        c[f].as_u64()
            .unwrap_or_else(|| panic!("counts.{f} in {run}"))
    };
    let received = n("received");
    let lost = [
        "lost_on_network",
        "lost_in_ipc",
        "lost_deadline",
        "lost_overrun",
        "lost_after_end",
        "missed_before_join",
    ]
    .iter()
    .map(|f| n(f))
    .sum::<u64>();
    assert_eq!(
        received + lost,
        u64::from(steps),
        "received {received} + lost {lost} != {steps} instants: {c}"
    );
    assert_eq!(n("instants"), u64::from(steps), "{c}");
    (received, lost)
}
