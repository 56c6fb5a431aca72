//! The sensor side: slots and truth leave shared memory for zenoh, estimates come back.
//!
//! It subscribes to `<prefix>/slots` only once the far side has subscribed to `<key>/slots`:
//! the publisher starts its stream when its first subscriber appears (docs/wire.md, Stream
//! rules), and a stream started before the runner exists would reach it mid-way.

use crate::args::BridgeArgs;
use crate::markers::{Ack, Markers};
use crate::report::BridgeReport;
use crate::session::{close_within, CloseOnStop, CLOSE_WAIT};
use crate::stop::Stop;
use anyhow::{anyhow, bail, Result};
use estpipe_wire::{self as wire, net, SLOT_DATA};
use iceoryx2::prelude::*;
use std::time::{Duration, Instant};
use zenoh::handlers::FifoChannel;
use zenoh::qos::CongestionControl;
use zenoh::Wait;

/// Slots forwarded per pass before the estimates and the signal are looked at again.
const BURST: usize = 256;

/// After the stream ended (`--once`), estimates are forwarded until none came for this long.
pub(crate) const LINGER: Duration = Duration::from_millis(500);

/// Runs the sensor side.
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
    let est_pub = estimates.publisher_builder().create().map_err(|e| {
        anyhow!(
            "cannot publish on {}/estimates ({e:?}): is a runner using this --prefix?",
            args.prefix
        )
    })?;

    let session = zenoh::open(args.zenoh_config()?)
        .wait()
        .map_err(|e| anyhow!("cannot open the zenoh session: {e}"))?;
    // Block: a full network queue slows this side down rather than dropping slots; what a
    // lossy link loses the far side sees as sequence gaps.
    let z_slots = session
        .declare_publisher(format!("{key}/slots"))
        .congestion_control(CongestionControl::Block)
        .express(true)
        .wait()
        .map_err(|e| anyhow!("zenoh publisher {key}/slots: {e}"))?;
    // The far side watches this token: zenoh withdraws it when this session ends, however.
    let _alive = session
        .liveliness()
        .declare_token(format!("{key}/alive/sensor"))
        .wait()
        .map_err(|e| anyhow!("zenoh liveliness {key}/alive/sensor: {e}"))?;
    let z_est = session
        .declare_subscriber(format!("{key}/estimates"))
        .with(FifoChannel::new(args.queue))
        .wait()
        .map_err(|e| anyhow!("zenoh subscriber {key}/estimates: {e}"))?;
    let z_acks = session
        .declare_subscriber(format!("{key}/acks"))
        .with(FifoChannel::new(args.queue))
        .wait()
        .map_err(|e| anyhow!("zenoh subscriber {key}/acks: {e}"))?;

    if !args.quiet {
        estpipe_process::errln!(
            "bridge: sensor side of {}: waiting for the estimator side on {key}",
            args.prefix
        );
    }
    let started = Instant::now();
    loop {
        if stop.requested() {
            report.ending = "interrupted before the estimator side came".into();
            return Ok(report);
        }
        let matching = z_slots
            .matching_status()
            .wait()
            .map_err(|e| anyhow!("zenoh matching status: {e}"))?;
        if matching.matching() {
            break;
        }
        if args.connect_timeout > 0.0 && started.elapsed().as_secs_f64() > args.connect_timeout {
            bail!(
                "no estimator side subscribed to {key}/slots within --connect-timeout {} s",
                args.connect_timeout
            );
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    // Truth and the event listener before the slot subscriber: the publisher starts on it.
    let truth_sub = truth
        .subscriber_builder()
        .buffer_size(wire::MAX_SUBSCRIBER_BUFFER)
        .create()
        .map_err(|e| anyhow!("cannot subscribe to {}/truth: {e:?}", args.prefix))?;
    let listener = ready
        .listener_builder()
        .create()
        .map_err(|e| anyhow!("cannot listen on {}/slots-ready: {e:?}", args.prefix))?;
    let slot_sub = slots
        .subscriber_builder()
        .buffer_size(wire::MAX_SUBSCRIBER_BUFFER)
        .create()
        .map_err(|e| anyhow!("cannot subscribe to {}/slots: {e:?}", args.prefix))?;
    if !args.quiet {
        estpipe_process::errln!("bridge: sensor side of {}: forwarding", args.prefix);
    }
    // A put blocked on a congested link returns when a stop closes the session.
    let close_on_stop = CloseOnStop::new(&session, &stop);

    let mut ended_at: Option<Instant> = None;
    let mut last_estimate = Instant::now();
    let mut sent = 0u64;
    let mut markers = Markers::default();
    loop {
        if stop.requested() {
            report.ending = "interrupted".into();
            break;
        }
        let mut busy = false;
        busy |= forward_truth(&truth_sub, &z_slots, &stop, &mut report)?;
        for _ in 0..BURST {
            let Some(sample) = slot_sub.receive().map_err(|e| anyhow!("slots: {e:?}"))? else {
                break;
            };
            busy = true;
            let (h, s) = (*sample.user_header(), *sample.payload());
            drop(sample);
            // The publisher sends an instant's truth before its slots: whatever truth came
            // meanwhile goes first, so the far side sees the same order.
            // A put the stop cut short ends this pass at the slot's own put below.
            forward_truth(&truth_sub, &z_slots, &stop, &mut report)?;
            // The same checks the far side makes: a bad slot never costs network bandwidth.
            let mut msg = net::encode_slot(&h, &s);
            if let Err(e) = net::decode_slot(&msg) {
                report.refuse(e.reason());
                continue;
            }
            sent += 1;
            if args
                .corrupt_every()
                .is_some_and(|n| n > 0 && sent.is_multiple_of(n))
            {
                msg[3] ^= 0x80;
            }
            if !put(&z_slots, &msg, &stop, "slot")? {
                break;
            }
            if s.kind == SLOT_DATA {
                report.slots += 1;
            } else {
                // Repeated until acknowledged: over UDP a lost END would leave the far side's
                // runner waiting for instants that never come (crate::markers).
                report.markers += 1;
                report.marker_puts += 1;
                markers.put(&s, &msg, Instant::now());
                ended_at.get_or_insert_with(Instant::now);
            }
        }
        // At most a burst per pass: a peer flooding `<key>/acks` faster than they are read
        // must not keep this pass from the slots (what it left waits for the next pass).
        for _ in 0..BURST {
            let Ok(Some(sample)) = z_acks.try_recv() else {
                break;
            };
            busy = true;
            match markers.ack(&sample.payload().to_bytes()) {
                Ok(Ack::Taken | Ack::Stale) => {}
                Err(reason) => report.refuse(reason),
            }
        }
        if let Some(msg) = markers.due(Instant::now()) {
            if !put(&z_slots, &msg, &stop, "marker")? {
                break;
            }
            report.marker_puts += 1;
        }
        // A burst per pass here too: estimates flooded onto `<key>/estimates` (by the far
        // side or by a foreign peer) must not keep this pass from the slots.
        for _ in 0..BURST {
            let Ok(Some(sample)) = z_est.try_recv() else {
                break;
            };
            busy = true;
            last_estimate = Instant::now();
            match net::decode_estimate(&sample.payload().to_bytes()) {
                Ok(e) => {
                    let out = est_pub
                        .loan_uninit()
                        .map_err(|e| anyhow!("estimates: {e:?}"))?
                        .write_payload(e);
                    out.send().map_err(|e| anyhow!("estimates: {e:?}"))?;
                    report.estimates += 1;
                }
                Err(e) => report.refuse(e.reason()),
            }
        }
        if args.once
            && markers.settled()
            && ended_at.is_some_and(|t| t.elapsed() > LINGER && last_estimate.elapsed() > LINGER)
        {
            report.ending = "the stream ended".into();
            break;
        }
        if !busy {
            // A wake-up per instant from the publisher; the timeout bounds the delay of
            // estimates, of the markers' re-sends and of the signal check.
            let _ = listener.timed_wait(|_| {}, Duration::from_micros(500));
        }
    }
    report.markers_acked = markers.acked;
    report.markers_unacked = markers.unacked;
    report.acks_stale = markers.stale;
    drop(close_on_stop);
    close_within(session, CLOSE_WAIT);
    Ok(report)
}

/// Puts `msg` on `z`; `Ok(false)` when it failed because a stop closed the session
/// ([`CloseOnStop`]): the message is not sent and the caller stops.
fn put(z: &zenoh::pubsub::Publisher<'_>, msg: &[u8], stop: &Stop, what: &str) -> Result<bool> {
    match z.put(msg).wait() {
        Ok(()) => Ok(true),
        Err(_) if stop.requested() => Ok(false),
        Err(e) => Err(anyhow!("zenoh put {what}: {e}")),
    }
}

/// Forwards every truth sample waiting in shared memory (on the slots key: one zenoh
/// publisher keeps the order); `Ok(true)` if there was one. Returns early when a stop closed
/// the session.
fn forward_truth(
    truth_sub: &iceoryx2::port::subscriber::Subscriber<ipc::Service, wire::Truth, ()>,
    z_slots: &zenoh::pubsub::Publisher<'_>,
    stop: &Stop,
    report: &mut BridgeReport,
) -> Result<bool> {
    let mut any = false;
    while let Some(t) = truth_sub.receive().map_err(|e| anyhow!("truth: {e:?}"))? {
        any = true;
        let t = *t.payload();
        if t.version != wire::WIRE_VERSION || t.nx == 0 || t.nx as usize > wire::MAX_NX {
            report.refuse("truth");
            continue;
        }
        if !put(z_slots, &net::encode_truth(&t), stop, "truth")? {
            break;
        }
        report.truth += 1;
    }
    Ok(any)
}
