//! Sending one slot by the contract's rules (docs/wire.md, "Sending a slot"): the slot
//! publisher with its stream header and back-pressure gate, blocked sends that give up on a
//! dead subscriber, slots sent again to a subscriber that missed them, and the waits, cut
//! into slices so that a stop is seen. Shared by `channel-sim`'s publisher
//! ([`crate::publisher`]) and the C client library (`clients/c/ffi`).

use crate::backpressure::{Gate, Mode, BLOCK_SLICE};
use anyhow::Result;
use estpipe_wire::services::SlotService;
use estpipe_wire::{self as wire, Slot, StreamHeader, SLOT_DATA};
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::SendError;
use iceoryx2::prelude::*;
use std::sync::Arc;
use std::time::Duration;

/// Why a wait ended early.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stop {
    /// SIGINT/SIGTERM/SIGHUP, or the end of the `--parent-pid` process ([`Gate::stop_requested`]).
    Signal,
}

/// Longest single sleep: a stop (a signal that landed just before the sleep began, or the
/// parent's end, which sends no signal) is seen within this.
pub const STOP_SLICE: Duration = Duration::from_millis(50);

/// Sleeps for `d`, or until [`Gate::stop_requested`]. A sleep cut short by any other signal
/// (SIGCONT, SIGSTOP then SIGCONT, SIGUSR1: iceoryx2 reports every interrupted sleep the
/// same way) is taken up again for the time that is left, so it changes nothing.
pub fn wait(node: &Node<ipc::Service>, gate: &Gate, d: Duration) -> Result<(), Stop> {
    let end = std::time::Instant::now() + d;
    loop {
        if gate.stop_requested() {
            return Err(Stop::Signal);
        }
        let left = end.saturating_duration_since(std::time::Instant::now());
        if left.is_zero() {
            return Ok(());
        }
        // An error is an interrupted sleep: the loop looks at the stop flag and sleeps on.
        let _ = node.wait(left.min(STOP_SLICE));
    }
}

/// What became of a slot handed to [`SlotSender::send`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sent {
    /// Delivered to every subscriber (or, in discard mode, dropped for a full one).
    Done,
    /// A termination request arrived while the send was blocked.
    Stopped,
    /// The subscriber the send waited for turned out to be dead and was cleaned up, or the
    /// marker's time ran out.
    GaveUp,
}

/// The slot publisher with what every send needs: the stream header, the back-pressure
/// gate and the node (for dead-node cleanup).
///
/// Public so that every publisher of the product sends a slot by the same rules
/// (`docs/wire.md`, "Sending a slot"): `channel-sim` here, and the C client library
/// (`clients/c/ffi`), which owns its node, service and gate, hence the [`Arc`]s.
#[derive(Debug)]
pub struct SlotSender {
    publisher: Publisher<ipc::Service, Slot, StreamHeader>,
    header: StreamHeader,
    gate: Arc<Gate>,
    node: Arc<Node<ipc::Service>>,
    service: Arc<SlotService>,
    /// Slots sent again after a blocked send gave up or a subscriber missed them.
    resent: u64,
    /// Slots a subscriber did not receive in discard mode (one per slot and subscriber).
    discarded: u64,
    /// The number of subscribers when some were found never to connect.
    unconnected_at: Option<usize>,
}

impl SlotSender {
    /// A sender of `publisher`'s slots (created on `service` with
    /// `RetryUntilDelivered` and `gate`'s [`Gate::handler`]), each with the user header
    /// `header`.
    pub fn new(
        publisher: Publisher<ipc::Service, Slot, StreamHeader>,
        header: StreamHeader,
        gate: Arc<Gate>,
        node: Arc<Node<ipc::Service>>,
        service: Arc<SlotService>,
    ) -> Self {
        Self {
            publisher,
            header,
            gate,
            node,
            service,
            resent: 0,
            discarded: 0,
            unconnected_at: None,
        }
    }

    /// Slots sent again after a blocked send gave up or a subscriber missed them.
    pub fn resent(&self) -> u64 {
        self.resent
    }

    /// Slots a subscriber did not receive in discard mode (one per slot and subscriber).
    pub fn discarded(&self) -> u64 {
        self.discarded
    }

    /// The subscribers of the slot service now.
    pub fn subscribers(&self) -> usize {
        self.service.dynamic_config().number_of_subscribers()
    }

    /// Subscribers that never connected and are not waited for; forgotten when the number
    /// of subscribers changed since (one left, or a new one came, which is waited for).
    fn unconnected(&mut self) -> usize {
        if self.unconnected_at.is_some_and(|s| s != self.subscribers()) {
            self.unconnected_at = None;
            self.gate.set_unconnected(0);
        }
        self.gate.unconnected() as usize
    }

    /// Sends `slot` (a marker: until `give_up`, even after a termination request). Blocking,
    /// a slot is sent again until every subscriber has it:
    ///
    /// * a send that blocked for a whole slice gave up on the blocked subscriber: unless a
    ///   signal or its death explains it, the slot goes again;
    /// * a subscriber that has not yet connected its end of the queue when the queue fills
    ///   is skipped by iceoryx2 (it refuses to wait for a receiver that may never come):
    ///   `send()` reports fewer receivers than there are subscribers, and the slot goes again
    ///   after a short pause.
    ///
    /// A second subscriber that already had the slot then receives it twice; the runner
    /// ignores a `seq` it has seen.
    pub fn send(&mut self, slot: Slot, give_up: Option<std::time::Instant>) -> Result<Sent> {
        let blocking = self.gate.mode() != Mode::Discard;
        let mut last_check = std::time::Instant::now();
        let mut internal_errors = 0u32;
        // Since when this slot has reached fewer subscribers than there are.
        let mut short_since: Option<std::time::Instant> = None;
        loop {
            self.gate.begin_send();
            let mut s = self.publisher.loan_uninit()?;
            *s.user_header_mut() = self.header;
            let mut out = s.write_payload(slot);
            if slot.kind != SLOT_DATA {
                out.payload_mut().send_ns = wire::monotonic_ns();
            }
            match out.send() {
                Ok(n) if !blocking => {
                    self.discarded += self.subscribers().saturating_sub(n) as u64;
                    return Ok(Sent::Done);
                }
                // A subscriber that does not read had the slot dropped (`--unread-limit`), or
                // never connected and is no longer waited for.
                Ok(n)
                    if n + self.gate.drops_this_send() + self.unconnected()
                        >= self.subscribers() =>
                {
                    return Ok(Sent::Done)
                }
                Ok(n) => {
                    let since = *short_since.get_or_insert_with(std::time::Instant::now);
                    if self
                        .gate
                        .unread_limit()
                        .is_some_and(|l| since.elapsed() >= l)
                    {
                        let subs = self.subscribers();
                        let missing = subs.saturating_sub(n + self.gate.drops_this_send());
                        self.unconnected_at = Some(subs);
                        self.gate.set_unconnected(missing as u32);
                        return Ok(Sent::Done);
                    }
                    // Backing off: a runner connects on its next read, within microseconds;
                    // one that does not read must not get thousands of duplicates.
                    let tries = since.elapsed().as_micros() / NOT_CONNECTED_PAUSE.as_micros();
                    std::thread::sleep(
                        NOT_CONNECTED_PAUSE
                            .saturating_mul(u32::try_from(tries).unwrap_or(u32::MAX).max(1) / 4 + 1)
                            .min(MAX_NOT_CONNECTED_PAUSE),
                    )
                }
                // Any signal interrupts iceoryx2's wait inside a blocked send (SIGCONT too),
                // which then reports an internal error rather than the signal: unless it was
                // a stop, the slot goes again. A cause that repeats on every try is not a
                // signal, and fails the run.
                Err(SendError::UnableToDeliver) => {}
                Err(e @ SendError::InternalError) => {
                    internal_errors += 1;
                    if internal_errors > MAX_INTERRUPTED_SENDS && !self.gate.stop_requested() {
                        return Err(e.into());
                    }
                }
                Err(e) => return Err(e.into()),
            }
            if give_up.is_none() && self.gate.stop_requested() {
                return Ok(Sent::Stopped);
            }
            if give_up.is_some_and(|t| std::time::Instant::now() > t) {
                return Ok(Sent::GaveUp);
            }
            if last_check.elapsed() >= BLOCK_SLICE {
                last_check = std::time::Instant::now();
                let _ = self.node.try_cleanup_dead_nodes();
                if self.subscribers() == 0 {
                    return Ok(Sent::GaveUp);
                }
            }
            self.resent += 1;
        }
    }
}

/// Pause before sending a slot again that a not yet connected subscriber missed.
const NOT_CONNECTED_PAUSE: Duration = Duration::from_micros(50);

/// The pause grows with the time the slot has been short (a quarter of it), up to this.
const MAX_NOT_CONNECTED_PAUSE: Duration = Duration::from_millis(10);

/// Internal errors one blocked send tolerates (each is a wait that a signal interrupted)
/// before the error counts as real.
const MAX_INTERRUPTED_SENDS: u32 = 1000;

/// Waits until `count()` > 0, cleaning up dead nodes on the way. `Ok(false)` on timeout
/// (`timeout` seconds; 0 waits for ever).
pub fn wait_for_subscriber(
    node: &Node<ipc::Service>,
    gate: &Gate,
    count: impl Fn() -> usize,
    timeout: f64,
) -> Result<bool, Stop> {
    let start = std::time::Instant::now();
    let mut last_cleanup = std::time::Instant::now();
    while count() == 0 {
        if timeout > 0.0 && start.elapsed().as_secs_f64() > timeout {
            return Ok(false);
        }
        if last_cleanup.elapsed() > Duration::from_millis(100) {
            let _ = node.try_cleanup_dead_nodes();
            last_cleanup = std::time::Instant::now();
        }
        wait(node, gate, Duration::from_millis(2))?;
    }
    Ok(true)
}
