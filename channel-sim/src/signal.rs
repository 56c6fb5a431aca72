//! Ctrl-C / SIGTERM without sleeping.
//!
//! iceoryx2's `Node::wait(Duration::ZERO)` is the documented way to ask for a termination
//! request, but it calls `nanosleep(0)`, and Linux lets a normal thread's sleep run late by
//! its timer slack: 50 µs by default (measured here: 55 µs median per call). A busy-polling
//! loop that checks for signals every millisecond with it is deaf for 5 % of the time, and
//! slots landing in those gaps wait. This asks iceoryx2's signal handler directly.

use iceoryx2_bb_posix::signal::SignalHandler;

/// Whether SIGINT or SIGTERM arrived since the last call (the first call installs
/// iceoryx2's handlers, as `Node::wait` does). Consumes the signal: call it from one place.
pub fn termination_requested() -> bool {
    SignalHandler::termination_requested()
}
