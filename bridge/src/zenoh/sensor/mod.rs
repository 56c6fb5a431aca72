//! The sensor side: slots and truth leave shared memory for zenoh, estimates come back.
//!
//! It subscribes to `<prefix>/slots` only once the far side has subscribed to `<key>/slots`:
//! the publisher starts its stream when its first subscriber appears (docs/wire.md, Stream
//! rules), and a stream started before the runner exists would reach it mid-way.

mod pass;

use crate::args::BridgeArgs;
use crate::link::linger::Linger;
use crate::link::markers::Markers;
use crate::link::report::BridgeReport;
use crate::link::shm::{self, Services};
use crate::link::wait::{wait_for, Waited};
use crate::stop::Stop;
use crate::zenoh::inbox::{self, Inbox};
use crate::zenoh::session::{self, close_within, CloseOnStop, CLOSE_WAIT};
use anyhow::{anyhow, bail, Result};
use estpipe_wire::{Estimate, Slot, StreamHeader, Truth};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use pass::Pass;
use std::time::Duration;
use zenoh::liveliness::LivelinessToken;
use zenoh::qos::CongestionControl;
use zenoh::{Session, Wait};

/// Runs the sensor side.
pub fn run(args: &BridgeArgs) -> Result<BridgeReport> {
    let stop = Stop::new(args.parent_pid);
    let key = args.key();
    let mut report = BridgeReport::new(args.side, key.clone());
    let services = Services::open(&args.prefix)?;
    let estimates = publish_estimates(&services, &args.prefix)?;
    let net = Net::open(args, &key)?;
    args.progress(&format!("waiting for the estimator side on {key}"));
    if !estimator_side_came(&net.slots, &stop, args, &key)? {
        report.ending = "interrupted before the estimator side came".into();
        return Ok(report);
    }
    let local = Local::subscribe(&services, &args.prefix)?;
    args.progress("forwarding");
    // A put blocked on a congested link returns when a stop closes the session.
    let close_on_stop = CloseOnStop::new(&net.session, &stop);
    let mut pass = Pass {
        args,
        stop: &stop,
        report,
        net: &net,
        local: &local,
        estimates: &estimates,
        markers: Markers::default(),
        linger: Linger::new(),
        sent: 0,
    };
    if let Some(ending) = pass.forward_until_end()? {
        pass.report.ending = ending.into();
    }
    let mut report = pass.report;
    report.markers_acked = pass.markers.acked;
    report.markers_unacked = pass.markers.unacked;
    report.acks_stale = pass.markers.stale;
    drop(close_on_stop);
    close_within(net.session, CLOSE_WAIT);
    Ok(report)
}

/// The publisher of the estimates that come back (the runner's, on the far host).
fn publish_estimates(
    services: &Services,
    prefix: &str,
) -> Result<Publisher<ipc::Service, Estimate, ()>> {
    services
        .estimates
        .publisher_builder()
        .create()
        .map_err(|e| {
            anyhow!(
                "cannot publish on {prefix}/estimates ({e:?}): is a runner using this --prefix?"
            )
        })
}

/// Waits for the estimator side's subscription to `<key>/slots`. `Ok(false)`: a stop came
/// first.
fn estimator_side_came(
    z_slots: &zenoh::pubsub::Publisher<'_>,
    stop: &Stop,
    args: &BridgeArgs,
    key: &str,
) -> Result<bool> {
    let waited = wait_for(stop, args.connect_timeout, Duration::from_millis(5), || {
        // A stop wins over an estimator side that is there: subscribing to the slots would
        // start the publisher's stream, for no one.
        if stop.requested() {
            return Ok(false);
        }
        let matching = z_slots
            .matching_status()
            .wait()
            .map_err(|e| anyhow!("zenoh matching status: {e}"))?;
        Ok(matching.matching())
    })?;
    match waited {
        Waited::Came => Ok(true),
        Waited::Stopped => Ok(false),
        Waited::TimedOut => bail!(
            "no estimator side subscribed to {key}/slots within --connect-timeout {} s",
            args.connect_timeout
        ),
    }
}

/// This side's zenoh session and what it declares on `<key>`.
struct Net {
    session: Session,
    slots: zenoh::pubsub::Publisher<'static>,
    /// The far side watches this token: zenoh withdraws it when this session ends, however.
    _alive: LivelinessToken,
    estimates: Inbox,
    acks: Inbox,
}

impl Net {
    fn open(args: &BridgeArgs, key: &str) -> Result<Self> {
        let session = session::open(args)?;
        // Block: a full network queue slows this side down rather than dropping slots; what a
        // lossy link loses the far side sees as sequence gaps.
        let slots = session::publisher(&session, key, "slots", CongestionControl::Block)?;
        let alive = session
            .liveliness()
            .declare_token(format!("{key}/alive/sensor"))
            .wait()
            .map_err(|e| anyhow!("zenoh liveliness {key}/alive/sensor: {e}"))?;
        let estimates = inbox::subscriber(&session, key, "estimates", args.queue)?;
        let acks = inbox::subscriber(&session, key, "acks", args.queue)?;
        Ok(Self {
            session,
            slots,
            _alive: alive,
            estimates,
            acks,
        })
    }
}

/// This host's stream, subscribed to once the estimator side is there.
struct Local {
    truth: Subscriber<ipc::Service, Truth, ()>,
    ready: Listener<ipc::Service>,
    slots: Subscriber<ipc::Service, Slot, StreamHeader>,
}

impl Local {
    fn subscribe(services: &Services, prefix: &str) -> Result<Self> {
        // Truth and the event listener before the slot subscriber: the publisher starts on it.
        let truth = shm::subscribe(&services.truth, prefix, "truth")?;
        let ready = services
            .ready
            .listener_builder()
            .create()
            .map_err(|e| anyhow!("cannot listen on {prefix}/slots-ready: {e:?}"))?;
        let slots = shm::subscribe(&services.slots, prefix, "slots")?;
        Ok(Self {
            truth,
            ready,
            slots,
        })
    }
}
