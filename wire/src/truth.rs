//! [`Truth`]: the true state, the payload of `<prefix>/truth` (evaluation only).

use crate::{MAX_NX, WIRE_VERSION};
use iceoryx2::prelude::*;

/// The true state x_k of one instant (evaluation only; estimators never read it).
#[derive(Clone, Copy, Debug, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("estpipe::wire::Truth")]
pub struct Truth {
    /// [`WIRE_VERSION`] of the writer.
    pub version: u32,
    /// Sampling instant k (0 = the initial state x_0).
    pub k: u32,
    /// The stream of node 0 (its publisher publishes the truth; as in [`Slot`](crate::Slot)).
    pub stream_id: u64,
    /// Valid entries of `x`.
    pub nx: u32,
    /// Reserved, 0.
    pub reserved: u32,
    /// x_k.
    pub x: [f64; MAX_NX],
}

impl Truth {
    /// Truth payload of instant `k`.
    pub fn new(k: u32, stream_id: u64, nx: usize, x: &[f64; MAX_NX]) -> Self {
        Self {
            version: WIRE_VERSION,
            k,
            stream_id,
            nx: nx as u32,
            reserved: 0,
            x: *x,
        }
    }
}
