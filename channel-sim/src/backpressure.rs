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

use iceoryx2::port::{BackpressureAction, BackpressureInfo};
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU8, Ordering};
use std::sync::Arc;
use std::time::Duration;

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
}

impl Gate {
    /// A gate in [`Mode::Discard`].
    pub fn new() -> Arc<Self> {
        Arc::new(Self::default())
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
            if signalled || info.elapsed_time >= BLOCK_SLICE {
                BackpressureAction::DiscardDataAndFail
            } else {
                BackpressureAction::Retry
            }
        }
    }
}
