//! IPC latency in one run: raw iceoryx2 and a Unix-domain socket, ping-pong between this
//! process and a copy of itself, in spin and blocking modes.
//!
//! Each round: the parent writes a ping carrying its `CLOCK_MONOTONIC` send time, the peer
//! stamps its receive time and answers with a pong carrying both. Recorded per round:
//!
//! - **one-way**: ping send → ping received by the peer (the quantity the pipeline's
//!   "slot sent → estimate published" is compared with);
//! - **round trip**: ping send → pong received by the parent.
//!
//! Modes: `iox-spin` (busy-poll `receive()`), `iox-block` (pub/sub plus an event service, the
//! receiver sleeps in a `WaitSet`; see `docs/design.md` "iceoryx2 0.10 facts"), `uds-spin`
//! (non-blocking socket, busy-read), `uds-block` (blocking `read`). The payload is 128 bytes
//! in every mode. Service names and socket paths contain the parent's pid, and both are
//! removed at the end (the socket file also on error).
//!
//! ```text
//! ipc_latency [--samples N] [--warmup N] [--rate HZ] [--modes iox-spin,uds-block,…] [--json FILE]
//! ```

use anyhow::{anyhow, bail, Context, Result};
use hdrhistogram::Histogram;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use std::io::{ErrorKind, Read, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use estpipe_wire::monotonic_ns;
use ipc_runner::latency::Percentiles;

/// The message of every mode: 128 bytes, fixed layout.
#[derive(Clone, Copy, Debug, ZeroCopySend)]
#[repr(C)]
#[type_name("benches::ipc_latency::Ping")]
struct Ping {
    seq: u64,
    send_ns: u64,
    recv_ns: u64,
    pad: [u64; 13],
}

const STOP: u64 = u64::MAX;
/// A peer that hears nothing for this long assumes its parent is gone and exits.
const PEER_IDLE: Duration = Duration::from_secs(20);
const MODES: [&str; 4] = ["iox-spin", "iox-block", "uds-spin", "uds-block"];

impl Ping {
    fn new(seq: u64) -> Self {
        Self {
            seq,
            send_ns: monotonic_ns(),
            recv_ns: 0,
            pad: [0; 13],
        }
    }
    fn to_bytes(self) -> [u8; 128] {
        let mut b = [0u8; 128];
        b[0..8].copy_from_slice(&self.seq.to_le_bytes());
        b[8..16].copy_from_slice(&self.send_ns.to_le_bytes());
        b[16..24].copy_from_slice(&self.recv_ns.to_le_bytes());
        b
    }
    fn from_bytes(b: &[u8; 128]) -> Self {
        let u = |i: usize| u64::from_le_bytes(b[i..i + 8].try_into().expect("8 bytes"));
        Self {
            seq: u(0),
            send_ns: u(8),
            recv_ns: u(16),
            pad: [0; 13],
        }
    }
}

/// One mode's histograms (ns).
struct Stats {
    one_way: Histogram<u64>,
    rtt: Histogram<u64>,
}

impl Stats {
    fn new() -> Result<Self> {
        let h = || Histogram::new_with_bounds(1, 60_000_000_000, 3);
        Ok(Self {
            one_way: h()?,
            rtt: h()?,
        })
    }
    fn record(&mut self, sent: &Ping, pong: &Ping, back_ns: u64) {
        let _ = self
            .one_way
            .record(pong.recv_ns.saturating_sub(sent.send_ns).max(1));
        let _ = self.rtt.record(back_ns.saturating_sub(sent.send_ns).max(1));
    }
}

struct Opts {
    samples: u64,
    warmup: u64,
    modes: Vec<String>,
    json: Option<PathBuf>,
    /// Pings per second; 0 = back to back (the next ping as soon as the pong is in).
    rate: f64,
}

impl Opts {
    /// Paced like `channel-sim --rate`: sleeps until ping `i`'s due time `t0 + i / rate`.
    /// Back to back, a run of 10⁵ rounds lasts ~0.1 s and rarely meets a timer tick or
    /// another process; paced, it is exposed to the same disturbances as the pipeline.
    fn pace(&self, t0: Instant, i: u64) {
        if self.rate > 0.0 {
            let due = t0 + Duration::from_secs_f64(i as f64 / self.rate);
            let now = Instant::now();
            if due > now {
                std::thread::sleep(due - now);
            }
        }
    }
}

fn parse_args(args: &[String]) -> Result<Opts> {
    let mut o = Opts {
        samples: 100_000,
        warmup: 5_000,
        modes: MODES.iter().map(|s| s.to_string()).collect(),
        json: None,
        rate: 0.0,
    };
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let mut val = || it.next().ok_or_else(|| anyhow!("{a} needs a value"));
        match a.as_str() {
            "--samples" => o.samples = val()?.parse().context("--samples")?,
            "--warmup" => o.warmup = val()?.parse().context("--warmup")?,
            "--modes" => o.modes = val()?.split(',').map(str::to_string).collect(),
            "--json" => o.json = Some(PathBuf::from(val()?)),
            "--rate" => o.rate = val()?.parse().context("--rate")?,
            "-h" | "--help" => {
                println!(
                    "ipc_latency [--samples N] [--warmup N] [--rate HZ] [--modes {}] [--json FILE]",
                    MODES.join(",")
                );
                std::process::exit(0);
            }
            other => bail!("unknown argument {other:?} (try --help)"),
        }
    }
    for m in &o.modes {
        if !MODES.contains(&m.as_str()) {
            bail!("unknown mode {m:?}; modes: {}", MODES.join(", "));
        }
    }
    if o.samples == 0 {
        bail!("--samples must be positive");
    }
    if !(o.rate >= 0.0 && o.rate.is_finite()) {
        bail!("--rate must be ≥ 0 (0 = back to back), got {}", o.rate);
    }
    Ok(o)
}

/// Kills and reaps the peer if the parent leaves early.
struct PeerGuard(Option<Child>);

impl Drop for PeerGuard {
    fn drop(&mut self) {
        if let Some(mut c) = self.0.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

impl PeerGuard {
    fn spawn(mode: &str, name: &str) -> Result<Self> {
        let exe = std::env::current_exe().context("cannot find own executable")?;
        let child = Command::new(exe)
            .args(["--peer", mode, name])
            .stdin(Stdio::null())
            .spawn()
            .context("cannot start the peer process")?;
        Ok(Self(Some(child)))
    }
    /// Waits for a clean exit after the STOP message.
    fn finish(mut self) -> Result<()> {
        let mut c = self.0.take().expect("peer");
        let deadline = Instant::now() + Duration::from_secs(10);
        loop {
            if let Some(st) = c.try_wait()? {
                if !st.success() {
                    bail!("peer exited with {st}");
                }
                return Ok(());
            }
            if Instant::now() > deadline {
                let _ = c.kill();
                let _ = c.wait();
                bail!("peer did not exit after STOP");
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }
}

// ---------------------------------------------------------------------------------- iceoryx2

struct IoxPorts {
    node: Node<ipc::Service>,
    tx: Publisher<ipc::Service, Ping, ()>,
    rx: Subscriber<ipc::Service, Ping, ()>,
    notifier: Notifier<ipc::Service>,
    listener: Listener<ipc::Service>,
    tx_subscribers: Box<dyn Fn() -> usize>,
}

fn iox_ports(prefix: &str, parent: bool) -> Result<IoxPorts> {
    let node = NodeBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .map_err(|e| anyhow!("iceoryx2 node: {e:?}"))?;
    let _ = node.try_cleanup_dead_nodes();
    let svc = |what: &str| -> Result<ServiceName> {
        ServiceName::new(&format!("{prefix}/{what}")).map_err(|e| anyhow!("{e:?}"))
    };
    let pubsub = |what: &str| {
        node.service_builder(&svc(what)?)
            .publish_subscribe::<Ping>()
            .subscriber_max_buffer_size(16)
            .history_size(0)
            .open_or_create()
            .map_err(|e| anyhow!("service {prefix}/{what}: {e:?}"))
    };
    let event = |what: &str| {
        node.service_builder(&svc(what)?)
            .event()
            .open_or_create()
            .map_err(|e| anyhow!("event {prefix}/{what}: {e:?}"))
    };
    let (out, inp) = if parent {
        ("ping", "pong")
    } else {
        ("pong", "ping")
    };
    let out_svc = pubsub(out)?;
    let in_svc = pubsub(inp)?;
    let out_ev = event(&format!("{out}-ready"))?;
    let in_ev = event(&format!("{inp}-ready"))?;
    let listener = in_ev
        .listener_builder()
        .create()
        .map_err(|e| anyhow!("listener: {e:?}"))?;
    let rx = in_svc
        .subscriber_builder()
        .buffer_size(16)
        .create()
        .map_err(|e| anyhow!("subscriber: {e:?}"))?;
    let tx = out_svc
        .publisher_builder()
        .create()
        .map_err(|e| anyhow!("publisher: {e:?}"))?;
    let notifier = out_ev
        .notifier_builder()
        .create()
        .map_err(|e| anyhow!("notifier: {e:?}"))?;
    let tx_subscribers = Box::new(move || out_svc.dynamic_config().number_of_subscribers());
    Ok(IoxPorts {
        node,
        tx,
        rx,
        notifier,
        listener,
        tx_subscribers,
    })
}

fn iox_send(p: &IoxPorts, msg: Ping, block: bool) -> Result<()> {
    let s = p.tx.loan_uninit().map_err(|e| anyhow!("loan: {e:?}"))?;
    s.write_payload(msg)
        .send()
        .map_err(|e| anyhow!("send: {e:?}"))?;
    if block {
        p.notifier.notify().map_err(|e| anyhow!("notify: {e:?}"))?;
    }
    Ok(())
}

/// Receives the next message; `None` when nothing came for `idle`.
fn iox_recv(
    p: &IoxPorts,
    ws: Option<&WaitSet<ipc::Service>>,
    idle: Duration,
) -> Result<Option<Ping>> {
    let start = Instant::now();
    let mut polls = 0u32;
    loop {
        if let Some(s) = p.rx.receive().map_err(|e| anyhow!("receive: {e:?}"))? {
            let mut m = *s;
            m.recv_ns = monotonic_ns();
            return Ok(Some(m));
        }
        match ws {
            None => {
                polls = polls.wrapping_add(1);
                if polls.is_multiple_of(4096) && start.elapsed() > idle {
                    return Ok(None);
                }
                std::hint::spin_loop();
            }
            Some(ws) => {
                // Wake-ups can be spurious: drain the listener, then re-check receive().
                ws.wait_and_process_once_with_timeout(
                    |_| {
                        p.listener.try_wait(|_| {}).ok();
                        CallbackProgression::Stop
                    },
                    Duration::from_millis(100),
                )
                .map_err(|e| anyhow!("waitset: {e:?}"))?;
                if start.elapsed() > idle {
                    return Ok(None);
                }
            }
        }
    }
}

fn iox_parent(block: bool, o: &Opts) -> Result<Stats> {
    let prefix = format!("benches-ipc-{}-{}", std::process::id(), block as u8);
    let p = iox_ports(&prefix, true)?;
    let peer = PeerGuard::spawn(if block { "iox-block" } else { "iox-spin" }, &prefix)?;
    // The first messages are lost before the peer's subscriber exists.
    let t0 = Instant::now();
    while (p.tx_subscribers)() == 0 {
        if t0.elapsed() > Duration::from_secs(10) {
            bail!("the peer did not subscribe within 10 s");
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    let ws = if block {
        Some(
            WaitSetBuilder::new()
                .create::<ipc::Service>()
                .map_err(|e| anyhow!("waitset: {e:?}"))?,
        )
    } else {
        None
    };
    let _guard = match &ws {
        Some(ws) => Some(
            ws.attach_notification(&p.listener)
                .map_err(|e| anyhow!("attach: {e:?}"))?,
        ),
        None => None,
    };
    let mut st = Stats::new()?;
    let t0 = Instant::now();
    for i in 0..o.warmup + o.samples {
        o.pace(t0, i);
        let ping = Ping::new(i);
        iox_send(&p, ping, block)?;
        let pong = iox_recv(&p, ws.as_ref(), Duration::from_secs(5))?
            .ok_or_else(|| anyhow!("no pong for ping {i} within 5 s"))?;
        if pong.seq != i {
            bail!("pong {} for ping {i}", pong.seq);
        }
        if i >= o.warmup {
            // The pong carries the peer's receive time in recv_ns; ours is in pong.recv_ns
            // after iox_recv stamped it, so keep the peer's from the payload.
            st.record(&ping, &pong_peer(&pong), pong.recv_ns);
        }
    }
    iox_send(&p, Ping::new(STOP), block)?;
    peer.finish()?;
    Ok(st)
}

/// The pong's payload keeps the peer's receive stamp in `pad[0]` (recv_ns is overwritten by
/// the parent's own stamp on receipt).
fn pong_peer(pong: &Ping) -> Ping {
    Ping {
        recv_ns: pong.pad[0],
        ..*pong
    }
}

fn iox_peer(block: bool, prefix: &str) -> Result<()> {
    let p = iox_ports(prefix, false)?;
    let ws = if block {
        Some(
            WaitSetBuilder::new()
                .create::<ipc::Service>()
                .map_err(|e| anyhow!("waitset: {e:?}"))?,
        )
    } else {
        None
    };
    let _guard = match &ws {
        Some(ws) => Some(
            ws.attach_notification(&p.listener)
                .map_err(|e| anyhow!("attach: {e:?}"))?,
        ),
        None => None,
    };
    // Answer only once the parent's pong subscriber exists.
    let t0 = Instant::now();
    while (p.tx_subscribers)() == 0 {
        if t0.elapsed() > PEER_IDLE {
            bail!("parent never subscribed");
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    while let Some(mut m) = iox_recv(&p, ws.as_ref(), PEER_IDLE)? {
        if m.seq == STOP {
            return Ok(());
        }
        m.pad[0] = m.recv_ns;
        iox_send(&p, m, block)?;
    }
    let _ = p.node.try_cleanup_dead_nodes();
    bail!("no message for {PEER_IDLE:?}: parent gone?")
}

// ------------------------------------------------------------------------ Unix-domain socket

fn sock_path(pid: u32, block: bool) -> PathBuf {
    std::env::temp_dir().join(format!("benches-ipc-{pid}-{}.sock", block as u8))
}

/// Removes the socket file on drop (also on error).
struct SockFile(PathBuf);

impl Drop for SockFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// Reads exactly one 128-byte message; busy-reads a non-blocking socket in spin mode.
fn uds_read(s: &mut UnixStream, spin: bool, idle: Duration) -> Result<Option<Ping>> {
    let mut b = [0u8; 128];
    let mut got = 0;
    let start = Instant::now();
    while got < b.len() {
        match s.read(&mut b[got..]) {
            Ok(0) => return Ok(None),
            Ok(n) => got += n,
            Err(e) if e.kind() == ErrorKind::WouldBlock && spin => {
                if start.elapsed() > idle {
                    return Ok(None);
                }
                std::hint::spin_loop();
            }
            Err(e) if e.kind() == ErrorKind::Interrupted => {}
            Err(e) => return Err(e.into()),
        }
    }
    let mut m = Ping::from_bytes(&b);
    m.pad[0] = m.recv_ns; // the peer's stamp, if any
    m.recv_ns = monotonic_ns();
    Ok(Some(m))
}

fn uds_write(s: &mut UnixStream, m: &Ping) -> Result<()> {
    let b = m.to_bytes();
    let mut sent = 0;
    while sent < b.len() {
        match s.write(&b[sent..]) {
            Ok(n) => sent += n,
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::Interrupted) => {
                std::hint::spin_loop()
            }
            Err(e) => return Err(e.into()),
        }
    }
    Ok(())
}

fn uds_parent(spin: bool, o: &Opts) -> Result<Stats> {
    let path = sock_path(std::process::id(), !spin);
    let _ = std::fs::remove_file(&path);
    let listener = UnixListener::bind(&path).with_context(|| format!("bind {path:?}"))?;
    let _file = SockFile(path.clone());
    let peer = PeerGuard::spawn(
        if spin { "uds-spin" } else { "uds-block" },
        path.to_str().context("socket path")?,
    )?;
    let (mut s, _) = listener.accept().context("accept")?;
    s.set_nonblocking(spin)?;
    s.set_read_timeout(if spin {
        None
    } else {
        Some(Duration::from_secs(5))
    })?;
    let mut st = Stats::new()?;
    let t0 = Instant::now();
    for i in 0..o.warmup + o.samples {
        o.pace(t0, i);
        let ping = Ping::new(i);
        uds_write(&mut s, &ping)?;
        let pong = uds_read(&mut s, spin, Duration::from_secs(5))?
            .ok_or_else(|| anyhow!("no pong for ping {i}"))?;
        if pong.seq != i {
            bail!("pong {} for ping {i}", pong.seq);
        }
        if i >= o.warmup {
            st.record(&ping, &pong_peer(&pong), pong.recv_ns);
        }
    }
    uds_write(&mut s, &Ping::new(STOP))?;
    peer.finish()?;
    Ok(st)
}

fn uds_peer(spin: bool, path: &Path) -> Result<()> {
    let mut s = UnixStream::connect(path).with_context(|| format!("connect {path:?}"))?;
    s.set_nonblocking(spin)?;
    s.set_read_timeout(if spin { None } else { Some(PEER_IDLE) })?;
    // On the wire, recv_ns carries the peer's receive stamp back to the parent.
    while let Some(m) = uds_read(&mut s, spin, PEER_IDLE)? {
        if m.seq == STOP {
            return Ok(());
        }
        uds_write(&mut s, &m)?;
    }
    bail!("connection closed or idle for {PEER_IDLE:?}")
}

// ------------------------------------------------------------------------------------ main

fn run() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.first().map(String::as_str) == Some("--peer") {
        let (mode, name) = match (args.get(1), args.get(2)) {
            (Some(m), Some(n)) => (m.as_str(), n.as_str()),
            _ => bail!("--peer MODE NAME"),
        };
        return match mode {
            "iox-spin" => iox_peer(false, name),
            "iox-block" => iox_peer(true, name),
            "uds-spin" => uds_peer(true, Path::new(name)),
            "uds-block" => uds_peer(false, Path::new(name)),
            m => bail!("unknown peer mode {m}"),
        };
    }
    let o = parse_args(&args)?;
    let mut rows = Vec::new();
    for m in &o.modes {
        eprintln!(
            "ipc_latency: {m}, {} rounds after {} warm-up",
            o.samples, o.warmup
        );
        let st = match m.as_str() {
            "iox-spin" => iox_parent(false, &o)?,
            "iox-block" => iox_parent(true, &o)?,
            "uds-spin" => uds_parent(true, &o)?,
            "uds-block" => uds_parent(false, &o)?,
            _ => unreachable!("checked in parse_args"),
        };
        rows.push((
            m.clone(),
            Percentiles::of(&st.one_way),
            Percentiles::of(&st.rtt),
        ));
    }
    println!(
        "{:<10} {:>10} {:>9} {:>9} {:>9} {:>9} {:>9}   round trip p50/p99 (µs)",
        "mode", "samples", "p50 µs", "p90", "p99", "p99.9", "max"
    );
    for (m, ow, rt) in &rows {
        println!(
            "{m:<10} {:>10} {:>9.2} {:>9.2} {:>9.2} {:>9.2} {:>9.1}   {:.2} / {:.2}",
            ow.count, ow.p50_us, ow.p90_us, ow.p99_us, ow.p999_us, ow.max_us, rt.p50_us, rt.p99_us
        );
    }
    if let Some(path) = &o.json {
        let mut s = String::from("{\n");
        for (i, (m, ow, rt)) in rows.iter().enumerate() {
            s.push_str(&format!(
                "  \"{m}\": {{\"one_way\": {}, \"round_trip\": {}}}{}\n",
                serde_json::to_string(ow)?,
                serde_json::to_string(rt)?,
                if i + 1 < rows.len() { "," } else { "" }
            ));
        }
        s.push_str("}\n");
        std::fs::write(path, s).with_context(|| format!("write {path:?}"))?;
    }
    Ok(())
}

fn main() {
    // Only errors: the "no config file" warning would otherwise print once per process.
    set_log_level(LogLevel::Error);
    if let Err(e) = run() {
        eprintln!("ipc_latency: {e:#}");
        std::process::exit(1);
    }
}
