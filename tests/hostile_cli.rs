//! Issue #20, a hostile user's command lines, each as a real process (`pipeline-node`, the
//! dispatch `ipc-runner` runs): bad input is one line on stderr with exit code 2 before any
//! work; nothing panics (no "panicked", no exit 101/134) or hangs (every wait is bounded);
//! whatever a run computed is written, also when it ends in error or by a signal.

#[path = "pipeline_common.rs"]
mod common;

use common::{csv, prefix, report, scratch, Proc};
use std::path::Path;
use std::time::{Duration, Instant};

/// A finished process: exit code, stdout, stderr and how long it took.
struct Done {
    code: Option<i32>,
    out: String,
    err: String,
    took: Duration,
}

/// Runs `pipeline-node <args>` to the end (killed and failed after `secs`).
fn node(dir: &Path, name: &str, args: &[&str], secs: u64) -> Done {
    let t0 = Instant::now();
    let mut p = Proc::start(dir, name, args);
    let st = p.wait(secs);
    let d = Done {
        code: st.code(),
        out: p.out(),
        err: p.err(),
        took: t0.elapsed(),
    };
    assert_sane(&d, name);
    d
}

/// No panic, no abort, no death by signal.
fn assert_sane(d: &Done, name: &str) {
    assert!(!d.err.contains("panicked"), "{name} panicked:\n{}", d.err);
    assert!(
        !matches!(d.code, None | Some(101 | 134)),
        "{name}: exit {:?}\n{}",
        d.code,
        d.err
    );
}

/// Exit code 2 and exactly one stderr line, `pipeline-node: error: …` with every needle.
fn assert_refused(d: &Done, needles: &[&str]) {
    assert_eq!(d.code, Some(2), "stderr: {}", d.err);
    let lines: Vec<&str> = d.err.lines().collect();
    assert_eq!(lines.len(), 1, "not one line: {:?}", d.err);
    assert!(
        lines[0].starts_with("pipeline-node: error: "),
        "{:?}",
        lines[0]
    );
    for n in needles {
        assert!(lines[0].contains(n), "{n:?} missing from {:?}", lines[0]);
    }
}

#[test]
fn outputs_are_checked_before_any_work() {
    let dir = scratch("hostile-outputs");
    // Was: seconds of particle filtering, then the failure.
    let d = node(
        &dir,
        "eval-json",
        &[
            "eval",
            "--scenario",
            "occlusion",
            "--particles",
            "5000",
            "--runs",
            "40",
            "--json",
            "/nonexistent/x.json",
        ],
        30,
    );
    assert_refused(&d, &["--json /nonexistent/x.json", "cannot create"]);
    assert!(d.took < Duration::from_secs(10), "took {:?}", d.took);
    assert!(d.out.is_empty(), "work was done: {}", d.out);
    let d = node(
        &dir,
        "eval-csv-dir",
        &[
            "eval",
            "--scenario",
            "linear",
            "--runs",
            "3",
            "--csv",
            dir.to_str().unwrap(),
        ],
        30,
    );
    assert_refused(&d, &["--csv", "is a directory"]);
    let d = node(
        &dir,
        "eval-plot",
        &[
            "eval",
            "--scenario",
            "linear",
            "--runs",
            "3",
            "--plot",
            "/nonexistent/p.svg",
        ],
        30,
    );
    assert_refused(&d, &["--plot /nonexistent/p.svg"]);
    // Was: the whole stream ran, then exit 1 without the summary. No publisher here: the
    // refusal comes before the runner waits for one (by default for ever).
    for flag in ["--json", "--estimates-csv", "--slots-csv", "--latency-csv"] {
        let p = prefix("hostile-run-out");
        let d = node(
            &dir,
            "run-out",
            &[
                "run",
                "--scenario",
                "linear",
                "--prefix",
                &p,
                flag,
                "/nonexistent/o",
            ],
            10,
        );
        assert_refused(&d, &[&format!("{flag} /nonexistent/o")]);
    }
    let d = node(
        &dir,
        "replay-out",
        &[
            "replay",
            "--scenario",
            "linear",
            "--input",
            "/nonexistent/in.csv",
            "--output",
            "/nonexistent/o.csv",
        ],
        10,
    );
    assert_refused(&d, &["--output /nonexistent/o.csv"]);
    let d = node(
        &dir,
        "demo-out",
        &["demo", "--scenario", "linear", "--out", "/proc/x"],
        10,
    );
    assert_refused(&d, &["--out /proc/x"]);
    // `demo --plot` is a file, as `eval --plot`: checked as one.
    let p = prefix("hostile-demo-plot");
    let d = node(
        &dir,
        "demo-plot",
        &[
            "demo",
            "--scenario",
            "linear",
            "--prefix",
            &p,
            "--out",
            dir.join("demo-out").to_str().unwrap(),
            "--plot",
            "/nonexistent/p.svg",
        ],
        10,
    );
    assert_refused(&d, &["--plot /nonexistent/p.svg"]);
    // The check creates a missing file and removes it: a later refusal leaves nothing.
    let json = dir.join("never.json");
    let d = node(
        &dir,
        "eval-no-junk",
        &[
            "eval",
            "--scenario",
            "linear",
            "--steps",
            "4294967295",
            "--json",
            json.to_str().unwrap(),
        ],
        30,
    );
    assert_refused(&d, &["--steps 4294967295"]);
    assert!(!json.exists(), "the output check left {json:?} behind");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn memory_is_checked_against_a_stated_budget() {
    let dir = scratch("hostile-memory");
    // Was: an abort on a 64 GiB allocation (exit 134).
    let d = node(
        &dir,
        "horizon",
        &["eval", "--scenario", "occlusion", "--steps", "4294967295"],
        30,
    );
    assert_refused(
        &d,
        &[
            "--steps 4294967295",
            "the budget is 2.000 GiB",
            "--max-memory MIB raises it",
        ],
    );
    // Was: accepted, about 11 h.
    let d = node(
        &dir,
        "runs",
        &["eval", "--scenario", "occlusion", "--runs", "10000000000"],
        30,
    );
    assert_refused(&d, &["--runs 10000000000", "GiB of memory", "--max-memory"]);
    // The budget is the flag's: 1 MiB holds a small evaluation, not 10⁶ run averages.
    let small = [
        "eval",
        "--scenario",
        "linear",
        "--runs",
        "20",
        "--steps",
        "10",
        "--quiet",
    ];
    let d = node(
        &dir,
        "small",
        &[&small[..], &["--max-memory", "1"]].concat(),
        60,
    );
    assert_eq!(d.code, Some(0), "{}", d.err);
    let d = node(
        &dir,
        "small-many",
        &[
            "eval",
            "--scenario",
            "linear",
            "--runs",
            "1000000",
            "--max-memory",
            "1",
        ],
        30,
    );
    assert_refused(&d, &["--runs 1000000", "the budget is 1.0 MiB"]);
    let p = prefix("hostile-steps");
    let d = node(
        &dir,
        "run-steps",
        &[
            "run",
            "--scenario",
            "linear",
            "--prefix",
            &p,
            "--steps",
            "4294967295",
        ],
        10,
    );
    assert_refused(&d, &["--steps 4294967295", "--max-memory"]);
    let d = node(
        &dir,
        "particles",
        &[
            "eval",
            "--scenario",
            "occlusion",
            "--particles",
            "10000000000",
        ],
        30,
    );
    assert_refused(&d, &["--particles 10000000000", "--max-memory"]);

    // replay: a k that jumps to 10⁷ (was: 3.4 GB, then an abort) is refused at its row.
    let log = dir.join("jump.csv");
    std::fs::write(&log, "k,node,delivered,y_0\n1,0,1,0.5\n10000000,0,0,\n").unwrap();
    let d = node(
        &dir,
        "replay-jump",
        &[
            "replay",
            "--scenario",
            "linear",
            "--input",
            log.to_str().unwrap(),
        ],
        30,
    );
    assert_refused(
        &d,
        &[
            "jump.csv line 3: k: k = 10000000",
            "--max-memory MIB raises it",
        ],
    );
    // The same span is the budget's to allow: 10⁴ instants fit the default, not 1 MiB.
    std::fs::write(&log, "k,node,delivered,y_0\n1,0,1,0.5\n10000,0,0,\n").unwrap();
    let args = [
        "replay",
        "--scenario",
        "linear",
        "--input",
        log.to_str().unwrap(),
    ];
    let d = node(&dir, "replay-ok", &args, 60);
    assert_eq!(d.code, Some(0), "{}", d.err);
    assert!(d.out.contains("replayed 10000 instants"), "{}", d.out);
    let d = node(
        &dir,
        "replay-1mib",
        &[&args[..], &["--max-memory", "1"]].concat(),
        30,
    );
    assert_refused(&d, &["line 3: k: k = 10000", "the budget holds"]);
    // Was: grew until memory ran out.
    let d = node(
        &dir,
        "replay-zero",
        &["replay", "--scenario", "linear", "--input", "/dev/zero"],
        30,
    );
    assert_refused(&d, &["/dev/zero line 1: longer than 65536 bytes"]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn replay_refuses_duplicates_and_bad_rows_with_code_2() {
    let dir = scratch("hostile-replay");
    let log = dir.join("log.csv");
    let replay = |name: &str, text: &str| {
        std::fs::write(&log, text).unwrap();
        node(
            &dir,
            name,
            &[
                "replay",
                "--scenario",
                "linear",
                "--input",
                log.to_str().unwrap(),
            ],
            30,
        )
    };
    // Was: the second row silently overwrote the first.
    let d = replay(
        "dup",
        "k,node,delivered,y_0\n1,0,1,0.5\n2,0,1,0.1\n2,0,0,\n",
    );
    assert_refused(
        &d,
        &["log.csv line 4: node: (k = 2, node 0) again; line 3 has it already"],
    );
    // Was: exit 1.
    let d = replay("bad-y", "k,node,delivered,y_0\n1,0,1,zero\n");
    assert_refused(&d, &["log.csv line 2: y_0: \"zero\""]);
    let d = replay("bad-k", "k,node,delivered,y_0\n-3,0,1,1\n");
    assert_refused(&d, &["log.csv line 2: k: \"-3\""]);
    let d = replay("order", "k,node,delivered,y_0\n5,0,1,1\n4,0,1,1\n");
    assert_refused(&d, &["line 3: k: k = 4 after k = 5"]);
    let d = replay("node", "k,node,delivered,y_0\n1,7,1,1\n");
    assert_refused(&d, &["line 2: node: node 7 but the scenario has 1 node(s)"]);
    let d = replay("header", "k,delivered,y_0\n1,1,1\n");
    assert_refused(&d, &["log.csv line 1: header lacks column \"node\""]);
    let d = replay("empty", "");
    assert_refused(&d, &["empty slot log"]);
    let d = node(
        &dir,
        "missing",
        &[
            "replay",
            "--scenario",
            "linear",
            "--input",
            "/nonexistent/log.csv",
        ],
        30,
    );
    assert_refused(&d, &["/nonexistent/log.csv: cannot open"]);
    let d = node(
        &dir,
        "estimator",
        &[
            "replay",
            "--scenario",
            "linear",
            "--input",
            "/dev/null",
            "--estimators",
            "nope",
        ],
        30,
    );
    assert_refused(&d, &["estimator \"nope\""]);
    // A good log still replays (the refusals above are not a reader that refuses all).
    let d = replay("good", "k,node,delivered,y_0\n1,0,1,0.5\n3,0,0,\n");
    assert_eq!(d.code, Some(0), "{}", d.err);
    assert!(d.out.contains("replayed 3 instants"), "{}", d.out);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn every_float_flag_refuses_nan_inf_and_meaningless_values() {
    let dir = scratch("hostile-floats");
    let p = prefix("hostile-floats");
    // (command, flag, bad values); the rest of each command line is valid.
    let run: &[&str] = &["run", "--scenario", "linear", "--prefix", &p];
    let demo: &[&str] = &["demo", "--scenario", "linear", "--prefix", &p];
    let eval: &[&str] = &["eval", "--scenario", "linear", "--runs", "2"];
    let replay: &[&str] = &["replay", "--scenario", "linear", "--input", "/dev/null"];
    let publisher: &[&str] = &["channel-sim", "--scenario", "linear", "--prefix", &p];
    let cases: &[(&[&str], &str, &[&str])] = &[
        // Was: `nan` meant forever.
        (run, "--connect-timeout", &["nan", "inf", "-1", "1e300"]),
        // Was: `nan` meant 0.
        (run, "--deadline-ms", &["nan", "inf", "-5", "0"]),
        (run, "--loss-rate", &["nan", "1", "-0.1"]),
        (demo, "--rate", &["nan", "inf", "-20"]),
        (demo, "--loss-rate", &["nan", "inf"]),
        (eval, "--loss-rate", &["nan", "inf", "1"]),
        (eval, "--transport-loss", &["nan", "-inf", "1.5"]),
        (replay, "--loss-rate", &["nan"]),
        (publisher, "--rate", &["nan", "inf", "-1"]),
        (publisher, "--connect-timeout", &["nan", "inf", "-1"]),
        // Was: `inf` panicked in Duration::from_secs_f64 after the stream.
        (publisher, "--linger", &["nan", "inf", "-1"]),
    ];
    let mut n = 0;
    for (cmd, flag, values) in cases {
        for v in *values {
            let arg = format!("{flag}={v}");
            let d = node(&dir, "float", &[cmd, &[arg.as_str()][..]].concat(), 10);
            assert_refused(&d, &[flag]);
            n += 1;
        }
    }
    assert_eq!(n, 32);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn eval_reports_progress_without_a_terminal_and_keeps_its_runs_on_sigint_and_sighup() {
    // SIGHUP: a closed terminal or ssh session; it used to kill eval with its runs unwritten.
    for (what, sig) in [("SIGINT", libc::SIGINT), ("SIGHUP", libc::SIGHUP)] {
        eval_keeps_its_runs_on(what, sig);
    }
}

fn eval_keeps_its_runs_on(what: &str, sig: libc::c_int) {
    let dir = scratch("hostile-eval-int");
    let (json, csv_path) = (dir.join("e.json"), dir.join("e.csv"));
    // ~0.1 s per run on one thread: a few progress lines, then SIGINT long before the end.
    let mut p = Proc::start(
        &dir,
        "eval",
        &[
            "eval",
            "--scenario",
            "occlusion",
            "--particles",
            "1000",
            "--runs",
            "400",
            "--steps",
            "40",
            "--threads",
            "1",
            "--progress-every",
            "0.2",
            "--json",
            json.to_str().unwrap(),
            "--csv",
            csv_path.to_str().unwrap(),
        ],
    );
    p.wait_for_stderr("/400 runs", 60);
    p.signal(sig);
    let st = p.wait(60);
    let d = Done {
        code: st.code(),
        out: p.out(),
        err: p.err(),
        took: Duration::ZERO,
    };
    assert_sane(&d, "eval");
    assert_eq!(d.code, Some(130), "{what}: {}", d.err);
    // Progress lines (stderr is a file here): done/total, ETA.
    let progress: Vec<&str> = d.err.lines().filter(|l| l.contains("/400 runs")).collect();
    assert!(
        !progress.is_empty() && progress.iter().all(|l| l.contains("ETA")),
        "{}",
        d.err
    );
    let r = report(&json);
    assert_eq!(r["ending"], "interrupted", "{r}");
    assert_eq!(r["runs_requested"], 400);
    let runs = r["runs"].as_u64().unwrap();
    assert!((1..400).contains(&runs), "{runs}");
    // The summary and the one error line give the same count.
    assert!(d.out.contains(&format!("{runs} of 400 runs")), "{}", d.out);
    let errors: Vec<&str> = d.err.lines().filter(|l| l.contains("error:")).collect();
    assert_eq!(errors.len(), 1, "{}", d.err);
    assert!(
        errors[0].contains(&format!("interrupted after {runs} of 400 runs")),
        "{}",
        errors[0]
    );
    for (name, e) in r["estimators"].as_object().unwrap() {
        assert_eq!(
            e["valid_runs"].as_u64().unwrap() + e["diverged_runs"].as_u64().unwrap(),
            runs,
            "{name}"
        );
        assert!(e["avg_mse"].is_f64(), "{name}: {e}");
    }
    let (head, rows) = csv(&csv_path);
    assert_eq!(rows.len(), 41);
    assert_eq!(head.len(), 1 + r["estimators"].as_object().unwrap().len());
    let _ = std::fs::remove_dir_all(&dir);
}

/// The runner's arguments with every output file in `dir`.
fn run_args<'a>(dir: &Path, p: &'a str, extra: &[&'a str]) -> Vec<String> {
    let mut a: Vec<String> = [
        "run",
        "--scenario",
        "linear",
        "--prefix",
        p,
        "--wait",
        "block",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    for (flag, file) in [
        ("--json", "r.json"),
        ("--estimates-csv", "est.csv"),
        ("--slots-csv", "slots.csv"),
        ("--latency-csv", "lat.csv"),
    ] {
        a.push(flag.into());
        a.push(dir.join(file).to_str().unwrap().into());
    }
    a.extend(extra.iter().map(|s| s.to_string()));
    a
}

fn start(dir: &Path, name: &str, args: &[String]) -> Proc {
    let a: Vec<&str> = args.iter().map(String::as_str).collect();
    Proc::start(dir, name, &a)
}

#[test]
fn a_restart_with_another_model_is_skipped_and_the_run_keeps_its_output() {
    let dir = scratch("hostile-run-fail");
    let p = prefix("hostile-run-fail");
    let args = run_args(
        &dir,
        &p,
        &[
            "--deadline-ms",
            "100",
            "--wait-for-restart",
            "--steps",
            "100000",
        ],
    );
    let mut run = start(&dir, "runner", &args);
    run.wait_for_stderr("waiting for channel-sim", 30);
    let pub1 = [
        "channel-sim",
        "--scenario",
        "linear",
        "--prefix",
        &p,
        "--rate",
        "200",
    ];
    let mut pub1 = Proc::start(&dir, "pub1", &[&pub1[..], &["--steps", "100000"]].concat());
    std::thread::sleep(Duration::from_millis(600));
    pub1.signal(libc::SIGKILL);
    let _ = pub1.wait(10);
    run.wait_for_stderr("waiting for channel-sim to restart", 30);
    // The restarted publisher runs another model: after the first session's instants were
    // processed its slots are counted and skipped (docs/wire.md, What the runner does with a
    // bad slot), and the run ends as lost when it is gone, with what it computed written.
    let mut pub2 = Proc::start(
        &dir,
        "pub2",
        &[
            "channel-sim",
            "--scenario",
            "occlusion",
            "--prefix",
            &p,
            "--rate",
            "200",
            "--steps",
            "200",
        ],
    );
    run.wait_for_stderr("stream header differs", 30);
    pub2.signal(libc::SIGKILL);
    let _ = pub2.wait(10);
    run.signal(libc::SIGINT);
    let st = run.wait(60);
    let d = Done {
        code: st.code(),
        out: run.out(),
        err: run.err(),
        took: Duration::ZERO,
    };
    assert_sane(&d, "runner");
    assert_eq!(d.code, Some(130), "{}", d.err);
    let r = report(&dir.join("r.json"));
    assert!(
        r["counts"]["skipped"]["header"].as_u64().unwrap() > 0,
        "{r}"
    );
    let instants = r["counts"]["instants"].as_u64().unwrap();
    assert!(instants > 0);
    let (_, rows) = csv(&dir.join("est.csv"));
    assert_eq!(rows.len() as u64, instants);
    let (_, lat) = csv(&dir.join("lat.csv"));
    assert_eq!(lat.len() as u64, instants);
    assert!(dir.join("slots.csv").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_lost_publisher_still_gets_the_summary_and_files() {
    let dir = scratch("hostile-run-lost");
    let p = prefix("hostile-run-lost");
    let mut run = start(
        &dir,
        "runner",
        &run_args(&dir, &p, &["--deadline-ms", "100"]),
    );
    run.wait_for_stderr("waiting for channel-sim", 30);
    let mut publ = Proc::start(
        &dir,
        "pub",
        &[
            "channel-sim",
            "--scenario",
            "linear",
            "--prefix",
            &p,
            "--rate",
            "200",
            "--steps",
            "100000",
        ],
    );
    std::thread::sleep(Duration::from_millis(400));
    publ.signal(libc::SIGKILL);
    let _ = publ.wait(10);
    let st = run.wait(30);
    assert_eq!(
        st.code(),
        Some(ipc_runner::run::EXIT_PUBLISHER_LOST),
        "{}",
        run.err()
    );
    assert!(!run.err().contains("panicked"));
    assert!(run.out().contains("ended: PublisherLost"), "{}", run.out());
    let r = report(&dir.join("r.json"));
    assert_eq!(r["ending"], "publisher_lost");
    let (_, rows) = csv(&dir.join("est.csv"));
    assert_eq!(rows.len() as u64, r["counts"]["instants"].as_u64().unwrap());
    assert!(!rows.is_empty());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_nan_truth_is_counted_and_left_out_of_every_mse() {
    let dir = scratch("hostile-nan-truth");
    let p = prefix("hostile-nan-truth");
    let steps = "60";
    let mut run = start(&dir, "runner", &run_args(&dir, &p, &["--steps", steps]));
    run.wait_for_stderr("waiting for channel-sim", 30);
    let mut publ = Proc::start(
        &dir,
        "pub",
        &[
            "channel-sim",
            "--scenario",
            "linear",
            "--prefix",
            &p,
            "--rate",
            "0",
            "--steps",
            steps,
            "--debug-nan-truth-at",
            "7",
        ],
    );
    let st = run.wait(60);
    let _ = publ.wait(30);
    assert_eq!(st.code(), Some(0), "{}", run.err());
    let r = report(&dir.join("r.json"));
    assert_eq!(r["truth_nonfinite"], 1, "{r}");
    assert_eq!(r["counts"]["instants"], 60);
    assert!(
        run.out().contains("truth not finite at 1 instant(s)"),
        "{}",
        run.out()
    );
    // Independently: the MSE over the estimates CSV's rows whose truth is finite.
    let (head, rows) = csv(&dir.join("est.csv"));
    let nx = head.iter().filter(|h| h.starts_with("truth_")).count();
    let missing = r["truth_missing"].as_u64().unwrap();
    let no_truth = rows
        .iter()
        .filter(|r| r[2..2 + nx].iter().any(|v| v.is_nan()));
    assert_eq!(no_truth.count() as u64, 1 + missing);
    for (e, est) in r["estimators"].as_array().unwrap().iter().enumerate() {
        let mse = est["mse"]
            .as_f64()
            .unwrap_or_else(|| panic!("null MSE: {est}"));
        assert_eq!(
            est["mse_instants"].as_u64().unwrap(),
            60 - 1 - missing,
            "{est}"
        );
        let (mut sum, mut n) = (0.0, 0);
        for row in rows
            .iter()
            .filter(|r| r[2..2 + nx].iter().all(|v| v.is_finite()))
        {
            let x = &row[2 + nx + e * nx..][..nx];
            sum += (0..nx).map(|j| (row[2 + j] - x[j]).powi(2)).sum::<f64>();
            n += 1;
        }
        let expect = sum / f64::from(n);
        assert!(
            (mse - expect).abs() <= 1e-12 * expect.abs(),
            "{est}: {mse} vs {expect}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// `pipeline-node <args>` with stdout (and with `both`, stderr too) a pipe whose reader is
/// already gone, as `eval … | head` leaves it: `(exit code, stderr)` (stderr empty when it
/// is the broken pipe too). Killed and failed after 60 s.
fn with_reader_gone(dir: &Path, args: &[&str], both: bool) -> (Option<i32>, String) {
    use std::process::{Command, Stdio};
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    let err_file = dir.join("gone.err");
    let stderr = if both {
        Stdio::from(writer.try_clone().unwrap())
    } else {
        Stdio::from(std::fs::File::create(&err_file).unwrap())
    };
    let mut child = Command::new(env!("CARGO_BIN_EXE_pipeline-node"))
        .args(args)
        .env("IOX2_LOG_LEVEL", "Error")
        .stdin(Stdio::null())
        .stdout(Stdio::from(writer))
        .stderr(stderr)
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    let status = loop {
        if let Some(st) = child.try_wait().unwrap() {
            break st;
        }
        if t0.elapsed() > Duration::from_secs(60) {
            let _ = child.kill();
            panic!("{args:?} did not end with its reader gone");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let err = std::fs::read_to_string(&err_file).unwrap_or_default();
    (status.code(), err)
}

/// `eval … | head`: a reader that leaves before the summary costs it the summary, not the
/// run: no panic, exit 0, the JSON and CSV written and byte-identical to those of the same
/// run printed to a file; with stderr gone too, the same. A refused flag keeps its exit
/// code 2 with nobody to read the line.
#[test]
fn eval_whose_reader_is_gone_still_writes_its_files() {
    let dir = scratch("hostile-eval-pipe");
    let files = |tag: &str| {
        (
            dir.join(format!("{tag}.json")),
            dir.join(format!("{tag}.csv")),
        )
    };
    let args = |json: &Path, csv: &Path| -> Vec<String> {
        [
            "eval",
            "--scenario",
            "occlusion",
            "--runs",
            "40",
            "--steps",
            "30",
            "--threads",
            "1",
            "--json",
            json.to_str().unwrap(),
            "--csv",
            csv.to_str().unwrap(),
        ]
        .map(String::from)
        .to_vec()
    };
    let (want_json, want_csv) = files("printed");
    let a = args(&want_json, &want_csv);
    let printed = node(
        &dir,
        "printed",
        &a.iter().map(String::as_str).collect::<Vec<_>>(),
        60,
    );
    assert_eq!(printed.code, Some(0), "{}", printed.err);
    assert!(printed.out.contains("avg_mse"), "{}", printed.out);
    for (tag, both) in [("stdout-gone", false), ("both-gone", true)] {
        let (json, csv) = files(tag);
        let a = args(&json, &csv);
        let (code, err) = with_reader_gone(
            &dir,
            &a.iter().map(String::as_str).collect::<Vec<_>>(),
            both,
        );
        assert!(!err.contains("panicked"), "{tag}: {err}");
        assert_eq!(code, Some(0), "{tag}: {err}");
        assert_eq!(
            std::fs::read(&json).unwrap(),
            std::fs::read(&want_json).unwrap(),
            "{tag}"
        );
        assert_eq!(
            std::fs::read(&csv).unwrap(),
            std::fs::read(&want_csv).unwrap(),
            "{tag}"
        );
    }
    let (code, _) = with_reader_gone(&dir, &["eval", "--runs", "0"], true);
    assert_eq!(code, Some(2));
    let _ = std::fs::remove_dir_all(&dir);
}
