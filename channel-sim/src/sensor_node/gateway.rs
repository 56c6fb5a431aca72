//! [`NodeLoop`]: the simulation whose channel is a set of sensor nodes on serial links.
//!
//! Every instant it runs the scenario's plant with the seed's random numbers, as channel-sim
//! does, sends each node its raw sample z_{m,k} (and, for seed 004, the shared bucket's level
//! ξ_k), and waits for the nodes' decisions. Each answer is checked against the contract
//! before it becomes the instant's observation: a frame that fails COBS, CRC or decoding is
//! counted and skipped, and the sample sent again (the node repeats its decision without
//! stepping its protocol); a decision for another instant is counted as stale and skipped; a
//! decision that breaks the protocol (sent without its share of the bucket, a measurement
//! that is not finite or not zero when withheld) is counted and not forwarded, its slot is
//! then lost. After all nodes answered, the shared bucket is updated (eq. 17) with what they
//! sent.
//!
//! Beside it the same instant runs through channel-sim's own channel stages, and every node
//! decision is compared with the simulator's (delivered, flags, the measurement's bits): the
//! count of equal and differing decisions is the loop's first figure.

use std::time::{Duration, Instant as Clock};

use estimator_core::protocol::shared_token_bucket::share_covers;
use estpipe_sensor_node::{
    decode, encode, Decision, FromNode, NodeStats, Sample, ToNode, MAX_FRAME, MAX_NY,
};

use super::config::{loop_config, Bucket};
use super::link::{Endpoint, Link, Received};
use crate::scenario::composed::ComposedSimulation;
use crate::sim::{
    Instant, Observation, Scenario, Simulation, FLAG_CENSORED, FLAG_TOKEN_BLOCKED, FLAG_TRIGGERED,
    MAX_NX,
};

/// Times a sample is sent again before the node is given up.
pub const RETRIES: u32 = 5;

/// The loop's counters.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LoopReport {
    /// Node decisions compared with channel-sim's (instant 0 included where the plant
    /// measures then).
    pub compared: u64,
    /// Of those, equal in delivery, flags and the measurement's bits.
    pub equal: u64,
    /// The first differences, one line each (at most 5).
    pub differences: Vec<String>,
    /// Frames that failed COBS, CRC or decoding, or were longer than a frame.
    pub corrupt: u64,
    /// Valid decisions for another instant than the one awaited.
    pub stale: u64,
    /// Waits for an answer that ended at the deadline.
    pub timeouts: u64,
    /// Samples sent again.
    pub resent: u64,
    /// Decisions that broke the protocol, not forwarded.
    pub refused: u64,
    /// Decisions forwarded, and of those transmitted.
    pub forwarded: u64,
    /// Forwarded decisions that carried a measurement.
    pub sent: u64,
    /// Every node's own counters (after [`NodeLoop::finish`]).
    pub nodes: Vec<Option<NodeStats>>,
}

impl LoopReport {
    /// The report as the gateway prints it, one line for the loop and one per node.
    pub fn lines(&self) -> Vec<String> {
        let mut v = vec![format!(
            "sensor nodes: decisions equal to channel-sim's: {} of {} ({} differ); {} \
             forwarded ({} sent); link: {} corrupt frame(s) skipped, {} stale, {} timeout(s), \
             {} sample(s) resent, {} decision(s) refused",
            self.equal,
            self.compared,
            self.compared - self.equal,
            self.forwarded,
            self.sent,
            self.corrupt,
            self.stale,
            self.timeouts,
            self.resent,
            self.refused
        )];
        v.extend(self.differences.iter().map(|d| format!("  differs: {d}")));
        for (m, s) in self.nodes.iter().enumerate() {
            v.push(match s {
                Some(s) => format!(
                    "node {m}: {} frames, {} bad frame(s), {} decisions ({} sent), {} \
                     repeated, {} refused, stack peak {} B",
                    s.frames, s.bad_frames, s.decisions, s.sent, s.repeats, s.refused, s.stack_peak
                ),
                None => format!("node {m}: no figures (it did not answer Finish)"),
            });
        }
        v
    }
}

/// The plant of a scenario with sensor nodes for its channel.
pub struct NodeLoop {
    sim: ComposedSimulation,
    links: Vec<Link>,
    ny: Vec<u8>,
    costs: Vec<u32>,
    bucket: Option<Box<dyn Bucket>>,
    timeout: Duration,
    report: LoopReport,
    failure: Option<String>,
}

impl std::fmt::Debug for NodeLoop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("NodeLoop")
            .field("links", &self.links)
            .field("report", &self.report)
            .finish_non_exhaustive()
    }
}

fn flags_of(d: &Decision) -> u32 {
    let mut f = 0;
    if d.triggered {
        f |= FLAG_TRIGGERED;
    }
    if d.blocked {
        f |= FLAG_TOKEN_BLOCKED;
    }
    if d.censored {
        f |= FLAG_CENSORED;
    }
    f
}

impl NodeLoop {
    /// Connects to every node (`endpoints[m]` is node m's line, waiting up to `connect` for
    /// it), configures it from the scenario's channel stages, and starts run `(seed, run)`;
    /// a plant that measures at k = 0 (seed 003) has its instant 0 decided by the nodes
    /// too (compared, not published: the stream starts at k = 1). `stop` cuts the wait for a
    /// line short (the publisher's stop signal).
    pub fn start(
        scenario: &dyn Scenario,
        seed: u64,
        run: u64,
        endpoints: &[Endpoint],
        connect: Duration,
        timeout: Duration,
        stop: &dyn Fn() -> bool,
    ) -> Result<Self, String> {
        let cfg = loop_config(scenario)?;
        if endpoints.len() != cfg.nodes.len() {
            return Err(format!(
                "scenario {} has {} node(s), {} --sensor-node line(s) given",
                scenario.name(),
                cfg.nodes.len(),
                endpoints.len()
            ));
        }
        let sim = scenario
            .as_any()
            .downcast_ref::<crate::scenario::composed::ComposedScenario>()
            .ok_or("not a composed scenario")?
            .simulate(seed, run);
        let give_up = Clock::now() + connect;
        let links = endpoints
            .iter()
            .map(|e| Link::connect(e, give_up, stop))
            .collect::<Result<Vec<_>, _>>()?;
        let mut lp = Self {
            sim,
            links,
            ny: cfg.nodes.iter().map(|c| c.ny).collect(),
            costs: cfg.costs,
            bucket: cfg.bucket,
            timeout,
            report: LoopReport {
                nodes: vec![None; cfg.nodes.len()],
                ..LoopReport::default()
            },
            failure: None,
        };
        for (m, c) in cfg.nodes.iter().enumerate() {
            // The node may take a moment to boot: the first answer gets the connect time.
            match lp.ask(m, &ToNode::Configure(*c), connect.max(timeout), |a| {
                matches!(a, FromNode::Ready { .. } | FromNode::Refused { .. })
            })? {
                FromNode::Ready { node, .. } if usize::from(node) == m => {}
                other => {
                    return Err(format!(
                        "{}: node {m} refused its configuration: {other:?}",
                        lp.links[m].endpoint()
                    ))
                }
            }
        }
        let first = lp.sim.initial_observations().map(<[Observation]>::to_vec);
        if let Some(reference) = first {
            let raw = lp.sim.raw_observations().map(<[Observation]>::to_vec);
            if let Some(raw) = raw {
                lp.exchange(0, &raw, &reference)?;
            }
        }
        Ok(lp)
    }

    /// The counters so far.
    pub fn report(&self) -> &LoopReport {
        &self.report
    }

    /// Why the loop cannot go on (a node gave no valid answer after [`RETRIES`] tries, or
    /// closed its line); the instant that failed carries no observation.
    pub fn failure(&self) -> Option<&str> {
        self.failure.as_deref()
    }

    /// Ends every node's run and collects its own figures (best effort, one timeout each).
    pub fn finish(&mut self) {
        for m in 0..self.links.len() {
            if let Ok(FromNode::Stats(s)) = self.ask(m, &ToNode::Finish, self.timeout, |a| {
                matches!(a, FromNode::Stats(_))
            }) {
                self.report.nodes[m] = Some(s);
            }
        }
    }

    /// Sends `msg` to node `m` and waits for an answer `wanted` accepts, sending again after
    /// a corrupt frame or a timeout, [`RETRIES`] times at most.
    fn ask(
        &mut self,
        m: usize,
        msg: &ToNode,
        timeout: Duration,
        wanted: impl Fn(&FromNode) -> bool,
    ) -> Result<FromNode, String> {
        self.tell(m, msg)?;
        self.answer(m, msg, timeout, wanted)
    }

    /// Sends `msg` to node `m`.
    fn tell(&mut self, m: usize, msg: &ToNode) -> Result<(), String> {
        let mut frame = [0u8; MAX_FRAME];
        let n = encode(msg, &mut frame).ok_or("a message longer than a frame")?;
        self.links[m].send(&frame[..n])
    }

    /// Waits for node `m`'s answer to `msg` (already sent once) that `wanted` accepts, sending
    /// `msg` again after a corrupt frame or a timeout, [`RETRIES`] times at most.
    fn answer(
        &mut self,
        m: usize,
        msg: &ToNode,
        timeout: Duration,
        wanted: impl Fn(&FromNode) -> bool,
    ) -> Result<FromNode, String> {
        for attempt in 0..=RETRIES {
            if attempt > 0 {
                self.report.resent += 1;
                self.tell(m, msg)?;
            }
            let deadline = Clock::now() + timeout;
            loop {
                match self.links[m].receive(deadline)? {
                    Received::Timeout => {
                        self.report.timeouts += 1;
                        break;
                    }
                    Received::Overlong => {
                        self.report.corrupt += 1;
                        break;
                    }
                    Received::Frame(mut f) => match decode::<FromNode>(&mut f) {
                        Err(_) => {
                            self.report.corrupt += 1;
                            break;
                        }
                        Ok(a) if wanted(&a) => return Ok(a),
                        Ok(_) => self.report.stale += 1,
                    },
                }
            }
        }
        Err(format!(
            "{}: node {m} gave no valid answer to {msg:?} in {} tries",
            self.links[m].endpoint(),
            RETRIES + 1
        ))
    }

    /// One instant with every node: samples out, decisions in, checked, compared with
    /// `reference` (channel-sim's observations), the bucket updated. The observations to
    /// publish (a refused decision has none).
    fn exchange(
        &mut self,
        k: u32,
        raw: &[Observation],
        reference: &[Observation],
    ) -> Result<Vec<Observation>, String> {
        let level = self.bucket.as_ref().map_or(0, |b| b.level());
        let nodes = self.links.len();
        let mut sent = vec![false; nodes];
        let mut out = Vec::with_capacity(nodes);
        let sample = |m: usize| {
            ToNode::Sample(Sample {
                k,
                z: raw[m].y,
                level,
            })
        };
        // Every node gets its sample before any answer is awaited: the nodes decide at once.
        for m in 0..nodes {
            self.tell(m, &sample(m))?;
        }
        for m in 0..nodes {
            let answer = self.answer(m, &sample(m), self.timeout, |a| {
                matches!(a, FromNode::Decision(d) if d.k == k)
                    || matches!(a, FromNode::Refused { k: rk, .. } if *rk == k)
            })?;
            let d = match answer {
                FromNode::Decision(d) => d,
                other => {
                    return Err(format!(
                        "{}: node {m} refused the sample of instant {k}: {other:?}",
                        self.links[m].endpoint()
                    ))
                }
            };
            if let Err(why) = self.check(m, &d, level) {
                self.report.refused += 1;
                if self.report.differences.len() < 5 {
                    self.report
                        .differences
                        .push(format!("k = {k}, node {m}: refused: {why}"));
                }
                continue;
            }
            sent[m] = d.sent;
            let obs = Observation {
                k,
                node: m as u8,
                delivered: d.sent,
                ny: self.ny[m],
                y: d.y,
                flags: flags_of(&d),
                // A grant of the shared bucket used ξ_{t−1}, the level the gateway sent with
                // the sample: the receiver's bucket mirror resynchronises on it (docs/wire.md,
                // "The bucket level on a delivered packet").
                tokens: (d.sent && self.bucket.is_some()).then_some(level),
            };
            self.compare(&obs, reference.get(m));
            self.report.forwarded += 1;
            self.report.sent += u64::from(d.sent);
            out.push(obs);
        }
        if let Some(b) = self.bucket.as_mut() {
            b.update(&sent)
                .map_err(|e| format!("shared bucket at instant {k}: {e}"))?;
        }
        Ok(out)
    }

    /// The contract a decision keeps: a finite measurement zero past ny when sent, all zero
    /// when withheld, never sent and blocked at once, and for the shared bucket sent only
    /// with the node's share (eq. 18) and blocked exactly when fired without it.
    fn check(&self, m: usize, d: &Decision, level: u32) -> Result<(), &'static str> {
        let ny = usize::from(self.ny[m]);
        if d.sent {
            if d.y.iter().any(|v| !v.is_finite()) {
                return Err("a measurement that is not finite");
            }
            if d.y[ny..MAX_NY].iter().any(|&v| v != 0.0) {
                return Err("entries past ny");
            }
            if d.blocked {
                return Err("sent and blocked");
            }
        } else if d.y.iter().any(|&v| v != 0.0) {
            return Err("a measurement with a withheld packet");
        }
        if self.bucket.is_some() {
            let granted = share_covers(level, self.links.len(), self.costs[m]);
            if d.sent && !(granted && d.triggered) {
                return Err("sent without firing or without its share of the bucket");
            }
            if d.blocked != (d.triggered && !granted) {
                return Err("blocked does not match its share of the bucket");
            }
        } else if d.triggered {
            return Err("a trigger without an event trigger");
        }
        Ok(())
    }

    fn compare(&mut self, obs: &Observation, reference: Option<&Observation>) {
        self.report.compared += 1;
        let same = reference.is_some_and(|r| {
            r.k == obs.k
                && r.delivered == obs.delivered
                && r.flags == obs.flags
                && r.tokens == obs.tokens
                && r.y
                    .iter()
                    .zip(&obs.y)
                    .all(|(a, b)| a.to_bits() == b.to_bits())
        });
        if same {
            self.report.equal += 1;
        } else if self.report.differences.len() < 5 {
            self.report.differences.push(format!(
                "k = {}, node {}: the node's {:?} / channel-sim's {:?}",
                obs.k, obs.node, obs, reference
            ));
        }
    }
}

impl Simulation for NodeLoop {
    fn initial_truth(&self) -> [f64; MAX_NX] {
        self.sim.initial_truth()
    }

    fn initial_observations(&self) -> Option<&[Observation]> {
        self.sim.initial_observations()
    }

    fn next_instant(&mut self) -> Instant {
        let reference = self.sim.next_instant();
        let mut inst = Instant {
            k: reference.k,
            truth: reference.truth,
            obs: heapless::Vec::new(),
        };
        if self.failure.is_some() {
            return inst;
        }
        let raw = self
            .sim
            .raw_observations()
            .map(<[Observation]>::to_vec)
            .unwrap_or_default();
        match self.exchange(reference.k, &raw, &reference.obs) {
            Ok(obs) => inst.obs = obs.into_iter().collect(),
            Err(e) => self.failure = Some(e),
        }
        inst
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::preset;
    use estpipe_sensor_node::{Deframer, Push, Reply, SensorNode};
    use std::io::{Read, Write};
    use std::os::unix::net::UnixListener;
    use std::path::PathBuf;

    /// A node of `estpipe_sensor_node`'s state machine on a thread, listening at `path` (as
    /// QEMU does), whose decisions pass through `lie` before they are sent.
    fn software_node(path: PathBuf, lie: fn(&mut Decision)) -> std::thread::JoinHandle<()> {
        let _ = std::fs::remove_file(&path);
        let listener = UnixListener::bind(&path).unwrap();
        std::thread::spawn(move || {
            let (mut s, _) = listener.accept().unwrap();
            let mut node = SensorNode::new();
            let mut deframer = Deframer::new();
            let mut out = [0u8; MAX_FRAME];
            let mut buf = [0u8; 256];
            while let Ok(n) = s.read(&mut buf) {
                if n == 0 {
                    return;
                }
                for &b in &buf[..n] {
                    let Push::Frame(f) = deframer.push(b) else {
                        continue;
                    };
                    match node.handle(f, &mut out, |_| {}) {
                        Reply::Nothing => {}
                        Reply::Send(len) => {
                            let mut a: FromNode = decode(&mut out[..len - 1]).unwrap();
                            if let FromNode::Decision(d) = &mut a {
                                lie(d);
                            }
                            let len = encode(&a, &mut out).unwrap();
                            s.write_all(&out[..len]).unwrap();
                        }
                        Reply::Finish => {
                            let len = node.finish(0, &mut out).unwrap();
                            let _ = s.write_all(&out[..len]);
                            return;
                        }
                    }
                }
            }
        })
    }

    fn sock(name: &str, m: usize) -> PathBuf {
        std::env::temp_dir().join(format!("cs-node-{}-{name}-{m}.sock", std::process::id()))
    }

    /// Runs `steps` instants of `scenario` (seed 11) with software nodes, node 0 lying.
    fn run(name: &str, scenario: &str, steps: u32, lie: fn(&mut Decision)) -> (LoopReport, u64) {
        let sc = preset(scenario).unwrap();
        let n = sc.nodes();
        let threads: Vec<_> = (0..n)
            .map(|m| software_node(sock(name, m), if m == 0 { lie } else { |_| {} }))
            .collect();
        let endpoints: Vec<_> = (0..n).map(|m| Endpoint::Unix(sock(name, m))).collect();
        let s = Duration::from_secs(5);
        let mut lp = NodeLoop::start(&*sc, 11, 0, &endpoints, s, s, &|| false).unwrap();
        let mut slots = 0;
        for _ in 0..steps {
            slots += lp.next_instant().obs.len() as u64;
            assert!(lp.failure().is_none(), "{:?}", lp.failure());
        }
        lp.finish();
        for t in threads {
            t.join().unwrap();
        }
        for m in 0..n {
            let _ = std::fs::remove_file(sock(name, m));
        }
        (lp.report().clone(), slots)
    }

    #[test]
    fn software_nodes_decide_as_channel_sim() {
        let (r, slots) = run("same", "tobit-fusion", 300, |_| {});
        assert_eq!((r.compared, r.equal, r.refused, slots), (900, 900, 0, 900));
        assert_eq!((r.corrupt, r.stale, r.timeouts, r.resent), (0, 0, 0, 0));
        let sent: u32 = r.nodes.iter().map(|s| s.unwrap().sent).sum();
        assert_eq!(u64::from(sent), r.sent);
    }

    #[test]
    fn a_node_that_sends_without_its_share_is_refused_not_forwarded() {
        // Node 0 claims to have sent whenever it was blocked: the gateway's eq. (18) check
        // refuses exactly those; the bucket is updated without them, so every other decision
        // is still channel-sim's.
        let (r, slots) = run("lie", "tobit-fusion", 300, |d| {
            if d.blocked {
                d.sent = true;
                d.blocked = false;
                d.y = [1.0, 1.0, 0.0, 0.0];
            }
        });
        let sc = preset("tobit-fusion").unwrap();
        let mut sim = sc.start(11, 0);
        let blocked = (0..300)
            .filter(|_| sim.next_instant().obs[0].flags & FLAG_TOKEN_BLOCKED != 0)
            .count() as u64;
        assert!(blocked > 0);
        assert_eq!(r.refused, blocked, "{r:?}");
        assert_eq!((r.compared, r.equal), (900 - blocked, 900 - blocked));
        assert_eq!(slots, 900 - blocked);
    }

    #[test]
    fn the_wrong_number_of_lines_is_refused_before_connecting() {
        let sc = preset("tobit-fusion").unwrap();
        let e = NodeLoop::start(
            &*sc,
            0,
            0,
            &[Endpoint::Unix("/nonexistent".into())],
            Duration::ZERO,
            Duration::from_secs(1),
            &|| false,
        )
        .unwrap_err();
        assert!(e.contains("3 node(s), 1 --sensor-node line(s)"), "{e}");
    }
}
