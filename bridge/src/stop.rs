//! SIGINT/SIGTERM as a flag, never as an interrupted wait: SIGCONT (job control, a debugger)
//! interrupts sleeps too and must not stop the bridge.

use iceoryx2_bb_posix::signal::SignalHandler;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};

/// A stop request of the binary the bridge runs in ([`also_stop_when`]).
static ALSO: OnceLock<fn() -> bool> = OnceLock::new();

/// Makes `requested` a stop request of every bridge of this process, beside iceoryx2's
/// SIGINT/SIGTERM: `ipc-runner bridge` passes the product's signal flag
/// (`channel_sim::signal`, which also stops on SIGHUP and SIGXCPU and owns SIGINT/SIGTERM
/// once installed), so that a closed terminal ends a bridge with its report, as it ends
/// `run`. The first call counts.
pub fn also_stop_when(requested: fn() -> bool) {
    let _ = ALSO.set(requested);
}

/// Latches the first termination request (iceoryx2's handler consumes it when asked); shared
/// with iceoryx2's back-pressure handler, which runs inside a blocked send.
#[derive(Clone, Debug, Default)]
pub(crate) struct Stop {
    flag: Arc<AtomicBool>,
    parent: Option<u32>,
}

impl Stop {
    /// Installs iceoryx2's handlers (so the default action never kills us mid-send); with
    /// `parent`, a parent that is gone counts as a termination request.
    pub(crate) fn new(parent: Option<u32>) -> Self {
        let s = Self {
            flag: Arc::default(),
            parent,
        };
        let _ = s.requested();
        s
    }

    /// Whether SIGINT or SIGTERM arrived (or what [`also_stop_when`] asks for), or the parent
    /// given is gone.
    pub(crate) fn requested(&self) -> bool {
        if !self.flag.load(Ordering::Relaxed)
            && (SignalHandler::termination_requested()
                || ALSO.get().is_some_and(|f| f())
                || self
                    .parent
                    .is_some_and(|p| std::os::unix::process::parent_id() != p))
        {
            self.flag.store(true, Ordering::Relaxed);
        }
        self.flag.load(Ordering::Relaxed)
    }
}
