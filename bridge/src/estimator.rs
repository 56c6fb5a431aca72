//! The estimator side: slots and truth from zenoh are checked, then written into shared
//! memory for the runner; the runner's estimates go back.
//!
//! Nothing reaches shared memory before `estpipe_wire::net`'s checks passed; the stream
//! header must also stay the same within a stream. What fails is counted by reason and
//! dropped. Sequence gaps become lost slots ([`crate::sequence`]).

use crate::args::BridgeArgs;
use crate::report::{BridgeReport, Stage};
use crate::sensor::LINGER;
use crate::sequence::{lost_slot, Arrival, Sequence};
use crate::session::{close_within, CLOSE_WAIT};
use crate::stop::Stop;
use anyhow::{anyhow, bail, Result};
use estpipe_wire::{self as wire, net, Slot, StreamHeader, Truth, SLOT_DATA};
use iceoryx2::port::{BackpressureAction, BackpressureInfo};
use iceoryx2::prelude::*;
use std::time::{Duration, Instant};
use zenoh::handlers::FifoChannel;
use zenoh::qos::CongestionControl;
use zenoh::Wait;

/// Longest a send into a full runner queue waits before the slot is dropped (counted): a
/// frozen runner must not freeze the bridge, and SIGINT must still end it.
const SEND_LIMIT: Duration = Duration::from_secs(1);

/// Slots handled per pass before the estimates and the signal are looked at again.
const BURST: usize = 256;

/// Runs the estimator side.
pub fn run(args: &BridgeArgs) -> Result<BridgeReport> {
    let stop = Stop::new(args.parent_pid);
    let key = args.key();
    let mut report = BridgeReport {
        side: Some(args.side),
        key: key.clone(),
        ..Default::default()
    };
    let node = estpipe_process::node::create(crate::NODE_NAME)?;
    let _ = node.try_cleanup_dead_nodes();
    let slots = wire::slot_service(&node, &args.prefix)?;
    let truth = wire::truth_service(&node, &args.prefix)?;
    let estimates = wire::estimate_service(&node, &args.prefix)?;
    let ready = wire::ready_event_service(&node, &args.prefix)?;
    let handler_stop = stop.clone();
    let slot_pub = slots
        .publisher_builder()
        .backpressure_strategy(BackpressureStrategy::RetryUntilDelivered)
        .set_backpressure_handler(move |info: &BackpressureInfo| {
            if handler_stop.requested() || info.elapsed_time >= SEND_LIMIT {
                BackpressureAction::DiscardDataAndFail
            } else {
                BackpressureAction::Retry
            }
        })
        .create()
        .map_err(|e| {
            anyhow!(
                "cannot publish on {}/slots ({e:?}): is a publisher or another bridge using this \
                 --prefix?",
                args.prefix
            )
        })?;
    let truth_pub = truth
        .publisher_builder()
        .create()
        .map_err(|e| anyhow!("cannot publish on {}/truth: {e:?}", args.prefix))?;
    let notifier = ready
        .notifier_builder()
        .default_event_id(wire::READY_EVENT)
        .create()
        .map_err(|e| anyhow!("cannot notify on {}/slots-ready: {e:?}", args.prefix))?;

    if !args.quiet {
        estpipe_process::errln!(
            "bridge: estimator side of {}: waiting for a runner",
            args.prefix
        );
    }
    let started = Instant::now();
    let mut last_cleanup = Instant::now();
    while slots.dynamic_config().number_of_subscribers() == 0 {
        if stop.requested() {
            report.ending = "interrupted before a runner came".into();
            return Ok(report);
        }
        if args.connect_timeout > 0.0 && started.elapsed().as_secs_f64() > args.connect_timeout {
            bail!(
                "no runner subscribed to {}/slots within --connect-timeout {} s",
                args.prefix,
                args.connect_timeout
            );
        }
        if last_cleanup.elapsed() > Duration::from_millis(100) {
            let _ = node.try_cleanup_dead_nodes();
            last_cleanup = Instant::now();
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    let est_sub = estimates
        .subscriber_builder()
        .buffer_size(wire::MAX_SUBSCRIBER_BUFFER)
        .create()
        .map_err(|e| anyhow!("cannot subscribe to {}/estimates: {e:?}", args.prefix))?;

    let session = zenoh::open(args.zenoh_config()?)
        .wait()
        .map_err(|e| anyhow!("cannot open the zenoh session: {e}"))?;
    let z_est = session
        .declare_publisher(format!("{key}/estimates"))
        .congestion_control(CongestionControl::Drop)
        .express(true)
        .wait()
        .map_err(|e| anyhow!("zenoh publisher {key}/estimates: {e}"))?;
    // Each marker taken (or seen again) is echoed here: the sensor side repeats it until then.
    let z_acks = session
        .declare_publisher(format!("{key}/acks"))
        .congestion_control(CongestionControl::Drop)
        .express(true)
        .wait()
        .map_err(|e| anyhow!("zenoh publisher {key}/acks: {e}"))?;
    let z_alive = session
        .liveliness()
        .declare_subscriber(format!("{key}/alive/sensor"))
        // A sensor side that came first is reported too, so that its end is always seen.
        .history(true)
        .with(FifoChannel::new(64))
        .wait()
        .map_err(|e| anyhow!("zenoh liveliness {key}/alive/sensor: {e}"))?;
    let z_slots = session
        .declare_subscriber(format!("{key}/slots"))
        .with(FifoChannel::new(args.queue))
        .wait()
        .map_err(|e| anyhow!("zenoh subscriber {key}/slots: {e}"))?;
    if !args.quiet {
        estpipe_process::errln!(
            "bridge: estimator side of {}: listening on {key}",
            args.prefix
        );
    }

    let mut fwd = Forward {
        publisher: &slot_pub,
        notifier: &notifier,
        report: &mut report,
        sequence: Sequence::default(),
        header: None,
        hop: Stage::default(),
        own: Stage::default(),
        max_gap: args.max_gap,
    };
    let mut ended_at: Option<Instant> = None;
    let mut last_estimate = Instant::now();
    let mut far = FarSide::default();
    let listening = Instant::now();
    loop {
        if stop.requested() {
            fwd.report.ending = "interrupted".into();
            break;
        }
        far.check(&z_alive, fwd.report, args.quiet);
        let absent = far
            .absent_since
            .unwrap_or(listening)
            .elapsed()
            .as_secs_f64();
        // After the stream's END the sensor side may leave: `--once` ends by its linger.
        if far.absent_since.is_some()
            && ended_at.is_none()
            && args.connect_timeout > 0.0
            && absent > args.connect_timeout
        {
            if !far.heard {
                bail!(
                    "no sensor side on {key} within --connect-timeout {} s{}",
                    args.connect_timeout,
                    if far.seen {
                        " (a liveliness token was there, but no message came)"
                    } else {
                        ""
                    }
                );
            }
            estpipe_process::errln!(
                "bridge: error: the sensor side on {key} is gone since {absent:.1} s \
                 (--connect-timeout {} s)",
                args.connect_timeout
            );
            fwd.report.ending = FAR_SIDE_LOST.into();
            break;
        }
        let mut busy = false;
        // Wait for the first slot of a pass (bounded, so estimates and signals are served).
        let first = z_slots
            .recv_timeout(Duration::from_micros(500))
            .map_err(|e| anyhow!("zenoh {key}/slots: {e}"))?;
        if let Some(sample) = first {
            busy = true;
            far.heard_now();
            let mut next = Some(sample);
            for i in 0..BURST {
                // Taken only when it is forwarded in this pass: a sample taken and left
                // would be lost.
                if i > 0 {
                    next = z_slots.try_recv().ok().flatten();
                }
                let Some(sample) = next.take() else {
                    break;
                };
                let bytes = sample.payload().to_bytes();
                let took = fwd.message(&bytes, &truth_pub)?;
                if took != Took::Other {
                    // Best effort: a lost echo only means one more repeat from the far side.
                    let _ = z_acks.put(&bytes[..]).wait();
                    fwd.report.acks += 1;
                }
                if took == Took::Marker {
                    ended_at.get_or_insert_with(Instant::now);
                }
            }
        }
        while let Some(e) = est_sub.receive().map_err(|e| anyhow!("estimates: {e:?}"))? {
            busy = true;
            last_estimate = Instant::now();
            z_est
                .put(&net::encode_estimate(e.payload())[..])
                .wait()
                .map_err(|e| anyhow!("zenoh put estimate: {e}"))?;
            fwd.report.estimates += 1;
        }
        if args.once
            && !busy
            && ended_at.is_some_and(|t| t.elapsed() > LINGER && last_estimate.elapsed() > LINGER)
        {
            fwd.report.ending = "the stream ended".into();
            break;
        }
    }
    fwd.report.network_hop = fwd.hop.percentiles();
    fwd.report.bridge_time = fwd.own.percentiles();
    // On a link that takes nothing, zenoh's close would wait 10 s.
    close_within(session, CLOSE_WAIT);
    Ok(report)
}

/// Whether the sensor side is there: its zenoh liveliness token `<key>/alive/sensor`
/// (declared by the sensor side, withdrawn by zenoh when its session ends, also when it is
/// killed). A bridge that vanishes is logged and counted; the stream goes on when it returns,
/// its gap counted as lost on the network.
///
/// `--connect-timeout` holds whenever the far side is absent (issue #39: once one had been
/// seen the estimator side waited for ever, and a rogue liveliness token kept it waiting
/// with no sensor side at all): absent from the start until a message arrives, and again
/// from the token's withdrawal until the next message. A token alone is not presence.
#[derive(Debug)]
struct FarSide {
    /// A token was declared at some point.
    seen: bool,
    /// A message came at some point.
    heard: bool,
    /// Since when no sensor side is known to be there (`None`: one is).
    absent_since: Option<Instant>,
}

impl Default for FarSide {
    fn default() -> Self {
        Self {
            seen: false,
            heard: false,
            absent_since: Some(Instant::now()),
        }
    }
}

/// `BridgeReport::ending` when the sensor side stayed away for `--connect-timeout` (exit
/// code 3, as a runner's lost publisher).
pub const FAR_SIDE_LOST: &str = "the sensor side was lost";

impl FarSide {
    /// A message from the far side arrived.
    fn heard_now(&mut self) {
        self.heard = true;
        self.absent_since = None;
    }

    fn check(
        &mut self,
        alive: &zenoh::pubsub::Subscriber<
            zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>,
        >,
        report: &mut BridgeReport,
        quiet: bool,
    ) {
        while let Ok(Some(s)) = alive.try_recv() {
            match s.kind() {
                zenoh::sample::SampleKind::Put => {
                    if self.seen && !quiet {
                        estpipe_process::errln!("bridge: sensor side back");
                    }
                    self.seen = true;
                }
                zenoh::sample::SampleKind::Delete => {
                    report.far_side_lost += 1;
                    self.absent_since.get_or_insert_with(Instant::now);
                    if !quiet {
                        estpipe_process::errln!(
                            "bridge: sensor side gone (its slots count as lost on the network \
                             until it returns)"
                        );
                    }
                }
            }
        }
    }
}

/// What one message on `<key>/slots` was, for the acknowledgement of markers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Took {
    /// A data slot, a truth sample, or a refused message.
    Other,
    /// A node's END/ABORT, forwarded: its stream is over.
    Marker,
    /// A copy of a marker already taken.
    RepeatedMarker,
}

/// Writes checked slots into shared memory.
struct Forward<'a> {
    publisher: &'a iceoryx2::port::publisher::Publisher<ipc::Service, Slot, StreamHeader>,
    notifier: &'a iceoryx2::port::notifier::Notifier<ipc::Service>,
    report: &'a mut BridgeReport,
    sequence: Sequence,
    header: Option<(u64, StreamHeader)>,
    hop: Stage,
    own: Stage,
    max_gap: u64,
}

impl Forward<'_> {
    /// One message of `<key>/slots`: a truth sample or a slot (one key, so that the truth of
    /// an instant arrives before its slots, as from the publisher itself).
    fn message(
        &mut self,
        bytes: &[u8],
        truth_pub: &iceoryx2::port::publisher::Publisher<ipc::Service, Truth, ()>,
    ) -> Result<Took> {
        if bytes.get(2) == Some(&(net::Kind::Truth as u8)) {
            match net::decode_truth(bytes) {
                Ok(t) => {
                    let out = truth_pub
                        .loan_uninit()
                        .map_err(|e| anyhow!("truth: {e:?}"))?
                        .write_payload(t);
                    out.send().map_err(|e| anyhow!("truth: {e:?}"))?;
                    self.report.truth += 1;
                }
                Err(e) => self.report.refuse(e.reason()),
            }
            return Ok(Took::Other);
        }
        self.arrive(bytes)
    }

    /// One slot message.
    fn arrive(&mut self, bytes: &[u8]) -> Result<Took> {
        let at = wire::monotonic_ns();
        let (h, s) = match net::decode_slot(bytes) {
            Ok(m) => m,
            Err(e) => {
                self.report.refuse(e.reason());
                return Ok(Took::Other);
            }
        };
        match self.header {
            Some((stream, ref known)) if stream == s.stream_id && *known != h => {
                self.report.refuse("header_changed");
                return Ok(Took::Other);
            }
            _ => self.header = Some((s.stream_id, h)),
        }
        match self.sequence.arrive(&s) {
            Arrival::RepeatedMarker => {
                // The sensor side sends every marker more than once (a lost END would hang
                // the runner); the copies after the first are expected, not refused.
                self.report.markers_repeated += 1;
                return Ok(Took::RepeatedMarker);
            }
            Arrival::Late if s.kind != SLOT_DATA => {
                // A marker of an instant this node's stream already passed: nothing to
                // forward, but echoed, so the far side stops repeating it.
                self.report.refuse("late");
                return Ok(Took::RepeatedMarker);
            }
            Arrival::Late => {
                self.report.refuse("late");
                return Ok(Took::Other);
            }
            Arrival::NewStream { lost } => {
                for k in 1..=lost {
                    self.send(&h, lost_slot(&s, k))?;
                    self.report.lost_on_network += 1;
                }
            }
            Arrival::InOrder { lost: 0, .. } => {}
            Arrival::InOrder { lost, .. } if u64::from(lost) > self.max_gap => {
                self.report.refuse("gap_too_large");
            }
            Arrival::InOrder { from, lost } => {
                for k in from..from + lost {
                    self.send(&h, lost_slot(&s, k))?;
                    self.report.lost_on_network += 1;
                }
            }
        }
        if s.send_ns != 0 && s.send_ns <= at {
            self.hop.record(at - s.send_ns);
        }
        self.send(&h, s)?;
        self.own.record(wire::monotonic_ns().saturating_sub(at));
        if s.kind == SLOT_DATA {
            self.report.slots += 1;
            Ok(Took::Other)
        } else {
            self.report.markers += 1;
            Ok(Took::Marker)
        }
    }

    fn send(&mut self, h: &StreamHeader, s: Slot) -> Result<()> {
        let mut sample = self
            .publisher
            .loan_uninit()
            .map_err(|e| anyhow!("slots: {e:?}"))?;
        *sample.user_header_mut() = *h;
        match sample.write_payload(s).send() {
            Ok(_) => {}
            Err(_) if s.kind == SLOT_DATA => self.report.dropped_at_bridge += 1,
            Err(e) => {
                return Err(anyhow!(
                    "slots: the END/ABORT marker was not delivered: {e:?}"
                ))
            }
        }
        // A wake-up per slot: each node is its own stream, so any slot may complete an instant.
        let _ = self.notifier.notify();
        Ok(())
    }
}
