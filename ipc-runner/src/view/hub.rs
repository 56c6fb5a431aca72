//! The frames the live view sends (docs/view.md): every frame goes to the connected pages
//! through a bounded broadcast queue (a page that falls [`QUEUE`] frames behind is dropped,
//! never waited for), and frames with points are kept, up to [`HISTORY_BYTES`], for a page
//! that connects later.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use tokio::sync::broadcast;

/// Frames a page may fall behind before it is dropped (3 s at 20 frames per second).
pub const QUEUE: usize = 64;
/// Bytes of frames kept for pages that connect later.
pub const HISTORY_BYTES: usize = 16 << 20;
/// Pages connected at once at most.
pub const MAX_CLIENTS: usize = 16;

#[derive(Debug, Default)]
struct Inner {
    history: VecDeque<Arc<str>>,
    bytes: usize,
    /// The newest frame (the state a new page starts from).
    last: Option<Arc<str>>,
}

/// Frames to the pages.
#[derive(Debug)]
pub struct Hub {
    inner: Mutex<Inner>,
    tx: broadcast::Sender<Arc<str>>,
    /// Pages connected now.
    pub clients: AtomicUsize,
    /// Pages dropped because they did not keep up.
    pub dropped: AtomicU64,
}

impl Default for Hub {
    fn default() -> Self {
        Self {
            inner: Mutex::default(),
            tx: broadcast::channel(QUEUE).0,
            clients: AtomicUsize::new(0),
            dropped: AtomicU64::new(0),
        }
    }
}

impl Hub {
    fn lock(&self) -> std::sync::MutexGuard<'_, Inner> {
        self.inner.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Sends `frame` to every page; keeps it for later pages when `keep`.
    pub fn publish(&self, frame: Arc<str>, keep: bool) {
        let mut g = self.lock();
        if keep {
            g.bytes += frame.len();
            g.history.push_back(Arc::clone(&frame));
            while g.bytes > HISTORY_BYTES {
                match g.history.pop_front() {
                    Some(f) => g.bytes -= f.len(),
                    None => break,
                }
            }
        } else {
            g.last = Some(Arc::clone(&frame));
        }
        // No page connected is no error.
        let _ = self.tx.send(frame);
    }

    /// For a new page: the kept frames and the newest state frame, and the queue of the frames
    /// after them (no frame missed, none twice).
    pub fn subscribe(&self) -> (Vec<Arc<str>>, broadcast::Receiver<Arc<str>>) {
        let g = self.lock();
        let rx = self.tx.subscribe();
        let mut past: Vec<Arc<str>> = g.history.iter().cloned().collect();
        past.extend(g.last.iter().cloned());
        (past, rx)
    }

    /// Counts a page dropped for not keeping up (`why`), and says so on stderr: a page that
    /// stops reading is let go, never waited for (docs/view.md, "Hostile pages").
    pub fn drop_slow(&self, why: &str) {
        let n = self.dropped.fetch_add(1, Ordering::Relaxed) + 1;
        estpipe_process::errln!("view: dropped a page that {why} ({n} dropped so far)");
    }
}
