//! Hostile slots (issue #20): a rogue publisher (`tests/rogue_publisher.rs`) puts malformed
//! slots with a correct stream header on `<prefix>/slots`; `ipc-runner run` counts each by its
//! reason, skips it and goes on (docs/wire.md, What the runner does with a bad slot). Every
//! case asserts the exit code, the counts in the runner's JSON, that no process panicked or
//! hung (bounded waits) and that the outputs exist.

#[path = "pipeline_common.rs"]
mod common;

use common::{prefix, report, scratch, Proc};
use serde_json::{json, Value};
use std::path::PathBuf;

/// Good slots of instants 1..=N, then the END marker.
const N: u64 = 10;

fn rogue_exe() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_rogue-publisher"))
}

/// What a case ran into.
struct Outcome {
    code: Option<i32>,
    report: Value,
    stderr: String,
}

/// Starts a runner on `scenario`, then the rogue with `script`; `during` runs while both are
/// up. Waits (bounded) for both and checks the outputs exist and nobody panicked.
fn case(
    name: &str,
    scenario: &str,
    script: &Value,
    extra: &[&str],
    during: impl FnOnce(&Proc, &Proc),
) -> Outcome {
    let dir = scratch(name);
    let p = prefix(name);
    let json_path = dir.join("runner.json");
    let csv = dir.join("estimates.csv");
    let script_path = dir.join("script.json");
    std::fs::write(&script_path, script.to_string()).unwrap();
    let mut args = vec![
        "run",
        "--scenario",
        scenario,
        "--prefix",
        &p,
        "--steps",
        "20",
        "--json",
        json_path.to_str().unwrap(),
        "--estimates-csv",
        csv.to_str().unwrap(),
        "--connect-timeout",
        "30",
    ];
    if !extra.contains(&"--deadline-ms") {
        args.extend_from_slice(&["--deadline-ms", "300"]);
    }
    args.extend_from_slice(extra);
    let mut run = Proc::start(&dir, "runner", &args);
    run.wait_for_stderr("waiting for channel-sim", 30);
    let mut rogue = Proc::start_program(
        &dir,
        "rogue",
        &rogue_exe(),
        &[
            "--prefix",
            &p,
            "--scenario",
            scenario,
            "--script",
            script_path.to_str().unwrap(),
        ],
    );
    during(&run, &rogue);
    let st = run.wait(60);
    let rst = rogue.wait(60);
    let stderr = run.err();
    assert!(
        !stderr.contains("panicked"),
        "{name}: runner panicked\n{stderr}"
    );
    assert!(rst.success(), "{name}: rogue {rst}\n{}", rogue.err());
    assert!(csv.exists(), "{name}: no estimates CSV ({st})\n{stderr}");
    let report = report(&json_path);
    let _ = std::fs::remove_dir_all(&dir);
    Outcome {
        code: st.code(),
        report,
        stderr,
    }
}

/// Good data slot of instant k.
fn good(k: u64) -> Value {
    json!({ "k": k })
}

/// Good slots 1..=N with `bad` inserted after instant `at` (or, `replace`, instead of it),
/// then END.
fn script_with(bad: &[Value], at: u64, replace: bool) -> Value {
    let mut v = Vec::new();
    for k in 1..=N {
        if !(replace && k == at) {
            v.push(good(k));
        }
        if k == at {
            v.extend_from_slice(bad);
        }
    }
    v.push(json!({ "end": true, "k": N }));
    Value::Array(v)
}

fn counts(o: &Outcome) -> &Value {
    &o.report["counts"]
}

/// A completed run of N instants in one session.
fn completed(o: &Outcome, what: &str) {
    assert_eq!(o.code, Some(0), "{what}: {}\n{}", o.report, o.stderr);
    assert_eq!(o.report["ending"], "completed", "{what}: {}", o.report);
    assert_eq!(counts(o)["instants"], N, "{what}: {}", o.report);
    assert_eq!(o.report["sessions"], 1, "{what}: {}", o.report);
    for e in o.report["estimators"].as_array().unwrap() {
        assert!(e["mse"].as_f64().is_some_and(f64::is_finite) || e["mse"].is_null());
    }
}

fn skipped_total(o: &Outcome) -> u64 {
    counts(o)["skipped"]
        .as_object()
        .unwrap()
        .values()
        .map(|v| v.as_u64().unwrap())
        .sum()
}

#[test]
fn structural_faults_are_counted_and_skipped_and_the_run_goes_on() {
    let big = 1_000_006u64;
    let cases: Vec<(&str, Vec<Value>, &str, u64)> = vec![
        (
            "version",
            vec![json!({"k": 6, "version": 99})],
            "version",
            1,
        ),
        ("kind", vec![json!({"k": 6, "kind": 7})], "kind", 1),
        ("node", vec![json!({"k": 6, "node": 5})], "node", 1),
        ("nodes", vec![json!({"k": 6, "nodes": 3})], "nodes", 1),
        ("kzero", vec![json!({"k": 0, "seq": 0})], "k_zero", 1),
        ("seq", vec![json!({"k": 6, "seq": 77})], "seq", 1),
        ("gap", vec![json!({"k": big, "seq": big - 1})], "gap", 1),
        (
            "kmax",
            vec![json!({"k": u32::MAX, "seq": u64::from(u32::MAX) - 1})],
            "gap",
            1,
        ),
        (
            "huge-end",
            vec![json!({"end": true, "k": u32::MAX, "seq": u32::MAX})],
            "marker",
            1,
        ),
        (
            "end-seq",
            vec![json!({"end": true, "k": 5, "seq": u64::MAX})],
            "marker_seq",
            1,
        ),
        ("header", vec![json!({"k": 6, "model_xor": 1})], "header", 1),
        (
            "stale-id",
            vec![
                json!({"k": 7, "stream_id": 2}),
                json!({"k": 8, "stream_id": 3}),
            ],
            "stream",
            2,
        ),
    ];
    for (name, bad, reason, n) in cases {
        let o = case(name, "linear", &script_with(&bad, 5, false), &[], |_, _| {});
        completed(&o, name);
        let c = counts(&o);
        assert_eq!(c["skipped"][reason], n, "{name}: {}", o.report);
        assert_eq!(skipped_total(&o), n, "{name}: {}", o.report);
        assert_eq!(c["received"], N, "{name}: {}", o.report);
        assert_eq!(c["lost_in_ipc"], 0, "{name}: {}", o.report);
        assert!(
            o.stderr.contains("first "),
            "{name}: the first such slot is not named\n{}",
            o.stderr
        );
    }
}

#[test]
fn content_faults_hand_the_nodes_slot_on_as_lost() {
    let cases: Vec<(&str, &str, Value, &str)> = vec![
        (
            "delivered",
            "linear",
            json!({"k": 5, "delivered": 0xAB}),
            "delivered",
        ),
        ("ny5", "linear", json!({"k": 5, "ny": 5}), "ny"),
        ("ny0", "linear", json!({"k": 5, "ny": 0}), "ny_zero"),
        // occlusion announces ny = 2: a delivered slot with ny = 1 is not read.
        ("ny1", "occlusion", json!({"k": 5, "ny": 1}), "ny"),
        ("nan", "linear", json!({"k": 5, "y": ["nan"]}), "non_finite"),
        (
            "inf",
            "occlusion",
            json!({"k": 5, "y": [1.0, "inf"]}),
            "non_finite",
        ),
    ];
    for (name, scenario, bad, reason) in cases {
        let o = case(
            name,
            scenario,
            &script_with(&[bad], 5, true),
            &[],
            |_, _| {},
        );
        completed(&o, name);
        let c = counts(&o);
        assert_eq!(c["skipped"][reason], 1, "{name}: {}", o.report);
        assert_eq!(skipped_total(&o), 1, "{name}: {}", o.report);
        assert_eq!(c["received"], N - 1, "{name}: {}", o.report);
        assert_eq!(c["lost_in_ipc"], 0, "{name}: {}", o.report);
        for e in o.report["estimators"].as_array().unwrap() {
            assert_eq!(e["rejected"], 0, "{name}: {}", o.report);
        }
    }
}

#[test]
fn a_flipping_stream_id_never_resets_the_estimators() {
    // After every good slot, one of another stream (some at k = 1 of that stream's
    // sequence would look like a restart only on a node without a stream: never here).
    let mut v = Vec::new();
    for k in 1..=N {
        v.push(good(k));
        v.push(json!({"k": k + 1, "stream_id": 1000 + k}));
    }
    v.push(json!({"end": true, "k": N}));
    let o = case("flip", "linear", &Value::Array(v), &[], |_, _| {});
    completed(&o, "flip");
    assert_eq!(counts(&o)["skipped"]["stream"], N, "{}", o.report);
    assert_eq!(counts(&o)["received"], N, "{}", o.report);
}

#[test]
fn unusable_period_and_send_time_are_counted_not_used() {
    // send_ns = 0 at instant 5: not a latency.
    let o = case(
        "send0",
        "linear",
        &script_with(&[json!({"k": 5, "send_ns": 0})], 5, true),
        &[],
        |_, _| {},
    );
    completed(&o, "send0");
    assert_eq!(counts(&o)["anomalies"]["send_ns"], 1, "{}", o.report);
    assert_eq!(
        o.report["latency"]["transport"]["count"],
        N - 1,
        "{}",
        o.report
    );
    assert_eq!(counts(&o)["received"], N);
    // send_ns in the future: the same.
    let o = case(
        "send-future",
        "linear",
        &script_with(&[json!({"k": 5, "send_ns": u64::MAX})], 5, true),
        &[],
        |_, _| {},
    );
    completed(&o, "send-future");
    assert_eq!(counts(&o)["anomalies"]["send_ns"], 1, "{}", o.report);
    let max_us = o.report["latency"]["end_to_end"]["max_us"]
        .as_f64()
        .unwrap();
    assert!(max_us < 10e6, "{}", o.report);

    // period_ns = 2^62 on every slot and no END: the data deadline still fires.
    let v: Vec<Value> = (1..=N)
        .map(|k| json!({"k": k, "period_ns": 1u64 << 62}))
        .collect();
    let o = case("period", "linear", &Value::Array(v), &[], |_, _| {});
    assert_eq!(
        o.code,
        Some(ipc_runner::run::EXIT_PUBLISHER_LOST),
        "{}",
        o.stderr
    );
    assert_eq!(o.report["ending"], "publisher_lost");
    assert_eq!(counts(&o)["anomalies"]["period_ns"], N, "{}", o.report);
    assert_eq!(counts(&o)["instants"], N, "{}", o.report);
}

#[test]
fn sigint_still_ends_a_run_fed_hostile_slots() {
    let v = Value::Array(vec![
        good(1),
        good(2),
        json!({"k": u32::MAX, "seq": u64::from(u32::MAX) - 1}),
        json!({"end": true, "k": u32::MAX, "seq": u32::MAX}),
    ]);
    let o = case(
        "sigint",
        "linear",
        &v,
        &["--deadline-ms", "60000"],
        |run: &Proc, rogue: &Proc| {
            rogue.wait_for_stderr("rogue-publisher: sent", 30);
            run.wait_for_stderr("first ", 30);
            std::thread::sleep(std::time::Duration::from_millis(100));
            run.signal(libc::SIGINT);
        },
    );
    assert_eq!(o.code, Some(130), "{}", o.stderr);
    assert_eq!(o.report["ending"], "interrupted");
    let c = counts(&o);
    assert_eq!(c["skipped"]["gap"], 1, "{}", o.report);
    assert_eq!(c["skipped"]["marker"], 1, "{}", o.report);
    assert_eq!(c["instants"], 2, "{}", o.report);
}
