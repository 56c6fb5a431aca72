//! A foreign zenoh publisher (tests/hostile_bridge.rs): messages that are no message of the
//! contract, as fast as zenoh takes them (reliable, congestion control `block`, so every one
//! reaches the bridge and its count is exact), then exits 0. Prints `flooding` on stderr once
//! the bridge's subscriber is matched and the flood begins.
//!
//! `--on slots` (the default) floods `<key>/slots`, the estimator side's input, and never
//! sends a well-formed slot. Per `--each` N: N of random bytes of a slot message's length but
//! no magic (refused as `magic`), N short messages of 1–40 random bytes (`length`), N slot
//! messages of another wire version (`version`), N truth messages of another version
//! (`version`), N messages of the estimate kind (`kind`); and `--oversized` M tagged slot
//! messages of `--oversized-kib` KiB (`length`). Prints the counts sent, as JSON by the reason
//! the bridge must give, on stdout.
//!
//! `--on acks` floods `<key>/acks`, where the sensor side takes the estimator side's echoes of
//! its END/ABORT markers (bridge/src/link/markers.rs). Like any peer of an unauthenticated link it
//! first reads `<key>/slots` until the first data slot of the real stream (stream id, header,
//! node count), stops reading, and then forges, per `--each` N: N empty messages and N
//! truncated acks (`length`), N of random bytes of an ack's length (`magic`), N acks of
//! another wire version (`version`), N of another message kind (`kind`), N data slots of the
//! stream (`ack_not_marker`), N markers of a node ≥ their own node count (`invalid`); N
//! well-formed acks each of another stream id, another k, the other kind (ABORT for END) and
//! a node the stream does not have; and N exact copies, per node, of the ack of the END the
//! stream will end with (`--end-k`), sent before it exists. The well-formed ones name no
//! marker being repeated: the sensor side drops them as stale (`acks_stale`), unrefused.
//! Then `--oversized` M (`length`). Prints `{"refused": {reason: count}, "stale": count,
//! "nodes": the stream's node count}`.

use anyhow::{anyhow, bail, Result};
use clap::{Parser, ValueEnum};
use estpipe_wire::net::{self, Kind};
use estpipe_wire::{Slot, StreamHeader, MAX_NODES, SLOT_ABORT, SLOT_DATA, SLOT_END};
use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use zenoh::qos::CongestionControl;
use zenoh::Wait;

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
enum On {
    /// `<key>/slots`, against the estimator side.
    Slots,
    /// `<key>/acks`, against the sensor side.
    Acks,
}

#[derive(Parser)]
struct Args {
    /// zenoh endpoint of the bridge to flood.
    #[arg(long)]
    connect: String,
    /// The bridge's key prefix.
    #[arg(long)]
    key: String,
    /// Which key under it to flood.
    #[arg(long, value_enum, default_value_t = On::Slots)]
    on: On,
    /// Messages of each small kind.
    #[arg(long, default_value_t = 1000)]
    each: u64,
    /// Oversized messages.
    #[arg(long, default_value_t = 100)]
    oversized: u64,
    /// Size of an oversized message, KiB.
    #[arg(long, default_value_t = 64)]
    oversized_kib: usize,
    /// `--on acks`: the k of the END markers the stream will end with (its last instant).
    #[arg(long, default_value_t = 0)]
    end_k: u32,
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

type Publisher<'a> = zenoh::pubsub::Publisher<'a>;

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
    let target = format!(
        "{}/{}",
        a.key,
        match a.on {
            On::Slots => "slots",
            On::Acks => "acks",
        }
    );
    let publisher = session
        .declare_publisher(target.clone())
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
            bail!("no subscriber on {target} within 30 s");
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    let out = match a.on {
        On::Slots => {
            eprintln!("zenoh-flood: flooding {target}");
            flood_slots(&a, &publisher)?
        }
        On::Acks => {
            let (h, s) = learn_stream(&session, &a.key)?;
            eprintln!(
                "zenoh-flood: flooding {target} (stream {:#x}, {} nodes)",
                s.stream_id, h.nodes
            );
            flood_acks(&a, &publisher, &h, &s)?
        }
    };
    println!("{out}");
    // Let zenoh hand the last messages to the link before the session closes.
    drop(publisher);
    session
        .close()
        .wait()
        .map_err(|e| anyhow!("zenoh close: {e}"))?;
    Ok(())
}

fn put(publisher: &Publisher<'_>, m: &[u8]) -> Result<()> {
    publisher
        .put(m)
        .wait()
        .map_err(|e| anyhow!("zenoh put: {e}"))
}

/// A message of `len` bytes with the tag of `kind` and this wire version, zeros after it.
fn tagged(kind: Kind, len: usize) -> Vec<u8> {
    let mut m = vec![0u8; len];
    m[..2].copy_from_slice(&net::MAGIC);
    m[2] = kind as u8;
    m[3] = estpipe_wire::WIRE_VERSION as u8;
    m
}

fn flood_slots(a: &Args, publisher: &Publisher<'_>) -> Result<serde_json::Value> {
    let version = estpipe_wire::WIRE_VERSION as u8 + 1;
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let (mut magic, mut length, mut versions, mut kind) = (0u64, 0u64, 0u64, 0u64);
    let mut wrong_version = tagged(Kind::Slot, net::SLOT_MESSAGE_LEN);
    wrong_version[3] = version;
    let mut truth_version = tagged(Kind::Truth, net::TRUTH_MESSAGE_LEN);
    truth_version[3] = version;
    let estimate_kind = tagged(Kind::Estimate, net::SLOT_MESSAGE_LEN);
    let oversized = tagged(Kind::Slot, a.oversized_kib * 1024);
    for i in 0..a.each {
        // Random bytes of the right length, no magic; byte 2 never says "truth".
        let mut g = vec![0u8; net::SLOT_MESSAGE_LEN];
        rng.fill(&mut g);
        g[0] = 0;
        g[2] = 0x7f;
        put(publisher, &g)?;
        magic += 1;
        let n = 1 + (rng.next() % 40) as usize;
        let mut short = vec![0u8; n];
        rng.fill(&mut short);
        if n > 2 {
            short[2] = 0x7f;
        }
        put(publisher, &short)?;
        length += 1;
        put(publisher, &wrong_version)?;
        put(publisher, &truth_version)?;
        versions += 2;
        put(publisher, &estimate_kind)?;
        kind += 1;
        if i < a.oversized {
            put(publisher, &oversized)?;
            length += 1;
        }
    }
    for _ in a.each..a.oversized {
        put(publisher, &oversized)?;
        length += 1;
    }
    Ok(serde_json::json!({
        "magic": magic,
        "length": length,
        "version": versions,
        "kind": kind,
    }))
}

/// Reads `<key>/slots` until the first well-formed data slot of the stream, then stops
/// reading (the subscriber is undeclared: the sensor side's puts never wait for this peer).
fn learn_stream(session: &zenoh::Session, key: &str) -> Result<(StreamHeader, Slot)> {
    let seen: Arc<Mutex<Option<(StreamHeader, Slot)>>> = Arc::default();
    let sink = Arc::clone(&seen);
    let sub = session
        .declare_subscriber(format!("{key}/slots"))
        .callback(move |sample| {
            if let Ok((h, s)) = net::decode_slot(&sample.payload().to_bytes()) {
                if s.kind == SLOT_DATA {
                    sink.lock().unwrap().get_or_insert((h, s));
                }
            }
        })
        .wait()
        .map_err(|e| anyhow!("zenoh subscriber {key}/slots: {e}"))?;
    eprintln!("zenoh-flood: reading {key}/slots for the stream");
    let t = Instant::now();
    let found = loop {
        if let Some(found) = *seen.lock().unwrap() {
            break found;
        }
        if t.elapsed() > Duration::from_secs(60) {
            bail!("no data slot on {key}/slots within 60 s");
        }
        std::thread::sleep(Duration::from_millis(1));
    };
    sub.undeclare()
        .wait()
        .map_err(|e| anyhow!("zenoh undeclare: {e}"))?;
    Ok(found)
}

fn flood_acks(
    a: &Args,
    publisher: &Publisher<'_>,
    h: &StreamHeader,
    s: &Slot,
) -> Result<serde_json::Value> {
    if a.end_k == 0 {
        bail!("--on acks needs --end-k");
    }
    let (sid, nodes) = (s.stream_id, h.nodes);
    if usize::from(nodes) >= MAX_NODES {
        bail!("a stream of {nodes} nodes leaves no node out of it to forge");
    }
    let ack = |kind: u32, k: u32, node: u8, nodes: u8, sid: u64| {
        let m = Slot {
            period_ns: s.period_ns,
            stream_start_ns: s.stream_start_ns,
            ..Slot::marker(kind, k, node, nodes, sid, 0)
        };
        net::encode_slot(h, &m)
    };
    // The echo the estimator side will send of node m's END: forged before the END exists.
    let future: Vec<_> = (0..nodes)
        .map(|m| ack(SLOT_END, a.end_k, m, nodes, sid))
        .collect();
    let mut wrong_version = future[0];
    wrong_version[3] = estpipe_wire::WIRE_VERSION as u8 + 1;
    let mut wrong_kind = future[0];
    wrong_kind[2] = Kind::Estimate as u8;
    let data = net::encode_slot(h, s);
    let foreign_node = ack(SLOT_END, a.end_k, nodes, nodes, sid);
    let oversized = tagged(Kind::Slot, a.oversized_kib * 1024);
    let mut rng = Rng(0x2545_f491_4f6c_dd1d);
    let mut refused = BTreeMap::<&str, u64>::new();
    let mut stale = 0u64;
    for i in 0..a.each {
        let mut send = |m: &[u8], reason: Option<&'static str>| -> Result<()> {
            put(publisher, m)?;
            match reason {
                Some(r) => *refused.entry(r).or_default() += 1,
                None => stale += 1,
            }
            Ok(())
        };
        let f = &future[(i % u64::from(nodes)) as usize];
        send(&[], Some("length"))?;
        let cut = 1 + (rng.next() % (net::SLOT_MESSAGE_LEN as u64 - 1)) as usize;
        send(&f[..cut], Some("length"))?;
        let mut g = [0u8; net::SLOT_MESSAGE_LEN];
        rng.fill(&mut g);
        g[0] = 0;
        send(&g, Some("magic"))?;
        send(&wrong_version, Some("version"))?;
        send(&wrong_kind, Some("kind"))?;
        send(&data, Some("ack_not_marker"))?;
        // Node ≥ its own node count: a marker of no node at all.
        send(&foreign_node, Some("invalid"))?;
        // Well-formed acks of markers the stream never sends.
        let m = (i % u64::from(nodes)) as u8;
        send(&ack(SLOT_END, a.end_k, m, nodes, sid ^ (1 + i)), None)?;
        let k = if i % 2 == 0 {
            a.end_k - 1
        } else {
            a.end_k + 1 + i as u32
        };
        send(&ack(SLOT_END, k, m, nodes, sid), None)?;
        send(&ack(SLOT_ABORT, a.end_k, m, nodes, sid), None)?;
        send(&ack(SLOT_END, a.end_k, nodes, MAX_NODES as u8, sid), None)?;
        // The real END's echo, every node's, before the END.
        for f in &future {
            send(f, None)?;
        }
    }
    for _ in 0..a.oversized {
        put(publisher, &oversized)?;
        *refused.entry("length").or_default() += 1;
    }
    Ok(serde_json::json!({ "refused": refused, "stale": stale, "nodes": nodes }))
}
