//! The live view's reader (docs/view.md): its own thread, reading the loop's [`ViewEvent`]s
//! (each estimate as published, then the instant's node statuses and truth); every 50 ms one
//! JSON frame of the decimated points ([`super::decimate`]) to the [`Hub`]. Nothing here can
//! slow the loop: the tap drops what a slow reader has no room for.

use super::decimate::{keep, Window};
use super::hub::Hub;
use super::tap::{EstimateEvent, InstantEvent, ViewEvent, LATE};
use estpipe_wire::MAX_NODES;
use serde_json::{json, Value};
use std::collections::HashMap;
use std::sync::mpsc::{Receiver, TryRecvError};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// A frame every this long.
const FRAME: Duration = Duration::from_millis(50);
/// With no instant for this long a running view says "no publisher".
const IDLE: Duration = Duration::from_secs(1);
/// The latency window: the newest instants.
const WINDOW: usize = 1000;

/// Estimates kept per estimator, to join with the instants of the next frame.
const RECENT: usize = 4096;

/// One estimate: its instant, x̂ and √P_ii.
type Point = (u32, Vec<f64>, Vec<f64>);

/// The recent estimates of one estimator.
#[derive(Clone, Debug, Default)]
struct Latest {
    recent: std::collections::VecDeque<Point>,
    cov_kind: u32,
}

/// The reader's state between frames.
#[derive(Debug)]
struct Feed {
    names: Vec<String>,
    latest: Vec<Latest>,
    index: HashMap<[u8; 16], usize>,
    pending: Vec<InstantEvent>,
    max_points: usize,
    latency: Window,
    lat_by_k: HashMap<u32, f64>,
    totals: [[u64; 4]; MAX_NODES],
    frame_counts: [[u64; 4]; MAX_NODES],
    nodes: u8,
    nx: usize,
    instants: u64,
    last_instant: Option<Instant>,
    ended: bool,
    last_state: &'static str,
    /// Pages the server dropped for not keeping up (the hub's count), as last sent.
    pages_dropped: u64,
    last_pages_dropped: u64,
}

fn nonfinite_null(v: &[f64]) -> Value {
    Value::Array(
        v.iter()
            .map(|x| {
                serde_json::Number::from_f64(*x)
                    .map(Value::Number)
                    .unwrap_or(Value::Null)
            })
            .collect(),
    )
}

impl Feed {
    fn new(max_points: usize) -> Self {
        Self {
            max_points,
            names: Vec::new(),
            latest: Vec::new(),
            index: HashMap::new(),
            pending: Vec::new(),
            latency: Window::new(WINDOW),
            lat_by_k: HashMap::new(),
            totals: [[0; 4]; MAX_NODES],
            frame_counts: [[0; 4]; MAX_NODES],
            nodes: 0,
            nx: 0,
            instants: 0,
            last_instant: None,
            ended: false,
            last_state: "",
            pages_dropped: 0,
            last_pages_dropped: 0,
        }
    }

    /// One estimate, as published.
    fn estimate(&mut self, e: &EstimateEvent) {
        let nx = usize::from(e.nx).min(e.x.len());
        let e_idx = match self.index.get(&e.name) {
            Some(&i) => i,
            None => {
                if self.names.len() >= 64 {
                    return;
                }
                let name = String::from_utf8_lossy(&e.name)
                    .trim_end_matches('\0')
                    .to_string();
                self.names.push(name);
                self.latest.push(Latest::default());
                self.index.insert(e.name, self.names.len() - 1);
                self.names.len() - 1
            }
        };
        let l = &mut self.latest[e_idx];
        let sigma = e.var[..nx].iter().map(|v| v.sqrt()).collect();
        if l.recent.len() == RECENT {
            l.recent.pop_front();
        }
        l.recent.push_back((e.k, e.x[..nx].to_vec(), sigma));
        l.cov_kind = e.cov_kind;
        self.nx = self.nx.max(nx);
        if e.latency_us.is_finite() {
            let v = self.lat_by_k.entry(e.k).or_insert(0.0);
            *v = v.max(e.latency_us);
        }
    }

    /// One event of the loop (its instant's estimates were published before it was sent).
    fn event(&mut self, ev: ViewEvent) {
        match ev {
            ViewEvent::Instant(i) => {
                self.instants += 1;
                self.last_instant = Some(Instant::now());
                self.nodes = self.nodes.max(i.nodes);
                for n in 0..usize::from(i.nodes) {
                    let s = usize::from(i.status[n]);
                    self.totals[n][s] += 1;
                    self.frame_counts[n][s] += 1;
                }
                if let Some(us) = self.lat_by_k.remove(&i.k) {
                    self.latency.push(us);
                }
                // Latency entries of instants never handed on (a gap) do not pile up.
                if self.lat_by_k.len() > 4 * WINDOW {
                    self.lat_by_k.clear();
                }
                // Bounded: a view that cannot keep up thins (the loop never waits).
                if self.pending.len() < RECENT {
                    self.pending.push(i);
                }
            }
            ViewEvent::Estimate(e) => self.estimate(&e),
            ViewEvent::Late { node, .. } => {
                let n = usize::from(node).min(MAX_NODES - 1);
                self.totals[n][usize::from(LATE)] += 1;
                self.frame_counts[n][usize::from(LATE)] += 1;
            }
            ViewEvent::Ended => self.ended = true,
        }
    }

    fn state(&self, now: Instant) -> &'static str {
        if self.ended {
            "run ended"
        } else if self
            .last_instant
            .is_none_or(|t| now.duration_since(t) > IDLE)
        {
            "no publisher"
        } else {
            "running"
        }
    }

    /// The frame of the points since the last one, and whether it has points.
    fn frame(&mut self, now: Instant) -> Option<(String, bool)> {
        let state = self.state(now);
        if self.pending.is_empty()
            && state == self.last_state
            && self.pages_dropped == self.last_pages_dropped
        {
            return None;
        }
        self.last_state = state;
        self.last_pages_dropped = self.pages_dropped;
        let n = self.pending.len();
        let points: Vec<Value> = keep(n, self.max_points)
            .into_iter()
            .map(|i| {
                let ev = &self.pending[i];
                // The newest estimate of the instant (an estimate may come after its event
                // when the subscriber connected late: the service's history).
                let est: Vec<Option<&Point>> = self
                    .latest
                    .iter()
                    .map(|l| l.recent.iter().rev().find(|p| p.0 == ev.k))
                    .collect();
                let nx = self.nx;
                json!({
                    "session": ev.session,
                    "k": ev.k,
                    "truth": if ev.has_truth { nonfinite_null(&ev.truth[..nx.min(8)]) } else { Value::Null },
                    "est": est.iter().map(|e| match e {
                        Some((_, x, s)) => json!([nonfinite_null(x), nonfinite_null(s)]),
                        None => Value::Null,
                    }).collect::<Vec<_>>(),
                    "st": &ev.status[..usize::from(ev.nodes)],
                })
            })
            .collect();
        self.pending.clear();
        let (p50, p99, w) = self.latency.quantiles();
        let nodes = usize::from(self.nodes);
        let frame = json!({
            "state": state,
            "instants": self.instants,
            "decimated_from": n,
            "nx": self.nx,
            "nodes": nodes,
            "names": self.names,
            "cov_kind": self.latest.iter().map(|l| l.cov_kind).collect::<Vec<_>>(),
            "points": points,
            "frame_counts": &self.frame_counts[..nodes],
            "totals": &self.totals[..nodes],
            "pages_dropped": self.pages_dropped,
            "latency": {"p50_us": nonfinite_null(&[p50])[0], "p99_us": nonfinite_null(&[p99])[0], "window": w},
        });
        self.frame_counts = [[0; 4]; MAX_NODES];
        Some((frame.to_string(), n > 0))
    }
}

/// Reads `events` until the process ends, publishing frames to `hub`. Points per series and
/// second at most: `max_points_per_s` (docs/view.md, Decimation).
pub fn run(events: Receiver<ViewEvent>, hub: Arc<Hub>, max_points_per_s: u32) {
    let per_frame = (f64::from(max_points_per_s) * FRAME.as_secs_f64()).ceil() as usize;
    let mut feed = Feed::new(per_frame.max(1));
    let mut next_frame = Instant::now() + FRAME;
    let mut events_open = true;
    loop {
        let now = Instant::now();
        while events_open {
            match events.try_recv() {
                Ok(ev) => feed.event(ev),
                Err(TryRecvError::Empty) => break,
                Err(TryRecvError::Disconnected) => events_open = false,
            }
        }
        if now >= next_frame {
            next_frame = now + FRAME;
            feed.pages_dropped = hub.dropped.load(std::sync::atomic::Ordering::Relaxed);
            if let Some((f, has_points)) = feed.frame(now) {
                hub.publish(Arc::from(f), has_points);
            }
        }
        std::thread::sleep(Duration::from_millis(2));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::view::decimate::MAX_POINTS;
    use crate::view::tap::{DELIVERED, DROPPED};

    fn est(name: &str, k: u32, x0: f64, p00: f64) -> EstimateEvent {
        let mut e = EstimateEvent {
            k,
            name: estpipe_wire::Estimate::encode_name(name),
            nx: 2,
            x: [0.0; estpipe_wire::MAX_NX],
            var: [0.0; estpipe_wire::MAX_NX],
            cov_kind: 1,
            latency_us: f64::from(k),
        };
        e.x[0] = x0;
        e.var[0] = p00;
        e.var[1] = 9.0;
        e
    }

    fn instant(k: u32) -> ViewEvent {
        let mut status = [DELIVERED; MAX_NODES];
        status[1] = DROPPED;
        ViewEvent::Instant(InstantEvent {
            session: 1,
            k,
            nodes: 2,
            status,
            has_truth: true,
            truth: [f64::from(k); 8],
        })
    }

    /// Estimates joined with their instants, σ from the diagonal, counts per node, the
    /// latency window, thinning past MAX_POINTS and the states.
    #[test]
    fn frames_join_estimates_and_instants() {
        let mut f = Feed::new(MAX_POINTS);
        let now = Instant::now();
        assert!(f.frame(now).unwrap().0.contains("no publisher"));
        for k in 1..=3 {
            f.estimate(&est("kf", k, f64::from(k), 4.0));
            f.event(instant(k));
        }
        let (text, points) = f.frame(Instant::now()).unwrap();
        assert!(points);
        let v: Value = serde_json::from_str(&text).unwrap();
        assert_eq!(v["state"], "running");
        assert_eq!(v["names"], json!(["kf"]));
        assert_eq!(v["points"].as_array().unwrap().len(), 3);
        assert_eq!(v["points"][2]["est"][0], json!([[3.0, 0.0], [2.0, 3.0]]));
        assert_eq!(v["points"][2]["truth"], json!([3.0, 3.0]));
        assert_eq!(v["totals"], json!([[3, 0, 0, 0], [0, 3, 0, 0]]));
        assert_eq!(v["latency"]["p50_us"], 2.0);
        for k in 4..=53 {
            f.estimate(&est("kf", k, 0.0, 1.0));
            f.event(instant(k));
        }
        let v: Value = serde_json::from_str(&f.frame(Instant::now()).unwrap().0).unwrap();
        assert_eq!(v["points"].as_array().unwrap().len(), MAX_POINTS);
        assert_eq!(v["points"][MAX_POINTS - 1]["k"], 53);
        assert_eq!(v["decimated_from"], 50);
        assert_eq!(v["instants"], 53);
        f.event(ViewEvent::Ended);
        let v: Value = serde_json::from_str(&f.frame(Instant::now()).unwrap().0).unwrap();
        assert_eq!(v["state"], "run ended");
        assert!(f.frame(Instant::now()).is_none(), "nothing new, no frame");
        // A page dropped by the server is news of its own.
        f.pages_dropped = 1;
        let v: Value = serde_json::from_str(&f.frame(Instant::now()).unwrap().0).unwrap();
        assert_eq!(v["pages_dropped"], 1);
        assert!(f.frame(Instant::now()).is_none());
    }
}
