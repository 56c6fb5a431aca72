//! Issue #33: the bridge over a UDP link with delay and jitter, `--lag` on (docs/bridge.md,
//! "A delaying link, tested"; docs/pipeline.md, "Late packets"). This kernel has no netem, so the
//! delay is a relay in user space on loopback (`delay_relay.rs`): every datagram from the
//! sensor side to the estimator side is held 40 ms ± 20 ms (uniform, fixed seed). Seed 004's
//! three nodes, one publisher at 50 Hz, `run --instant-deadline-ms 5 --lag 8` (160 ms).
//!
//! * In order (a datagram is held at least until the one before it went, as behind a slow
//!   packet in a queue): an instant's three slots arrive spread over the jitter, the deadline
//!   hands the instant on without the slowest, which comes within the lag. Nothing is lost:
//!   every slot the deadline gave up is folded in (`late_folded` = `lost_deadline` > 0,
//!   `late` = 0, nothing lost on the network, received + folded = 3 × instants), the slot log
//!   replays with `--lag 8` to the live estimates bit for bit, and with every late slot in,
//!   the final estimates are the on-time stream's.
//! * Reordering (netem's jitter: a datagram with a shorter delay overtakes): zenoh's UDP
//!   transport drops every frame that arrives after a later one (its sequence numbers), so an
//!   overtaken slot is lost, never late. The test shows it: overtaken datagrams, the bridge's
//!   and the runner's `lost_on_network` equal and > 0, every instant accounted for, and the
//!   log still replays bit for bit.

#[path = "bridge_common.rs"]
mod bridge_common;
#[path = "pipeline_common.rs"]
mod common;
#[path = "delay_relay.rs"]
mod delay_relay;

use bridge_common::{assert_ok, bridge};
use common::{prefix, report, scratch, Proc};
use delay_relay::{Delay, Relay};
use std::path::{Path, PathBuf};
use std::time::Duration;

const S: &str = "tobit-fusion";
const NODES: u64 = 3;
const STEPS: u32 = 200;
const LAG: &str = "8";

/// What one bridged run over the relay left: its directory, the runner's report, the
/// estimator side's report, and the relay's counts.
struct Delayed {
    dir: PathBuf,
    run: serde_json::Value,
    est: serde_json::Value,
    relay: Relay,
}

/// One run: publisher on A, sensor side listening on UDP, the relay, the estimator side
/// connecting to the relay, the runner on B.
fn delayed_run(test: &str, reorder: bool) -> Delayed {
    let dir = scratch(test);
    let (a, b) = (prefix(&format!("{test}-a")), prefix(&format!("{test}-b")));
    let key = format!("estpipe-test/{}", prefix("key"));
    let sensor_port = bridge_common::free_port();
    let relay = Relay::start(
        sensor_port,
        Delay {
            mean: Duration::from_millis(40),
            jitter: Duration::from_millis(20),
            reorder,
            // The session set-up and the declarations (a few dozen datagrams) in order; the
            // stream (about 800 datagrams) reorders.
            in_order_first: 200,
            seed: 0x5eed_0033,
        },
    );
    // The listening side first (a UDP connect to a port nobody listens on is refused).
    let mut sen = bridge(
        &dir,
        "sensor",
        &a,
        &key,
        &format!("udp/127.0.0.1:{sensor_port}"),
        true,
        &[],
    );
    sen.wait_for_stderr("sensor side of", 30);
    let mut est = bridge(
        &dir,
        "estimator",
        &b,
        &key,
        &format!("udp/127.0.0.1:{}", relay.port),
        true,
        &[],
    );
    let (json, csv, log) = (
        dir.join("run.json"),
        dir.join("run.csv"),
        dir.join("slots.csv"),
    );
    let steps = STEPS.to_string();
    let mut run = Proc::start(
        &dir,
        "run",
        &[
            "run",
            "--scenario",
            S,
            "--prefix",
            &b,
            "--steps",
            &steps,
            "--instant-deadline-ms",
            "5",
            "--lag",
            LAG,
            "--json",
            json.to_str().unwrap(),
            "--estimates-csv",
            csv.to_str().unwrap(),
            "--slots-csv",
            log.to_str().unwrap(),
            "--connect-timeout",
            "60",
        ],
    );
    let mut publ = Proc::start(
        &dir,
        "pub",
        &[
            "channel-sim",
            "--scenario",
            S,
            "--prefix",
            &a,
            "--rate",
            "50",
            "--steps",
            &steps,
            "--quiet",
        ],
    );
    assert_ok(&mut publ, 60);
    assert_ok(&mut run, 60);
    assert_ok(&mut est, 30);
    assert_ok(&mut sen, 30);
    Delayed {
        run: report(&json),
        est: report(&dir.join("bridge-estimator.json")),
        dir,
        relay,
    }
}

/// `replay` of `log` with `extra` flags: its stdout and its `--output` CSV.
fn replay(dir: &Path, name: &str, log: &Path, extra: &[&str]) -> (String, PathBuf) {
    let out = dir.join(format!("{name}.csv"));
    let mut args = vec![
        "replay",
        "--input",
        log.to_str().unwrap(),
        "--scenario",
        S,
        "--output",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let mut p = Proc::start(dir, name, &args);
    assert!(p.wait(120).success(), "{name}: {}", p.err());
    (p.out(), out)
}

/// The run's slot log replayed with `--lag 8` equals its live estimates, bit for bit, for
/// every estimator and instant; the replay's summary.
fn replays_bit_for_bit(d: &Delayed) -> String {
    let (said, replayed) = replay(&d.dir, "replay", &d.dir.join("slots.csv"), &["--lag", LAG]);
    let (lh, live) = common::csv(&d.dir.join("run.csv"));
    let (rh, again) = common::csv(&replayed);
    assert_eq!(live.len(), STEPS as usize);
    assert_eq!(live.len(), again.len());
    let mut compared = 0;
    for (j, name) in rh.iter().enumerate().skip(1) {
        let i = lh
            .iter()
            .position(|h| h == name)
            .unwrap_or_else(|| panic!("{name}"));
        for (a, b) in live.iter().zip(&again) {
            assert_eq!(a[i].to_bits(), b[j].to_bits(), "{name}");
            compared += 1;
        }
    }
    assert!(compared > 1000, "{compared}");
    said
}

/// The log with its `late_after` column emptied (every slot on time); how many were late.
fn on_time(log: &Path, out: &Path) -> u64 {
    let s = std::fs::read_to_string(log).unwrap();
    let mut lines = s.lines();
    let head = lines.next().unwrap();
    let col = head
        .split(',')
        .position(|c| c == "late_after")
        .expect("a late_after column");
    let (mut late, mut w) = (0, format!("{head}\n"));
    for l in lines {
        let mut f: Vec<&str> = l.split(',').collect();
        late += u64::from(f[col] != "0");
        f[col] = "0";
        w.push_str(&f.join(","));
        w.push('\n');
    }
    std::fs::write(out, w).unwrap();
    late
}

fn count(r: &serde_json::Value, k: &str) -> u64 {
    r["counts"][k]
        .as_u64()
        .unwrap_or_else(|| panic!("counts.{k}: {r}"))
}

#[test]
fn delayed_slots_within_the_lag_are_folded_in_and_replay_bit_for_bit() {
    let d = delayed_run("delayed-link", false);
    let (r, e, c) = (&d.run, &d.est, &d.relay.counts);
    eprintln!(
        "relay: {} down, {} held behind an earlier one, {} dropped, max held {:.1} ms; run: {}",
        Relay::get(&c.down),
        Relay::get(&c.held_behind),
        Relay::get(&c.dropped),
        Relay::get(&c.max_held_ns) as f64 / 1e6,
        r["counts"]
    );
    assert_eq!(Relay::get(&c.dropped), 0);
    assert_eq!(Relay::get(&c.overtaken), 0);
    // Nothing lost anywhere: the bridge forwarded every slot, refused none.
    assert_eq!(e["slots"], NODES * u64::from(STEPS), "{e}");
    assert_eq!(e["lost_on_network"], 0, "{e}");
    assert_eq!(e["refused"], serde_json::json!({}), "{e}");
    assert_eq!(count(r, "instants"), u64::from(STEPS), "{r}");
    assert_eq!(count(r, "lost_on_network"), 0, "{r}");
    // The jitter made slots late, and every one of them came within the lag and was folded.
    let folded = count(r, "late_folded");
    assert!(folded > 0, "no slot was late: {r}");
    assert_eq!(count(r, "late"), 0, "a slot came beyond the lag: {r}");
    assert_eq!(folded, count(r, "lost_deadline"), "{r}");
    assert_eq!(
        count(r, "received") + folded,
        NODES * u64::from(STEPS),
        "{r}"
    );

    let said = replays_bit_for_bit(&d);
    assert!(
        said.contains(&format!("{folded} slot(s) arrived late")),
        "{said}"
    );
    // Every late slot in: the final estimates are the on-time stream's.
    let ok_log = d.dir.join("on-time.csv");
    assert_eq!(on_time(&d.dir.join("slots.csv"), &ok_log), folded);
    let (on, _) = replay(&d.dir, "replay-on-time", &ok_log, &["--lag", LAG]);
    let finals = |s: &str| -> Vec<String> {
        s.lines()
            .filter(|l| l.contains("final estimate"))
            .map(str::to_owned)
            .collect()
    };
    assert!(!finals(&said).is_empty(), "{said}");
    assert_eq!(finals(&said), finals(&on), "{said}\n{on}");
    let _ = std::fs::remove_dir_all(&d.dir);
}

#[test]
fn over_a_reordering_link_an_overtaken_slot_is_lost_not_late() {
    let d = delayed_run("reordering-link", true);
    let (r, e, c) = (&d.run, &d.est, &d.relay.counts);
    let overtaken = Relay::get(&c.overtaken);
    eprintln!(
        "relay: {} down, {overtaken} overtaken, {} dropped; bridge: {} slots, {} lost; run: {}",
        Relay::get(&c.down),
        Relay::get(&c.dropped),
        e["slots"],
        e["lost_on_network"],
        r["counts"]
    );
    assert_eq!(Relay::get(&c.dropped), 0);
    assert!(overtaken > 0, "the jitter reordered nothing");
    // zenoh dropped the overtaken frames before the bridge saw them: the bridge refused no
    // slot as out of order (`late`), it saw gaps, and every slot is forwarded or lost.
    let lost = e["lost_on_network"].as_u64().unwrap();
    assert!(lost > 0, "{e}");
    assert_eq!(e["refused"], serde_json::json!({}), "{e}");
    assert_eq!(
        e["slots"].as_u64().unwrap() + lost,
        NODES * u64::from(STEPS),
        "{e}"
    );
    // The bridge writes a lost slot when the node's next slot reveals the gap, which may be
    // after the instant's deadline: then the runner counts it late (folded when within the
    // lag: a loss folded in is still a loss). Every slot is accounted for.
    assert_eq!(count(r, "instants"), u64::from(STEPS), "{r}");
    let (late, folded) = (count(r, "late"), count(r, "late_folded"));
    assert_eq!(count(r, "lost_deadline"), late + folded, "{r}");
    assert_eq!(
        count(r, "received") + folded + late + count(r, "lost_on_network"),
        NODES * u64::from(STEPS),
        "{r}"
    );
    // Every node's END reached the runner, however often the link overtook it: the sensor
    // side repeated each until the estimator side echoed it (docs/bridge.md, "The END of a
    // stream"). The echo itself may never come back: zenoh's declarations cross the same
    // reordering link, and an overtaken one is dropped like a slot (a fresh-clone CI run:
    // no estimate and no echo reached the sensor side; 3 markers put 211 times, given up
    // after 5 s, and the runner still had all three). So: every marker acknowledged or given
    // up on, and all of them forwarded.
    let sen = report(&d.dir.join("bridge-sensor.json"));
    eprintln!(
        "END markers: {} put {} times, {} acknowledged, {} given up; {} estimates back",
        sen["markers"],
        sen["marker_puts"],
        sen["markers_acked"],
        sen["markers_unacked"],
        sen["estimates"]
    );
    assert_eq!(count(r, "markers"), NODES, "{r}");
    assert_eq!(e["markers"], NODES, "{e}");
    let settled = sen["markers_acked"].as_u64().unwrap() + sen["markers_unacked"].as_u64().unwrap();
    assert_eq!(settled, NODES, "{sen}");
    assert!(sen["marker_puts"].as_u64().unwrap() >= NODES, "{sen}");
    replays_bit_for_bit(&d);
    let _ = std::fs::remove_dir_all(&d.dir);
}
