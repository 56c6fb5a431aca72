//! Back-pressure on the slot service (`docs/wire.md`, QoS): at `--rate 0` the publisher
//! waits for a full queue, so nothing is lost; a blocked publisher still ends on SIGINT and
//! notices a SIGKILLed runner; paced, a full queue drops slots and the runner counts them.

#[path = "pipeline_common.rs"]
mod common;

use common::{prefix, report, scratch, Proc};
use std::time::{Duration, Instant};

fn runner(dir: &std::path::Path, name: &str, p: &str, extra: &[&str]) -> Proc {
    let json = dir.join(format!("{name}.json"));
    let mut args = vec![
        "run",
        "--scenario",
        "linear",
        "--prefix",
        p,
        "--json",
        json.to_str().unwrap(),
        "--quiet",
    ];
    args.extend_from_slice(extra);
    let run = Proc::start(dir, name, &args);
    // Quiet runners print nothing: wait until the slot service has its subscriber instead.
    wait_for_subscriber(p);
    run
}

fn publisher(dir: &std::path::Path, name: &str, p: &str, extra: &[&str]) -> Proc {
    let mut args = vec!["channel-sim", "--scenario", "linear", "--prefix", p];
    args.extend_from_slice(extra);
    Proc::start(dir, name, &args)
}

/// Waits until `<p>/slots` has a subscriber (the runner is ready).
fn wait_for_subscriber(p: &str) {
    use iceoryx2::prelude::*;
    set_log_level(LogLevel::Error);
    let node = NodeBuilder::new().create::<ipc::Service>().unwrap();
    let start = Instant::now();
    loop {
        if let Ok(s) = estpipe_wire::slot_service(&node, p) {
            if s.dynamic_config().number_of_subscribers() > 0 {
                return;
            }
        }
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "no runner on {p}"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// Waits until the runner on `p` has published an estimate (it has received a slot).
fn wait_for_first_estimate(p: &str) {
    use iceoryx2::prelude::*;
    set_log_level(LogLevel::Error);
    let node = NodeBuilder::new().create::<ipc::Service>().unwrap();
    let sub = estpipe_wire::estimate_service(&node, p)
        .unwrap()
        .subscriber_builder()
        .create()
        .unwrap();
    let start = Instant::now();
    while sub.receive().unwrap().is_none() {
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "no estimate on {p} within 30 s"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
}

#[test]
fn rate_0_loses_no_slot_of_100000() {
    let dir = scratch("lossless");
    let p = prefix("lossless");
    // The default queue of 256 slots: the publisher is far faster than the runner's loop.
    let mut run = runner(&dir, "runner", &p, &["--steps", "100000"]);
    let mut publ = publisher(
        &dir,
        "pub",
        &p,
        &["--rate", "0", "--steps", "100000", "--quiet"],
    );
    assert!(publ.wait(120).success(), "{}", publ.err());
    assert!(run.wait(120).success(), "{}", run.err());
    let r = report(&dir.join("runner.json"));
    let c = &r["counts"];
    assert_eq!(r["ending"], "completed", "{r}");
    assert_eq!(c["received"], 100_000, "{r}");
    assert_eq!(c["lost_in_ipc"], 0, "{r}");
    assert_eq!(c["instants"], 100_000, "{r}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_blocked_publisher_ends_on_sigint_with_an_abort_marker() {
    let dir = scratch("blocked-sigint");
    let p = prefix("blocked-sigint");
    // A runner that takes 20 ms per slot behind a 4-slot queue: the publisher blocks.
    let mut run = runner(
        &dir,
        "runner",
        &p,
        &["--buffer", "4", "--debug-slow-us", "20000"],
    );
    let mut publ = publisher(&dir, "pub", &p, &["--rate", "0", "--steps", "100000"]);
    publ.wait_for_stderr("waiting for a subscriber", 30);
    std::thread::sleep(Duration::from_millis(500));
    let t = Instant::now();
    publ.signal(libc::SIGINT);
    let st = publ.wait(10);
    let took = t.elapsed();
    assert!(st.success(), "{st}\n{}", publ.err());
    assert!(publ.err().contains("stopped by signal"), "{}", publ.err());
    // The ABORT marker itself waits for room (4 slots × 20 ms), nothing longer.
    assert!(took < Duration::from_secs(3), "took {took:?}");
    assert!(run.wait(30).success(), "{}", run.err());
    let r = report(&dir.join("runner.json"));
    assert_eq!(r["ending"], "publisher_stopped", "{r}");
    assert_eq!(r["counts"]["lost_in_ipc"], 0, "{r}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_blocked_publisher_notices_a_sigkilled_runner() {
    let dir = scratch("blocked-kill");
    let p = prefix("blocked-kill");
    let run = runner(
        &dir,
        "runner",
        &p,
        &["--buffer", "4", "--debug-slow-us", "20000"],
    );
    let mut publ = publisher(
        &dir,
        "pub",
        &p,
        &["--rate", "0", "--steps", "100000", "--connect-timeout", "1"],
    );
    // Killed only once it has stepped an instant: iceoryx2 0.10 blocks a sender only after the
    // subscriber's first receive (docs/wire.md, "Stream rules"), and a fixed sleep was too short
    // for a loaded machine (the runner never read, the publisher never blocked).
    wait_for_first_estimate(&p);
    let t = Instant::now();
    run.signal(libc::SIGKILL);
    publ.wait_for_stderr("subscriber lost", 10);
    let took = t.elapsed();
    // The blocked send gives up after a slice and finds the dead node.
    assert!(took < Duration::from_secs(2), "took {took:?}");
    let st = publ.wait(10);
    assert!(!st.success(), "no subscriber came back, yet: {st}");
    assert!(
        publ.err().contains("no subscriber came back"),
        "{}",
        publ.err()
    );
    drop(run);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn paced_publishing_drops_and_counts_when_the_queue_is_full() {
    let dir = scratch("paced-drop");
    let p = prefix("paced-drop");
    let mut run = runner(
        &dir,
        "runner",
        &p,
        &["--buffer", "4", "--debug-slow-us", "2000"],
    );
    let mut publ = publisher(&dir, "pub", &p, &["--rate", "5000", "--steps", "500"]);
    assert!(publ.wait(60).success(), "{}", publ.err());
    assert!(run.wait(60).success(), "{}", run.err());
    let r = report(&dir.join("runner.json"));
    let c = &r["counts"];
    let lost = c["lost_in_ipc"].as_u64().unwrap();
    assert!(
        lost > 0,
        "a 2 ms consumer of a 5 kHz stream lost nothing? {r}"
    );
    assert_eq!(c["received"].as_u64().unwrap() + lost, 500, "{r}");
    assert_eq!(c["instants"], 500, "{r}");
    // The publisher counted the same drops.
    let err = publ.err();
    assert!(
        err.contains(&format!("{lost} slot(s) dropped")),
        "runner lost {lost}; publisher said:\n{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
