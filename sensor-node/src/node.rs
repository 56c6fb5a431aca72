//! The sensor node's state machine: what the firmware runs on every frame from its gateway.
//!
//! It decides each instant with estimator-core's sensor-side protocols, the same code the
//! simulator's channel stages run (`channel-sim/src/channel/`), in the same order: Tobit
//! censoring (seed 004 eq. 2, [`censor`]), then the schedule: seed 003's token bucket
//! (eqs. 2-3, [`TokenBucket`]) or seed 004's dynamic event trigger (eqs. 11-15,
//! [`EventTrigger`]) granted by the node's share of the shared bucket (eqs. 16-18,
//! [`share_covers`]), all in `f64` on entries padded to [`MAX_NY`] as the simulator pads them,
//! so that the decisions are the simulator's bit for bit.
//!
//! Hostile input is counted, never trusted: a frame that fails COBS, CRC or decoding is
//! counted in [`NodeStats::bad_frames`] and skipped without an answer (the gateway sends the
//! sample again); a message that decodes but cannot be run is answered with
//! [`FromNode::Refused`]. A sample sent again for the instant last decided gets the same
//! decision again, without stepping the protocol a second time.

use estimator_core::protocol::event_trigger::{EventTrigger, EventTriggerConfig};
use estimator_core::protocol::shared_token_bucket::share_covers;
use estimator_core::protocol::tobit::censor;
use estimator_core::protocol::token_bucket::{TokenBucket, TokenBucketConfig};
use nalgebra::SVector;

use crate::frame::{
    decode, encode, Decision, FromNode, NodeConfig, NodeStats, Refusal, Sample, Schedule, ToNode,
    LINK_VERSION, MAX_NY,
};

type Vector = SVector<f64, MAX_NY>;

/// Where [`SensorNode::handle`] is within a sample, for a caller that measures the parts
/// (the firmware's instruction-count marker); each carries the sample's k.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Phase {
    /// The frame is decoded (COBS, CRC, postcard) and is a sample.
    Decoded(u32),
    /// The protocol decided (or repeated) the instant.
    Decided(u32),
    /// The answer is encoded.
    Encoded(u32),
}

/// What to do after a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reply {
    /// Nothing to send (a corrupt frame, counted).
    Nothing,
    /// Send the first `n` bytes of the output buffer.
    Send(usize),
    /// The run is over: send [`SensorNode::finish`]'s frame and stop.
    Finish,
}

#[derive(Clone, Copy, Debug)]
enum Protocol {
    Always,
    Bucket(TokenBucket),
    Trigger {
        trigger: EventTrigger<f64, MAX_NY>,
        cost: u32,
        nodes: usize,
    },
}

#[derive(Clone, Copy, Debug)]
struct Configured {
    ny: usize,
    censor: Option<Vector>,
    protocol: Protocol,
}

/// A sensor node: its configuration once received, its protocol state, its last decision and
/// its counters. At most 256 bytes, no allocation.
#[derive(Clone, Copy, Debug, Default)]
pub struct SensorNode {
    cfg: Option<Configured>,
    last: Option<Decision>,
    stats: NodeStats,
}

impl SensorNode {
    /// A node waiting for its configuration.
    pub const fn new() -> Self {
        Self {
            cfg: None,
            last: None,
            stats: NodeStats {
                frames: 0,
                bad_frames: 0,
                decisions: 0,
                sent: 0,
                repeats: 0,
                refused: 0,
                stack_peak: 0,
            },
        }
    }

    /// The counters so far.
    pub fn stats(&self) -> &NodeStats {
        &self.stats
    }

    /// Counts a frame that never became one (the deframer's overlong bytes).
    pub fn count_bad_frame(&mut self) {
        self.stats.bad_frames = self.stats.bad_frames.saturating_add(1);
    }

    /// Handles one received frame (its bytes without the delimiter, decoded in place) and
    /// writes the answer, if any, into `out` ([`crate::frame::MAX_FRAME`] bytes suffice).
    pub fn handle(&mut self, frame: &mut [u8], out: &mut [u8], mut at: impl FnMut(Phase)) -> Reply {
        let msg = match decode::<ToNode>(frame) {
            Ok(m) => m,
            Err(_) => {
                self.count_bad_frame();
                return Reply::Nothing;
            }
        };
        self.stats.frames = self.stats.frames.saturating_add(1);
        let answer = match msg {
            ToNode::Finish => return Reply::Finish,
            ToNode::Configure(c) => match self.configure(&c) {
                Ok(()) => FromNode::Ready {
                    node: c.node,
                    version: LINK_VERSION,
                },
                Err(reason) => self.refuse(0, reason),
            },
            ToNode::Sample(s) => {
                at(Phase::Decoded(s.k));
                let a = match self.sample(&s) {
                    Ok(d) => FromNode::Decision(d),
                    Err(reason) => self.refuse(s.k, reason),
                };
                at(Phase::Decided(s.k));
                let n = encode(&a, out);
                at(Phase::Encoded(s.k));
                return n.map_or(Reply::Nothing, Reply::Send);
            }
        };
        encode(&answer, out).map_or(Reply::Nothing, Reply::Send)
    }

    /// The answer to [`ToNode::Finish`]: the counters with the measured `stack_peak`.
    pub fn finish(&mut self, stack_peak: u32, out: &mut [u8]) -> Option<usize> {
        self.stats.stack_peak = stack_peak;
        encode(&FromNode::Stats(self.stats), out)
    }

    fn refuse(&mut self, k: u32, reason: Refusal) -> FromNode {
        self.stats.refused = self.stats.refused.saturating_add(1);
        FromNode::Refused { k, reason }
    }

    fn configure(&mut self, c: &NodeConfig) -> Result<(), Refusal> {
        if c.version != LINK_VERSION {
            return Err(Refusal::Version);
        }
        if self.cfg.is_some() {
            return Err(Refusal::State);
        }
        let ny = usize::from(c.ny);
        if !(1..=MAX_NY).contains(&ny) {
            return Err(Refusal::Config);
        }
        let censor = match c.censor {
            Some(t) if t.iter().all(|v| v.is_finite()) => Some(Vector::from(t)),
            Some(_) => return Err(Refusal::Config),
            None => None,
        };
        let protocol = match c.schedule {
            Schedule::Always => Protocol::Always,
            Schedule::TokenBucket { a, b, s, z0 } => Protocol::Bucket(TokenBucket::new(
                TokenBucketConfig::new(a, b, s, z0).map_err(|_| Refusal::Config)?,
            )),
            Schedule::EventTrigger {
                sigma,
                chi,
                lambda,
                eta0,
                allow_paper_violation,
                reference,
                cost,
                nodes,
            } => {
                let cfg = if allow_paper_violation {
                    EventTriggerConfig::new_allowing_paper_violation(sigma, chi, lambda, eta0)
                } else {
                    EventTriggerConfig::new(sigma, chi, lambda, eta0)
                }
                .map_err(|_| Refusal::Config)?;
                if nodes == 0 || c.node >= nodes {
                    return Err(Refusal::Config);
                }
                Protocol::Trigger {
                    trigger: EventTrigger::new(cfg, Vector::from(reference))
                        .map_err(|_| Refusal::Config)?,
                    cost,
                    nodes: usize::from(nodes),
                }
            }
        };
        self.cfg = Some(Configured {
            ny,
            censor,
            protocol,
        });
        Ok(())
    }

    fn sample(&mut self, s: &Sample) -> Result<Decision, Refusal> {
        let Some(cfg) = self.cfg.as_mut() else {
            return Err(Refusal::State);
        };
        match self.last {
            Some(d) if d.k == s.k => {
                self.stats.repeats = self.stats.repeats.saturating_add(1);
                return Ok(d);
            }
            Some(d) if d.k.checked_add(1) != Some(s.k) => return Err(Refusal::OutOfOrder),
            _ => {}
        }
        let d = decide(cfg, s)?;
        self.last = Some(d);
        self.stats.decisions = self.stats.decisions.saturating_add(1);
        self.stats.sent = self.stats.sent.saturating_add(u32::from(d.sent));
        Ok(d)
    }
}

/// One instant, in the simulator's stage order: censor, then schedule. Nothing changes on
/// error.
fn decide(cfg: &mut Configured, s: &Sample) -> Result<Decision, Refusal> {
    let mut z = Vector::from(s.z);
    // The simulator's observations are zero past ny, whatever a gateway sends there.
    z.as_mut_slice()[cfg.ny..].fill(0.0);
    let (mut y, censored) = match &cfg.censor {
        Some(tau) => {
            let (y, observed) = censor(&z, tau).map_err(|_| Refusal::Sample)?;
            (y, observed[..cfg.ny].iter().any(|&o| !o))
        }
        None => {
            if z.iter().any(|v| !v.is_finite()) {
                return Err(Refusal::Sample);
            }
            (z, false)
        }
    };
    y.as_mut_slice()[cfg.ny..].fill(0.0);
    let (sent, triggered, blocked) = match &mut cfg.protocol {
        Protocol::Always => (true, false, false),
        Protocol::Bucket(b) => {
            let t = b.step().transmit;
            (t, false, !t)
        }
        Protocol::Trigger {
            trigger,
            cost,
            nodes,
        } => {
            let granted = share_covers(s.level, *nodes, *cost);
            let o = trigger.step(&y, granted).map_err(|_| Refusal::Sample)?;
            (o.sent, o.triggered, o.triggered && !granted)
        }
    };
    Ok(Decision {
        k: s.k,
        sent,
        triggered,
        blocked,
        censored,
        y: if sent { y.into() } else { [0.0; MAX_NY] },
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::MAX_FRAME;

    fn frame_of(m: &ToNode) -> ([u8; MAX_FRAME], usize) {
        let mut b = [0u8; MAX_FRAME];
        let n = encode(m, &mut b).unwrap();
        (b, n - 1)
    }

    fn ask(node: &mut SensorNode, m: &ToNode) -> Option<FromNode> {
        let (mut f, n) = frame_of(m);
        let mut out = [0u8; MAX_FRAME];
        match node.handle(&mut f[..n], &mut out, |_| {}) {
            Reply::Send(len) => Some(decode(&mut out[..len - 1]).unwrap()),
            Reply::Nothing => None,
            Reply::Finish => Some(FromNode::Stats(*node.stats())),
        }
    }

    fn bucket_config() -> ToNode {
        ToNode::Configure(NodeConfig {
            version: LINK_VERSION,
            node: 0,
            ny: 2,
            censor: None,
            schedule: Schedule::TokenBucket {
                a: 2,
                b: 3,
                s: 10,
                z0: 6,
            },
        })
    }

    fn sample(k: u32) -> ToNode {
        ToNode::Sample(Sample {
            k,
            z: [k as f64, -1.0, 0.0, 0.0],
            level: 0,
        })
    }

    #[test]
    fn token_bucket_node_follows_the_papers_pattern_and_repeats_without_stepping() {
        let mut node = SensorNode::new();
        assert_eq!(
            ask(&mut node, &sample(0)),
            Some(FromNode::Refused {
                k: 0,
                reason: Refusal::State
            })
        );
        assert_eq!(
            ask(&mut node, &bucket_config()),
            Some(FromNode::Ready {
                node: 0,
                version: LINK_VERSION
            })
        );
        // Seed 003's pattern from k = 0 (estimator-core's token_bucket tests by hand).
        let want = [true, true, true, true, true, true, false, true, true, false];
        for (k, &w) in want.iter().enumerate() {
            let Some(FromNode::Decision(d)) = ask(&mut node, &sample(k as u32)) else {
                panic!("k = {k}");
            };
            assert_eq!((d.k, d.sent, d.blocked), (k as u32, w, !w));
            assert_eq!(d.y[0], if w { k as f64 } else { 0.0 });
            // The same sample again: the same answer, the bucket not stepped.
            assert_eq!(
                ask(&mut node, &sample(k as u32)),
                Some(FromNode::Decision(d))
            );
        }
        assert_eq!(
            ask(&mut node, &sample(12)),
            Some(FromNode::Refused {
                k: 12,
                reason: Refusal::OutOfOrder
            })
        );
        let s = *node.stats();
        assert_eq!((s.decisions, s.sent, s.repeats, s.refused), (10, 8, 10, 2));
    }

    #[test]
    fn corrupt_frames_are_counted_and_skipped() {
        let mut node = SensorNode::new();
        let _ = ask(&mut node, &bucket_config());
        let (mut f, n) = frame_of(&sample(0));
        f[n / 2] ^= 0x10;
        let mut out = [0u8; MAX_FRAME];
        assert_eq!(node.handle(&mut f[..n], &mut out, |_| {}), Reply::Nothing);
        // Truncated: the first half of a frame.
        let (mut f, n) = frame_of(&sample(0));
        assert_eq!(
            node.handle(&mut f[..n / 2], &mut out, |_| {}),
            Reply::Nothing
        );
        assert_eq!(node.stats().bad_frames, 2);
        // The protocol did not move: k = 0 is still the first decision.
        assert!(matches!(
            ask(&mut node, &sample(0)),
            Some(FromNode::Decision(Decision {
                k: 0,
                sent: true,
                ..
            }))
        ));
    }

    #[test]
    fn bad_configurations_are_refused_by_name() {
        let refused = |c: NodeConfig| {
            let mut node = SensorNode::new();
            match ask(&mut node, &ToNode::Configure(c)) {
                Some(FromNode::Refused { reason, .. }) => reason,
                other => panic!("{other:?}"),
            }
        };
        let ToNode::Configure(good) = bucket_config() else {
            unreachable!()
        };
        assert_eq!(refused(NodeConfig { version: 9, ..good }), Refusal::Version);
        assert_eq!(refused(NodeConfig { ny: 5, ..good }), Refusal::Config);
        assert_eq!(
            refused(NodeConfig {
                schedule: Schedule::TokenBucket {
                    a: 4,
                    b: 3,
                    s: 10,
                    z0: 0
                },
                ..good
            }),
            Refusal::Config
        );
        assert_eq!(
            refused(NodeConfig {
                censor: Some([f64::NAN; MAX_NY]),
                ..good
            }),
            Refusal::Config
        );
        // λχ = 0.5 without the opt-in.
        let trig = |allow| Schedule::EventTrigger {
            sigma: 0.1,
            chi: 5.0,
            lambda: 0.1,
            eta0: 1.5,
            allow_paper_violation: allow,
            reference: [0.0; MAX_NY],
            cost: 3,
            nodes: 3,
        };
        assert_eq!(
            refused(NodeConfig {
                schedule: trig(false),
                ..good
            }),
            Refusal::Config
        );
        let mut node = SensorNode::new();
        let c = NodeConfig {
            schedule: trig(true),
            ..good
        };
        assert!(matches!(
            ask(&mut node, &ToNode::Configure(c)),
            Some(FromNode::Ready { .. })
        ));
        assert_eq!(
            ask(&mut node, &ToNode::Configure(c)),
            Some(FromNode::Refused {
                k: 0,
                reason: Refusal::State
            })
        );
    }

    #[test]
    fn the_node_state_is_small() {
        // docs/sensor-node.md: "a fixed 256 bytes at most" (on the host, usize is 8 bytes).
        assert!(size_of::<SensorNode>() <= 256);
    }

    #[test]
    fn triggered_node_uses_its_share_of_the_level() {
        // σ = 0, η₀ = 0: the trigger fires whenever y moves; 3 nodes, c = 3: a grant needs
        // ξ ≥ 9 (eq. 18 as L c ≤ ξ).
        let mut node = SensorNode::new();
        let c = NodeConfig {
            version: LINK_VERSION,
            node: 1,
            ny: 2,
            censor: Some([0.0, 0.0, -f64::MAX, -f64::MAX]),
            schedule: Schedule::EventTrigger {
                sigma: 0.0,
                chi: 5.0,
                lambda: 0.5,
                eta0: 0.0,
                allow_paper_violation: true,
                reference: [0.0, 0.0, -f64::MAX, -f64::MAX],
                cost: 3,
                nodes: 3,
            },
        };
        let _ = ask(&mut node, &ToNode::Configure(c));
        let s = |k, z: [f64; 2], level| {
            ToNode::Sample(Sample {
                k,
                z: [z[0], z[1], 0.0, 0.0],
                level,
            })
        };
        let Some(FromNode::Decision(d)) = ask(&mut node, &s(1, [1.0, -2.0], 9)) else {
            panic!()
        };
        // Censored at τ = 0 and sent with the grant.
        assert!(d.sent && d.triggered && !d.blocked && d.censored);
        assert_eq!(d.y, [1.0, 0.0, 0.0, 0.0]);
        let Some(FromNode::Decision(d)) = ask(&mut node, &s(2, [3.0, 1.0], 8)) else {
            panic!()
        };
        assert!(!d.sent && d.triggered && d.blocked && !d.censored);
        assert_eq!(d.y, [0.0; MAX_NY]);
    }
}
