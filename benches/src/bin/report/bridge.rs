//! Part `bridge`: the bridge hop over loopback (issue #21) against raw zenoh pub/sub of the
//! same payload and against the one-host pipeline, in one run, the three setups alternating
//! over rounds (which goes first rotates), medians over the rounds and per-round ratios.
//!
//! Per round and setup, one paced run (latency) and one unpaced run (throughput, nothing
//! lost):
//!
//! - raw zenoh: `zenoh_latency` (`benches/src/bin/zenoh_latency.rs`, two processes, TCP on
//!   loopback, the bridge's slot message);
//! - the bridge hop: `ipc-runner demo --via zenoh` (publisher → sensor-side bridge → zenoh →
//!   estimator-side bridge → runner), the estimator-side bridge's `network_hop` and
//!   `bridge_time` from its report, the runner's transport and end-to-end latency from its
//!   own;
//! - the one-host pipeline: `ipc-runner demo`, the same scenario, rate and steps.
//!
//! Throughput of a demo: instants ÷ (first slot sent → last instant's estimates published),
//! from its `latency.csv`; of raw zenoh: messages ÷ (first sent → last taken by the
//! subscriber). A throughput run that lost anything (or whose counts do not add up) fails the
//! part.

use crate::command::{run_json, say};
use crate::demo::demo_scenario;
use crate::eval_baseline::median;
use crate::opts::Opts;
use crate::prose;
use anyhow::{bail, ensure, Context, Result};
use serde_json::Value;
use std::fmt::Write as _;
use std::process::{Command, Stdio};
use std::time::Instant;

/// Messages (slots) per second of the paced runs.
pub const BRIDGE_RATE: f64 = 1000.0;

/// The setups, in the order of the tables.
const SETUPS: [&str; 3] = [
    "raw zenoh pub/sub",
    "bridge hop (`demo --via zenoh`)",
    "one-host pipeline (`demo`)",
];

/// How long the part ran and how big it was (for the prose).
#[derive(Clone, Copy, Debug)]
struct Size {
    rounds: usize,
    paced: u32,
    burst: u32,
}

/// What one setup measured in one round.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Measure {
    /// Latency stages of the paced run: (stage, p50 µs, p99 µs).
    stages: Vec<(&'static str, f64, f64)>,
    /// Messages (slots) per second of the unpaced run.
    throughput: f64,
    /// Messages (slots) the paced run lost, all causes.
    lost_paced: u64,
}

impl Measure {
    fn stage(&self, name: &str) -> Option<(f64, f64)> {
        self.stages.iter().find(|s| s.0 == name).map(|s| (s.1, s.2))
    }
}

/// The files of one `ipc-runner demo` run.
#[derive(Clone, Debug, Default)]
pub struct DemoFiles {
    /// `report.json`.
    report: Value,
    /// `bridge-estimator.json` (`--via zenoh` only).
    bridge: Option<Value>,
    /// `latency.csv`.
    latency_csv: String,
}

pub fn part(o: &Opts, md: &mut String) -> Result<()> {
    let size = if o.quick {
        Size {
            rounds: 2,
            paced: 1000,
            burst: 5000,
        }
    } else {
        Size {
            rounds: 5,
            paced: 3000,
            burst: 30_000,
        }
    };
    let started = Instant::now();
    let mut rounds: Vec<[Measure; 3]> = Vec::new();
    for r in 0..size.rounds {
        let mut m: [Measure; 3] = Default::default();
        for i in 0..3 {
            let s = (r + i) % 3;
            say(&format!(
                "bridge: round {}/{}, {}",
                r + 1,
                size.rounds,
                SETUPS[s]
            ));
            m[s] = match s {
                0 => from_raw(
                    &raw(o, size.paced, BRIDGE_RATE)?,
                    &raw(o, size.burst, 0.0)?,
                    size.paced,
                    size.burst,
                )?,
                _ => {
                    let via = if s == 1 { "zenoh" } else { "shm" };
                    from_demo(
                        &demo(o, via, BRIDGE_RATE, size.paced, r)?,
                        &demo(o, via, 0.0, size.burst, r)?,
                        size.paced,
                        size.burst,
                    )?
                }
            };
        }
        rounds.push(m);
    }
    prose::push(md, &intro(size, started.elapsed().as_secs_f64()));
    render(md, &rounds);
    Ok(())
}

fn intro(size: Size, secs: f64) -> String {
    prose::fill(
        include_str!("prose/bridge.md"),
        &[
            ("bytes", &estpipe_wire::net::SLOT_MESSAGE_LEN),
            ("scenario", &demo_scenario()),
            ("rate", &BRIDGE_RATE),
            ("paced", &size.paced),
            ("burst", &size.burst),
            ("rounds", &size.rounds),
            ("secs", &format!("{secs:.0}")),
        ],
    )
}

/// Runs `zenoh_latency` (`rate` 0: unpaced).
fn raw(o: &Opts, samples: u32, rate: f64) -> Result<Value> {
    run_json(
        &o.target.join("release/zenoh_latency"),
        &[
            "--samples",
            &samples.to_string(),
            "--rate",
            &rate.to_string(),
        ],
    )
}

/// Raw zenoh's figures from its paced and unpaced runs of `paced` and `burst` messages;
/// refuses an unpaced run that lost or refused anything, and counts that do not add up.
pub fn from_raw(paced: &Value, burst: &Value, n_paced: u32, n_burst: u32) -> Result<Measure> {
    let check = |v: &Value, n: u32| -> Result<u64> {
        let n = u64::from(n);
        let u = |k: &str| {
            v[k].as_u64()
                .with_context(|| format!("zenoh_latency {k}: {v}"))
        };
        ensure!(u("sent")? == n, "zenoh_latency sent {} of {n}", u("sent")?);
        ensure!(
            u("received")? + u("lost")? == n,
            "zenoh_latency: received + lost ≠ sent: {v}"
        );
        ensure!(
            u("measured")? == u("received")?
                && v["one_way"]["count"].as_u64() == Some(u("measured")?),
            "zenoh_latency: measured ≠ received: {v}"
        );
        ensure!(
            u("refused")? == 0 && u("out_of_order")? == 0,
            "zenoh_latency: {v}"
        );
        u("lost")
    };
    let lost_paced = check(paced, n_paced)?;
    ensure!(
        check(burst, n_burst)? == 0,
        "raw zenoh lost messages unpaced: {burst}"
    );
    let ow = &paced["one_way"];
    Ok(Measure {
        stages: vec![("one way", f(ow, "p50_us")?, f(ow, "p99_us")?)],
        throughput: f(burst, "throughput_per_s")?,
        lost_paced,
    })
}

fn f(v: &Value, k: &str) -> Result<f64> {
    v[k].as_f64()
        .filter(|x| x.is_finite())
        .with_context(|| format!("no number {k:?} in {v}"))
}

/// Runs `ipc-runner demo` (`--via via`, a sleeping runner) and reads its files.
fn demo(o: &Opts, via: &str, rate: f64, steps: u32, round: usize) -> Result<DemoFiles> {
    let bin = o.target.join("release/ipc-runner");
    let tag = format!("{}-{via}-{rate}-{round}", std::process::id());
    let out = std::env::temp_dir().join(format!("benches-report-bridge-{tag}"));
    say(&format!(
        "ipc-runner demo --via {via} --wait block --rate {rate} --steps {steps}"
    ));
    let st = Command::new("timeout")
        .arg("300")
        .arg(&bin)
        .args(["demo", "--quiet", "--wait", "block", "--via", via])
        .args(["--scenario", demo_scenario()])
        .args(["--rate", &rate.to_string(), "--steps", &steps.to_string()])
        .args(["--prefix", &format!("benches-bridge-{tag}")])
        .arg("--out")
        .arg(&out)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .context("ipc-runner demo");
    let read = |name: &str| -> Result<String> {
        std::fs::read_to_string(out.join(name)).with_context(|| format!("demo's {name}"))
    };
    let files = || -> Result<DemoFiles> {
        let st = st?;
        if !st.success() {
            bail!("ipc-runner demo --via {via} --rate {rate} failed ({st})");
        }
        Ok(DemoFiles {
            report: serde_json::from_str(&read("report.json")?)?,
            bridge: match via {
                "zenoh" => Some(serde_json::from_str(&read("bridge-estimator.json")?)?),
                _ => None,
            },
            latency_csv: read("latency.csv")?,
        })
    };
    let v = files();
    let _ = std::fs::remove_dir_all(&out);
    v
}

/// What a demo lost (all causes), after checking that its counts add up to `steps` slots of
/// one node and that the run completed.
fn demo_lost(d: &DemoFiles, steps: u32) -> Result<u64> {
    let c = &d.report["counts"];
    let u = |k: &str| {
        c[k].as_u64()
            .with_context(|| format!("report.json counts.{k}: {c}"))
    };
    ensure!(
        d.report["ending"].as_str() == Some("completed"),
        "the demo ended {}",
        d.report["ending"]
    );
    let steps = u64::from(steps);
    ensure!(
        u("instants")? == steps,
        "{} instants of {steps}",
        u("instants")?
    );
    // Slots of the node that never reached the estimators, by cause.
    let mut lost = 0;
    for k in [
        "lost_in_ipc",
        "missed_before_join",
        "lost_deadline",
        "lost_overrun",
        "lost_after_end",
    ] {
        lost += u(k)?;
    }
    ensure!(
        u("received")? + lost == steps,
        "received + lost ≠ {steps} slots: {c}"
    );
    lost += u("lost_on_network")?;
    ensure!(
        u("delivered")? + u("dropped_by_channel")? + u("lost_on_network")? == u("received")?,
        "delivered + dropped + lost on the network ≠ received: {c}"
    );
    if let Some(b) = &d.bridge {
        let bu = |k: &str| {
            b[k].as_u64()
                .with_context(|| format!("bridge report {k}: {b}"))
        };
        let refused: u64 = b["refused"]
            .as_object()
            .context("bridge report refused")?
            .values()
            .filter_map(Value::as_u64)
            .sum();
        ensure!(
            bu("lost_on_network")? == u("lost_on_network")?,
            "the bridge and the runner disagree on the slots lost on the network"
        );
        ensure!(
            bu("slots")? + bu("lost_on_network")? == steps,
            "bridge: slots + lost on the network ≠ {steps}: {b}"
        );
        lost += refused + bu("dropped_at_bridge")?;
    }
    Ok(lost)
}

/// Instants per second from `latency.csv`: rows ÷ (first slot sent → last estimates
/// published).
fn csv_throughput(csv: &str, steps: u32) -> Result<f64> {
    let rows: Vec<&str> = csv.lines().skip(1).filter(|l| !l.is_empty()).collect();
    ensure!(
        rows.len() == steps as usize,
        "latency.csv: {} rows of {steps}",
        rows.len()
    );
    let last: Vec<f64> = rows[rows.len() - 1]
        .split(',')
        .map(|x| x.parse().unwrap_or(f64::NAN))
        .collect();
    ensure!(
        last.len() == 5,
        "latency.csv row {:?}",
        rows[rows.len() - 1]
    );
    let span = last[2] + last[4] * 1e-6;
    ensure!(span > 0.0, "latency.csv spans {span} s");
    Ok(rows.len() as f64 / span)
}

/// A demo's figures from its paced and unpaced runs.
pub fn from_demo(
    paced: &DemoFiles,
    burst: &DemoFiles,
    n_paced: u32,
    n_burst: u32,
) -> Result<Measure> {
    let lost_paced = demo_lost(paced, n_paced)?;
    ensure!(
        demo_lost(burst, n_burst)? == 0,
        "the demo at --rate 0 lost slots: {}",
        burst.report["counts"]
    );
    let lat = &paced.report["latency"];
    let mut stages = Vec::new();
    if let Some(b) = &paced.bridge {
        for (name, key) in [
            ("network hop", "network_hop"),
            ("bridge's own time", "bridge_time"),
        ] {
            stages.push((name, f(&b[key], "p50_us")?, f(&b[key], "p99_us")?));
        }
    }
    for (name, key) in [("transport", "transport"), ("end to end", "end_to_end")] {
        stages.push((name, f(&lat[key], "p50_us")?, f(&lat[key], "p99_us")?));
    }
    Ok(Measure {
        stages,
        throughput: csv_throughput(&burst.latency_csv, n_burst)?,
        lost_paced,
    })
}

/// What each stage times.
fn stage_text(name: &str) -> &'static str {
    match name {
        "one way" => "one way: put (stamped in the payload) → taken from the subscriber's FIFO",
        "network hop" => "network hop: slot sent by the publisher → taken by the estimator-side bridge (`network_hop`)",
        "bridge's own time" => "the estimator-side bridge's own time: taken → written into shared memory (`bridge_time`)",
        "transport" => "transport: slot sent → received by the runner",
        "end to end" => "end to end: slot sent → the instant's estimates published",
        _ => "?",
    }
}

/// `a / b` per round, its median, minimum and maximum.
fn ratio(
    rounds: &[[Measure; 3]],
    a: impl Fn(&[Measure; 3]) -> f64,
    b: impl Fn(&[Measure; 3]) -> f64,
) -> String {
    let r: Vec<f64> = rounds.iter().map(|m| a(m) / b(m)).collect();
    let (lo, hi) = r
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &x| {
            (l.min(x), h.max(x))
        });
    format!("{:.2} ({lo:.2}–{hi:.2})", median(r))
}

fn list(v: impl Iterator<Item = f64>, digits: usize) -> String {
    v.map(|x| format!("{x:.digits$}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The part's tables from its rounds.
fn render(md: &mut String, rounds: &[[Measure; 3]]) {
    md.push_str(
        "| setup | stage | p50 µs | p99 µs | p50 µs of each round | p99 µs of each round | lost |\n\
         |---|---|---:|---:|---|---|---:|\n",
    );
    for (s, setup) in SETUPS.iter().enumerate() {
        let Some(first) = rounds.first() else { break };
        let lost: u64 = rounds.iter().map(|m| m[s].lost_paced).sum();
        for (name, _, _) in &first[s].stages {
            let p = |q: usize| -> Vec<f64> {
                rounds
                    .iter()
                    .map(|m| {
                        m[s].stage(name)
                            .map_or(f64::NAN, |(p50, p99)| if q == 50 { p50 } else { p99 })
                    })
                    .collect()
            };
            let _ = writeln!(
                md,
                "| {setup} | {} | {:.1} | {:.1} | {} | {} | {lost} |",
                stage_text(name),
                median(p(50)),
                median(p(99)),
                list(p(50).into_iter(), 1),
                list(p(99).into_iter(), 1),
            );
        }
    }
    md.push_str(
        "\n| setup | messages/s at `--rate 0` (median of rounds) | each round | lost |\n\
         |---|---:|---|---:|\n",
    );
    for (s, setup) in SETUPS.iter().enumerate() {
        let t = || rounds.iter().map(|m| m[s].throughput);
        let _ = writeln!(
            md,
            "| {setup} | {:.0} | {} | 0 |",
            median(t().collect()),
            list(t(), 0)
        );
    }
    let st = |s: usize, name: &'static str, q: usize| {
        move |m: &[Measure; 3]| {
            m[s].stage(name)
                .map_or(f64::NAN, |(p50, p99)| if q == 50 { p50 } else { p99 })
        }
    };
    let thr = |s: usize| move |m: &[Measure; 3]| m[s].throughput;
    md.push_str(
        "\n| ratio: median of the per-round ratios (min–max) | of p50 | of p99 | of messages/s |\n\
         |---|---:|---:|---:|\n",
    );
    let _ = writeln!(
        md,
        "| bridge hop ÷ one-host pipeline (runner's transport; end to end for messages/s) | {} | {} | {} |",
        ratio(rounds, st(1, "transport", 50), st(2, "transport", 50)),
        ratio(rounds, st(1, "transport", 99), st(2, "transport", 99)),
        ratio(rounds, thr(1), thr(2)),
    );
    let _ = writeln!(
        md,
        "| bridge's network hop ÷ raw zenoh one way (messages/s: bridge hop end to end ÷ raw zenoh) | {} | {} | {} |",
        ratio(rounds, st(1, "network hop", 50), st(0, "one way", 50)),
        ratio(rounds, st(1, "network hop", 99), st(0, "one way", 99)),
        ratio(rounds, thr(1), thr(0)),
    );
    md.push('\n');
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn raw_json(n: u64, lost: u64, p50: f64) -> Value {
        json!({"payload_bytes": 156, "sent": n, "received": n - lost, "measured": n - lost,
               "refused": 0, "out_of_order": 0, "lost": lost, "samples": n, "warmup": 0,
               "rate": 1000.0, "span_s": 1.0, "throughput_per_s": 50000.0 + p50,
               "one_way": {"count": n - lost, "p50_us": p50, "p90_us": 2.0 * p50,
                           "p99_us": 3.0 * p50, "p999_us": 4.0 * p50, "max_us": 5.0 * p50}})
    }

    fn pct(p50: f64) -> Value {
        json!({"count": 10, "p50_us": p50, "p90_us": p50, "p99_us": 2.0 * p50,
               "p999_us": 3.0 * p50, "max_us": 4.0 * p50})
    }

    /// A demo's files as `ipc-runner demo` writes them (the fields the part reads).
    fn demo_files(steps: u64, bridge: bool, lost_on_network: u64, p50: f64) -> DemoFiles {
        let mut csv = String::from("session,k,t_s,transport_us,end_to_end_us\n");
        for k in 1..=steps {
            let _ = writeln!(
                csv,
                "1,{k},{:.6},{p50:.3},{:.3}",
                (k - 1) as f64 * 1e-4,
                p50 + 1.0
            );
        }
        DemoFiles {
            report: json!({"ending": "completed",
                "counts": {"received": steps, "delivered": steps - lost_on_network,
                           "dropped_by_channel": 0, "lost_in_ipc": 0,
                           "lost_on_network": lost_on_network, "lost_deadline": 0,
                           "lost_overrun": 0, "missed_before_join": 0, "lost_after_end": 0,
                           "instants": steps},
                "latency": {"transport": pct(p50), "step": pct(0.1), "end_to_end": pct(p50 + 1.0)}}),
            bridge: bridge.then(|| json!({"slots": steps - lost_on_network,
                "lost_on_network": lost_on_network, "refused": {}, "dropped_at_bridge": 0,
                "network_hop": {"count": steps, "p50_us": p50 - 10.0, "p99_us": 2.0 * p50, "max_us": 9.0},
                "bridge_time": {"count": steps, "p50_us": 3.0, "p99_us": 6.0, "max_us": 9.0}})),
            latency_csv: csv,
        }
    }

    fn round(raw_p50: f64) -> [Measure; 3] {
        [
            from_raw(&raw_json(30, 0, raw_p50), &raw_json(50, 0, raw_p50), 30, 50).unwrap(),
            from_demo(
                &demo_files(30, true, 0, 100.0),
                &demo_files(50, true, 0, 100.0),
                30,
                50,
            )
            .unwrap(),
            from_demo(
                &demo_files(30, false, 0, 20.0),
                &demo_files(50, false, 0, 20.0),
                30,
                50,
            )
            .unwrap(),
        ]
    }

    #[test]
    fn the_tables_have_their_rows_and_ratios() {
        let rounds = vec![round(40.0), round(50.0), round(45.0)];
        let mut md = String::new();
        render(&mut md, &rounds);
        let rows: Vec<&str> = md.lines().filter(|l| l.starts_with("| ")).collect();
        // Head + 7 stages, head + 3 setups, head + 2 ratios.
        assert_eq!(rows.len(), 8 + 4 + 3, "{md}");
        assert!(md.contains("| raw zenoh pub/sub | one way: put (stamped in the payload) → taken from the subscriber's FIFO | 45.0 | 135.0 | 40.0, 50.0, 45.0 | 120.0, 150.0, 135.0 | 0 |"), "{md}");
        assert!(md.contains("(`network_hop`) | 90.0 | 200.0 |"), "{md}");
        // Transport 100 against 20 µs: 5×; the network hop 90 against 40, 50, 45 µs.
        assert!(
            md.contains("| 5.00 (5.00–5.00) | 5.00 (5.00–5.00) |"),
            "{md}"
        );
        assert!(md.contains("| 2.00 (1.80–2.25) |"), "{md}");
        // 50 instants over 49 × 0.1 ms + 101 µs (the last estimates published).
        let thr = 50.0 / (49.0 * 1e-4 + 101e-6);
        assert!(
            md.contains(&format!("| bridge hop (`demo --via zenoh`) | {thr:.0} |")),
            "{md}"
        );
        assert!(md.lines().all(|l| !l.contains("NaN")), "{md}");
    }

    #[test]
    fn a_loss_at_full_speed_or_counts_that_do_not_add_up_fail() {
        assert!(from_raw(&raw_json(30, 0, 1.0), &raw_json(50, 1, 1.0), 30, 50).is_err());
        // A paced loss is counted, not refused.
        assert_eq!(
            from_raw(&raw_json(30, 2, 1.0), &raw_json(50, 0, 1.0), 30, 50)
                .unwrap()
                .lost_paced,
            2
        );
        let ok = demo_files(50, true, 0, 100.0);
        assert!(from_demo(&ok, &demo_files(50, true, 1, 100.0), 50, 50).is_err());
        assert_eq!(
            from_demo(&demo_files(50, true, 3, 100.0), &ok, 50, 50)
                .unwrap()
                .lost_paced,
            3
        );
        // Fewer instants than asked for.
        assert!(from_demo(&ok, &ok, 50, 60).is_err());
        let mut odd = ok.clone();
        odd.report["counts"]["delivered"] = json!(49);
        assert!(from_demo(&ok, &odd, 50, 50).is_err());
        assert!(from_raw(&raw_json(30, 0, 1.0), &raw_json(50, 0, 1.0), 30, 49).is_err());
    }

    #[test]
    fn the_prose_fills() {
        let s = intro(
            Size {
                rounds: 5,
                paced: 3000,
                burst: 30_000,
            },
            100.0,
        );
        assert!(s.contains("5 rounds"), "{s}");
    }
}
