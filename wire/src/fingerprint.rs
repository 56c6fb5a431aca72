//! [`Fnv1a64`]: the hash behind [`StreamHeader::model`](crate::StreamHeader::model).
//!
//! FNV-1a with 64 bits (offset basis `0xcbf29ce484222325`, prime `0x100000001b3`) over a byte
//! sequence made of the writes below, all little-endian. What a scenario feeds it is defined
//! in `docs/wire.md` ("Model fingerprint"); a foreign publisher does not need to compute it,
//! it copies the value `ipc-runner stream-header` prints.

/// An FNV-1a 64 hasher with the contract's encodings of integers, floats, strings and
/// matrices.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Fnv1a64(u64);

impl Default for Fnv1a64 {
    fn default() -> Self {
        Self::new()
    }
}

impl Fnv1a64 {
    const OFFSET_BASIS: u64 = 0xcbf2_9ce4_8422_2325;
    const PRIME: u64 = 0x0000_0100_0000_01b3;

    /// The empty hash (the offset basis).
    pub const fn new() -> Self {
        Self(Self::OFFSET_BASIS)
    }

    /// Raw bytes.
    pub fn bytes(&mut self, b: &[u8]) -> &mut Self {
        for &x in b {
            self.0 ^= u64::from(x);
            self.0 = self.0.wrapping_mul(Self::PRIME);
        }
        self
    }

    /// An integer as 8 bytes little-endian.
    pub fn u64(&mut self, v: u64) -> &mut Self {
        self.bytes(&v.to_le_bytes())
    }

    /// A float as its IEEE-754 bits (`f64::to_bits`), 8 bytes little-endian: exact, and
    /// `0.0` and `-0.0` differ.
    pub fn f64(&mut self, v: f64) -> &mut Self {
        self.u64(v.to_bits())
    }

    /// Floats, one after the other (no length).
    pub fn f64s(&mut self, v: &[f64]) -> &mut Self {
        for &x in v {
            self.f64(x);
        }
        self
    }

    /// A string as its byte length ([`Fnv1a64::u64`]) then its UTF-8 bytes.
    pub fn str(&mut self, s: &str) -> &mut Self {
        self.u64(s.len() as u64).bytes(s.as_bytes())
    }

    /// A matrix as `rows`, `cols` ([`Fnv1a64::u64`]) then its entries column by column
    /// (nalgebra's storage order) as [`Fnv1a64::f64`].
    pub fn matrix(&mut self, rows: usize, cols: usize, column_major: &[f64]) -> &mut Self {
        self.u64(rows as u64).u64(cols as u64).f64s(column_major)
    }

    /// The hash so far.
    pub fn finish(&self) -> u64 {
        self.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_the_published_fnv1a_64_vectors() {
        // From the FNV reference test suite (Noll): "" and "a" and "foobar".
        assert_eq!(Fnv1a64::new().finish(), 0xcbf29ce484222325);
        assert_eq!(Fnv1a64::new().bytes(b"a").finish(), 0xaf63dc4c8601ec8c);
        assert_eq!(Fnv1a64::new().bytes(b"foobar").finish(), 0x85944171f73967e8);
    }

    #[test]
    fn encodings_are_distinct() {
        let h = |f: fn(&mut Fnv1a64)| {
            let mut h = Fnv1a64::new();
            f(&mut h);
            h.finish()
        };
        assert_ne!(
            h(|h| {
                h.f64(0.0);
            }),
            h(|h| {
                h.f64(-0.0);
            })
        );
        assert_ne!(
            h(|h| {
                h.str("ab").str("");
            }),
            h(|h| {
                h.str("a").str("b");
            })
        );
        assert_ne!(
            h(|h| {
                h.matrix(1, 2, &[1.0, 2.0]);
            }),
            h(|h| {
                h.matrix(2, 1, &[1.0, 2.0]);
            })
        );
    }
}
