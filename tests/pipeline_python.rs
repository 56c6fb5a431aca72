//! The Python client (`clients/python`) against the real runner: the example publisher feeds
//! `ipc-runner run` with the slots of a recorded log, the example subscriber prints the
//! estimates, and both the runner's and the subscriber's estimates equal `ipc-runner replay`
//! of the same slots bit for bit.
//!
//! Needs the `iceoryx2` PyPI package (`clients/python/requirements.txt`); the interpreter is
//! `$ESTPIPE_PYTHON` (default `python3`). Without the package the test says so on one line and
//! passes; `.ci/run` installs it in a venv so CI always runs it.

#[path = "pipeline_common.rs"]
mod common;
#[path = "replay_check.rs"]
mod replay_check;
#[path = "skip_log.rs"]
mod skip_log;

use common::{prefix, scratch, Proc};
use std::path::{Path, PathBuf};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The interpreter, or `None` (and the one-line reason) when it cannot import iceoryx2.
fn python() -> Option<PathBuf> {
    let py = std::env::var("ESTPIPE_PYTHON").unwrap_or_else(|_| "python3".into());
    let ok = std::process::Command::new(&py)
        .args(["-c", "import iceoryx2"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        // Named explicitly (as .ci/run does), the interpreter is required: a failure.
        assert!(
            std::env::var_os("ESTPIPE_PYTHON").is_none(),
            "ESTPIPE_PYTHON={py} cannot import iceoryx2"
        );
        skip_log::skipped(
            &skip_log::current_test("python"),
            &format!(
                "`{py} -c \"import iceoryx2\"` fails (pip install -r \
                 clients/python/requirements.txt, or point ESTPIPE_PYTHON at such an interpreter)"
            ),
        );
        return None;
    }
    Some(PathBuf::from(py))
}

/// Feeds `slots` (a slot log of `scenario`, `--config FILE` or `--scenario NAME`) through the
/// Python publisher into the runner and checks the estimates against a replay.
fn python_feeds_the_runner(py: &Path, name: &str, scenario: &[&str], slots: &Path) {
    let dir = scratch(&format!("python-{name}"));
    let p = prefix(&format!("python-{name}"));
    let clients = repo().join("clients/python/examples");
    let instants = replay_check::last_instant(slots);
    let steps = instants.to_string();

    // The header the publisher must write, as a foreign publisher gets it.
    let mut header = Proc::start(&dir, "header", &[&["stream-header"][..], scenario].concat());
    assert!(header.wait(30).success(), "{}", header.err());
    let header_json = dir.join("header.json");
    std::fs::write(&header_json, header.out()).unwrap();

    let est_csv = dir.join("run-estimates.csv");
    let json = dir.join("run.json");
    let mut run_args = vec!["run", "--prefix", &p, "--steps", &steps];
    run_args.extend_from_slice(scenario);
    run_args.extend_from_slice(&[
        "--estimates-csv",
        est_csv.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ]);
    let mut run = Proc::start(&dir, "runner", &run_args);
    run.wait_for_stderr("waiting for channel-sim", 30);

    let sub_py = clients.join("print_estimates.py");
    let mut sub = Proc::start_program(
        &dir,
        "subscriber",
        py,
        &[
            sub_py.to_str().unwrap(),
            "--prefix",
            &p,
            "--csv",
            "--idle-exit",
            "3",
        ],
    );
    sub.wait_for_stderr("ready", 30);
    let pub_py = clients.join("publish_slots.py");
    let mut publ = Proc::start_program(
        &dir,
        "publisher",
        py,
        &[
            pub_py.to_str().unwrap(),
            "--prefix",
            &p,
            "--header",
            header_json.to_str().unwrap(),
            "--slots",
            slots.to_str().unwrap(),
        ],
    );
    assert!(run.wait(120).success(), "runner: {}", run.err());
    assert!(publ.wait(60).success(), "publisher: {}", publ.err());
    assert!(sub.wait(60).success(), "subscriber: {}", sub.err());

    let names = replay_check::equal_to_replay(
        &dir,
        name,
        "Python",
        &json,
        &est_csv,
        slots,
        scenario,
        instants,
        &sub.out(),
    );
    eprintln!(
        "{name}: {instants} instants × {} estimator(s) from the Python publisher equal the replay bit for bit",
        names.len()
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_python_publisher_feeds_the_runner_and_the_estimates_equal_the_replay() {
    let Some(py) = python() else { return };
    // A two-node TOML scenario with its recorded log (docs/replay.md).
    let example = repo().join("channel-sim/scenarios/example.toml");
    python_feeds_the_runner(
        &py,
        "example",
        &["--config", example.to_str().unwrap()],
        &repo().join("docs/examples/example-slots.csv"),
    );

    // A longer log of the linear preset, recorded by the runner from channel-sim.
    let (dir, log) = replay_check::record_linear_log("python-record");
    python_feeds_the_runner(&py, "linear", &["--scenario", "linear"], &log);
    let _ = std::fs::remove_dir_all(&dir);
}

/// The README's "Feed your own sensors" steps in its order, each started after a pause as a
/// person typing them leaves: the runner (default connect timeout), the stream header, the
/// subscriber (`--idle-exit 2`), the recording demo, the publisher. The runner must wait for
/// the publisher however long the person takes, the subscriber's idle timer must start at its
/// first estimate, nothing may end in a traceback, and the runner's summary must say why it has
/// no MSE (the Python publisher sends no truth) instead of printing NaN.
///
/// The pause is `ESTPIPE_TYPING_PAUSE_S` seconds (default 3, to keep the suite's time
/// bounded: it already exceeds the subscriber's `--idle-exit 2` that the old code counted from
/// its own start). The 30 s pauses (over the runner's former 30 s connect timeout)
/// are run by hand with `ESTPIPE_TYPING_PAUSE_S=30`, about 2½ minutes.
#[test]
fn the_readme_python_flow_works_at_typing_speed() {
    let Some(py) = python() else { return };
    let pause_s: f64 = std::env::var("ESTPIPE_TYPING_PAUSE_S")
        .ok()
        .map(|v| v.parse().expect("ESTPIPE_TYPING_PAUSE_S: seconds"))
        .unwrap_or(3.0);
    let pause = || std::thread::sleep(std::time::Duration::from_secs_f64(pause_s));
    let dir = scratch("python-typing");
    let (mine, rec) = (prefix("typing-mine"), prefix("typing-rec"));
    let clients = repo().join("clients/python/examples");
    let steps = "2000";

    // 1. the runner, with no flag about waiting.
    let mut run = Proc::start_in(
        &dir,
        "runner",
        &[
            "run",
            "--scenario",
            "linear",
            "--steps",
            steps,
            "--prefix",
            &mine,
            "--wait",
            "block",
        ],
        &[],
        None,
    );
    run.wait_for_stderr("waiting for channel-sim", 30);
    pause();

    // 2. the header.
    std::fs::create_dir_all(dir.join("out")).unwrap();
    let mut header = Proc::start(&dir, "header", &["stream-header", "--scenario", "linear"]);
    assert!(header.wait(30).success(), "{}", header.err());
    let header_json = dir.join("out/header.json");
    std::fs::write(&header_json, header.out()).unwrap();
    pause();

    // 3. the subscriber.
    let sub_py = clients.join("print_estimates.py");
    let mut sub = Proc::start_program(
        &dir,
        "subscriber",
        &py,
        &[
            sub_py.to_str().unwrap(),
            "--prefix",
            &mine,
            "--idle-exit",
            "2",
        ],
    );
    sub.wait_for_stderr("ready", 30);
    pause();

    // 4. the slot log, recorded by a demo on a prefix of its own, then the publisher.
    let mut demo = Proc::start_in(
        &dir,
        "demo",
        &[
            "demo",
            "--scenario",
            "linear",
            "--steps",
            steps,
            "--rate",
            "0",
            "--prefix",
            &rec,
            "--out",
            "out/my-demo",
            "--quiet",
        ],
        &[],
        None,
    );
    assert!(demo.wait(300).success(), "demo: {}", demo.err());
    pause();
    let pub_py = clients.join("publish_slots.py");
    let slots = dir.join("out/my-demo/slots.csv");
    let mut publ = Proc::start_program(
        &dir,
        "publisher",
        &py,
        &[
            pub_py.to_str().unwrap(),
            "--prefix",
            &mine,
            "--header",
            header_json.to_str().unwrap(),
            "--slots",
            slots.to_str().unwrap(),
            "--rate",
            "500",
        ],
    );
    let published = publ.wait(120);
    assert!(
        published.success() && !publ.err().contains("Traceback"),
        "publisher: {published}: {}",
        publ.err()
    );
    let ran = run.wait(120);
    assert!(ran.success(), "runner: {ran}: {}", run.err());
    assert!(sub.wait(60).success(), "subscriber: {}", sub.err());

    let summary = run.out();
    assert!(
        summary.contains("no truth: MSE not computed"),
        "the summary does not say why there is no MSE:\n{summary}"
    );
    assert!(!summary.contains("NaN"), "{summary}");
    // The subscriber printed the estimates up to the last instant (k right-aligned in 5).
    let printed = sub.out();
    assert!(
        printed.contains(&format!("k {steps:>5} ")),
        "the subscriber printed no estimate of k = {steps}: {} line(s)\n{}",
        printed.lines().count(),
        sub.err()
    );
    eprintln!(
        "typing speed: {pause_s} s pauses, the runner waited, the subscriber printed {} \
         estimate line(s)",
        printed.lines().count()
    );
    let _ = std::fs::remove_dir_all(&dir);
}
