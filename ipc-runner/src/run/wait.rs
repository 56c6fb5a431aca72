//! Waiting for the next slot, one way per [`WaitMode`](super::args::WaitMode):
//!
//! * **spin** busy-polls: a wait is one `PAUSE`, and the clock (and with it the deadline and
//!   the signal check) is read only every [`SPIN_CLOCK_EVERY`] empty polls;
//! * **block** sleeps in a WaitSet on the `slots-ready` event;
//! * **listener** sleeps on the `slots-ready` listener directly.
//!
//! A wake-up says only that something may be there: wake-ups can be spurious and one
//! notification may stand for several slots, so the loop re-drains `receive()` after each.
//!
//! Only SIGINT/SIGTERM/SIGHUP stop a run: the flag of `estpipe_process::signal`, read after every
//! wake-up. iceoryx2 reports every wait that a signal cut short as an interrupt (SIGCONT, a
//! stop and continue, SIGUSR1 …); that is a wake-up like any other (docs/security.md,
//! "Signals").

use crate::transport::Transport;
use anyhow::{anyhow, bail, Result};
use estpipe_wire as wire;
use iceoryx2::port::listener::{Listener, ListenerWaitError};
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetGuard;
use std::time::Duration;

use super::args::WaitMode;

/// Spin mode reads the clock once per this many empty polls. A `clock_gettime` costs about
/// as much as a poll, so reading it every poll (twice, as the loop once did) stretches the
/// time between polls, and with it the delay before a landed slot is seen (profile in
/// `docs/pipeline.md`). The deadlines the clock serves are milliseconds; 256 polls are far
/// shorter.
pub const SPIN_CLOCK_EVERY: u32 = 256;

/// Why a wait returned.
#[derive(Debug)]
pub(super) enum Woke {
    /// Slots may be there.
    Ready,
    /// SIGINT, SIGTERM or SIGHUP.
    Signal,
}

/// The WaitSet `--wait block` sleeps in (`None` otherwise). The caller owns it because the
/// [`Waiter`] borrows it.
pub(super) fn waitset(mode: WaitMode, t: &Transport) -> Result<Option<WaitSet<ipc::Service>>> {
    match &t.listener {
        Some(_) if mode == WaitMode::Block => Ok(Some(
            WaitSetBuilder::new()
                .create::<ipc::Service>()
                .map_err(|e| anyhow!("cannot create WaitSet: {e:?}"))?,
        )),
        _ => Ok(None),
    }
}

/// The wait primitive of a run.
pub(super) enum Waiter<'a> {
    /// `--wait spin` (no listener).
    Spin(Spin),
    /// `--wait block`.
    Block(Block<'a>),
    /// `--wait listener`.
    Listener(Sleep<'a>),
}

impl<'a> Waiter<'a> {
    /// Block with `waitset` and `t`'s listener, listener with the listener alone, else spin.
    pub(super) fn new(
        t: &'a Transport,
        waitset: Option<&'a WaitSet<ipc::Service>>,
    ) -> Result<Self> {
        Ok(match (waitset, &t.listener) {
            (Some(ws), Some(l)) => Self::Block(Block {
                guard: ws
                    .attach_notification(l)
                    .map_err(|e| anyhow!("cannot attach listener to WaitSet: {e:?}"))?,
                waitset: ws,
                listener: l,
            }),
            (None, Some(l)) => Self::Listener(Sleep { listener: l }),
            _ => Self::Spin(Spin::new()),
        })
    }

    /// The time to check the deadline against, or `None` when a termination request arrived.
    /// Spinning hands out its last clock reading (a stale `now` can only make a deadline fire
    /// later) and checks for signals here; the sleeping modes read the clock and check for
    /// signals in [`Waiter::wait`].
    #[inline]
    pub(super) fn now(&mut self) -> Option<u64> {
        match self {
            Self::Spin(s) => s.now(),
            Self::Block(_) | Self::Listener(_) => Some(wire::monotonic_ns()),
        }
    }

    /// Waits until slots may be there, a signal arrived, or about `timeout_ns` passed;
    /// `idle` (no stream yet): spinning sleeps [`IDLE_SLEEP`] per poll instead.
    #[inline]
    pub(super) fn wait(&mut self, timeout_ns: u64, idle: bool) -> Result<Woke> {
        match self {
            Self::Spin(s) if idle => Ok(s.sleep(timeout_ns)),
            Self::Spin(_) => {
                // One PAUSE per poll: a longer back-off (32 were here) delays a slot that lands
                // just after a poll by all of it. Signals are checked in `now`.
                core::hint::spin_loop();
                Ok(Woke::Ready)
            }
            Self::Block(b) => b.wait(timeout_ns),
            Self::Listener(l) => l.wait(timeout_ns),
        }
    }
}

/// The spin loop's clock: read every [`SPIN_CLOCK_EVERY`] polls, and the stop flag with it.
pub(super) struct Spin {
    idle_polls: u32,
    clock: u64,
}

impl Spin {
    fn new() -> Self {
        Self {
            idle_polls: 0,
            clock: wire::monotonic_ns(),
        }
    }

    /// Signals through `estpipe_process::signal` (one atomic load), not `Node::wait(ZERO)`: its
    /// `nanosleep(0)` would leave the loop deaf for the timer slack.
    #[inline]
    fn now(&mut self) -> Option<u64> {
        self.idle_polls = self.idle_polls.wrapping_add(1);
        if self.idle_polls.is_multiple_of(SPIN_CLOCK_EVERY) {
            self.clock = wire::monotonic_ns();
            if estpipe_process::signal::termination_requested() {
                return None;
            }
        }
        Some(self.clock)
    }
}

/// How long a spinning loop with no stream sleeps between polls: the delay its first slot
/// may wait, against a core kept busy for as long as no publisher comes.
pub(super) const IDLE_SLEEP: Duration = Duration::from_millis(1);

impl Spin {
    /// Sleeps up to [`IDLE_SLEEP`] (at most `timeout_ns`), then reads the clock and the stop
    /// flag, as every sleeping mode does after a wake-up.
    fn sleep(&mut self, timeout_ns: u64) -> Woke {
        std::thread::sleep(IDLE_SLEEP.min(Duration::from_nanos(timeout_ns.max(1000))));
        self.clock = wire::monotonic_ns();
        woke()
    }
}

/// After a wake-up (whatever its cause): a stop, or slots may be there.
#[inline]
fn woke() -> Woke {
    if estpipe_process::signal::termination_requested() {
        Woke::Signal
    } else {
        Woke::Ready
    }
}

/// `--wait block`: the listener attached to a WaitSet.
pub(super) struct Block<'a> {
    waitset: &'a WaitSet<ipc::Service>,
    guard: WaitSetGuard<'a, 'a, ipc::Service>,
    listener: &'a Listener<ipc::Service>,
}

impl Block<'_> {
    fn wait(&mut self, timeout_ns: u64) -> Result<Woke> {
        let (g, l) = (&self.guard, self.listener);
        // The result (`Interrupt` for any signal, SIGCONT too; `TerminationRequest` for
        // iceoryx2's own record of one; else events or a timeout) is a wake-up either way:
        // the stop flag decides, as after every other wake-up.
        self.waitset
            .wait_and_process_once_with_timeout(
                |id| {
                    if id.has_event_from(g) {
                        // Consume the notifications; the data is drained by the caller.
                        let _ = l.try_wait(|_| {});
                    }
                    CallbackProgression::Continue
                },
                Duration::from_nanos(timeout_ns.max(1000)),
            )
            .map_err(|e| anyhow!("WaitSet failed: {e:?}"))?;
        Ok(woke())
    }
}

/// `--wait listener`: a timed wait on the listener itself.
pub(super) struct Sleep<'a> {
    listener: &'a Listener<ipc::Service>,
}

impl Sleep<'_> {
    fn wait(&mut self, timeout_ns: u64) -> Result<Woke> {
        match self
            .listener
            .timed_wait(|_| {}, Duration::from_nanos(timeout_ns.max(1000)))
        {
            // A signal cut the wait short: Ctrl-C if the flag says so, else nothing.
            Ok(_) | Err(ListenerWaitError::InterruptSignal) => Ok(woke()),
            Err(e) => bail!("listener wait failed: {e:?}"),
        }
    }
}
