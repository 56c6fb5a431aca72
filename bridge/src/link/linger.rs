//! When a `--once` bridge ends: its stream is over, and the estimates that still come back
//! for it have gone quiet.

use std::time::{Duration, Instant};

/// After the stream ended (`--once`), estimates are forwarded until none came for this long.
pub(crate) const LINGER: Duration = Duration::from_millis(500);

/// The end of a stream, as the `--once` exit of either side sees it.
#[derive(Debug)]
pub(crate) struct Linger {
    /// When the first END/ABORT marker went through.
    ended_at: Option<Instant>,
    last_estimate: Instant,
}

impl Linger {
    /// A stream not ended yet; the estimates' quiet counts from now.
    pub(crate) fn new() -> Self {
        Self {
            ended_at: None,
            last_estimate: Instant::now(),
        }
    }

    /// A marker went through: its node's stream is over.
    pub(crate) fn ended(&mut self) {
        self.ended_at.get_or_insert_with(Instant::now);
    }

    /// Whether a marker went through.
    pub(crate) fn is_ended(&self) -> bool {
        self.ended_at.is_some()
    }

    /// An estimate came back.
    pub(crate) fn estimate(&mut self) {
        self.last_estimate = Instant::now();
    }

    /// Whether the stream ended more than [`LINGER`] ago and no estimate came for as long: a
    /// runner still stepping the last instants would be cut off sooner.
    pub(crate) fn over(&self) -> bool {
        self.ended_at
            .is_some_and(|t| t.elapsed() > LINGER && self.last_estimate.elapsed() > LINGER)
    }
}
