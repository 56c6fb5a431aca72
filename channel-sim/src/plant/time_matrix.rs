//! A linear plant's matrix that is constant or a function of the time index k. Reading a
//! constant one borrows it instead of building a copy per step.

use std::borrow::Cow;

use estpipe_wire::Fnv1a64;
use nalgebra::DMatrix;

/// A matrix that is constant or a function of the time index k.
#[derive(Clone, Debug)]
pub enum TimeMatrix {
    /// The same matrix at every k.
    Constant(DMatrix<f64>),
    /// `at(k)`, which must return a `rows × cols` finite matrix for every k.
    Varying {
        /// Row count of every `at(k)`.
        rows: usize,
        /// Column count of every `at(k)`.
        cols: usize,
        /// The matrix at instant k.
        at: fn(usize) -> DMatrix<f64>,
    },
}

impl TimeMatrix {
    /// The matrix at instant `k` (borrowed when constant).
    pub fn at(&self, k: usize) -> Cow<'_, DMatrix<f64>> {
        match self {
            TimeMatrix::Constant(m) => Cow::Borrowed(m),
            TimeMatrix::Varying { at, .. } => Cow::Owned(at(k)),
        }
    }

    /// Instants a time-varying matrix is fingerprinted at (a function cannot be hashed;
    /// its first values stand for it).
    pub const FINGERPRINT_INSTANTS: usize = 4;

    /// Feeds the matrix to a model fingerprint: `0` and the matrix when constant, `1` and
    /// the matrices at k = 0..[`TimeMatrix::FINGERPRINT_INSTANTS`] when time-varying.
    pub fn fingerprint(&self, h: &mut Fnv1a64) {
        match self {
            TimeMatrix::Constant(m) => {
                h.u64(0);
                super::fingerprint_matrix(h, m);
            }
            TimeMatrix::Varying { at, .. } => {
                h.u64(1);
                for k in 0..Self::FINGERPRINT_INSTANTS {
                    super::fingerprint_matrix(h, &at(k));
                }
            }
        }
    }

    /// `(rows, cols)`.
    pub fn shape(&self) -> (usize, usize) {
        match self {
            TimeMatrix::Constant(m) => m.shape(),
            TimeMatrix::Varying { rows, cols, .. } => (*rows, *cols),
        }
    }
}

impl From<DMatrix<f64>> for TimeMatrix {
    fn from(m: DMatrix<f64>) -> Self {
        TimeMatrix::Constant(m)
    }
}
