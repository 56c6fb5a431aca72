//! Raw zenoh pub/sub between this process and a copy of itself over TCP on loopback: the
//! baseline of the bridge hop (`ipc-runner bridge`, docs/bridge.md) in `BENCHMARKS.md`.
//!
//! The parent listens on a free loopback port and publishes; the child (this executable,
//! started with `--sub ENDPOINT`) connects and subscribes. Both sessions are configured as the
//! bridge's are (peer mode, multicast scouting off, one TCP link); the publisher as the
//! sensor-side bridge's slots publisher (`CongestionControl::Block`, express), the subscriber
//! as the estimator side's (a FIFO of 4096 samples, the bridge's `--queue` default). Each
//! message is a slot as `estpipe_wire::net::encode_slot` makes it (the bridge's slot message,
//! [`net::SLOT_MESSAGE_LEN`] bytes) with its `CLOCK_MONOTONIC` send time in `send_ns`,
//! stamped just before the put; the child stamps the arrival when it takes the sample from
//! its FIFO, decodes it with the bridge's checks and records arrival − `send_ns` (one way),
//! and checks the sequence numbers are dense. An end message carries the count sent.
//!
//! ```text
//! zenoh_latency [--samples N] [--warmup N] [--rate HZ] [--json]
//! ```
//!
//! `--rate 0` sends as fast as the publisher's blocking congestion control lets it (the
//! throughput run): `throughput_per_s` = messages after warm-up ÷ (last arrival − first send
//! after warm-up). With `--json`, one JSON object on stdout.

use anyhow::{anyhow, bail, Context, Result};
use estpipe_wire::{self as wire, monotonic_ns, net};
use hdrhistogram::Histogram;
use ipc_runner::latency::Percentiles;
use std::io::Read as _;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};
use zenoh::handlers::FifoChannel;
use zenoh::qos::CongestionControl;
use zenoh::Wait;

/// The key of the run (one per parent pid).
fn key(pid: u32) -> String {
    format!("benches/zenoh-latency/{pid}")
}

/// A subscriber that hears nothing for this long assumes its parent is gone and exits.
const IDLE: Duration = Duration::from_secs(20);
/// How long the publisher waits for the subscriber to appear.
const CONNECT: Duration = Duration::from_secs(30);
/// The end message: this tag, then the count sent (u64, little-endian).
const END: &[u8; 3] = b"END";
/// The subscriber's FIFO (the bridge's `--queue` default).
const QUEUE: usize = 4096;

#[derive(Debug)]
struct Opts {
    samples: u64,
    warmup: u64,
    rate: f64,
    json: bool,
}

fn parse_args(args: &[String]) -> Result<Opts> {
    let mut o = Opts {
        samples: 3000,
        warmup: 0,
        rate: 1000.0,
        json: false,
    };
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let mut val = || it.next().ok_or_else(|| anyhow!("{a} needs a value"));
        match a.as_str() {
            "--samples" => o.samples = val()?.parse().context("--samples")?,
            "--warmup" => o.warmup = val()?.parse().context("--warmup")?,
            "--rate" => o.rate = val()?.parse().context("--rate")?,
            "--json" => o.json = true,
            x => bail!("unknown argument {x:?}"),
        }
    }
    if o.samples == 0 {
        bail!("--samples must be positive");
    }
    if !(o.rate.is_finite() && o.rate >= 0.0) {
        bail!("--rate must be a finite number ≥ 0, got {}", o.rate);
    }
    Ok(o)
}

/// The zenoh configuration of both ends: the bridge's (multicast scouting off), one endpoint.
fn config(role: &str, endpoint: &str) -> Result<zenoh::Config> {
    let mut c = zenoh::Config::default();
    let mut set = |k: &str, v: &str| {
        c.insert_json5(k, v)
            .map_err(|e| anyhow!("zenoh configuration {k} = {v}: {e}"))
    };
    set("scouting/multicast/enabled", "false")?;
    set(
        &format!("{role}/endpoints"),
        &serde_json::to_string(&[endpoint])?,
    )?;
    Ok(c)
}

/// The slot of message `i` (seq `i`), a one-node stream of the `linear` scenario's shape.
fn slot(i: u64) -> (wire::StreamHeader, wire::Slot) {
    let h = wire::StreamHeader::new("linear", 1, 2, &[1], 0x5eed);
    let k = u32::try_from(i + 1).unwrap_or(u32::MAX);
    let mut s = wire::Slot::data(k, 0, 1, 0xbe9c);
    s.ny = 1;
    s.delivered = 1;
    s.period_ns = 1_000_000;
    s.stream_start_ns = 1;
    s.y[0] = 0.25;
    (h, s)
}

fn parent(o: &Opts) -> Result<serde_json::Value> {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .context("no free loopback port")?
        .port();
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let key = key(std::process::id());
    let session = zenoh::open(config("listen", &endpoint)?)
        .wait()
        .map_err(|e| anyhow!("cannot open the zenoh session: {e}"))?;
    let publisher = session
        .declare_publisher(key.clone())
        .congestion_control(CongestionControl::Block)
        .express(true)
        .wait()
        .map_err(|e| anyhow!("zenoh publisher {key}: {e}"))?;
    let exe = std::env::current_exe().context("cannot find own executable")?;
    let mut child = Command::new(exe)
        .args(["--sub", &endpoint, &key, &o.warmup.to_string()])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .spawn()
        .context("cannot start the subscriber")?;
    let sent = match publish(o, &publisher) {
        Ok(n) => n,
        Err(e) => {
            let _ = child.kill();
            let _ = child.wait();
            return Err(e);
        }
    };
    let mut out = String::new();
    child
        .stdout
        .take()
        .context("subscriber's stdout")?
        .read_to_string(&mut out)?;
    let st = child.wait()?;
    if !st.success() {
        bail!("the subscriber failed ({st})");
    }
    drop(publisher);
    drop(session);
    report(o, &out, sent)
}

/// Waits for the subscriber, then publishes the warm-up and the samples at the rate (`0`: as
/// fast as they go) and the end marker with their number; returns that number.
fn publish(o: &Opts, publisher: &zenoh::pubsub::Publisher<'_>) -> Result<u64> {
    let t = Instant::now();
    while !publisher
        .matching_status()
        .wait()
        .map_err(|e| anyhow!("zenoh matching status: {e}"))?
        .matching()
    {
        if t.elapsed() > CONNECT {
            bail!("no subscriber within {CONNECT:?}");
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    let total = o.warmup + o.samples;
    let t0 = Instant::now();
    for i in 0..total {
        if o.rate > 0.0 {
            let due = t0 + Duration::from_secs_f64(i as f64 / o.rate);
            let now = Instant::now();
            if due > now {
                std::thread::sleep(due - now);
            }
        }
        let (h, mut s) = slot(i);
        s.send_ns = monotonic_ns();
        publisher
            .put(&net::encode_slot(&h, &s)[..])
            .wait()
            .map_err(|e| anyhow!("zenoh put: {e}"))?;
    }
    let mut end = END.to_vec();
    end.extend_from_slice(&total.to_le_bytes());
    publisher
        .put(end)
        .wait()
        .map_err(|e| anyhow!("zenoh put: {e}"))?;
    Ok(total)
}

/// The subscriber's JSON (`out`), checked against the `sent` count, with the run's settings
/// and the number lost added.
fn report(o: &Opts, out: &str, sent: u64) -> Result<serde_json::Value> {
    let mut v: serde_json::Value =
        serde_json::from_str(out).context("the subscriber's JSON on its stdout")?;
    let received = v["received"].as_u64().context("received")?;
    if v["sent"].as_u64() != Some(sent) {
        bail!("the subscriber heard of {} sent, {sent} were", v["sent"]);
    }
    v["samples"] = o.samples.into();
    v["warmup"] = o.warmup.into();
    v["rate"] = o.rate.into();
    v["lost"] = (sent - received.min(sent)).into();
    Ok(v)
}

fn subscriber(endpoint: &str, key: &str, warmup: u64) -> Result<()> {
    let session = zenoh::open(config("connect", endpoint)?)
        .wait()
        .map_err(|e| anyhow!("cannot open the zenoh session: {e}"))?;
    let sub = session
        .declare_subscriber(key)
        .with(FifoChannel::new(QUEUE))
        .wait()
        .map_err(|e| anyhow!("zenoh subscriber {key}: {e}"))?;
    let mut hist = Histogram::<u64>::new_with_bounds(1, 60_000_000_000, 3)?;
    let (mut received, mut refused, mut out_of_order) = (0u64, 0u64, 0u64);
    let mut next = 0u64;
    let (mut first_send, mut last_arrival) = (None::<u64>, 0u64);
    let sent = loop {
        let sample = sub
            .recv_timeout(IDLE)
            .map_err(|e| anyhow!("zenoh {key}: {e}"))?
            .ok_or_else(|| anyhow!("nothing for {IDLE:?}"))?;
        let bytes = sample.payload().to_bytes();
        let arrival = monotonic_ns();
        if bytes.len() == END.len() + 8 && bytes.starts_with(END) {
            break u64::from_le_bytes(bytes[END.len()..].try_into()?);
        }
        let s = match net::decode_slot(&bytes) {
            Ok((_, s)) => s,
            Err(_) => {
                refused += 1;
                continue;
            }
        };
        received += 1;
        if s.seq < next {
            out_of_order += 1;
        }
        next = next.max(s.seq + 1);
        if s.seq >= warmup {
            hist.saturating_record(arrival.saturating_sub(s.send_ns).max(1));
            first_send.get_or_insert(s.send_ns);
            last_arrival = arrival;
        }
    };
    drop(sub);
    drop(session);
    let measured = hist.len();
    let span_ns = first_send.map_or(0, |f| last_arrival.saturating_sub(f));
    let v = serde_json::json!({
        "payload_bytes": net::SLOT_MESSAGE_LEN,
        "sent": sent,
        "received": received,
        "measured": measured,
        "refused": refused,
        "out_of_order": out_of_order,
        "one_way": Percentiles::of(&hist),
        "span_s": span_ns as f64 / 1e9,
        "throughput_per_s": if span_ns > 0 { measured as f64 / (span_ns as f64 / 1e9) } else { 0.0 },
    });
    println!("{v}");
    Ok(())
}

fn run() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.first().map(String::as_str) == Some("--sub") {
        let (Some(endpoint), Some(key), Some(warmup)) = (args.get(1), args.get(2), args.get(3))
        else {
            bail!("--sub ENDPOINT KEY WARMUP");
        };
        return subscriber(endpoint, key, warmup.parse()?);
    }
    let o = parse_args(&args)?;
    let v = parent(&o)?;
    if o.json {
        println!("{v}");
    } else {
        let p = &v["one_way"];
        println!(
            "zenoh pub/sub, {} B over TCP loopback, {} messages at {}: one way p50 {} µs, p99 {} \
             µs; {:.0} messages/s; {} lost",
            v["payload_bytes"],
            v["measured"],
            if o.rate > 0.0 {
                format!("{} Hz", o.rate)
            } else {
                "full speed".into()
            },
            p["p50_us"],
            p["p99_us"],
            v["throughput_per_s"].as_f64().unwrap_or(f64::NAN),
            v["lost"]
        );
    }
    Ok(())
}

fn main() {
    if let Err(e) = run() {
        eprintln!("zenoh_latency: {e:#}");
        std::process::exit(1);
    }
}
