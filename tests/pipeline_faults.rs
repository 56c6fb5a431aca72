//! Faults across real processes: SIGKILL of either side, a slow consumer, a wrong wire
//! format version and non-finite measurements. Every test uses its own service prefix and
//! cleans up dead nodes afterwards (also when it fails: `Proc` kills and cleans on drop).

#[path = "pipeline_common.rs"]
mod common;

use common::{prefix, report, scratch, Proc};
use std::time::Duration;

const S: &str = "linear";

fn runner(dir: &std::path::Path, name: &str, prefix: &str, extra: &[&str]) -> Proc {
    let json = dir.join(format!("{name}.json"));
    let mut args = vec![
        "run",
        "--scenario",
        S,
        "--prefix",
        prefix,
        "--json",
        json.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    Proc::start(dir, name, &args)
}

fn publisher(dir: &std::path::Path, name: &str, prefix: &str, extra: &[&str]) -> Proc {
    let mut args = vec!["channel-sim", "--scenario", S, "--prefix", prefix];
    args.extend_from_slice(extra);
    Proc::start(dir, name, &args)
}

/// The "no slot for X ms" the runner reports when the deadline passes.
fn silence_ms(stderr: &str) -> f64 {
    let at = stderr.find("no slot for ").expect("loss report") + "no slot for ".len();
    stderr[at..].split(' ').next().unwrap().parse().unwrap()
}

#[test]
fn publisher_sigkill_is_detected_at_the_deadline_and_a_restart_resumes() {
    let dir = scratch("pubkill");
    let p = prefix("pubkill");
    let mut run = runner(
        &dir,
        "runner",
        &p,
        &[
            "--wait",
            "block",
            "--deadline-ms",
            "100",
            "--wait-for-restart",
        ],
    );
    run.wait_for_stderr("waiting for channel-sim", 30);
    let mut pub1 = publisher(&dir, "pub1", &p, &["--rate", "200", "--steps", "100000"]);
    std::thread::sleep(Duration::from_millis(600));
    pub1.signal(libc::SIGKILL);
    let _ = pub1.wait(10);
    run.wait_for_stderr("publisher lost", 30);
    let err = run.err();
    let silent = silence_ms(&err);
    // Fires after period (5 ms) + deadline (100 ms), not before; the upper bound only guards
    // against a missed detection (scheduling on a shared machine can add delay).
    assert!(silent >= 105.0, "fired early: {silent} ms\n{err}");
    assert!(silent < 2000.0, "detected late: {silent} ms\n{err}");
    // The dead publisher is gone after the cleanup (ours or that of any other process: the
    // cleanup is machine-wide, so the count of nodes *we* removed may be 0).
    assert!(err.contains("0 publisher(s) remain"), "{err}");

    let mut pub2 = publisher(&dir, "pub2", &p, &["--rate", "0", "--steps", "120"]);
    assert!(pub2.wait(60).success(), "{}", pub2.err());
    let st = run.wait(60);
    assert!(st.success(), "{st}\n{}", run.err());
    let r = report(&dir.join("runner.json"));
    assert_eq!(r["ending"], "completed");
    assert_eq!(r["sessions"], 2);
    assert_eq!(r["publisher_losses"], 1);
    eprintln!("publisher SIGKILL detected after {silent} ms of silence");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn publisher_sigkill_without_restart_exits_nonzero() {
    let dir = scratch("pubkill-exit");
    let p = prefix("pubkill-exit");
    let mut run = runner(&dir, "runner", &p, &["--deadline-ms", "100"]);
    run.wait_for_stderr("waiting for channel-sim", 30);
    let mut pub1 = publisher(&dir, "pub1", &p, &["--rate", "200", "--steps", "100000"]);
    std::thread::sleep(Duration::from_millis(500));
    pub1.signal(libc::SIGKILL);
    let _ = pub1.wait(10);
    let st = run.wait(30);
    assert_eq!(
        st.code(),
        Some(ipc_runner::run::EXIT_PUBLISHER_LOST),
        "{}",
        run.err()
    );
    assert!(run.err().contains("publisher lost"));
    assert_eq!(report(&dir.join("runner.json"))["ending"], "publisher_lost");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn runner_sigkill_then_a_new_runner_takes_over() {
    let dir = scratch("runkill");
    let p = prefix("runkill");
    let steps = 300u64;
    let mut publ = publisher(
        &dir,
        "pub",
        &p,
        &["--rate", "200", "--steps", &steps.to_string()],
    );
    let run1 = runner(&dir, "runner1", &p, &[]);
    std::thread::sleep(Duration::from_millis(500));
    run1.signal(libc::SIGKILL);
    // The publisher notices the dead subscriber (dead-node cleanup) and pauses.
    publ.wait_for_stderr("subscriber lost", 30);
    let mut run2 = runner(&dir, "runner2", &p, &["--wait", "listener"]);
    let st = run2.wait(60);
    assert!(st.success(), "{st}\n{}", run2.err());
    assert!(publ.wait(30).success(), "{}", publ.err());
    let r = report(&dir.join("runner2.json"));
    assert_eq!(r["ending"], "completed");
    assert_eq!(r["counts"]["instants"], steps);
    let missed = r["counts"]["missed_before_join"].as_u64().unwrap();
    assert!(missed > 0, "{r}");
    drop(run1);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn slow_consumer_counts_gaps_instead_of_crashing() {
    let dir = scratch("slow");
    let p = prefix("slow");
    let mut run = runner(
        &dir,
        "runner",
        &p,
        &["--buffer", "4", "--debug-slow-us", "500"],
    );
    run.wait_for_stderr("waiting for channel-sim", 30);
    // Discarding, not the lossless default of --rate 0: the gaps are what is tested.
    let mut publ = publisher(
        &dir,
        "pub",
        &p,
        &["--rate", "0", "--steps", "300", "--backpressure", "discard"],
    );
    let st = run.wait(60);
    assert!(st.success(), "{st}\n{}", run.err());
    assert!(publ.wait(30).success());
    let r = report(&dir.join("runner.json"));
    let c = &r["counts"];
    assert_eq!(r["ending"], "completed");
    // Every instant is still stepped (lost slots count as dropped measurements) …
    assert_eq!(c["instants"], 300);
    // … and the slots add up: received + lost = sent.
    let lost = c["lost_in_ipc"].as_u64().unwrap();
    assert!(
        lost > 0,
        "no gap with a 4-slot queue and a slow consumer? {r}"
    );
    assert_eq!(c["received"].as_u64().unwrap() + lost, 300);
    assert_eq!(
        c["missed_before_join"], 0,
        "subscribed before the stream started: {r}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn wrong_wire_version_is_counted_and_skipped_with_a_clear_message() {
    let dir = scratch("version");
    let p = prefix("version");
    let mut run = runner(&dir, "runner", &p, &[]);
    run.wait_for_stderr("waiting for channel-sim", 30);
    let _publ = publisher(
        &dir,
        "pub",
        &p,
        &[
            "--rate",
            "0",
            "--steps",
            "50",
            "--debug-wire-version",
            "99",
            "--connect-timeout",
            "2",
        ],
    );
    // Wire version 3: every slot of another version is counted and skipped, the run goes on
    // (docs/wire.md, What the runner does with a bad slot); channel-sim's END marker carries
    // the right version, so the 50 instants are handed on as lost and the run completes.
    let st = run.wait(30);
    assert!(st.success(), "{st}\n{}", run.err());
    let err = run.err();
    assert!(err.contains("wire format version 99"), "{err}");
    assert!(err.contains("same source"), "{err}");
    let r = report(&dir.join("runner.json"));
    let c = &r["counts"];
    assert_eq!(c["skipped"]["version"], 50, "{r}");
    assert_eq!(
        (&c["received"], &c["lost_in_ipc"]),
        (&0.into(), &50.into()),
        "{r}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn non_finite_measurements_are_counted_and_handed_on_as_lost() {
    let dir = scratch("nan");
    let p = prefix("nan");
    let mut run = runner(&dir, "runner", &p, &["--buffer", "4096"]);
    run.wait_for_stderr("waiting for channel-sim", 30);
    let mut publ = publisher(
        &dir,
        "pub",
        &p,
        &["--rate", "2000", "--steps", "200", "--debug-nan-every", "5"],
    );
    assert!(run.wait(60).success(), "{}", run.err());
    assert!(publ.wait(30).success());
    let r = report(&dir.join("runner.json"));
    assert_eq!(
        r["counts"]["lost_in_ipc"], 0,
        "precondition: no IPC loss {r}"
    );
    // Wire version 3: a non-finite measurement is a malformed slot, counted and handed to
    // the estimators as lost (docs/wire.md, What the runner does with a bad slot). Every 5th
    // delivered measurement is NaN.
    let c = &r["counts"];
    let nan = c["skipped"]["non_finite"].as_u64().unwrap();
    let delivered = c["delivered"].as_u64().unwrap() + nan;
    assert_eq!(nan, delivered / 5, "{r}");
    assert!(nan > 0, "{r}");
    assert_eq!(c["received"].as_u64().unwrap() + nan, 200, "{r}");
    assert_eq!(c["instants"], 200, "{r}");
    let e = &r["estimators"][0];
    assert_eq!(e["rejected"], 0, "{r}");
    assert!(e["mse"].as_f64().unwrap().is_finite());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn ctrl_c_ends_the_runner_cleanly_in_every_wait_mode() {
    let dir = scratch("sigint");
    for mode in ["spin", "block", "listener"] {
        let p = prefix(&format!("sigint-{mode}"));
        let mut run = runner(
            &dir,
            &format!("runner-{mode}"),
            &p,
            &["--wait", mode, "--connect-timeout", "60"],
        );
        run.wait_for_stderr("waiting for channel-sim", 30);
        let st = std::process::Command::new("kill")
            .args(["-INT", &run.pid().to_string()])
            .status()
            .unwrap();
        assert!(st.success());
        let st = run.wait(10);
        assert_eq!(st.code(), Some(130), "{mode}: {st}\n{}", run.err());
        let r = report(&dir.join(format!("runner-{mode}.json")));
        assert_eq!(r["ending"], "interrupted", "{mode}: {r}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
