//! The pipeline across a network: the publisher and the runner on separate prefixes, joined
//! only by two `bridge` processes over zenoh on loopback (docs/bridge.md).
//!
//! * Nothing lost: the bridged run's estimates equal the direct run's bit for bit.
//! * A sensor-side bridge killed mid-stream and started again: the run goes on, what the
//!   network lost meanwhile arrives as lost slots (counted on the network), the run ends 0.
//! * A message that fails the far side's checks is counted by reason and never forwarded.

#[path = "bridge_common.rs"]
mod bridge_common;
#[path = "pipeline_common.rs"]
mod common;

use bridge_common::{assert_ok, bridge, estimates, free_port, publisher, runner};
use common::{report, scratch, Proc};
use std::time::Duration;

#[test]
fn bridged_run_equals_the_direct_run_bit_for_bit() {
    const STEPS: u32 = 400;
    let dir = scratch("bridge-same");
    // Direct: one prefix.
    let direct = common::prefix("bridge-direct");
    let mut run = runner(&dir, "direct", &direct, STEPS, &[]);
    std::thread::sleep(Duration::from_millis(200));
    let mut publ = publisher(&dir, "pub-direct", &direct, STEPS, 2000);
    assert_ok(&mut publ, 60);
    assert_ok(&mut run, 60);

    // Bridged: publisher on A, runner on B, zenoh between.
    let (a, b) = (common::prefix("bridge-a"), common::prefix("bridge-b"));
    let key = format!("estpipe-test/{}", common::prefix("key"));
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let mut est = bridge(&dir, "estimator", &b, &key, &endpoint, true, &[]);
    let mut run = runner(&dir, "bridged", &b, STEPS, &[]);
    let mut sen = bridge(&dir, "sensor", &a, &key, &endpoint, true, &[]);
    let mut publ = publisher(&dir, "pub-bridged", &a, STEPS, 2000);
    assert_ok(&mut publ, 60);
    assert_ok(&mut run, 60);
    assert_ok(&mut est, 30);
    assert_ok(&mut sen, 30);

    let (d, g) = (
        estimates(&dir.join("direct.csv")),
        estimates(&dir.join("bridged.csv")),
    );
    // One row per instant, every estimator's estimate in its columns.
    assert_eq!(d.len(), STEPS as usize);
    assert_eq!(g.len(), STEPS as usize);
    for (i, (x, y)) in d.iter().zip(&g).enumerate() {
        assert_eq!(x, y, "row {i} differs");
    }
    let e = report(&dir.join("bridge-estimator.json"));
    let s = report(&dir.join("bridge-sensor.json"));
    let nodes = 1; // the occlusion example has one sensor
    assert_eq!(e["slots"], u64::from(STEPS) * nodes);
    assert_eq!(s["slots"], u64::from(STEPS) * nodes);
    assert_eq!(e["lost_on_network"], 0);
    assert_eq!(e["refused"], serde_json::json!({}));
    assert!(e["network_hop"]["count"].as_u64().unwrap() > 0);
    // The estimates came back to the sensor host.
    assert!(s["estimates"].as_u64().unwrap() > 0);
    let r = report(&dir.join("bridged.json"));
    assert_eq!(r["counts"]["lost_on_network"], 0);
}

#[test]
fn corrupted_messages_are_counted_and_never_forwarded() {
    const STEPS: u32 = 300;
    let dir = scratch("bridge-corrupt");
    let (a, b) = (common::prefix("bridge-ca"), common::prefix("bridge-cb"));
    let key = format!("estpipe-test/{}", common::prefix("key"));
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let mut est = bridge(&dir, "estimator", &b, &key, &endpoint, true, &[]);
    let mut run = runner(&dir, "run", &b, STEPS, &[]);
    // Every 10th slot message leaves the sensor side with a wrong version byte.
    let mut sen = bridge(
        &dir,
        "sensor",
        &a,
        &key,
        &endpoint,
        true,
        &["--debug-corrupt-every", "10"],
    );
    let mut publ = publisher(&dir, "pub", &a, STEPS, 2000);
    assert_ok(&mut publ, 60);
    assert_ok(&mut run, 60);
    assert_ok(&mut est, 30);
    assert_ok(&mut sen, 30);
    let e = report(&dir.join("bridge-estimator.json"));
    let corrupted = u64::from(STEPS) / 10;
    assert_eq!(e["refused"]["version"], corrupted);
    assert_eq!(e["slots"], u64::from(STEPS) - corrupted);
    // Each refused slot is a gap the next one reveals: written as lost, never as data.
    assert_eq!(e["lost_on_network"], corrupted);
    let r = report(&dir.join("run.json"));
    assert_eq!(r["counts"]["lost_on_network"], corrupted);
    assert_eq!(
        r["counts"]["received"].as_u64().unwrap(),
        u64::from(STEPS) - corrupted
    );
}

#[test]
fn a_killed_sensor_bridge_is_noticed_and_the_run_resumes_when_it_returns() {
    const STEPS: u32 = 1500;
    let dir = scratch("bridge-kill");
    let (a, b) = (common::prefix("bridge-ka"), common::prefix("bridge-kb"));
    let key = format!("estpipe-test/{}", common::prefix("key"));
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let mut est = bridge(&dir, "estimator", &b, &key, &endpoint, true, &[]);
    // A stall limit longer than the outage: the runner waits for the bridge to return.
    let mut run = runner(&dir, "run", &b, STEPS, &["--deadline-ms", "5000"]);
    let sen = bridge(&dir, "sensor", &a, &key, &endpoint, true, &[]);
    let mut publ = publisher(&dir, "pub", &a, STEPS, 500);
    // Kill it once it forwards (connected, the far side subscribed), mid-stream.
    sen.wait_for_stderr("forwarding", 30);
    std::thread::sleep(Duration::from_millis(500));
    sen.signal(libc::SIGKILL);
    drop(sen);
    est.wait_for_stderr("sensor side gone", 30);
    std::thread::sleep(Duration::from_millis(300));
    common::cleanup_dead_nodes();
    let mut sen = bridge(&dir, "sensor2", &a, &key, &endpoint, true, &[]);
    assert_ok(&mut publ, 60);
    assert_ok(&mut run, 60);
    assert_ok(&mut est, 30);
    assert_ok(&mut sen, 30);
    let e = report(&dir.join("bridge-estimator.json"));
    let lost = e["lost_on_network"].as_u64().unwrap();
    // What the publisher sent while no sensor side was there went nowhere (it pauses soon
    // after its subscriber is gone, so how much is timing); all of it is accounted for.
    assert!(lost > 0, "lost {lost}");
    assert_eq!(e["slots"].as_u64().unwrap() + lost, u64::from(STEPS));
    assert!(e["far_side_lost"].as_u64().unwrap() >= 1);
    let r = report(&dir.join("run.json"));
    assert_eq!(r["counts"]["lost_on_network"].as_u64().unwrap(), lost);
}

/// `demo --via zenoh`: the same seed gives the estimates of `demo` bit for bit, and the
/// summary shows the network hop.
#[test]
fn demo_via_zenoh_equals_demo() {
    let dir = scratch("bridge-demo");
    let mut outs = Vec::new();
    for via in ["shm", "zenoh"] {
        let out = dir.join(via);
        let prefix = common::prefix("bridge-demo");
        let mut p = Proc::start(
            &dir,
            &format!("demo-{via}"),
            &[
                "demo",
                "--scenario",
                "occlusion",
                "--steps",
                "300",
                "--rate",
                "1000",
                "--seed",
                "5",
                "--wait",
                "block",
                "--via",
                via,
                "--prefix",
                &prefix,
                "--out",
                out.to_str().unwrap(),
                "--quiet",
            ],
        );
        assert_ok(&mut p, 90);
        if via == "zenoh" {
            assert!(p.out().contains("network (zenoh, loopback)"), "{}", p.out());
            let e = report(&out.join("bridge-estimator.json"));
            assert_eq!(e["slots"], 300);
            assert_eq!(e["lost_on_network"], 0);
        }
        outs.push(estimates(&out.join("estimates.csv")));
    }
    assert_eq!(outs[0].len(), 300);
    assert_eq!(outs[0], outs[1]);
}
