//! SIGINT, SIGTERM and SIGHUP as a flag; every other signal changes nothing
//! (docs/security.md, "Signals"). SIGHUP is a stop like the others: a closed terminal or ssh
//! session used to kill a long `eval` with its finished runs unwritten.
//!
//! iceoryx2 0.10 installs one handler (without `SA_RESTART`) for a dozen signals, SIGCONT and
//! SIGTSTP among them, and records only the *last* one in a single slot that every
//! `termination_requested()` call consumes. Three things followed: any signal interrupted a
//! wait and the wait reported an interrupt, which the product took for Ctrl-C (a SIGCONT from
//! job control, a debugger or a cgroup resume ended the stream); a SIGINT followed by any
//! other signal before the next check was forgotten; and Ctrl-Z did not stop the process. So
//! the product installs its own handler for SIGINT, SIGTERM and SIGHUP, which only sets a flag that
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

/// The signals that stop a run: the ones that ask a process to end (SIGXCPU: the soft CPU
/// limit, before the hard one kills).
const STOP: [libc::c_int; 4] = [libc::SIGINT, libc::SIGTERM, libc::SIGHUP, libc::SIGXCPU];
/// Signals whose default action kills the process although nobody asked it to end (a stray
/// timer, I/O readiness, a power event; SIGXFSZ makes the write that crossed the file-size
/// limit fail with `EFBIG` instead, an error the command reports): ignored, so that a run
/// never dies with its results unwritten. The real-time signals are ignored too
/// ([`install`]).
const IGNORED: [libc::c_int; 5] = [
    libc::SIGALRM,
    libc::SIGIO,
    libc::SIGPWR,
    libc::SIGXFSZ,
    libc::SIGSTKFLT,
];
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
        for s in IGNORED
            .into_iter()
            .chain(libc::SIGRTMIN()..=libc::SIGRTMAX())
        {
            set_action(s, libc::SIG_IGN);
        }
    });
}

fn set_action(signal: libc::c_int, handler: libc::sighandler_t) {
    // SAFETY: `sigaction` with a zeroed action, an empty mask and `SIG_DFL`, `SIG_IGN` or a
    // handler that only stores to atomics (async-signal-safe). No `SA_RESTART`: a blocking
    // wait returns at once on a stop signal, so a stop is seen within a wait slice.
    #[allow(unsafe_code)]
    unsafe {
        let mut action: libc::sigaction = std::mem::zeroed();
        action.sa_sigaction = handler;
        libc::sigemptyset(&mut action.sa_mask);
        let _ = libc::sigaction(signal, &action, std::ptr::null_mut());
    }
}

/// Whether a stop signal (SIGINT, SIGTERM, SIGHUP, SIGXCPU) arrived since the process
/// started (the first call installs the handlers). The flag stays set: every caller sees it, however many ask.
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
        libc::SIGHUP => "SIGHUP",
        libc::SIGXCPU => "SIGXCPU",
        _ => "a termination signal",
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sigcont_and_stray_signals_change_nothing_and_sigterm_sets_the_flag_for_every_caller() {
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
        // Signals that would kill by default without anyone asking for an end: ignored
        // (this test process would die here otherwise).
        for s in [libc::SIGALRM, libc::SIGIO, libc::SIGPWR, libc::SIGRTMIN()] {
            // SAFETY: raise(3) on this process; the signal is ignored.
            #[allow(unsafe_code)]
            unsafe {
                libc::raise(s);
            }
        }
        assert!(!termination_requested());
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
