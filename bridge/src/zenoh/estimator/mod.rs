//! The estimator side: slots and truth from zenoh are checked, then written into shared
//! memory for the runner (`link/forward.rs`); the runner's estimates go back.
//!
//! It subscribes to `<key>/slots` only once a runner has subscribed to `<prefix>/slots`
//! (docs/bridge.md, "Start-up order"), and it watches the sensor side's liveliness
//! (`far_side`).

mod far_side;
mod pass;

pub use far_side::FAR_SIDE_LOST;

use crate::args::BridgeArgs;
use crate::link::forward::{Forward, Outlets};
use crate::link::linger::Linger;
use crate::link::report::BridgeReport;
use crate::link::shm::{self, Services};
use crate::link::wait::{wait_for, Waited};
use crate::stop::Stop;
use crate::zenoh::inbox::{self, Inbox};
use crate::zenoh::session::{self, close_within, CLOSE_WAIT};
use anyhow::{anyhow, bail, Result};
use far_side::FarSide;
use iceoryx2::prelude::*;
use pass::Pass;
use std::time::{Duration, Instant};
use zenoh::handlers::FifoChannel;
use zenoh::pubsub::Publisher;
use zenoh::qos::CongestionControl;
use zenoh::{Session, Wait};

/// Runs the estimator side.
pub fn run(args: &BridgeArgs) -> Result<BridgeReport> {
    let stop = Stop::new(args.parent_pid);
    let key = args.key();
    let mut report = BridgeReport::new(args.side, key.clone());
    let services = Services::open(&args.prefix)?;
    let outlets = Outlets::open(&services, &stop, &args.prefix)?;
    args.progress("waiting for a runner");
    if !runner_came(&services, &stop, args)? {
        report.ending = "interrupted before a runner came".into();
        return Ok(report);
    }
    let estimates = shm::subscribe(&services.estimates, &args.prefix, "estimates")?;
    let net = Net::open(args, &key)?;
    args.progress(&format!("listening on {key}"));
    let mut pass = Pass {
        args,
        key: &key,
        stop: &stop,
        fwd: Forward::new(outlets, report, args.max_gap),
        estimates,
        far: FarSide::new(net.alive),
        z_slots: &net.slots,
        z_estimates: &net.estimates,
        z_acks: &net.acks,
        linger: Linger::new(),
    };
    let ending = pass.forward_until_end()?;
    let mut report = pass.fwd.into_report();
    report.ending = ending.into();
    // On a link that takes nothing, zenoh's close would wait 10 s.
    close_within(net.session, CLOSE_WAIT);
    Ok(report)
}

/// Waits for a runner's subscription to `<prefix>/slots`: forwarded before it, the stream
/// would reach it mid-way. `Ok(false)`: a stop came first.
fn runner_came(services: &Services, stop: &Stop, args: &BridgeArgs) -> Result<bool> {
    let mut last_cleanup = Instant::now();
    let waited = wait_for(stop, args.connect_timeout, Duration::from_millis(2), || {
        // As at the start: the ports of a process killed meanwhile must not stay behind.
        if last_cleanup.elapsed() > Duration::from_millis(100) {
            let _ = services.node.try_cleanup_dead_nodes();
            last_cleanup = Instant::now();
        }
        Ok(services.slots.dynamic_config().number_of_subscribers() > 0)
    })?;
    match waited {
        Waited::Came => Ok(true),
        Waited::Stopped => Ok(false),
        Waited::TimedOut => bail!(
            "no runner subscribed to {}/slots within --connect-timeout {} s",
            args.prefix,
            args.connect_timeout
        ),
    }
}

/// This side's zenoh session and what it declares on `<key>`.
struct Net {
    session: Session,
    estimates: Publisher<'static>,
    /// Each marker taken (or seen again) is echoed here: the sensor side repeats it until then.
    acks: Publisher<'static>,
    alive: Inbox,
    slots: Inbox,
}

impl Net {
    fn open(args: &BridgeArgs, key: &str) -> Result<Self> {
        let session = session::open(args)?;
        // Drop, not block: a congested way back must not hold up the slots this thread
        // forwards; a lost echo costs one more repeat of its marker.
        let estimates = session::publisher(&session, key, "estimates", CongestionControl::Drop)?;
        let acks = session::publisher(&session, key, "acks", CongestionControl::Drop)?;
        let alive = session
            .liveliness()
            .declare_subscriber(format!("{key}/alive/sensor"))
            // A sensor side that came first is reported too, so that its end is always seen.
            .history(true)
            .with(FifoChannel::new(64))
            .wait()
            .map_err(|e| anyhow!("zenoh liveliness {key}/alive/sensor: {e}"))?;
        let slots = inbox::subscriber(&session, key, "slots", args.queue)?;
        Ok(Self {
            session,
            estimates,
            acks,
            alive,
            slots,
        })
    }
}
