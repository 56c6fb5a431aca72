//! When the loop next expects a slot: the data deadline after the last one (its period plus
//! `--deadline-ms`), the connect timeout before a stream's first, and the re-checks of a
//! stalled publisher against `--stall-limit`.

use super::args::RunArgs;
use estpipe_wire as wire;

/// How long a wait for a stream's first slot spins before it sleeps.
const IDLE_AFTER_NS: u64 = 100_000_000;

/// When the next slot is due.
pub(super) struct Deadline {
    pub(super) deadline_ns: u64,
    pub(super) connect_ns: u64,
    /// `--stall-limit` (0: none).
    pub(super) stall_ns: u64,
    pub(super) period_ns: u64,
    /// `None` while waiting for the first slot of a stream (the connect timeout applies).
    pub(super) last_data_ns: Option<u64>,
    pub(super) waiting_since: u64,
    /// While the publisher is stalled: when to look at it again.
    pub(super) recheck_ns: Option<u64>,
}

impl Deadline {
    pub(super) fn new(args: &RunArgs) -> Self {
        Self {
            deadline_ns: (args.deadline_ms * 1e6) as u64,
            connect_ns: (args.connect_timeout * 1e9) as u64,
            stall_ns: (args.stall_limit * 1e9) as u64,
            period_ns: 0,
            last_data_ns: None,
            waiting_since: wire::monotonic_ns(),
            recheck_ns: None,
        }
    }

    /// A slot arrived at `recv_ns`; the silence it ended if the publisher was stalled.
    #[inline]
    pub(super) fn data(&mut self, recv_ns: u64) -> Option<u64> {
        let last = self.last_data_ns.replace(recv_ns);
        self.recheck_ns
            .take()
            .map(|_| recv_ns.saturating_sub(last.unwrap_or(recv_ns)))
    }

    /// Whether the loop has waited for a stream's first slot longer than [`IDLE_AFTER_NS`]
    /// at `now` (the first moments of a wait still spin: a publisher that is already there
    /// gets the spin loop's latency from its first slot on).
    #[inline]
    pub(super) fn idle_since(&self, now: u64) -> bool {
        self.last_data_ns.is_none() && now.saturating_sub(self.waiting_since) > IDLE_AFTER_NS
    }

    pub(super) fn due(&self) -> u64 {
        if let Some(t) = self.recheck_ns {
            return t;
        }
        match self.last_data_ns {
            Some(t_last) => t_last
                .saturating_add(self.period_ns)
                .saturating_add(self.deadline_ns),
            None if self.connect_ns == 0 => u64::MAX,
            None => self.waiting_since.saturating_add(self.connect_ns),
        }
    }
}
