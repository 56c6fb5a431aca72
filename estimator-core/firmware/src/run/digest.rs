//! FNV-1a 64: the vector files' check hash and the digest of a run's estimates.

use nalgebra::{SMatrix, SVector};

/// FNV-1a, 64 bit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Fnv1a64(pub u64);

impl Default for Fnv1a64 {
    fn default() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }
}

impl Fnv1a64 {
    /// Feeds bytes.
    pub fn bytes(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 ^= u64::from(b);
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }

    /// Feeds the IEEE-754 bit pattern of `x`, little-endian.
    pub fn f32(&mut self, x: f32) {
        self.bytes(&x.to_bits().to_le_bytes());
    }

    /// Feeds an estimate: every entry of x̂, then the upper triangle of P row by row.
    pub fn estimate<const N: usize>(&mut self, x: &SVector<f32, N>, p: &SMatrix<f32, N, N>) {
        for i in 0..N {
            self.f32(x[i]);
        }
        for i in 0..N {
            for j in i..N {
                self.f32(p[(i, j)]);
            }
        }
    }
}

/// FNV-1a 64 of a byte string.
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut h = Fnv1a64::default();
    h.bytes(bytes);
    h.0
}
