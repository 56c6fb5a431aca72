//! A zenoh peer with a configuration of its own (tests/bridge_auth.rs): it tries to join a
//! bridge's zenoh network with the credentials its `--config` gives (none, a wrong
//! certificate, a wrong password, or valid ones), then publishes on `<key>/slots` and
//! listens on `<key>/estimates` for a bounded time, and says what it got on stdout as JSON:
//! `{"connected", "peers", "matched", "put", "put_errors", "received", "open_error"}`
//! (`matched`: a subscriber of `<key>/slots` was announced to it).
//!
//! What it publishes are messages of the slot tag with another wire version: any one that
//! reached a bridge's estimator side would be counted there as refused (`version`), so the
//! estimator side's report shows whether anything got through. Exit 0 whatever zenoh
//! refused (the refusal is the result); 2 on a bad flag.

use anyhow::{anyhow, Result};
use clap::Parser;
use estpipe_wire::net::{self, Kind};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use zenoh::qos::CongestionControl;
use zenoh::Wait;

#[derive(Parser)]
struct Args {
    /// zenoh configuration (JSON5): endpoints, TLS, user/password.
    #[arg(long)]
    config: std::path::PathBuf,
    /// The bridge's key prefix.
    #[arg(long)]
    key: String,
    /// Give up joining after this many milliseconds without a peer.
    #[arg(long, default_value_t = 3000)]
    join_ms: u64,
    /// Wait this long for a subscriber of `<key>/slots` to be announced before publishing
    /// (publishing goes ahead without one).
    #[arg(long, default_value_t = 1000)]
    match_ms: u64,
    /// Messages to publish on `<key>/slots` once joined (1 ms apart).
    #[arg(long, default_value_t = 0)]
    publish: u64,
    /// Listen on `<key>/estimates` this long after joining (and publishing).
    #[arg(long, default_value_t = 0)]
    listen_ms: u64,
}

fn main() {
    let a = Args::parse();
    let out = match peer(&a) {
        Ok(v) => v,
        Err(e) => serde_json::json!({ "connected": false, "open_error": format!("{e}") }),
    };
    println!("{out}");
}

fn peer(a: &Args) -> Result<serde_json::Value> {
    let c = zenoh::Config::from_file(&a.config).map_err(|e| anyhow!("config: {e}"))?;
    let session = zenoh::open(c).wait().map_err(|e| anyhow!("open: {e}"))?;
    let received = Arc::new(AtomicU64::new(0));
    let r = Arc::clone(&received);
    let _sub = session
        .declare_subscriber(format!("{}/estimates", a.key))
        .callback(move |_| {
            r.fetch_add(1, Ordering::Relaxed);
        })
        .wait()
        .map_err(|e| anyhow!("subscriber: {e}"))?;
    let publisher = session
        .declare_publisher(format!("{}/slots", a.key))
        .congestion_control(CongestionControl::Block)
        .wait()
        .map_err(|e| anyhow!("publisher: {e}"))?;
    let t = Instant::now();
    let peers = loop {
        let info = session.info();
        let n = info.peers_zid().wait().count() + info.routers_zid().wait().count();
        if n > 0 || t.elapsed() >= Duration::from_millis(a.join_ms) {
            break n;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let (mut put, mut put_errors, mut matched) = (0u64, 0u64, false);
    eprintln!(
        "zenoh-peer: {}",
        if peers > 0 { "joined" } else { "not joined" }
    );
    if peers > 0 {
        let t = Instant::now();
        while t.elapsed() < Duration::from_millis(a.match_ms) {
            matched = publisher
                .matching_status()
                .wait()
                .map_err(|e| anyhow!("matching: {e}"))?
                .matching();
            if matched {
                break;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        let mut m = vec![0u8; net::SLOT_MESSAGE_LEN];
        m[..2].copy_from_slice(&net::MAGIC);
        m[2] = Kind::Slot as u8;
        m[3] = estpipe_wire::WIRE_VERSION as u8 + 1;
        for _ in 0..a.publish {
            match publisher.put(m.clone()).wait() {
                Ok(()) => put += 1,
                Err(_) => put_errors += 1,
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        std::thread::sleep(Duration::from_millis(a.listen_ms));
    }
    let out = serde_json::json!({
        "connected": peers > 0,
        "peers": peers,
        "matched": matched,
        "put": put,
        "put_errors": put_errors,
        "received": received.load(Ordering::Relaxed),
    });
    drop(publisher);
    let _ = session.close().wait();
    Ok(out)
}
