//! The spec's linear model at one instant, at the fixed sizes the core filters take.
//!
//! The spec describes a model with nalgebra's dynamic matrices; the core runs on const-generic
//! ones. The matrices are constant, so the adapters convert them once, at construction; of a
//! controlled model only the input term `B_u u_{k−1}` changes, and [`Snapshot::set_input`]
//! writes it in place at every step, without allocating ([`super::fed::Fed`]).

use estimator_core::model::LinearSystem;
use estpipe_spec::LinearModel;
use estpipe_wire::MAX_NX;
use nalgebra::{DMatrix, SMatrix, SVector};

/// One node's view of the model at instant `k` as a core [`LinearSystem`]: `A`, `B Q Bᵀ` and
/// the known input term `B_u u` (a control input, if the plant has one) of `k − 1`, the node's
/// `C` and `D R Dᵀ` of `k`. A node that measures fewer components than `NY` (sensors of
/// different ny) is padded: zero rows of `C`, unit variances in `D R Dᵀ`, and zeros in its
/// measurement (`slots`), so the padded components have zero innovation and no gain — the
/// update is the node's own, exactly. The filters call it with the `k` it was taken
/// at, so the instant arguments of the [`LinearSystem`] methods are not needed.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Snapshot<const NX: usize, const NY: usize> {
    pub(crate) a: SMatrix<f64, NX, NX>,
    pub(crate) q: SMatrix<f64, NX, NX>,
    pub(crate) c: SMatrix<f64, NY, NX>,
    pub(crate) r: SMatrix<f64, NY, NY>,
    pub(crate) u: Option<SVector<f64, NX>>,
}

impl<const NX: usize, const NY: usize> Snapshot<NX, NY> {
    /// Node 0 at instant `k`.
    pub(crate) fn at(model: &LinearModel, k: usize) -> Self {
        let [s] = Self::nodes(model, 1, k);
        s
    }

    /// Nodes `0..nodes` at instant `k` (`A` and `B Q Bᵀ` converted once). The entries from
    /// `nodes` on, which no node fills, have `C = 0` and `D R Dᵀ = I`.
    pub(crate) fn nodes<const L: usize>(model: &LinearModel, nodes: usize, k: usize) -> [Self; L] {
        let (a, q) = (fixed(model.a()), fixed(model.process_cov()));
        let u = input(model, k);
        core::array::from_fn(|m| {
            let (c, r) = if m < nodes {
                (
                    padded(model.c(m), 0.0),
                    padded(model.measurement_cov(m), 1.0),
                )
            } else {
                (SMatrix::zeros(), SMatrix::identity())
            };
            Self { a, q, c, r, u }
        })
    }

    /// The input term of instant `k` (`B_u u_{k−1}`), written in place.
    pub(crate) fn set_input(&mut self, model: &LinearModel, k: usize) {
        self.u = input(model, k);
    }
}

/// `B_u u_{k−1}` of instant `k`, if the model has an input.
fn input<const NX: usize>(model: &LinearModel, k: usize) -> Option<SVector<f64, NX>> {
    let mut u = [0.0; MAX_NX];
    model
        .input_into(k.saturating_sub(1), &mut u)
        .then(|| SVector::<f64, NX>::from_fn(|i, _| u[i]))
}

impl<const NX: usize, const NY: usize> LinearSystem<f64, NX, NY> for Snapshot<NX, NY> {
    #[inline]
    fn a(&self, _k: usize) -> SMatrix<f64, NX, NX> {
        self.a
    }
    #[inline]
    fn c(&self, _k: usize) -> SMatrix<f64, NY, NX> {
        self.c
    }
    #[inline]
    fn process_cov(&self, _k: usize) -> SMatrix<f64, NX, NX> {
        self.q
    }
    #[inline]
    fn measurement_cov(&self, _k: usize) -> SMatrix<f64, NY, NY> {
        self.r
    }
    #[inline]
    fn input(&self, _k: usize) -> Option<SVector<f64, NX>> {
        self.u
    }
}

/// `m` in the top-left corner of an `R × C` matrix, `diagonal` on the rest of the diagonal
/// and zeros elsewhere (`m` itself when it is `R × C`).
pub(crate) fn padded<const R: usize, const C: usize>(
    m: &DMatrix<f64>,
    diagonal: f64,
) -> SMatrix<f64, R, C> {
    SMatrix::from_fn(|i, j| {
        if i < m.nrows() && j < m.ncols() {
            m[(i, j)]
        } else if i == j {
            diagonal
        } else {
            0.0
        }
    })
}

/// A dynamic matrix at fixed size (the caller knows the dimensions match).
pub(crate) fn fixed<const R: usize, const C: usize>(m: &DMatrix<f64>) -> SMatrix<f64, R, C> {
    SMatrix::from_fn(|i, j| m[(i, j)])
}
