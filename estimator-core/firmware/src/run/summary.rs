//! What a run reports: the counts, the digest and the final x̂ of one estimator over a stream,
//! and the `RESULT` line the firmware prints and the host check compares.

use core::fmt;

use super::digest::Fnv1a64;

/// Largest state dimension of a result line.
pub const MAX_NX: usize = 3;

/// What one estimator did over the stream.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Summary {
    /// Estimator name (`kf`, `ikf`, …).
    pub name: &'static str,
    /// Instants processed.
    pub steps: u32,
    /// Measurements used (per node and instant).
    pub arrivals: u32,
    /// Node slots without a measurement (per node and instant).
    pub dropouts: u32,
    /// Steps that returned an error (the estimator kept its previous state).
    pub errors: u32,
    /// Instant k of the first error (0 if none).
    pub first_error: u32,
    /// FNV-1a 64 over every step's label byte and estimate (see [`Digested`](super::Digested)).
    pub digest: u64,
    /// Entries of x̂ in `x_bits` (0 if the estimator could not be built).
    pub nx: usize,
    /// Bit patterns of the final x̂ (the first `nx`).
    pub x_bits: [u32; MAX_NX],
}

impl Summary {
    pub(super) fn new(name: &'static str) -> Self {
        Self {
            name,
            steps: 0,
            arrivals: 0,
            dropouts: 0,
            errors: 0,
            first_error: 0,
            digest: Fnv1a64::default().0,
            nx: 0,
            x_bits: [0; MAX_NX],
        }
    }

    pub(super) fn error(&mut self, k: u32) {
        if self.errors == 0 {
            self.first_error = k;
        }
        self.errors += 1;
    }

    /// The final estimate as numbers (entries past `nx` are 0).
    pub fn x(&self) -> [f32; MAX_NX] {
        self.x_bits.map(f32::from_bits)
    }
}

/// The result line; the host check compares it character for character.
impl fmt::Display for Summary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} steps={} arrivals={} dropouts={} errors={} first_error={} digest={:016x} x=[",
            self.name,
            self.steps,
            self.arrivals,
            self.dropouts,
            self.errors,
            self.first_error,
            self.digest,
        )?;
        for (i, b) in self.x_bits.iter().take(self.nx).enumerate() {
            if i > 0 {
                f.write_str(" ")?;
            }
            write!(f, "{b:08x}")?;
        }
        f.write_str("]")
    }
}
