//! SIGINT and SIGTERM as a flag; every other signal changes nothing (docs/security.md,
//! "Signals").
//!
//! iceoryx2 0.10 installs one handler (without `SA_RESTART`) for a dozen signals, SIGCONT and
//! SIGTSTP among them, and records only the *last* one in a single slot that every
//! `termination_requested()` call consumes. Three things followed: any signal interrupted a
//! wait and the wait reported an interrupt, which the product took for Ctrl-C (a SIGCONT from
//! job control, a debugger or a cgroup resume ended the stream); a SIGINT followed by any
//! other signal before the next check was forgotten; and Ctrl-Z did not stop the process. So
//! the product installs its own handler for SIGINT and SIGTERM, which only sets a flag that
//! stays set, and gives the job-control signals back their default actions. A wait that
//! returns early (`EINTR`: a signal, or on Linux a stop and continue even without a handler)
//! is only a wake-up: callers look at [`termination_requested`] and wait again.
//!
//! Asking the flag costs one atomic load, so the busy-polling loop can ask without sleeping
//! (iceoryx2's `Node::wait(ZERO)` calls `nanosleep(0)`, which Linux lets run late by the
//! timer slack, 50 µs by default: docs/pipeline.md).

use iceoryx2_bb_posix::signal::SignalHandler;
use std::sync::atomic::{AtomicBool, AtomicI32, Ordering};
use std::sync::Once;

static TERMINATION: AtomicBool = AtomicBool::new(false);
static SIGNAL: AtomicI32 = AtomicI32::new(0);
static INSTALL: Once = Once::new();

/// The signals that stop a run.
const STOP: [libc::c_int; 2] = [libc::SIGINT, libc::SIGTERM];
/// Job control: iceoryx2 catches these, so Ctrl-Z would neither stop the process nor would
/// `fg` resume it without interrupting every wait. Their default actions are restored.
const JOB_CONTROL: [libc::c_int; 4] = [libc::SIGTSTP, libc::SIGTTIN, libc::SIGTTOU, libc::SIGCONT];

extern "C" fn on_stop(signal: libc::c_int) {
    // Only async-signal-safe work here: two atomic stores.
    SIGNAL.store(signal, Ordering::Relaxed);
    TERMINATION.store(true, Ordering::SeqCst);
}

/// Installs the handlers (once per process; later calls do nothing). Call it before the
/// first wait; [`termination_requested`] calls it too.
pub fn install() {
    INSTALL.call_once(|| {
        // iceoryx2 registers its handlers when its signal handler is first used (by the first
        // `Node::wait` or WaitSet wait); that would replace ours, so let it happen now, first.
        let _ = SignalHandler::last_signal();
        for s in STOP {
            set_action(s, on_stop as *const () as libc::sighandler_t);
        }
        for s in JOB_CONTROL {
            set_action(s, libc::SIG_DFL);
        }
    });
}

fn set_action(signal: libc::c_int, handler: libc::sighandler_t) {
    // SAFETY: `sigaction` with a zeroed action, an empty mask and either `SIG_DFL` or a handler
    // that only stores to atomics (async-signal-safe). No `SA_RESTART`: a blocking wait returns
    // at once on SIGINT/SIGTERM, so a stop is seen within a wait slice.
    #[allow(unsafe_code)]
    unsafe {
        let mut action: libc::sigaction = std::mem::zeroed();
        action.sa_sigaction = handler;
        libc::sigemptyset(&mut action.sa_mask);
        let _ = libc::sigaction(signal, &action, std::ptr::null_mut());
    }
}

/// Whether SIGINT or SIGTERM arrived since the process started (the first call installs the
/// handlers). The flag stays set: every caller sees it, however many ask.
#[inline]
pub fn termination_requested() -> bool {
    install();
    TERMINATION.load(Ordering::Relaxed)
}

/// The name of the signal that requested termination (`None` before one arrived).
pub fn termination_signal() -> Option<&'static str> {
    if !TERMINATION.load(Ordering::SeqCst) {
        return None;
    }
    Some(match SIGNAL.load(Ordering::Relaxed) {
        libc::SIGINT => "SIGINT",
        libc::SIGTERM => "SIGTERM",
        _ => "a termination signal",
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sigcont_changes_nothing_and_sigterm_sets_the_flag_for_every_caller() {
        install();
        assert!(!termination_requested());
        // SAFETY: raise(3) on this process; SIGCONT's default action on a running process is
        // nothing.
        #[allow(unsafe_code)]
        unsafe {
            libc::raise(libc::SIGCONT);
        }
        assert!(!termination_requested());
        assert_eq!(termination_signal(), None);
        #[allow(unsafe_code)]
        // SAFETY: raise(3); our handler only sets the flag.
        unsafe {
            libc::raise(libc::SIGTERM);
        }
        // Not consumed: every caller sees it.
        assert!(termination_requested());
        assert!(termination_requested());
        assert_eq!(termination_signal(), Some("SIGTERM"));
    }
}
