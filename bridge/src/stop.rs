//! SIGINT/SIGTERM as a flag, never as an interrupted wait: SIGCONT (job control, a debugger)
//! interrupts sleeps too and must not stop the bridge.

use iceoryx2_bb_posix::signal::SignalHandler;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// Latches the first termination request (iceoryx2's handler consumes it when asked); shared
/// with iceoryx2's back-pressure handler, which runs inside a blocked send.
#[derive(Clone, Debug, Default)]
pub(crate) struct Stop(Arc<AtomicBool>);

impl Stop {
    /// Installs iceoryx2's handlers (so the default action never kills us mid-send).
    pub(crate) fn new() -> Self {
        let s = Self::default();
        let _ = s.requested();
        s
    }

    /// Whether SIGINT or SIGTERM arrived.
    pub(crate) fn requested(&self) -> bool {
        if !self.0.load(Ordering::Relaxed) && SignalHandler::termination_requested() {
            self.0.store(true, Ordering::Relaxed);
        }
        self.0.load(Ordering::Relaxed)
    }
}
