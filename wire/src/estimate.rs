//! [`Estimate`]: one estimator's x̂_k and its covariance, the payload of `<prefix>/estimates`
//! and of the `<prefix>/estimates-latest` blackboard.

use crate::{MAX_NX, WIRE_VERSION};
use iceoryx2::prelude::*;

/// Entries of the packed upper triangle of an `MAX_NX × MAX_NX` covariance.
pub const COV_LEN: usize = MAX_NX * (MAX_NX + 1) / 2;

/// [`Estimate::status`]: the step succeeded.
pub const STATUS_OK: u32 = 0;
/// [`Estimate::status`]: the step refused its input (e.g. a non-finite measurement); the
/// estimate is the previous one.
pub const STATUS_REFUSED: u32 = 1;
/// [`Estimate::status`]: no step yet (the blackboard's placeholder before the first instant).
pub const STATUS_NONE_YET: u32 = 2;

/// [`Estimate::cov_kind`]: the estimator has no covariance; `p` is NaN.
pub const COV_NONE: u32 = 0;
/// [`Estimate::cov_kind`]: `p` is the estimator's error covariance P_k.
pub const COV_ESTIMATE: u32 = 1;
/// [`Estimate::cov_kind`]: `p` is an upper bound on the error covariance, the quantity the
/// estimator's paper propagates (the NN estimator, the Tobit filters).
pub const COV_BOUND: u32 = 2;

/// Index in [`Estimate::p`] of `P[i][j]` (either order) for an `nx`-state estimate: the
/// upper triangle row by row, `P00 P01 … P0(nx−1) P11 … P(nx−1)(nx−1)`, i.e.
/// `i·nx − i·(i−1)/2 + (j − i)` for `i ≤ j`. Entries from `nx·(nx+1)/2` on are 0.
pub const fn packed_index(nx: usize, i: usize, j: usize) -> usize {
    let (i, j) = if i <= j { (i, j) } else { (j, i) };
    i * nx - i * i.saturating_sub(1) / 2 + (j - i)
}

/// One estimator's estimate x̂_k, published by the runner after each instant.
#[derive(Clone, Copy, Debug, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("estpipe::wire::Estimate")]
pub struct Estimate {
    /// [`WIRE_VERSION`] of the writer.
    pub version: u32,
    /// Sampling instant k.
    pub k: u32,
    /// Stream the estimate belongs to.
    pub stream_id: u64,
    /// Running count of estimates published by this runner.
    pub seq: u64,
    /// Index of the estimator in the runner's list.
    pub estimator: u32,
    /// Valid entries of `x`.
    pub nx: u32,
    /// Estimator name, UTF-8, zero-padded.
    pub name: [u8; 16],
    /// [`STATUS_OK`], [`STATUS_REFUSED`] or [`STATUS_NONE_YET`].
    pub status: u32,
    /// What `p` holds: [`COV_NONE`], [`COV_ESTIMATE`] or [`COV_BOUND`].
    pub cov_kind: u32,
    /// x̂_k (entries ≥ `nx` are 0).
    pub x: [f64; MAX_NX],
    /// P_k's upper triangle row by row ([`packed_index`]); `nx·(nx+1)/2` valid entries.
    pub p: [f64; COV_LEN],
    /// `send_ns` of the slot that completed instant k.
    pub slot_send_ns: u64,
    /// `CLOCK_MONOTONIC` when the runner received that slot.
    pub receive_ns: u64,
    /// `CLOCK_MONOTONIC` when this estimator's step finished.
    pub step_done_ns: u64,
    /// Slots that arrived late and were folded into this estimator since its previous estimate
    /// (`--lag`, docs/pipeline.md "Late packets"): this estimate is the one they would have
    /// given on time. 0: no revision.
    pub late_folded: u32,
    /// The oldest instant those late slots belonged to (0 when `late_folded` is 0): the
    /// estimates published for instants `revised_from..k` are superseded.
    pub revised_from: u32,
}

impl Estimate {
    /// The placeholder of a latest-estimate board entry before the estimator's first step:
    /// `k = 0`, `seq = u64::MAX`, [`STATUS_NONE_YET`], `x` zero, no covariance.
    pub fn none_yet(estimator: u32, name: [u8; 16]) -> Self {
        Self {
            version: WIRE_VERSION,
            k: 0,
            stream_id: 0,
            seq: u64::MAX,
            estimator,
            nx: 0,
            name,
            status: STATUS_NONE_YET,
            cov_kind: COV_NONE,
            x: [0.0; MAX_NX],
            p: [f64::NAN; COV_LEN],
            slot_send_ns: 0,
            receive_ns: 0,
            step_done_ns: 0,
            late_folded: 0,
            revised_from: 0,
        }
    }

    /// Encodes an estimator name into the fixed 16-byte field (truncated on a char boundary).
    pub fn encode_name(name: &str) -> [u8; 16] {
        let mut out = [0u8; 16];
        let mut end = name.len().min(16);
        while !name.is_char_boundary(end) {
            end -= 1;
        }
        out[..end].copy_from_slice(&name.as_bytes()[..end]);
        out
    }

    /// The estimator name.
    pub fn name(&self) -> &str {
        let end = self.name.iter().position(|&b| b == 0).unwrap_or(16);
        core::str::from_utf8(&self.name[..end]).unwrap_or("?")
    }

    /// `P[i][j]` of the packed covariance.
    pub fn covariance(&self, i: usize, j: usize) -> f64 {
        self.p[packed_index(self.nx as usize, i, j)]
    }

    /// Packs the row-major `nx × nx` matrix `full` (its upper triangle) into `p`; entries
    /// past the triangle become 0.
    pub fn pack_covariance(nx: usize, full: &[f64], p: &mut [f64; COV_LEN]) {
        *p = [0.0; COV_LEN];
        for i in 0..nx {
            for j in i..nx {
                p[packed_index(nx, i, j)] = full[i * nx + j];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packed_index_walks_the_upper_triangle_row_by_row() {
        for nx in 1..=MAX_NX {
            let mut next = 0;
            for i in 0..nx {
                for j in i..nx {
                    assert_eq!(packed_index(nx, i, j), next, "nx {nx} ({i},{j})");
                    assert_eq!(packed_index(nx, j, i), next);
                    next += 1;
                }
            }
            assert_eq!(next, nx * (nx + 1) / 2);
        }
        assert_eq!(packed_index(MAX_NX, MAX_NX - 1, MAX_NX - 1), COV_LEN - 1);
    }

    #[test]
    fn pack_and_read_back() {
        let nx = 3;
        let full: Vec<f64> = (0..9).map(|v| f64::from(v as u8)).collect();
        let mut e = Estimate::none_yet(0, Estimate::encode_name("kf"));
        e.nx = nx as u32;
        Estimate::pack_covariance(nx, &full, &mut e.p);
        assert_eq!(e.covariance(0, 2), 2.0);
        assert_eq!(e.covariance(2, 0), 2.0);
        assert_eq!(e.covariance(1, 1), 4.0);
        assert_eq!(e.covariance(2, 2), 8.0);
        assert_eq!(e.p[6..], [0.0; COV_LEN - 6]);
    }

    #[test]
    fn names_are_truncated_on_char_boundaries() {
        let mut e = Estimate::none_yet(0, Estimate::encode_name("cce"));
        assert_eq!(e.name(), "cce");
        e.name = Estimate::encode_name("ααααααααα"); // 18 bytes
        assert_eq!(e.name(), "αααααααα");
    }
}
