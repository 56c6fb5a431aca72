//! What the publisher does when a subscriber's slot queue is full.
//!
//! The slot service does not overflow (`docs/wire.md`, QoS), so a full queue is the
//! publisher's to handle, through iceoryx2's back-pressure handler:
//!
//! * **block** (the default at `--rate 0`): `send()` waits until the subscriber has made
//!   room, so "as fast as possible" loses nothing. The wait is cut into slices of
//!   [`BLOCK_SLICE`]: after each the send gives up on that subscriber (iceoryx2's
//!   `DiscardDataAndFail`) and the publisher looks for dead nodes before it sends the same slot
//!   again. A SIGKILLed runner keeps its full queue registered until someone cleans it up, and
//!   SIGINT/SIGTERM/SIGHUP must still end the run, so a send never waits for more than a slice
//!   without the publisher noticing either.
//! * **discard** (the default when paced): the slot is dropped for that subscriber at once;
//!   the runner sees the gap in `seq` and counts it as lost in the IPC, and the publisher
//!   counts it too (a `send()` that reached fewer subscribers than there are).
//!
//! END and ABORT markers are always sent blocking ([`Mode::Final`]): a stream whose end
//! marker was discarded would leave the runner waiting for its deadline.
//!
//! **A subscriber that does not read** (issue #39: a foreign subscriber on `<prefix>/slots`
//! that never reads held a `--rate 0` run for as long as it lived, every slot re-sent to
//! every subscriber each slice): a receiver whose queue stayed full for `--unread-limit`
//! seconds, slice after slice, is *unread*. From then on a slot that finds its queue full is
//! dropped for it at once (counted, [`Gate::unread_drops`]) instead of blocking the others;
//! it still gets every slot its queue has room for. The publisher says so in one line per
//! such subscriber. A subscriber that never reads at all never connects to the publisher
//! (iceoryx2 0.10 connects a subscriber on its reads), so its queue never blocks: `send()`
//! just reaches one subscriber fewer than there are, and the slot went again and again
//! (7 500 times a second). Such a shortfall that lasts `--unread-limit` is a subscriber that
//! does not read too ([`Gate::set_unconnected`]). A runner stopped for longer than the limit is treated the same way: it
//! loses (and counts as lost in the IPC) what its full queue could not take.

use iceoryx2::port::{BackpressureAction, BackpressureInfo};
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, AtomicU8, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Default of `--unread-limit`: seconds a receiver's queue may stay full before it is
/// treated as a subscriber that does not read.
pub const DEFAULT_UNREAD_LIMIT_S: f64 = 2.0;

/// Receivers whose blocking is tracked (the contract's slot service admits 4 subscribers;
/// a service of at most `estpipe_wire::services::QOS_LIMIT` is accepted).
const TRACKED: usize = 64;

/// What the handler remembers of one receiver that blocked a send.
#[derive(Clone, Copy, Debug)]
struct Blocked {
    id: u128,
    /// Since when its queue has stayed full (slice after slice).
    since: Instant,
    /// When a send last gave up on it after a whole slice.
    gave_up: Option<Instant>,
    /// Treated as a subscriber that does not read.
    unread: bool,
}

/// Longest a blocked send waits before the publisher checks for a dead subscriber.
pub const BLOCK_SLICE: Duration = Duration::from_millis(100);

/// `--backpressure`: what a full subscriber queue does to the publisher.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Backpressure {
    /// Block at `--rate 0`, discard when paced.
    Auto,
    /// Wait for room: nothing is lost, a slow runner slows the publisher down.
    Block,
    /// Drop the slot for that subscriber: the publisher keeps its pace, the runner counts
    /// the gap.
    Discard,
}

impl Backpressure {
    /// Whether data slots are sent blocking at `rate` Hz (0 = as fast as possible).
    pub fn blocks(self, rate: f64) -> bool {
        match self {
            Self::Auto => rate == 0.0,
            Self::Block => true,
            Self::Discard => false,
        }
    }
}

/// How the next sends treat a full queue.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum Mode {
    /// Drop the sample for the full subscriber.
    Discard = 0,
    /// Wait up to [`BLOCK_SLICE`]; a termination request ends the wait.
    Block = 1,
    /// Wait up to [`BLOCK_SLICE`] even after a termination request (END/ABORT markers).
    Final = 2,
}

/// The state the back-pressure handler shares with the publisher loop.
#[derive(Debug, Default)]
pub struct Gate {
    mode: AtomicU8,
    stop: AtomicBool,
    /// `--parent-pid`: the process whose end stops the publisher (0: none).
    parent: AtomicU32,
    /// The parent was found gone (the reason for the stop, beside a signal).
    orphaned: AtomicBool,
    /// `--unread-limit` in ns (0: never).
    unread_limit_ns: AtomicU64,
    /// The receivers that blocked a send (bounded: [`TRACKED`]).
    blocked: Mutex<Vec<Blocked>>,
    /// Slots dropped for an unread receiver, in all.
    unread_drops: AtomicU64,
    /// Slots dropped for an unread receiver during the current send.
    drops_this_send: AtomicU64,
    /// Receivers newly found unread, not yet reported.
    newly_unread: AtomicU32,
    /// Subscribers that never connected to this publisher (they connect on their first
    /// read) and missed slots for `--unread-limit`: not waited for any more.
    unconnected: AtomicU32,
}

impl Gate {
    /// A gate in [`Mode::Discard`] with the default `--unread-limit`.
    pub fn new() -> Arc<Self> {
        let g = Self {
            blocked: Mutex::new(Vec::with_capacity(TRACKED)),
            ..Self::default()
        };
        g.set_unread_limit(DEFAULT_UNREAD_LIMIT_S);
        Arc::new(g)
    }

    /// Seconds a receiver's queue may stay full before it counts as unread (0: never).
    pub fn set_unread_limit(&self, seconds: f64) {
        let ns = if seconds > 0.0 {
            (seconds * 1e9).min(u64::MAX as f64) as u64
        } else {
            0
        };
        self.unread_limit_ns.store(ns, Ordering::Relaxed);
    }

    /// Slots dropped for receivers that do not read, in all.
    pub fn unread_drops(&self) -> u64 {
        self.unread_drops.load(Ordering::Relaxed)
    }

    /// Starts a send: the drops for unread receivers are counted from here.
    pub fn begin_send(&self) {
        self.drops_this_send.store(0, Ordering::Relaxed);
    }

    /// Receivers the current send dropped the slot for because they do not read.
    pub fn drops_this_send(&self) -> usize {
        self.drops_this_send.load(Ordering::Relaxed) as usize
    }

    /// Receivers found unread since the last call (for the one report line each).
    pub fn take_newly_unread(&self) -> u32 {
        self.newly_unread.swap(0, Ordering::Relaxed)
    }

    /// Receivers treated as unread now (those that blocked and those that never connected).
    pub fn unread_receivers(&self) -> usize {
        self.blocked
            .lock()
            .map_or(0, |b| b.iter().filter(|r| r.unread).count())
            + self.unconnected() as usize
    }

    /// `--unread-limit` (`None`: never).
    pub fn unread_limit(&self) -> Option<Duration> {
        match self.unread_limit_ns.load(Ordering::Relaxed) {
            0 => None,
            ns => Some(Duration::from_nanos(ns)),
        }
    }

    /// Subscribers that never connected and are no longer waited for.
    pub fn unconnected(&self) -> u32 {
        self.unconnected.load(Ordering::Relaxed)
    }

    /// `n` subscribers never connected within `--unread-limit` (0: none, e.g. after the
    /// subscriber count changed); reported once when it grows.
    pub fn set_unconnected(&self, n: u32) {
        let old = self.unconnected.swap(n, Ordering::Relaxed);
        if n > old {
            self.newly_unread.fetch_add(n - old, Ordering::Relaxed);
        }
    }

    /// What a full queue of receiver `id` gets after `elapsed` of this delivery: `Some(true)`
    /// drop it for this receiver (unread), `Some(false)` give up this try, `None` wait on.
    fn full_queue(&self, id: u128, retries: u64, elapsed: Duration, stop: bool) -> Option<bool> {
        let now = Instant::now();
        let limit = self.unread_limit_ns.load(Ordering::Relaxed);
        let Ok(mut blocked) = self.blocked.lock() else {
            return (stop || elapsed >= BLOCK_SLICE).then_some(false);
        };
        let at = match blocked.iter().position(|r| r.id == id) {
            Some(i) => i,
            None => {
                if blocked.len() == TRACKED {
                    // Forget the receiver that blocked longest ago.
                    blocked.remove(0);
                }
                blocked.push(Blocked {
                    id,
                    since: now,
                    gave_up: None,
                    unread: false,
                });
                blocked.len() - 1
            }
        };
        let r = &mut blocked[at];
        if r.unread {
            return Some(true);
        }
        // A new delivery right after a give-up continues the streak; one after the receiver
        // took a slot (no give-up for a while) starts a new one.
        if retries == 0 && r.gave_up.is_none_or(|t| now - t > 2 * BLOCK_SLICE) {
            r.since = now;
        }
        if !(stop || elapsed >= BLOCK_SLICE) {
            return None;
        }
        r.gave_up = Some(now);
        if limit > 0 && (now - r.since).as_nanos() >= u128::from(limit) {
            r.unread = true;
            self.newly_unread.fetch_add(1, Ordering::Relaxed);
            return Some(true);
        }
        Some(false)
    }

    /// Sets how the next sends treat a full queue.
    pub fn set_mode(&self, m: Mode) {
        self.mode.store(m as u8, Ordering::Relaxed);
    }

    /// How the next sends treat a full queue.
    pub fn mode(&self) -> Mode {
        match self.mode.load(Ordering::Relaxed) {
            0 => Mode::Discard,
            1 => Mode::Block,
            _ => Mode::Final,
        }
    }

    /// Stops the publisher as SIGTERM would once `pid` is no longer its parent process: a
    /// parent that died (even by SIGKILL) leaves its child to another process
    /// (docs/security.md, "Signals").
    pub fn set_parent(&self, pid: u32) {
        self.parent.store(pid, Ordering::Relaxed);
    }

    /// Whether SIGINT/SIGTERM/SIGHUP arrived ([`estpipe_process::signal`]) or the
    /// `--parent-pid` process is gone, seen here or by the handler during a blocked send;
    /// latched. Nothing else stops a run: any other signal only ends a wait early.
    pub fn stop_requested(&self) -> bool {
        if !self.stop.load(Ordering::Relaxed) {
            let parent = self.parent.load(Ordering::Relaxed);
            let orphaned = parent != 0 && std::os::unix::process::parent_id() != parent;
            if orphaned {
                self.orphaned.store(true, Ordering::Relaxed);
            }
            if orphaned || estpipe_process::signal::termination_requested() {
                self.stop.store(true, Ordering::Relaxed);
            }
        }
        self.stop.load(Ordering::Relaxed)
    }

    /// Why the publisher stopped early, for its last message (`None` if it did not):
    /// "stopped by signal (SIGTERM)" or "stopped: parent process N is gone".
    pub fn stop_reason(&self) -> Option<String> {
        if !self.stop.load(Ordering::Relaxed) {
            return None;
        }
        if self.orphaned.load(Ordering::Relaxed) {
            return Some(format!(
                "stopped: parent process {} is gone",
                self.parent.load(Ordering::Relaxed)
            ));
        }
        Some(match estpipe_process::signal::termination_signal() {
            Some(name) => format!("stopped by signal ({name})"),
            None => "stopped by signal".to_string(),
        })
    }

    /// iceoryx2's back-pressure handler, called while a subscriber's queue is full.
    pub fn handler(self: &Arc<Self>) -> impl Fn(&BackpressureInfo) -> BackpressureAction + Send {
        let gate = Arc::clone(self);
        move |info| {
            let mode = gate.mode.load(Ordering::Relaxed);
            if mode == Mode::Discard as u8 {
                return BackpressureAction::DiscardData;
            }
            let signalled = mode == Mode::Block as u8 && gate.stop_requested();
            match gate.full_queue(
                info.receiver_port_id,
                info.retries,
                info.elapsed_time,
                signalled,
            ) {
                None => BackpressureAction::Retry,
                Some(false) => BackpressureAction::DiscardDataAndFail,
                Some(true) => {
                    gate.unread_drops.fetch_add(1, Ordering::Relaxed);
                    gate.drops_this_send.fetch_add(1, Ordering::Relaxed);
                    BackpressureAction::DiscardData
                }
            }
        }
    }
}
