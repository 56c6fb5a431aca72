//! The estimator flags mean the same in every command (`ipc_runner::estimator_args`):
//! `--estimators NAME --gate P` runs `NAME+gate` in `run`, `demo`, `replay` and `eval` (a new
//! user's `demo --estimators cce --gate 0.99` ran no estimator and reported a completed run
//! with an empty table), and a selection that runs nothing is one line, exit code 2, before
//! any work.

#[path = "pipeline_common.rs"]
mod common;

use common::{prefix, report, scratch, Proc};
use std::path::Path;

const SELECT: [&str; 4] = ["--estimators", "cce", "--gate", "0.99"];

/// Runs `pipeline-node <args>` to the end and checks it succeeded.
fn ok(dir: &Path, name: &str, args: &[&str]) -> Proc {
    let mut p = Proc::start(dir, name, args);
    let st = p.wait(120);
    assert!(st.success(), "{name}: {st}\n{}", p.err());
    p
}

/// The names of a run report's estimators (`run --json`, `demo`'s report.json).
fn names(r: &serde_json::Value) -> Vec<String> {
    r["estimators"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["name"].as_str().unwrap().to_owned())
        .collect()
}

#[test]
fn a_name_under_the_gate_runs_its_gated_estimator_in_every_command() {
    let dir = scratch("select-gate");
    let p = prefix("select-gate");
    let (json, slots) = (dir.join("run.json"), dir.join("slots.csv"));

    // run, against a publisher of the same scenario.
    let mut run_args = vec!["run", "--scenario", "occlusion", "--prefix", &p];
    run_args.extend_from_slice(&SELECT);
    run_args.extend_from_slice(&["--steps", "40", "--wait", "block", "--quiet"]);
    run_args.extend_from_slice(&["--json", json.to_str().unwrap()]);
    run_args.extend_from_slice(&["--slots-csv", slots.to_str().unwrap()]);
    let mut run = Proc::start(&dir, "run", &run_args);
    let mut publ = common::start_channel_sim(&dir, &p, "occlusion", 40, 1000);
    let st = run.wait(60);
    assert!(st.success(), "run: {st}\n{}", run.err());
    assert!(publ.wait(30).success(), "{}", publ.err());
    let r = report(&json);
    assert_eq!(r["ending"], "completed");
    assert_eq!(names(&r), ["cce+gate"], "run");
    assert!(
        r["estimators"][0]["gate"]["tested"].as_u64().unwrap() > 0,
        "{r}"
    );

    // demo: the command the user ran.
    let out = dir.join("demo");
    let dp = prefix("select-gate-demo");
    let mut demo_args = vec!["demo", "--scenario", "occlusion", "--prefix", &dp];
    demo_args.extend_from_slice(&SELECT);
    demo_args.extend_from_slice(&["--steps", "40", "--rate", "1000", "--quiet"]);
    demo_args.extend_from_slice(&["--out", out.to_str().unwrap()]);
    let demo = ok(&dir, "demo", &demo_args);
    let r = report(&out.join("report.json"));
    assert_eq!(r["ending"], "completed");
    assert_eq!(names(&r), ["cce+gate"], "demo");
    assert!(demo.out().contains("cce+gate"), "{}", demo.out());

    // replay, of the slots `run` recorded.
    let replayed = dir.join("replayed.csv");
    let mut replay_args = vec!["replay", "--scenario", "occlusion"];
    replay_args.extend_from_slice(&["--input", slots.to_str().unwrap()]);
    replay_args.extend_from_slice(&SELECT);
    replay_args.extend_from_slice(&["--output", replayed.to_str().unwrap()]);
    ok(&dir, "replay", &replay_args);
    let text = std::fs::read_to_string(&replayed).unwrap();
    let head: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    assert_eq!(head[0], "k");
    assert!(
        head.len() > 1 && head[1..].iter().all(|h| h.starts_with("cce+gate_")),
        "replay: {head:?}"
    );

    // eval.
    let ej = dir.join("eval.json");
    let mut eval_args = vec!["eval", "--scenario", "occlusion", "--runs", "3"];
    eval_args.extend_from_slice(&SELECT);
    eval_args.extend_from_slice(&["--quiet", "--json", ej.to_str().unwrap()]);
    ok(&dir, "eval", &eval_args);
    let r = report(&ej);
    let evaluated: Vec<&String> = r["estimators"].as_object().unwrap().keys().collect();
    assert_eq!(evaluated, ["cce+gate"], "eval");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_selection_that_runs_nothing_is_refused_in_every_command() {
    let dir = scratch("select-none");
    let slots = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/examples/example-slots.csv");
    let slots = slots.to_str().unwrap();
    let p = prefix("select-none");
    let out = dir.join("out");
    let out = out.to_str().unwrap();
    let commands: [(&str, Vec<&str>); 4] = [
        ("run", vec!["run", "--prefix", &p, "--connect-timeout", "5"]),
        (
            "demo",
            vec![
                "demo",
                "--scenario",
                "occlusion",
                "--prefix",
                &p,
                "--out",
                out,
            ],
        ),
        ("replay", vec!["replay", "--input", slots]),
        (
            "eval",
            vec!["eval", "--scenario", "occlusion", "--runs", "2"],
        ),
    ];
    // `nn` (seed 003's estimator) does not apply to the occlusion scenario; `pf` with no
    // particles is not built; a gated name without the gate names nothing.
    let cases: [(&[&str], &str); 3] = [
        (
            &["--estimators", "nn", "--gate", "0.99"],
            "estimator \"nn\" does not apply to scenario \"occlusion\"; available: ",
        ),
        (
            &["--estimators", "pf", "--particles", "0"],
            "estimator \"pf\" needs --particles N above 0",
        ),
        (
            &["--estimators", "cce+gate"],
            "estimator \"cce+gate\" needs --gate P",
        ),
    ];
    for (command, args) in &commands {
        for (i, (flags, needle)) in cases.iter().enumerate() {
            let mut all = args.clone();
            all.extend_from_slice(flags);
            let name = format!("{command}-{i}");
            let mut proc = Proc::start(&dir, &name, &all);
            let st = proc.wait(30);
            let err = proc.err();
            assert_eq!(st.code(), Some(2), "{name}: {st}\n{err}");
            let lines: Vec<&str> = err.lines().collect();
            assert_eq!(lines.len(), 1, "{name}: not one line: {err:?}");
            assert!(
                lines[0].starts_with("pipeline-node: error: "),
                "{name}: {err}"
            );
            assert!(lines[0].contains(needle), "{name}: {needle:?} not in {err}");
        }
    }
    assert!(
        !Path::new(out).join("report.json").exists(),
        "demo wrote a report"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
