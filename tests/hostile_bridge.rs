//! Issue #21 across real processes: a bridge that goes away, and hostile input to the bridge
//! (docs/bridge.md, "A bridge that goes away"; docs/security.md).
//!
//! * A SIGKILLed estimator-side bridge (the runner's only slot publisher) started again: the
//!   runner waits for it as a stall, the slots missed meanwhile count as lost on the network,
//!   the run ends 0 with every instant accounted for. One that never returns ends the run
//!   within `--stall-limit`, outputs written, exit 3.
//! * Bad flags and files: one line, exit 2, no panic; no far side within `--connect-timeout`:
//!   one line, exit 1, promptly.
//! * SIGINT ends a forwarding bridge with its report ("interrupted"); 500 SIGCONTs change no
//!   estimate; a frozen runner costs slots dropped at the bridge, never a frozen bridge; a
//!   foreign zenoh publisher flooding `<key>/slots` with garbage is counted by reason and
//!   none of it reaches shared memory.
//! * A foreign zenoh peer that read the stream id off `<key>/slots` floods `<key>/acks`, the
//!   sensor side's input, with malformed acks (counted by reason), well-formed acks of
//!   markers never sent and forged echoes of the stream's ENDs before they are sent (counted
//!   as stale): no END is cancelled, the sensor side's memory stays bounded, and the run ends
//!   as a clean one, with the same estimates.
//!
//! Every test has its own prefixes, key and port; readiness is read from stderr. Time bounds
//! are generous for a loaded 2-core VM.

#[path = "bridge_common.rs"]
mod bridge_common;
#[path = "pipeline_common.rs"]
mod common;

use bridge_common::{accounted, assert_ok, estimates, free_port, Chain};
use common::{prefix, scratch, Proc};
use std::path::Path;
use std::time::{Duration, Instant};

/// The flooder `flood` ends cleanly while the publisher `publ` is still sending (a flood
/// that outlasted the stream would not have been seen whole by the bridge under test).
fn flood_ends_before_the_stream(flood: &mut Proc, publ: &mut Proc) {
    let st = flood.wait(60);
    assert!(st.success(), "flood: {st}\n{}", flood.err());
    assert!(
        publ.child.as_mut().unwrap().try_wait().unwrap().is_none(),
        "the flood outlasted the stream: make it shorter"
    );
}

/// `pipeline-node <args>` must fail with exit `code` and exactly one line on stderr, without
/// a panic, within `secs`; its stderr.
fn fails(dir: &Path, name: &str, args: &[&str], code: i32, secs: u64) -> String {
    let mut p = Proc::start(dir, name, args);
    let st = p.wait(secs);
    let err = p.err();
    assert_eq!(st.code(), Some(code), "{name}: {st}\n{err}");
    assert!(!err.contains("panicked"), "{name} panicked:\n{err}");
    assert_eq!(
        err.trim_end().lines().count(),
        1,
        "{name}: not one line:\n{err}"
    );
    err
}

/// `bridge --side estimator` on a fresh prefix with `extra`: must be refused as bad input.
fn bad_flag(test: &str, extra: &[&str]) -> String {
    let dir = scratch(test);
    let p = prefix(test);
    let mut args = vec!["bridge", "--side", "estimator", "--prefix", &p];
    args.extend_from_slice(extra);
    fails(&dir, "bridge", &args, 2, 20)
}

#[test]
fn connect_timeout_nan_is_refused() {
    let err = bad_flag("bf-nan", &["--connect-timeout", "nan"]);
    assert!(err.contains("--connect-timeout"), "{err}");
}

#[test]
fn connect_timeout_negative_is_refused() {
    bad_flag("bf-neg", &["--connect-timeout", "-1"]);
    let err = bad_flag("bf-neg2", &["--connect-timeout=-1"]);
    assert!(err.contains("--connect-timeout"), "{err}");
}

#[test]
fn queue_zero_is_refused() {
    let err = bad_flag("bf-q0", &["--queue", "0"]);
    assert!(err.contains("--queue"), "{err}");
}

#[test]
fn queue_too_long_is_refused() {
    let err = bad_flag("bf-qbig", &["--queue", "99999999"]);
    assert!(err.contains("--queue"), "{err}");
}

#[test]
fn max_gap_out_of_range_is_refused() {
    let err = bad_flag("bf-gap", &["--max-gap", "1000001"]);
    assert!(err.contains("--max-gap"), "{err}");
    bad_flag("bf-gap2", &["--max-gap", "-5"]);
}

#[test]
fn unwritable_report_dir_is_refused() {
    let err = bad_flag("bf-rep", &["--report", "/nonexistent-estpipe-dir/r.json"]);
    assert!(err.contains("--report"), "{err}");
    let err = bad_flag("bf-rep2", &["--report", "/dev/null/r.json"]);
    assert!(err.contains("--report"), "{err}");
}

#[test]
fn wildcard_key_is_refused() {
    let err = bad_flag("bf-key", &["--key", "a/*"]);
    assert!(err.contains("--key"), "{err}");
    bad_flag("bf-key2", &["--key", "a/**/b"]);
    bad_flag("bf-key3", &["--key", "a//b"]);
    // A key is printed in every progress line: a newline in it split them.
    let err = bad_flag("bf-key4", &["--key", "a\nb"]);
    assert!(err.contains("control characters"), "{err}");
}

#[test]
fn endpoints_zenoh_would_refuse_only_at_the_session_are_bad_flags() {
    // They used to exit 1 with zenoh's "cannot open the zenoh session: invalid port value
    // at …/lib.rs:62".
    for (name, e, why) in [
        ("bf-port", "tcp/127.0.0.1:99999", "not a port number"),
        ("bf-ip", "tcp/999.1.1.1:1", "not an IPv4 address"),
        ("bf-noport", "udp/127.0.0.1", "HOST:PORT"),
    ] {
        let err = bad_flag(name, &["--listen", e]);
        assert!(err.contains("--listen") && err.contains(why), "{e}: {err}");
    }
}

#[test]
fn missing_zenoh_config_is_refused() {
    let err = bad_flag("bf-zc", &["--zenoh-config", "/nonexistent-estpipe.json5"]);
    assert!(err.contains("--zenoh-config"), "{err}");
}

#[test]
fn zenoh_config_not_json5_is_refused() {
    let dir = scratch("bf-zc-json");
    let f = dir.join("z.json5");
    std::fs::write(&f, "mode = \"peer\"\n[[[not json5\n").unwrap();
    let err = bad_flag("bf-zc-json", &["--zenoh-config", f.to_str().unwrap()]);
    assert!(err.contains("--zenoh-config"), "{err}");
}

#[test]
fn zenoh_config_with_a_wrong_field_is_refused() {
    let dir = scratch("bf-zc-field");
    for (name, text) in [
        ("unknown.json5", "{ mode: \"peer\", no_such_field: 1 }"),
        ("type.json5", "{ mode: 42 }"),
        ("value.json5", "{ mode: \"sideways\" }"),
    ] {
        let f = dir.join(name);
        std::fs::write(&f, text).unwrap();
        let err = bad_flag("bf-zc-field", &["--zenoh-config", f.to_str().unwrap()]);
        assert!(err.contains("--zenoh-config"), "{name}: {err}");
    }
}

/// No far side within `--connect-timeout 1`: one line, exit 1, within a few seconds.
fn times_out(test: &str, side: &str, with_runner: bool) -> String {
    let c = Chain::new(test);
    let _run = with_runner.then(|| {
        let r = c.loud_runner("run", 100, &[]);
        r.wait_for_stderr("waiting for channel-sim", 30);
        r
    });
    let (prefix, role) = if side == "sensor" {
        (&c.a, "--listen")
    } else {
        (&c.b, "--connect")
    };
    let t = Instant::now();
    let err = fails(
        &c.dir,
        "bridge",
        &[
            "bridge",
            "--side",
            side,
            "--prefix",
            prefix,
            "--key",
            &c.key,
            role,
            &c.endpoint,
            "--connect-timeout",
            "1",
            "--quiet",
        ],
        1,
        20,
    );
    let took = t.elapsed();
    assert!(took < Duration::from_secs(8), "{side}: took {took:?}");
    assert!(err.contains("--connect-timeout 1"), "{err}");
    eprintln!("{test}: {took:?}: {}", err.trim_end());
    err
}

#[test]
fn sensor_side_without_a_far_side_gives_up_after_the_connect_timeout() {
    let err = times_out("to-sensor", "sensor", false);
    assert!(err.contains("no estimator side"), "{err}");
}

#[test]
fn estimator_side_without_a_runner_gives_up_after_the_connect_timeout() {
    let err = times_out("to-est", "estimator", false);
    assert!(err.contains("no runner"), "{err}");
}

#[test]
fn estimator_side_without_a_sensor_side_gives_up_after_the_connect_timeout() {
    let err = times_out("to-est-far", "estimator", true);
    assert!(err.contains("no sensor side"), "{err}");
}

/// The estimator-side bridge SIGKILLed mid-stream and started again: the runner waits for it
/// (a stall), what it missed meanwhile is lost on the network, and the run ends 0 with every
/// instant received or lost.
#[test]
fn a_killed_estimator_bridge_is_waited_for_and_the_run_resumes_when_it_returns() {
    const STEPS: u32 = 2500;
    let c = Chain::new("hb-kill-est");
    let est = c.estimator("estimator", &[]);
    // The outage at 500 Hz stays well within --max-gap 5000 instants and --stall-limit 10 s.
    let mut run = c.loud_runner("run", STEPS, &["--max-gap", "5000"]);
    let mut sen = c.sensor("sensor", &[]);
    let mut publ = c.publisher("pub", STEPS, 500);
    sen.wait_for_stderr("forwarding", 30);
    std::thread::sleep(Duration::from_millis(500));
    est.signal(libc::SIGKILL);
    drop(est);
    run.wait_for_stderr("waiting for a bridge to come back", 30);
    let mut est = c.estimator("estimator2", &[]);
    assert_ok(&mut publ, 60);
    assert_ok(&mut run, 60);
    assert_ok(&mut est, 30);
    assert_ok(&mut sen, 30);
    let r = c.report("run.json");
    let (received, lost) = accounted(&r, STEPS);
    let net = r["counts"]["lost_on_network"].as_u64().unwrap();
    assert!(net > 0, "{r}");
    assert_eq!(net, lost, "every loss is the bridge's outage: {r}");
    assert_eq!(r["counts"]["lost_in_ipc"], 0, "{r}");
    assert_eq!(r["ending"], "completed", "{r}");
    assert_eq!(r["publisher_losses"], 0, "{r}");
    assert!(r["stalls"]["count"].as_u64().unwrap() >= 1, "{r}");
    let s = c.report("bridge-sensor.json");
    assert_eq!(s["slots"], u64::from(STEPS), "{s}");
    let e = c.report("bridge-estimator2.json");
    assert!(e["slots"].as_u64().unwrap() <= received, "{e}");
    let err = run.err();
    assert!(err.contains("goes on from another bridge"), "{err}");
    eprintln!(
        "killed estimator bridge: received {received}, lost on the network {net}, stall {} ms",
        r["stalls"]["longest_ms"]
    );
}

/// A bridge that does not come back: the run ends within `--stall-limit` (exit 3), its
/// outputs written, saying so.
#[test]
fn a_runner_whose_bridge_never_returns_ends_within_the_stall_limit() {
    const STEPS: u32 = 5000;
    let c = Chain::new("hb-never");
    let est = c.estimator("estimator", &[]);
    let mut run = c.loud_runner("run", STEPS, &["--stall-limit", "1.5"]);
    let sen = c.sensor("sensor", &[]);
    let _publ = c.publisher("pub", STEPS, 1000);
    sen.wait_for_stderr("forwarding", 30);
    std::thread::sleep(Duration::from_millis(300));
    est.signal(libc::SIGKILL);
    let t = Instant::now();
    drop(est);
    let st = run.wait(30);
    let took = t.elapsed();
    let err = run.err();
    assert_eq!(st.code(), Some(3), "{st}\n{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(took < Duration::from_secs(6), "took {took:?}\n{err}");
    assert!(
        err.contains("the bridge did not come back within --stall-limit 1.5 s"),
        "{err}"
    );
    let r = c.report("run.json");
    assert_eq!(r["ending"], "publisher_lost", "{r}");
    assert!(r["counts"]["received"].as_u64().unwrap() > 0, "{r}");
    assert!(r["stalls"]["count"].as_u64().unwrap() >= 1, "{r}");
    assert!(!estimates(&c.dir.join("run.csv")).is_empty());
    eprintln!("bridge never returned: the run ended {took:?} after the kill");
}

/// SIGINT or SIGHUP to either side while it forwards: it ends within a bounded time, exit 0,
/// its report written with the ending "interrupted".
#[test]
fn sigint_and_sighup_end_a_forwarding_bridge_with_its_report() {
    let c = Chain::new("hb-int");
    let est = bridge_common::bridge(&c.dir, "estimator", &c.b, &c.key, &c.endpoint, false, &[]);
    let _run = c.runner("run", 100_000, &[]);
    let sen = bridge_common::bridge(&c.dir, "sensor", &c.a, &c.key, &c.endpoint, false, &[]);
    let _publ = c.publisher("pub", 100_000, 1000);
    sen.wait_for_stderr("forwarding", 30);
    est.wait_for_stderr("listening on", 30);
    std::thread::sleep(Duration::from_millis(300));
    // SIGHUP (a closed terminal) to the estimator side: it used to kill it without a report.
    let sides = [
        (sen, "sensor", libc::SIGINT),
        (est, "estimator", libc::SIGHUP),
    ];
    for (mut p, name, sig) in sides {
        p.signal(sig);
        let t = Instant::now();
        let st = p.wait(10);
        let took = t.elapsed();
        assert!(st.success(), "{name}: {st}\n{}", p.err());
        assert!(took < Duration::from_secs(3), "{name}: took {took:?}");
        let r = c.report(&format!("bridge-{name}.json"));
        assert_eq!(r["ending"], "interrupted", "{name}: {r}");
        assert!(r["slots"].as_u64().unwrap() > 0, "{name}: {r}");
        assert!(p.err().contains("interrupted"), "{name}: {}", p.err());
        eprintln!("signal {sig} to the {name} side: ended after {took:?}");
    }
}

/// One bridged run of `steps` at 1000 Hz; with `storm`, 500 SIGCONTs to each bridge while
/// the stream flows. Its estimates.
fn bridged_run(test: &str, steps: u32, storm: bool) -> Vec<String> {
    let c = Chain::new(test);
    let mut est = c.estimator("estimator", &[]);
    let mut run = c.runner("run", steps, &[]);
    let mut sen = c.sensor("sensor", &[]);
    let mut publ = c.publisher("pub", steps, 1000);
    if storm {
        sen.wait_for_stderr("forwarding", 30);
        let t = Instant::now();
        for _ in 0..500 {
            for p in [&est, &sen] {
                // SAFETY: kill(2) on our own child's pid; it must still be running.
                #[allow(unsafe_code)]
                let rc = unsafe { libc::kill(p.pid(), libc::SIGCONT) };
                assert_eq!(rc, 0, "{} ended during the storm", p.name);
            }
            std::thread::sleep(Duration::from_micros(200));
        }
        eprintln!("1000 SIGCONTs in {:?}", t.elapsed());
    }
    assert_ok(&mut publ, 60);
    assert_ok(&mut run, 60);
    assert_ok(&mut est, 30);
    assert_ok(&mut sen, 30);
    let r = c.report("run.json");
    assert_eq!(r["counts"]["received"], u64::from(steps), "{r}");
    estimates(&c.dir.join("run.csv"))
}

#[test]
fn sigcont_storm_to_both_bridges_changes_no_estimate() {
    const STEPS: u32 = 1500;
    let quiet = bridged_run("hb-cont-ref", STEPS, false);
    let storm = bridged_run("hb-cont", STEPS, true);
    assert_eq!(quiet.len(), STEPS as usize);
    assert_eq!(storm.len(), STEPS as usize);
    for (i, (x, y)) in quiet.iter().zip(&storm).enumerate() {
        assert_eq!(x, y, "row {i} differs");
    }
}

/// The runner SIGSTOPped for ~2 s: its 64-slot queue fills, the estimator-side bridge drops
/// what the runner does not take within its send limit (counted) and goes on; the run ends 0
/// with every instant accounted for.
#[test]
fn a_frozen_runner_costs_slots_dropped_at_the_bridge_not_a_frozen_bridge() {
    const STEPS: u32 = 5000;
    let c = Chain::new("hb-frozen");
    let mut est = c.estimator("estimator", &[]);
    let mut run = c.runner("run", STEPS, &["--buffer", "64"]);
    let mut sen = c.sensor("sensor", &[]);
    let mut publ = c.publisher("pub", STEPS, 1000);
    sen.wait_for_stderr("forwarding", 30);
    std::thread::sleep(Duration::from_millis(300));
    run.signal(libc::SIGSTOP);
    std::thread::sleep(Duration::from_secs(2));
    run.signal(libc::SIGCONT);
    assert_ok(&mut publ, 60);
    assert_ok(&mut run, 60);
    assert_ok(&mut est, 30);
    assert_ok(&mut sen, 30);
    let e = c.report("bridge-estimator.json");
    let dropped = e["dropped_at_bridge"].as_u64().unwrap();
    assert!(dropped > 0, "{e}");
    let r = c.report("run.json");
    let (received, lost) = accounted(&r, STEPS);
    assert!(lost >= dropped, "{r}");
    eprintln!("frozen runner: {dropped} dropped at the bridge, received {received}, lost {lost}");
}

/// A foreign zenoh publisher on `<key>/slots` puts garbage, wrong-version and oversized
/// messages at full speed while a real stream flows: the estimator side counts every one by
/// reason, and the runner receives exactly the real slots.
#[test]
fn a_flood_of_foreign_messages_is_counted_by_reason_and_never_forwarded() {
    const STEPS: u32 = 3000;
    let c = Chain::new("hb-flood");
    let flood_ep = format!("tcp/127.0.0.1:{}", free_port());
    let mut est = c.estimator("estimator", &["--listen", &flood_ep]);
    let mut run = c.runner("run", STEPS, &[]);
    let mut sen = c.sensor("sensor", &[]);
    est.wait_for_stderr("listening on", 30);
    let flood_exe = Path::new(env!("CARGO_BIN_EXE_zenoh-flood"));
    let mut flood = Proc::start_program(
        &c.dir,
        "flood",
        flood_exe,
        &[
            "--connect",
            &flood_ep,
            "--key",
            &c.key,
            "--each",
            "1000",
            "--oversized",
            "50",
        ],
    );
    flood.wait_for_stderr("flooding", 30);
    let mut publ = c.publisher("pub", STEPS, 1000);
    // The flood must have been over before the stream's END, so that the bridge saw all of it.
    flood_ends_before_the_stream(&mut flood, &mut publ);
    let sent: serde_json::Value = serde_json::from_str(flood.out().trim()).unwrap();
    assert_ok(&mut publ, 60);
    assert_ok(&mut run, 60);
    assert_ok(&mut est, 30);
    assert_ok(&mut sen, 30);
    let e = c.report("bridge-estimator.json");
    assert_eq!(e["refused"], sent, "{e}");
    assert_eq!(e["slots"], u64::from(STEPS), "{e}");
    assert_eq!(e["lost_on_network"], 0, "{e}");
    let r = c.report("run.json");
    let (received, _) = accounted(&r, STEPS);
    assert_eq!(received, u64::from(STEPS), "{r}");
    assert_eq!(r["counts"]["lost_on_network"], 0, "{r}");
    let skipped = r["counts"]["skipped"].as_object().unwrap();
    assert!(skipped.values().all(|v| v == 0), "{r}");
    eprintln!("flood refused by reason: {}", e["refused"]);
}

/// The peak resident memory of process `pid` (`VmHWM`), KiB.
fn peak_rss_kib(pid: i32) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap();
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .unwrap_or_else(|| panic!("no VmHWM in /proc/{pid}/status"))
}

/// A foreign zenoh peer on `<key>/acks`, the sensor side's input for the echoes of its
/// END/ABORT markers, that first read the stream id off `<key>/slots`: empty, truncated,
/// oversized, random, wrong-version and wrong-kind messages, data slots, markers of no node,
/// well-formed acks of markers the stream never sends, and exact copies of the acks of the
/// stream's future ENDs, while a real stream flows. The sensor side counts every malformed
/// one by reason and every well-formed one as stale, its memory stays bounded, the forged
/// echoes cancel no real END (each is repeated until its own echo comes), and the run ends
/// as a clean run does, with the same estimates.
#[test]
fn a_flood_of_forged_acks_is_counted_and_cancels_no_real_end() {
    const STEPS: u32 = 5000;
    const OVERSIZED: u64 = 64;
    const OVERSIZED_KIB: u64 = 1024;
    let clean = bridged_run("hb-acks-ref", STEPS, false);
    let c = Chain::new("hb-acks");
    let mut est = c.estimator("estimator", &[]);
    let mut run = c.runner("run", STEPS, &["--stall-limit", "20"]);
    let mut sen = c.sensor("sensor", &[]);
    // The estimator side subscribed first: the flooder's own reading of `<key>/slots` must not
    // be what starts the stream.
    sen.wait_for_stderr("forwarding", 30);
    let flood_exe = Path::new(env!("CARGO_BIN_EXE_zenoh-flood"));
    let (end_k, oversized, kib) = (
        STEPS.to_string(),
        OVERSIZED.to_string(),
        OVERSIZED_KIB.to_string(),
    );
    let mut flood = Proc::start_program(
        &c.dir,
        "flood",
        flood_exe,
        &[
            "--connect",
            &c.endpoint,
            "--key",
            &c.key,
            "--on",
            "acks",
            "--each",
            "300",
            "--oversized",
            &oversized,
            "--oversized-kib",
            &kib,
            "--end-k",
            &end_k,
        ],
    );
    flood.wait_for_stderr("reading", 30);
    let peak_before = peak_rss_kib(sen.pid());
    let mut publ = c.publisher("pub", STEPS, 1000);
    // The flood must have been over before the stream's END: the forged echoes of the ENDs
    // are then acks of markers not yet sent, and the sensor side saw all of it.
    flood_ends_before_the_stream(&mut flood, &mut publ);
    let peak_after = peak_rss_kib(sen.pid());
    let sent: serde_json::Value = serde_json::from_str(flood.out().trim()).unwrap();
    assert_ok(&mut publ, 60);
    // The runner sees every node's END: it ends at once, not after --stall-limit.
    let t = Instant::now();
    assert_ok(&mut run, 60);
    let ended = t.elapsed();
    assert!(ended < Duration::from_secs(10), "the runner took {ended:?}");
    assert_ok(&mut est, 30);
    assert_ok(&mut sen, 30);

    let s = c.report("bridge-sensor.json");
    let e = c.report("bridge-estimator.json");
    let n = |v: &serde_json::Value, f: &str| {
        v[f].as_u64()
            .unwrap_or_else(|| panic!("{f} not a count in {v}"))
    };
    // Every malformed message refused by the reason the flooder expected, nothing else.
    assert_eq!(s["refused"], sent["refused"], "{s}");
    let refused: u64 = sent["refused"]
        .as_object()
        .unwrap()
        .values()
        .map(|v| v.as_u64().unwrap())
        .sum();
    assert_eq!(refused, 300 * 7 + OVERSIZED, "{sent}");
    // Every well-formed forged ack is stale, as is every real echo after a marker's first;
    // none of them is refused.
    let forged_stale = n(&sent, "stale");
    let nodes = n(&sent, "nodes");
    assert_eq!(forged_stale, 300 * (4 + nodes), "{sent}");
    let stale = n(&s, "acks_stale");
    assert!(
        stale >= forged_stale && stale - forged_stale <= n(&e, "acks") - n(&s, "markers_acked"),
        "stale acks {stale}: forged {forged_stale}\n{s}\n{e}"
    );
    // Each node's END put, repeated until its own echo came, and acknowledged by it.
    assert_eq!(n(&s, "markers"), nodes, "{s}");
    assert_eq!(n(&s, "markers_acked"), nodes, "{s}");
    assert_eq!(n(&s, "markers_unacked"), 0, "{s}");
    assert!(n(&s, "marker_puts") >= nodes, "{s}");
    assert_eq!(n(&e, "markers"), nodes, "{e}");
    assert_eq!(n(&s, "slots"), u64::from(STEPS) * nodes, "{s}");
    assert_eq!(e["refused"], serde_json::json!({}), "{e}");
    // 64 MiB of oversized messages: none of them is kept.
    let grew = peak_after.saturating_sub(peak_before);
    assert!(
        grew < OVERSIZED * OVERSIZED_KIB / 2,
        "the sensor side's peak RSS grew by {grew} KiB during the flood"
    );

    let r = c.report("run.json");
    let (received, _) = accounted(&r, STEPS);
    assert_eq!(received, u64::from(STEPS), "{r}");
    assert_eq!(r["ending"], "completed", "{r}");
    let skipped = r["counts"]["skipped"].as_object().unwrap();
    assert!(skipped.values().all(|v| v == 0), "{r}");
    let flooded = estimates(&c.dir.join("run.csv"));
    assert_eq!(flooded.len(), clean.len());
    for (i, (x, y)) in clean.iter().zip(&flooded).enumerate() {
        assert_eq!(x, y, "row {i} differs from the clean run's");
    }
    eprintln!(
        "forged acks: refused by reason {}, {forged_stale} stale of {stale}; the sensor side's \
         peak RSS grew {grew} KiB; the runner ended {ended:?} after the publisher",
        s["refused"]
    );
}
