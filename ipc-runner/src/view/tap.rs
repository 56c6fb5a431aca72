//! The loop's side of the live view (docs/view.md): after an instant's estimates are
//! published, what the estimates service does not carry — every node's slot status and the
//! truth — goes into a bounded queue with `try_send`, which never blocks and allocates
//! nothing; when the view falls behind the record is dropped (counted by the view as a gap).
//! Without `--view` the tap is empty and costs one branch.

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

/// What the loop tells the view.
#[derive(Clone, Copy, Debug)]
pub enum ViewEvent {
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
