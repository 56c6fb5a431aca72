//! SIGINT on a congested link: the sensor side (publisher + `bridge --side sensor`) and the
//! estimator side (`bridge --side estimator` + runner) in two network namespaces joined by a
//! veth pair, zenoh over TCP, and mid-stream the link blackholed (nftables drops everything
//! B receives on it): the sensor side's puts (`CongestionControl::Block`) then wait on a
//! full send queue, and zenoh's close waits for a peer that never answers.
//!
//! Every process still ends promptly on SIGINT, with its report (docs/bridge.md, "Hostile
//! input"): the sensor side within zenoh's own bound on a blocked put (`wait_before_close`,
//! 5 s by default) plus the bridge's 0.5 s bound on the close — asserted as 7 s; before the
//! bound on the close it took 15 s here —, the estimator side and the runner within 3 s.
//!
//! Without root, `ip netns` or nftables, the test is skipped with one line.

#[path = "pipeline_common.rs"]
mod common;
#[path = "netns_common.rs"]
mod netns;
#[path = "skip_log.rs"]
mod skip_log;

use common::{report, scratch, Proc};
use netns::{BridgeArgs, Netns, ADDR_A};
use std::time::{Duration, Instant};

const PORT: u16 = 7451;

/// SIGINT to `p`: its exit status and how long it took (panics after `secs`).
fn interrupt(p: &mut Proc, secs: u64) -> (std::process::ExitStatus, Duration) {
    p.signal(libc::SIGINT);
    let t = Instant::now();
    let st = p.wait(secs);
    (st, t.elapsed())
}

#[test]
fn sigint_ends_every_process_promptly_on_a_blackholed_link() {
    let ns = match Netns::pair('c') {
        Ok(n) => n,
        Err(why) => {
            skip_log::skipped(
                &skip_log::current_test("congested_link"),
                &format!("no network namespaces here ({why})"),
            );
            return;
        }
    };
    if let Err(why) = ns.exec(&ns.b, &["nft", "add", "table", "inet", "estp"]) {
        skip_log::skipped(
            &skip_log::current_test("congested_link"),
            &format!("no nftables here ({why})"),
        );
        return;
    }
    let dir = scratch("congested-link");
    let (a, b) = (common::prefix("cong-a"), common::prefix("cong-b"));
    let key = format!("estpipe-test/{}", common::prefix("key"));
    let endpoint = format!("tcp/{ADDR_A}:{PORT}");
    let bridge = |nsn: &str, side, role, prefix| {
        let b = BridgeArgs {
            side,
            role,
            prefix,
            key: &key,
            endpoint: &endpoint,
        };
        ns.bridge(nsn, &dir, &b, &[])
    };
    let json = dir.join("run.json");
    let mut sen = bridge(&ns.a, "sensor", "--listen", &a);
    sen.wait_for_stderr("waiting for the estimator side", 30);
    let mut est = bridge(&ns.b, "estimator", "--connect", &b);
    let mut run = ns.start(
        &ns.b,
        &dir,
        "run",
        &[
            "run",
            "--scenario",
            "linear",
            "--prefix",
            &b,
            "--wait",
            "block",
            "--stall-limit",
            "0",
            "--json",
            json.to_str().unwrap(),
            "--quiet",
        ],
    );
    let mut publ = ns.start(
        &ns.a,
        &dir,
        "pub",
        &[
            "channel-sim",
            "--scenario",
            "linear",
            "--prefix",
            &a,
            "--rate",
            "20000",
            "--steps",
            "10000000",
            "--quiet",
        ],
    );
    sen.wait_for_stderr("forwarding", 30);
    std::thread::sleep(Duration::from_millis(1000));
    // The blackhole: B takes nothing from the link (no data, no ACKs, no keep-alives).
    let chain = "{ type filter hook input priority 0; }";
    let rule = format!("iifname \"{}\" drop", ns.vb);
    ns.exec(
        &ns.b,
        &["nft", "add", "chain", "inet", "estp", "inp", chain],
    )
    .and_then(|_| ns.exec(&ns.b, &["nft", "add", "rule", "inet", "estp", "inp", &rule]))
    .unwrap();
    // Long enough for the send queues to fill (a fraction of a second at 20 kHz here).
    std::thread::sleep(Duration::from_secs(3));

    for (p, name, bound) in [(&mut sen, "sensor", 7), (&mut est, "estimator", 3)] {
        let (st, took) = interrupt(p, 30);
        let err = p.err();
        eprintln!("SIGINT to the {name} side on the blackholed link: ended after {took:?}");
        assert!(st.success(), "{name}: {st}\n{err}");
        assert!(!err.contains("panicked"), "{name}:\n{err}");
        assert!(
            took < Duration::from_secs(bound),
            "{name}: took {took:?}\n{err}"
        );
        let r = report(&dir.join(format!("bridge-{name}.json")));
        assert_eq!(r["ending"], "interrupted", "{name}: {r}");
        assert!(r["slots"].as_u64().unwrap() > 0, "{name}: {r}");
    }
    // The runner (its slots stopped with the link) and the publisher (its subscriber gone).
    let (st, took) = interrupt(&mut run, 30);
    assert_eq!(st.code(), Some(130), "run: {st}\n{}", run.err());
    assert!(took < Duration::from_secs(3), "run: took {took:?}");
    let r = report(&json);
    assert!(r["counts"]["received"].as_u64().unwrap() > 0, "{r}");
    let (st, took) = interrupt(&mut publ, 30);
    assert!(!publ.err().contains("panicked"), "{}", publ.err());
    assert!(took < Duration::from_secs(3), "pub: {st} after {took:?}");
}
