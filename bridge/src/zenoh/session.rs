//! The zenoh session of a bridge: opened from the command line, its publishers declared
//! alike, a put that a stop may cut short, and an end that never waits on a congested link.
//!
//! On a link that takes nothing (a blackholed or saturated path), zenoh's `close` waits for
//! its own 10 s timeout, and a put under `CongestionControl::Block` waits up to the
//! transport's `wait_before_close` (5 s by default) before it returns. A stop request must
//! not wait for either (docs/bridge.md, "Hostile input"): [`CloseOnStop`] closes the session
//! as soon as the stop comes, which ends a blocked put at once, and [`close_within`] bounds
//! every close.

use crate::args::BridgeArgs;
use crate::stop::Stop;
use anyhow::{anyhow, Result};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::thread::JoinHandle;
use std::time::Duration;
use zenoh::pubsub::Publisher;
use zenoh::qos::CongestionControl;
use zenoh::{Session, Wait};

/// How long a bridge waits for its session to close before it goes on (and exits).
pub(crate) const CLOSE_WAIT: Duration = Duration::from_millis(500);

/// How often [`CloseOnStop`] looks at the stop request.
const POLL: Duration = Duration::from_millis(10);

/// Opens the session `args` configure.
pub(crate) fn open(args: &BridgeArgs) -> Result<Session> {
    zenoh::open(args.zenoh_config()?)
        .wait()
        .map_err(|e| anyhow!("cannot open the zenoh session: {e}"))
}

/// A publisher on `<key>/<name>`. Express, as every publisher of the bridge: a message leaves
/// at once instead of waiting to be batched with later ones, so the link adds no wait of its own.
pub(crate) fn publisher(
    session: &Session,
    key: &str,
    name: &str,
    congestion: CongestionControl,
) -> Result<Publisher<'static>> {
    session
        .declare_publisher(format!("{key}/{name}"))
        .congestion_control(congestion)
        .express(true)
        .wait()
        .map_err(|e| anyhow!("zenoh publisher {key}/{name}: {e}"))
}

/// Puts `msg` on `z`; `Ok(false)` when it failed because a stop closed the session
/// ([`CloseOnStop`]): the message is not sent and the caller stops.
pub(crate) fn put(z: &Publisher<'_>, msg: &[u8], stop: &Stop, what: &str) -> Result<bool> {
    match z.put(msg).wait() {
        Ok(()) => Ok(true),
        Err(_) if stop.requested() => Ok(false),
        Err(e) => Err(anyhow!("zenoh put {what}: {e}")),
    }
}

/// Closes `session` on a thread of its own and waits at most `wait` for it; `true` if it
/// closed in time. A close still under way when the process exits ends with it.
pub(crate) fn close_within(session: Session, wait: Duration) -> bool {
    let (done, closed) = mpsc::channel();
    let spawned = std::thread::Builder::new()
        .name("zenoh-close".into())
        .spawn(move || {
            let _ = session.close().wait();
            let _ = done.send(());
        });
    spawned.is_ok() && closed.recv_timeout(wait).is_ok()
}

/// While alive, closes the session (within [`CLOSE_WAIT`]) as soon as a stop is requested,
/// so that a put blocked on a congested link returns (with an error, which the caller reads
/// as the stop). Dropping it ends the watch.
#[derive(Debug)]
pub(crate) struct CloseOnStop {
    done: Arc<AtomicBool>,
    watcher: Option<JoinHandle<()>>,
}

impl CloseOnStop {
    pub(crate) fn new(session: &Session, stop: &Stop) -> Self {
        let done = Arc::new(AtomicBool::new(false));
        let (session, stop, d) = (session.clone(), stop.clone(), Arc::clone(&done));
        let watcher = std::thread::Builder::new()
            .name("close-on-stop".into())
            .spawn(move || {
                while !d.load(Ordering::Relaxed) {
                    if stop.requested() {
                        close_within(session, CLOSE_WAIT);
                        return;
                    }
                    std::thread::sleep(POLL);
                }
            })
            .ok();
        Self { done, watcher }
    }
}

impl Drop for CloseOnStop {
    fn drop(&mut self) {
        self.done.store(true, Ordering::Relaxed);
        if let Some(w) = self.watcher.take() {
            let _ = w.join();
        }
    }
}
