//! The stop request of a bridge: the product's signal flag (`estpipe_process::signal`:
//! SIGINT, SIGTERM, SIGHUP, SIGXCPU; never an interrupted wait, since SIGCONT from job control
//! or a debugger interrupts sleeps too), or a parent that is gone.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// Latches the first termination request; shared with iceoryx2's back-pressure handler, which
/// runs inside a blocked send.
#[derive(Clone, Debug, Default)]
pub(crate) struct Stop {
    flag: Arc<AtomicBool>,
    parent: Option<u32>,
}

impl Stop {
    /// Installs the product's signal handlers (so that no stop signal's default action kills
    /// the bridge mid-send, without its report); with `parent`, a parent that is gone counts
    /// as a termination request.
    pub(crate) fn new(parent: Option<u32>) -> Self {
        let s = Self {
            flag: Arc::default(),
            parent,
        };
        let _ = s.requested();
        s
    }

    /// Whether a stop signal arrived, or the parent given is gone.
    pub(crate) fn requested(&self) -> bool {
        if !self.flag.load(Ordering::Relaxed)
            && (estpipe_process::signal::termination_requested()
                || self
                    .parent
                    .is_some_and(|p| std::os::unix::process::parent_id() != p))
        {
            self.flag.store(true, Ordering::Relaxed);
        }
        self.flag.load(Ordering::Relaxed)
    }
}
