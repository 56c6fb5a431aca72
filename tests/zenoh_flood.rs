//! A foreign zenoh publisher on `<key>/slots` (tests/hostile_bridge.rs): messages that are no
//! slot of the contract, as fast as zenoh takes them (reliable, congestion control `block`,
//! so every one reaches the bridge and its count is exact), then exits 0. It never sends a
//! well-formed slot.
//!
//! Per `--each` N: N of random bytes of a slot message's length but no magic (refused as
//! `magic`), N short messages of 1–40 random bytes (`length`), N slot messages of another wire
//! version (`version`), N truth messages of another version (`version`), N messages of the
//! estimate kind (`kind`); and `--oversized` M tagged slot messages of 64 KiB (`length`).
//! Prints `flooding` on stderr once the bridge's subscriber is matched, and the counts sent,
//! as JSON by the reason the bridge must give, on stdout.

use anyhow::{anyhow, bail, Result};
use clap::Parser;
use estpipe_wire::net::{self, Kind};
use std::time::{Duration, Instant};
use zenoh::qos::CongestionControl;
use zenoh::Wait;

#[derive(Parser)]
struct Args {
    /// zenoh endpoint of the bridge to flood.
    #[arg(long)]
    connect: String,
    /// The bridge's key prefix (`<key>/slots` is flooded).
    #[arg(long)]
    key: String,
    /// Messages of each small kind.
    #[arg(long, default_value_t = 1000)]
    each: u64,
    /// Oversized messages (64 KiB).
    #[arg(long, default_value_t = 100)]
    oversized: u64,
}

/// xorshift64: reproducible garbage.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }

    fn fill(&mut self, b: &mut [u8]) {
        for x in b {
            *x = self.next() as u8;
        }
    }
}

fn main() -> Result<()> {
    let a = Args::parse();
    let mut c = zenoh::Config::default();
    let set = |c: &mut zenoh::Config, k: &str, v: &str| {
        c.insert_json5(k, v)
            .map_err(|e| anyhow!("zenoh configuration {k}: {e}"))
    };
    set(&mut c, "scouting/multicast/enabled", "false")?;
    set(
        &mut c,
        "connect/endpoints",
        &serde_json::to_string(&[&a.connect])?,
    )?;
    let session = zenoh::open(c)
        .wait()
        .map_err(|e| anyhow!("zenoh open: {e}"))?;
    let publisher = session
        .declare_publisher(format!("{}/slots", a.key))
        .congestion_control(CongestionControl::Block)
        .wait()
        .map_err(|e| anyhow!("zenoh publisher: {e}"))?;
    let t = Instant::now();
    while !publisher
        .matching_status()
        .wait()
        .map_err(|e| anyhow!("zenoh matching: {e}"))?
        .matching()
    {
        if t.elapsed() > Duration::from_secs(30) {
            bail!("no subscriber on {}/slots within 30 s", a.key);
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    eprintln!("zenoh-flood: flooding {}/slots", a.key);

    let version = estpipe_wire::WIRE_VERSION as u8 + 1;
    let tagged = |kind: Kind, len: usize| {
        let mut m = vec![0u8; len];
        m[..2].copy_from_slice(&net::MAGIC);
        m[2] = kind as u8;
        m[3] = estpipe_wire::WIRE_VERSION as u8;
        m
    };
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let put = |m: &[u8]| {
        publisher
            .put(m)
            .wait()
            .map_err(|e| anyhow!("zenoh put: {e}"))
    };
    let (mut magic, mut length, mut versions, mut kind) = (0u64, 0u64, 0u64, 0u64);
    let mut wrong_version = tagged(Kind::Slot, net::SLOT_MESSAGE_LEN);
    wrong_version[3] = version;
    let mut truth_version = tagged(Kind::Truth, net::TRUTH_MESSAGE_LEN);
    truth_version[3] = version;
    let estimate_kind = tagged(Kind::Estimate, net::SLOT_MESSAGE_LEN);
    let oversized = tagged(Kind::Slot, 64 * 1024);
    for i in 0..a.each {
        // Random bytes of the right length, no magic; byte 2 never says "truth".
        let mut g = vec![0u8; net::SLOT_MESSAGE_LEN];
        rng.fill(&mut g);
        g[0] = 0;
        g[2] = 0x7f;
        put(&g)?;
        magic += 1;
        let n = 1 + (rng.next() % 40) as usize;
        let mut short = vec![0u8; n];
        rng.fill(&mut short);
        if n > 2 {
            short[2] = 0x7f;
        }
        put(&short)?;
        length += 1;
        put(&wrong_version)?;
        put(&truth_version)?;
        versions += 2;
        put(&estimate_kind)?;
        kind += 1;
        if i < a.oversized {
            put(&oversized)?;
            length += 1;
        }
    }
    for _ in a.each..a.oversized {
        put(&oversized)?;
        length += 1;
    }
    println!(
        "{}",
        serde_json::json!({
            "magic": magic,
            "length": length,
            "version": versions,
            "kind": kind,
        })
    );
    // Let zenoh hand the last messages to the link before the session closes.
    drop(publisher);
    session
        .close()
        .wait()
        .map_err(|e| anyhow!("zenoh close: {e}"))?;
    Ok(())
}
