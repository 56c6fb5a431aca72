//! The loop's side of the live view (docs/view.md): after an instant's estimates are
//! published, each estimator's x̂ and the diagonal of its covariance, every node's slot status
//! and the truth go into a bounded queue with `try_send`, which never blocks and allocates
//! nothing; when the view falls behind the record is dropped (counted by the view as a gap).
//! The view does not subscribe to `<prefix>/estimates`: one more subscriber would cost every
//! send a delivery on the latency path. Without `--view` the tap is empty and costs one
//! branch.

use estpipe_wire::{Observation, FLAG_IPC_LOST, FLAG_NET_LOST, MAX_NODES, MAX_NX};
use std::sync::mpsc::SyncSender;

/// A node's slot was delivered.
pub const DELIVERED: u8 = 0;
/// Dropped by the channel (the publisher said so).
pub const DROPPED: u8 = 1;
/// Lost in the IPC or on the network (the runner never had it).
pub const LOST: u8 = 2;
/// Arrived after its instant was handed on (`--lag`).
pub const LATE: u8 = 3;

/// What became of a node's slot at its instant: [`DELIVERED`], [`LOST`] (flagged lost in the
/// IPC or on the network) or [`DROPPED`] (by the channel); the plots of a finished run use the
/// same codes.
#[inline]
pub fn slot_status(o: &Observation) -> u8 {
    if o.delivered {
        DELIVERED
    } else if o.flags & (FLAG_IPC_LOST | FLAG_NET_LOST) != 0 {
        LOST
    } else {
        DROPPED
    }
}

/// One instant as the loop saw it.
#[derive(Clone, Copy, Debug)]
pub struct InstantEvent {
    /// Session of the runner.
    pub session: u32,
    /// The instant.
    pub k: u32,
    /// Sensor nodes (valid entries of `status`).
    pub nodes: u8,
    /// [`DELIVERED`], [`DROPPED`] or [`LOST`] per node.
    pub status: [u8; MAX_NODES],
    /// Whether `truth` holds x_k.
    pub has_truth: bool,
    /// x_k (valid: the scenario's nx entries).
    pub truth: [f64; MAX_NX],
}

/// One estimator's estimate of an instant, the values it was published with.
#[derive(Clone, Copy, Debug)]
pub struct EstimateEvent {
    /// The instant.
    pub k: u32,
    /// The estimator's name, as on the wire (NUL-padded).
    pub name: [u8; 16],
    /// Valid entries of `x` and `var`.
    pub nx: u8,
    /// x̂_k.
    pub x: [f64; MAX_NX],
    /// The diagonal of the published covariance (or bound).
    pub var: [f64; MAX_NX],
    /// The estimate message's `cov_kind`.
    pub cov_kind: u32,
    /// The runner's end-to-end latency of the instant (slot sent → estimates published), µs;
    /// NaN when the slot's send time is unusable.
    pub latency_us: f64,
}

/// What the loop tells the view.
#[derive(Clone, Copy, Debug)]
pub enum ViewEvent {
    /// An estimate was published (before its instant's [`ViewEvent::Instant`]).
    Estimate(EstimateEvent),
    /// An instant's estimates were published.
    Instant(InstantEvent),
    /// A late slot of instant `k` from `node` arrived.
    Late {
        /// Its instant.
        k: u32,
        /// Its node.
        node: u8,
    },
    /// The run ended.
    Ended,
}

/// The sending end; empty without `--view`.
#[derive(Clone, Debug, Default)]
pub struct ViewTap(Option<SyncSender<ViewEvent>>);

impl ViewTap {
    /// A tap into `tx`.
    pub fn new(tx: SyncSender<ViewEvent>) -> Self {
        Self(Some(tx))
    }

    /// Whether a view listens.
    #[inline]
    pub fn is_on(&self) -> bool {
        self.0.is_some()
    }

    /// An estimate that was published; never blocks.
    #[inline]
    pub fn estimate(&self, e: EstimateEvent) {
        if let Some(tx) = &self.0 {
            let _ = tx.try_send(ViewEvent::Estimate(e));
        }
    }

    /// Instant `k`'s node statuses and truth; never blocks.
    #[inline]
    pub fn instant(
        &self,
        session: u32,
        k: u32,
        obs: &[Observation],
        truth: Option<&[f64; MAX_NX]>,
    ) {
        let Some(tx) = &self.0 else { return };
        let mut status = [DELIVERED; MAX_NODES];
        for (s, o) in status.iter_mut().zip(obs) {
            *s = slot_status(o);
        }
        let _ = tx.try_send(ViewEvent::Instant(InstantEvent {
            session,
            k,
            nodes: obs.len().min(MAX_NODES) as u8,
            status,
            has_truth: truth.is_some(),
            truth: truth.copied().unwrap_or([f64::NAN; MAX_NX]),
        }));
    }

    /// A late slot; never blocks.
    #[inline]
    pub fn late(&self, k: u32, node: u8) {
        if let Some(tx) = &self.0 {
            let _ = tx.try_send(ViewEvent::Late { k, node });
        }
    }

    /// The run ended; never blocks.
    pub fn ended(&self) {
        if let Some(tx) = &self.0 {
            let _ = tx.try_send(ViewEvent::Ended);
        }
    }
}
