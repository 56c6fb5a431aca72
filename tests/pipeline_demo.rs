//! The demo over real processes and shared memory reproduces the in-process `eval` of the
//! same scenario, seed and run exactly: every estimate bit for bit, and the MSE. The IPC must
//! not change a single number. The slot log the demo records replays to the same estimates.

#[path = "pipeline_common.rs"]
mod common;

use common::{csv, report, scratch, Proc};
use ipc_runner::estimators::FACTORIES;
use ipc_runner::eval::EvalOptions;
use ipc_runner::eval::{evaluate, RunConfig};

const SEED: u64 = 7;

/// Two sensor nodes, bursty + i.i.d. loss: exercises multi-node instants.
fn config() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../channel-sim/scenarios/example.toml")
}

#[test]
fn demo_matches_in_process_eval_exactly_and_replays() {
    let cfg = config();
    let scenario = channel_sim::scenario::config::load(&cfg).unwrap();
    let _ = check(&["--config", cfg.to_str().unwrap()], &scenario, 150);
}

/// The default scenario of the demo, with every real-time estimator that applies to it and
/// the particle filter, which is opt-in (`--particles`, given to the demo and the replay
/// alike; seeded: estimators are built for the same seed and run).
#[test]
fn occlusion_demo_matches_in_process_eval_exactly() {
    let scenario = channel_sim::scenario::preset("occlusion").unwrap();
    let _ = check(
        &["--scenario", "occlusion", "--particles", "5000"],
        scenario.as_ref(),
        60,
    );
}

/// `demo --gate P` (docs/gate.md): the gated estimators (`<name>+gate`) over shared memory
/// are `eval --gate P`'s bit for bit, their rejection counts are eval's, and the summary
/// prints them; the replay of the slot log with `--gate P` agrees.
#[test]
fn gated_demo_matches_in_process_eval_exactly() {
    let scenario = channel_sim::scenario::preset("occlusion").unwrap();
    check_gated(
        &["--scenario", "occlusion", "--gate", "0.99"],
        scenario.as_ref(),
        80,
        Some(0.99),
    );
}

/// A user's own model with occlusion regions (a TOML `kind = "occlusion"` stage): the demo
/// runs the occlusion estimators and their known-loss-rate variants on it, bit for bit as
/// `eval` and the replay of its slot log.
#[test]
fn user_occlusion_model_demo_matches_in_process_eval_exactly() {
    let cfg = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../channel-sim/scenarios/occlusion-user.toml");
    let scenario = channel_sim::scenario::config::load(&cfg).unwrap();
    let names = check(
        &["--config", cfg.to_str().unwrap(), "--loss-rate", "0.05"],
        &scenario,
        100,
    );
    for want in [
        "ikf",
        "cce",
        "kf-io",
        "adf",
        "cce-mix",
        "kf-io-mix",
        "adf-mix",
    ] {
        assert!(names.iter().any(|n| n == want), "{want} not in {names:?}");
    }
}

/// Sensors of different ny (`two-sensors.toml`: node 0 measures position and velocity, node 1
/// position only) through real processes: the publisher announces each node's ny in the
/// stream header, the runner takes it from there, and the estimates are `eval`'s bit for bit
/// and replay from the slot log (whose rows have each node's own number of `y_` values).
#[test]
fn mixed_ny_demo_matches_in_process_eval_exactly() {
    let cfg = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../channel-sim/scenarios/two-sensors.toml");
    let scenario = channel_sim::scenario::config::load(&cfg).unwrap();
    let names = check(&["--config", cfg.to_str().unwrap()], &scenario, 120);
    assert!(names.iter().any(|n| n == "ikf"), "{names:?}");
}

/// Runs the demo with `scenario_args` and checks it against `eval`; returns the names of the
/// estimators the demo ran.
fn check(scenario_args: &[&str], scenario: &dyn channel_sim::Scenario, steps: u32) -> Vec<String> {
    check_gated(scenario_args, scenario, steps, None)
}

fn check_gated(
    scenario_args: &[&str],
    scenario: &dyn channel_sim::Scenario,
    steps: u32,
    gate: Option<f64>,
) -> Vec<String> {
    let dir = scratch("demo");
    let prefix = common::prefix("demo");
    let out = dir.join("out");
    let mut args = vec!["demo"];
    args.extend_from_slice(scenario_args);
    let steps_s = steps.to_string();
    let seed_s = SEED.to_string();
    args.extend_from_slice(&[
        "--steps",
        &steps_s,
        "--rate",
        "1000",
        "--seed",
        &seed_s,
        "--wait",
        "block",
        "--out",
        out.to_str().unwrap(),
        "--prefix",
        &prefix,
        "--quiet",
    ]);
    let mut demo = Proc::start(&dir, "demo", &args);
    let status = demo.wait(300);
    assert!(status.success(), "demo failed: {status}\n{}", demo.err());
    let text = demo.out();
    for needle in ["MSE vs truth", "lost in IPC", "p99.9", "end to end"] {
        assert!(text.contains(needle), "summary lacks {needle:?}:\n{text}");
    }
    let r = report(&out.join("report.json"));
    assert_eq!(r["ending"], "completed");
    // The scenario's own name (a `--config` file's too).
    assert_eq!(r["scenario"], scenario.name());
    assert_eq!(r["counts"]["instants"], u64::from(steps));
    assert_eq!(
        r["counts"]["lost_in_ipc"], 0,
        "precondition: no IPC loss {r}"
    );
    assert_eq!(r["truth_missing"], 0);
    for (file, needle) in [
        ("trajectories.svg", "<svg"),
        ("latency.svg", "slot sent → estimates published"),
    ] {
        let text = std::fs::read_to_string(out.join(file)).unwrap_or_default();
        assert!(text.contains(needle), "{file} lacks {needle:?}");
    }
    check_latency_trace(&out, &r, steps);

    // The same experiment in-process, by `eval` (run 0 of seed SEED, one run).
    let nx = scenario.nx();
    let loss_rate = scenario_args
        .iter()
        .position(|a| *a == "--loss-rate")
        .map_or(0.0, |i| scenario_args[i + 1].parse().unwrap());
    #[allow(clippy::needless_update)]
    let options = EvalOptions {
        runs: 1,
        horizon: steps,
        seed: SEED,
        gate,
        loss_rate,
        ..EvalOptions::default()
    };
    let config = RunConfig {
        threads: Some(1),
        progress: false,
    };
    let ev = evaluate(scenario, &options, FACTORIES, &config).unwrap();
    let traj = &ev.trajectory;

    let (head, rows) = csv(&out.join("estimates.csv"));
    assert_eq!(rows.len(), steps as usize);
    let reported = r["estimators"].as_array().unwrap();
    assert!(!reported.is_empty());
    check_trajectories_plot(&out, &r, nx);
    for (e, rep) in reported.iter().enumerate() {
        let name = rep["name"].as_str().unwrap();
        let j_eval = traj.names.iter().position(|n| *n == name).unwrap();
        let col = head.iter().position(|h| *h == format!("{name}_0")).unwrap();
        for (i, row) in rows.iter().enumerate() {
            let k = i + 1;
            assert_eq!(row[1], k as f64);
            for j in 0..nx {
                assert_eq!(
                    row[2 + j].to_bits(),
                    traj.truth[k * nx + j].to_bits(),
                    "truth k={k}"
                );
                let ours = row[col + j];
                let theirs = traj.estimates[j_eval][k * nx + j];
                assert_eq!(ours.to_bits(), theirs.to_bits(), "{name} k={k} x[{j}]");
            }
        }
        let (_, res) = ev.estimators.iter().find(|(n, _)| n == name).unwrap();
        if gate.is_some() && name != "pf" && name != "nn" {
            assert!(name.ends_with("+gate"), "{name}");
            let g = res
                .gate
                .unwrap_or_else(|| panic!("{name}: eval has no gate counts"));
            assert!(g.tested > 0, "{name}");
            assert_eq!(rep["gate"]["tested"], g.tested, "{name}");
            assert_eq!(rep["gate"]["rejected"], g.rejected, "{name}");
            assert!(text.contains(&format!(
                "{name}: innovation gate rejected {} of {}",
                g.rejected, g.tested
            )));
        }
        let ours = rep["mse"].as_f64().unwrap();
        assert_eq!(
            ours.to_bits(),
            res.avg_mse.to_bits(),
            "{name} (#{e}): demo MSE {ours:e}, eval {:e}",
            res.avg_mse
        );
    }

    // The slot log the demo wrote replays to the same estimates.
    let replayed = dir.join("replayed.csv");
    let slots = out.join("slots.csv");
    let mut rargs = vec!["replay", "--input", slots.to_str().unwrap()];
    rargs.extend_from_slice(scenario_args);
    rargs.extend_from_slice(&["--seed", &seed_s, "--output", replayed.to_str().unwrap()]);
    let mut rp = Proc::start(&dir, "replay", &rargs);
    assert!(rp.wait(300).success(), "{}", rp.err());
    let (rhead, rrows) = csv(&replayed);
    assert_eq!(rrows.len(), steps as usize);
    for (c, h) in rhead.iter().enumerate().skip(1) {
        let col = head.iter().position(|x| x == h).unwrap();
        for (i, row) in rrows.iter().enumerate() {
            assert_eq!(
                row[c].to_bits(),
                rows[i][col].to_bits(),
                "replay {h} k={}",
                i + 1
            );
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
    reported
        .iter()
        .map(|r| r["name"].as_str().unwrap().to_owned())
        .collect()
}

/// `latency.csv` has one row per instant, in send order, and is the same data as the
/// histograms of `report.json`: the end-to-end maxima agree (hdrhistogram keeps 3
/// significant digits, hence the 0.1 % tolerance).
fn check_latency_trace(out: &std::path::Path, r: &serde_json::Value, steps: u32) {
    let (head, rows) = csv(&out.join("latency.csv"));
    assert_eq!(
        head,
        ["session", "k", "t_s", "transport_us", "end_to_end_us"]
    );
    assert_eq!(rows.len(), steps as usize);
    let mut prev_t = -1.0;
    for (i, row) in rows.iter().enumerate() {
        assert_eq!(row[1], (i + 1) as f64);
        assert!(row[2] >= prev_t, "send times out of order at k={}", i + 1);
        prev_t = row[2];
        assert!(
            0.0 <= row[3] && row[3] <= row[4],
            "k={}: transport {} > end to end {}",
            i + 1,
            row[3],
            row[4]
        );
    }
    // The last instant was sent about steps / rate seconds after the first (--rate 1000).
    let span = rows[rows.len() - 1][2];
    let expect = f64::from(steps - 1) / 1000.0;
    assert!(
        (span - expect).abs() < 0.05 + 0.05 * expect,
        "first to last send {span} s, paced {expect} s"
    );
    // End to end is one sample per instant in both; transport is per slot in the histogram
    // but only the completing slot's in the trace (two nodes here).
    let tol = |h: f64| 1e-3 * h + 2e-3;
    for (col, key, equal) in [(3, "transport", false), (4, "end_to_end", true)] {
        let csv_max = rows.iter().map(|r| r[col]).fold(0.0, f64::max);
        let hist_max = r["latency"][key]["max_us"].as_f64().unwrap();
        let ok = if equal {
            (csv_max - hist_max).abs() <= tol(hist_max)
        } else {
            csv_max <= hist_max + tol(hist_max)
        };
        assert!(
            ok,
            "{key}: max {csv_max} µs in latency.csv, {hist_max} µs in report.json"
        );
    }
    let svg = std::fs::read_to_string(out.join("latency-trace.svg")).unwrap_or_default();
    assert!(svg.contains("end to end, max per bin"), "latency-trace.svg");
}

/// The plot after the run (`trajectories.svg`): every estimator in the legend, with its ±2σ
/// band or saying it has no covariance; at least one band polygon per banded estimator and
/// component; the node strip's totals are the run's counts (no loss, no `--lag` here). (The
/// SVG backend writes each text on a line of its own.)
fn check_trajectories_plot(out: &std::path::Path, r: &serde_json::Value, nx: usize) {
    let svg = std::fs::read_to_string(out.join("trajectories.svg")).unwrap();
    let names: Vec<&str> = r["estimators"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["name"].as_str().unwrap())
        .collect();
    let banded = names
        .iter()
        .filter(|n| svg.contains(&format!("\n{n} ± 2σ\n")))
        .count();
    for n in &names {
        assert!(
            svg.contains(&format!("\n{n} ± 2σ\n"))
                || svg.contains(&format!("\n{n} (no covariance)\n")),
            "{n} not in the legend"
        );
    }
    assert!(banded > 0, "no estimator with a band: {names:?}");
    let polygons = svg.matches("<polygon").count();
    assert!(
        polygons >= banded * nx,
        "{polygons} band polygons for {banded} × {nx}"
    );
    let c = &r["counts"];
    for (label, key) in [
        ("delivered", "delivered"),
        ("dropped by the channel", "dropped_by_channel"),
    ] {
        let want = format!("\n{label}: {}\n", c[key]);
        assert!(svg.contains(&want), "the strip lacks {want:?}");
    }
    assert!(svg.contains("\nlost (IPC or network): 0\n") && svg.contains("\nlate (--lag): 0\n"));
}
