//! A delaying UDP relay on loopback, netem's `delay D J` in user space for kernels without
//! netem (tests/pipeline_delayed_link.rs): every datagram from the far side (`target`) to
//! the side that connects to the relay is held for D ± J (uniform, a fixed seed), either in
//! order (a datagram never overtakes an earlier one: it is held at least until the one before
//! it went, as on a link whose queue delays everything behind a slow packet) or not (a
//! datagram with a shorter delay overtakes, as netem's jitter does). The other direction is
//! forwarded at once. Bounded: at most [`QUEUE`] datagrams held (more are dropped and
//! counted), every wait at most 20 ms; the threads end when the relay is dropped.
//!
//! Include as a module (`#[path = "delay_relay.rs"] mod delay_relay;`).

#![allow(dead_code)]

use std::collections::BinaryHeap;
use std::net::{SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Datagrams held at most.
pub const QUEUE: usize = 4096;

/// Longest wait of a relay thread.
const SLICE: Duration = Duration::from_millis(20);

/// How the relay delays.
#[derive(Clone, Copy, Debug)]
pub struct Delay {
    /// Mean delay.
    pub mean: Duration,
    /// Half-width of the uniform jitter around the mean.
    pub jitter: Duration,
    /// Whether a datagram may overtake an earlier one.
    pub reorder: bool,
    /// The first this many datagrams keep their order even with `reorder`: zenoh's session
    /// set-up and declarations cross the same link, and an overtaken declaration is dropped
    /// like a slot, so a link reordering from its first datagram can keep the bridges from
    /// ever matching (docs/bridge.md, "A delaying link, tested").
    pub in_order_first: u64,
    /// Seed of the jitter (xorshift64; not 0).
    pub seed: u64,
}

/// What the relay did (its own counts).
#[derive(Debug, Default)]
pub struct Counts {
    /// Datagrams from the connecting side to the target.
    pub up: AtomicU64,
    /// Datagrams from the target delivered to the connecting side.
    pub down: AtomicU64,
    /// Datagrams delivered after one that reached the relay later (overtaken).
    pub overtaken: AtomicU64,
    /// Datagrams held beyond their own delay because an earlier one was still held.
    pub held_behind: AtomicU64,
    /// Datagrams dropped because [`QUEUE`] were held.
    pub dropped: AtomicU64,
    /// Longest time a datagram spent in the relay (ns).
    pub max_held_ns: AtomicU64,
}

/// A running relay: connect to `127.0.0.1:<port>`.
pub struct Relay {
    pub port: u16,
    pub counts: Arc<Counts>,
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
}

/// A held datagram, ordered by release time (earliest first), then by arrival.
struct Held {
    release: Instant,
    arrival: u64,
    at: Instant,
    bytes: Vec<u8>,
}

impl PartialEq for Held {
    fn eq(&self, o: &Self) -> bool {
        (self.release, self.arrival) == (o.release, o.arrival)
    }
}
impl Eq for Held {}
impl PartialOrd for Held {
    fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Held {
    fn cmp(&self, o: &Self) -> std::cmp::Ordering {
        (o.release, o.arrival).cmp(&(self.release, self.arrival))
    }
}

impl Relay {
    /// Relays between a side that will connect to the returned port and `target` (a
    /// listening UDP port on loopback), delaying what `target` sends.
    pub fn start(target: u16, delay: Delay) -> Self {
        let front = UdpSocket::bind("127.0.0.1:0").unwrap();
        let back = UdpSocket::bind("127.0.0.1:0").unwrap();
        back.connect(("127.0.0.1", target)).unwrap();
        front.set_read_timeout(Some(SLICE)).unwrap();
        let port = front.local_addr().unwrap().port();
        let (counts, stop) = (
            Arc::new(Counts::default()),
            Arc::new(AtomicBool::new(false)),
        );
        let client: Arc<Mutex<Option<SocketAddr>>> = Arc::default();
        let up = {
            let (front, back) = (front.try_clone().unwrap(), back.try_clone().unwrap());
            let (counts, stop, client) = (counts.clone(), stop.clone(), client.clone());
            std::thread::spawn(move || {
                let mut buf = vec![0u8; 65536];
                while !stop.load(Ordering::Relaxed) {
                    if let Ok((n, from)) = front.recv_from(&mut buf) {
                        *client.lock().unwrap() = Some(from);
                        if back.send(&buf[..n]).is_ok() {
                            counts.up.fetch_add(1, Ordering::Relaxed);
                        }
                    }
                }
            })
        };
        let down = {
            let (counts, stop) = (counts.clone(), stop.clone());
            std::thread::spawn(move || down(front, back, client, delay, &counts, &stop))
        };
        Self {
            port,
            counts,
            stop,
            threads: vec![up, down],
        }
    }

    /// A count, read now.
    pub fn get(c: &AtomicU64) -> u64 {
        c.load(Ordering::Relaxed)
    }
}

impl Drop for Relay {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

/// The delayed direction: receive from `back`, hold, send to the client through `front`.
fn down(
    front: UdpSocket,
    back: UdpSocket,
    client: Arc<Mutex<Option<SocketAddr>>>,
    d: Delay,
    counts: &Counts,
    stop: &AtomicBool,
) {
    let mut rng = d.seed.max(1);
    let mut held: BinaryHeap<Held> = BinaryHeap::new();
    let (mut arrivals, mut last_release, mut last_sent) = (0u64, None::<Instant>, 0u64);
    let mut buf = vec![0u8; 65536];
    while !stop.load(Ordering::Relaxed) {
        let now = Instant::now();
        let wait = held
            .peek()
            .map(|h| h.release.saturating_duration_since(now))
            .unwrap_or(SLICE)
            .clamp(Duration::from_millis(1), SLICE);
        back.set_read_timeout(Some(wait)).unwrap();
        if let Ok(n) = back.recv(&mut buf) {
            let at = Instant::now();
            if held.len() >= QUEUE {
                counts.dropped.fetch_add(1, Ordering::Relaxed);
            } else {
                rng ^= rng << 13;
                rng ^= rng >> 7;
                rng ^= rng << 17;
                // Uniform in [mean − jitter, mean + jitter].
                let u = (rng >> 11) as f64 / (1u64 << 53) as f64;
                let own = d.mean.as_secs_f64() + (2.0 * u - 1.0) * d.jitter.as_secs_f64();
                let mut release = at + Duration::from_secs_f64(own.max(0.0));
                if !d.reorder || arrivals < d.in_order_first {
                    if let Some(l) = last_release.filter(|&l| l > release) {
                        release = l;
                        counts.held_behind.fetch_add(1, Ordering::Relaxed);
                    }
                }
                last_release = Some(release);
                arrivals += 1;
                held.push(Held {
                    release,
                    arrival: arrivals,
                    at,
                    bytes: buf[..n].to_vec(),
                });
            }
        }
        let now = Instant::now();
        let to = *client.lock().unwrap();
        while held.peek().is_some_and(|h| h.release <= now) {
            let h = held.pop().unwrap();
            if h.arrival < last_sent {
                counts.overtaken.fetch_add(1, Ordering::Relaxed);
            }
            last_sent = last_sent.max(h.arrival);
            if let Some(to) = to {
                if front.send_to(&h.bytes, to).is_ok() {
                    counts.down.fetch_add(1, Ordering::Relaxed);
                }
            }
            let ns = u64::try_from(now.duration_since(h.at).as_nanos()).unwrap_or(u64::MAX);
            counts.max_held_ns.fetch_max(ns, Ordering::Relaxed);
        }
    }
}
