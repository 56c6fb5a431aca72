//! `ipc-runner eval` as a user runs it: outputs, and one-line errors with exit code 2.

use std::path::PathBuf;
use std::process::{Command, Output};

fn ipc_runner(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_ipc-runner"))
        .args(args)
        .output()
        .expect("start ipc-runner")
}

fn temp_dir(name: &str) -> PathBuf {
    let dir =
        std::env::temp_dir().join(format!("ipc-runner-eval-cli-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Exit code 2, exactly one line on stderr containing `needle`, nothing panicked.
fn assert_usage_error(out: &Output, needle: &str) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "stderr: {err}");
    assert_eq!(err.lines().count(), 1, "not one line: {err:?}");
    assert!(err.contains(needle), "expected {needle:?} in {err:?}");
    assert!(!err.contains("panicked"));
}

#[test]
fn bad_flags_are_one_line_errors_with_code_2() {
    assert_usage_error(
        &ipc_runner(&["eval", "--scenario", "linear", "--bogus"]),
        "--bogus",
    );
    assert_usage_error(
        &ipc_runner(&["eval", "--scenario", "nope"]),
        "unknown scenario 'nope'",
    );
    assert_usage_error(
        &ipc_runner(&["eval", "--scenario", "linear", "--runs", "0"]),
        "--runs",
    );
    assert_usage_error(
        &ipc_runner(&["eval", "--scenario", "linear", "--runs", "x"]),
        "--runs",
    );
    // An empty evaluation is refused, by either name of the horizon.
    assert_usage_error(&ipc_runner(&["eval", "--steps", "0"]), "--steps");
    assert_usage_error(&ipc_runner(&["eval", "--horizon", "0"]), "--steps");
    assert_usage_error(
        &ipc_runner(&["eval", "--scenario", "linear", "--plot", "out.jpg"]),
        ".svg or .png",
    );
    assert_usage_error(&ipc_runner(&["frobnicate"]), "frobnicate");
    assert_usage_error(
        &ipc_runner(&[
            "eval",
            "--scenario",
            "occlusion",
            "--estimators",
            "cce,nope",
        ]),
        "estimator \"nope\" does not apply to scenario \"occlusion\"",
    );
    assert_usage_error(
        &ipc_runner(&["eval", "--scenario", "occlusion", "--estimators", "adf-mix"]),
        "need --loss-rate P",
    );
    for bad in ["1", "-0.1", "nan", "x"] {
        for flag in ["--loss-rate", "--transport-loss"] {
            let arg = format!("{flag}={bad}");
            assert_usage_error(
                &ipc_runner(&["eval", "--scenario", "occlusion", &arg]),
                flag,
            );
        }
    }
}

#[test]
fn estimators_flag_selects_in_registry_order_and_pf_by_name() {
    let out = ipc_runner(&[
        "eval",
        "--scenario",
        "occlusion",
        "--runs",
        "4",
        "--steps",
        "5",
        "--quiet",
        "--estimators",
        "adf,pf,ikf,cce-mix",
        "--loss-rate",
        "0.1",
        "--particles",
        "50",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    let rows: Vec<&str> = text
        .lines()
        .filter_map(|l| l.split_whitespace().next())
        .filter(|w| ["kf", "ikf", "cce", "adf", "cce-mix", "pf"].contains(w))
        .collect();
    assert_eq!(rows, ["ikf", "adf", "cce-mix", "pf"], "{text}");
}

#[test]
fn bad_toml_is_a_one_line_error_naming_the_field() {
    let dir = temp_dir("toml");
    let example = include_str!("../../channel-sim/scenarios/example.toml");
    let cases = [
        ("p_loss = 0.1", "p_loss = 1.5", "stages[0].p_loss"),
        ("r = [[0.25]]", "r = [[-0.25]]", "sensors[0].r"),
        (
            "a = [[0.95, 0.10], [-0.10, 0.95]]",
            "a = [[0.95, 0.10]]",
            "model.a",
        ),
        ("p_loss = 0.1", "p_loss = [", "line"),
    ];
    for (i, (from, to, needle)) in cases.into_iter().enumerate() {
        let path = dir.join(format!("bad{i}.toml"));
        std::fs::write(&path, example.replacen(from, to, 1)).unwrap();
        let out = ipc_runner(&["eval", "--config", path.to_str().unwrap(), "--quiet"]);
        assert_usage_error(&out, needle);
    }
    let missing = dir.join("missing.toml");
    assert_usage_error(
        &ipc_runner(&["eval", "--config", missing.to_str().unwrap()]),
        "missing.toml",
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn writes_json_csv_and_plots() {
    let dir = temp_dir("outputs");
    let (json, csv, svg, png) = (
        dir.join("r.json"),
        dir.join("r.csv"),
        dir.join("r.svg"),
        dir.join("r.png"),
    );
    for plot in [&svg, &png] {
        let out = ipc_runner(&[
            "eval",
            "--scenario",
            "linear",
            "--runs",
            "20",
            "--steps",
            "25",
            "--seed",
            "4",
            "--quiet",
            "--json",
            json.to_str().unwrap(),
            "--csv",
            csv.to_str().unwrap(),
            "--plot",
            plot.to_str().unwrap(),
        ]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(stdout.contains("kf") && stdout.contains("ikf"), "{stdout}");
    }
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(v["estimators"]["kf"]["mse"].as_array().unwrap().len(), 26);
    assert_eq!(std::fs::read_to_string(&csv).unwrap().lines().count(), 27);
    assert!(std::fs::read_to_string(&svg).unwrap().contains("<svg"));
    assert_eq!(&std::fs::read(&png).unwrap()[1..4], b"PNG");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Without `--scenario`, `eval` runs the default preset of every subcommand (occlusion), and
/// `--horizon`, the former name of `--steps`, still sets the horizon.
#[test]
fn eval_defaults_to_occlusion_and_takes_horizon_for_steps() {
    let dir = temp_dir("defaults");
    let json = |name: &str| dir.join(name);
    for (name, flag) in [("steps.json", "--steps"), ("horizon.json", "--horizon")] {
        let out = ipc_runner(&[
            "eval",
            "--runs",
            "2",
            flag,
            "7",
            "--quiet",
            "--json",
            json(name).to_str().unwrap(),
        ]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let read = |name: &str| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(json(name)).unwrap()).unwrap()
    };
    let (a, b) = (read("steps.json"), read("horizon.json"));
    assert_eq!(a["scenario"], "occlusion", "{a}");
    assert_eq!(a["horizon"], 7, "{a}");
    assert_eq!(a, b, "--horizon and --steps differ");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `--paired NAME`: a name that was not run is a one-line usage error; otherwise a table of
/// every other estimator's paired difference, whose difference is the difference of the
/// two averages (every run valid: the pairs are all runs).
#[test]
fn paired_differences_from_a_named_estimator() {
    assert_usage_error(
        &ipc_runner(&[
            "eval",
            "--scenario",
            "linear",
            "--runs",
            "4",
            "--steps",
            "10",
            "--paired",
            "nope",
        ]),
        "--paired nope: not one of the estimators run",
    );
    let dir = temp_dir("paired");
    let json = dir.join("e.json");
    let out = ipc_runner(&[
        "eval",
        "--scenario",
        "linear",
        "--runs",
        "40",
        "--steps",
        "50",
        "--quiet",
        "--paired",
        "kf",
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    let table = stdout
        .split("paired differences from kf")
        .nth(1)
        .expect("the paired table");
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let avg = |n: &str| v["estimators"][n]["avg_mse"].as_f64().unwrap();
    // Roles in the JSON as in the table: the full-information kf is the oracle.
    assert_eq!(v["estimators"]["kf"]["role"], "oracle");
    assert_eq!(v["estimators"]["ikf"]["role"], "baseline");
    let row = table
        .lines()
        .find(|l| l.starts_with("ikf "))
        .expect("an ikf row");
    let diff: f64 = row.split_whitespace().nth(1).unwrap().parse().unwrap();
    assert!(
        (diff - (avg("ikf") - avg("kf"))).abs() < 1e-5,
        "{row}: {} − {}",
        avg("ikf"),
        avg("kf")
    );
    let _ = std::fs::remove_dir_all(&dir);
}
