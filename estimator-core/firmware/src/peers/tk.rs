//! `typed-kalman` 0.1 on a [`Problem`]: its `LinearKf` (Joseph form; `update` checks the
//! innovation and noise for NaN/∞, factors S by Cholesky and refuses a non-finite result).

use na35::{SMatrix, SVector};
use nalgebra::Vector2;
use typed_kalman::LinearKf;

use super::{KfStep, Problem, NY};

/// nalgebra 0.34 to 0.35 (same column-major layout), at construction only.
fn conv<const R: usize, const C: usize>(m: &nalgebra::SMatrix<f32, R, C>) -> SMatrix<f32, R, C> {
    SMatrix::from_column_slice(m.as_slice())
}

/// `typed-kalman`'s filter with the model's matrices.
#[derive(Clone, Debug)]
pub struct Tk<const NX: usize> {
    f: SMatrix<f32, NX, NX>,
    q: SMatrix<f32, NX, NX>,
    h: SMatrix<f32, NY, NX>,
    r: SMatrix<f32, NY, NY>,
    kf: LinearKf<NX, f32>,
}

impl<const NX: usize> Tk<NX> {
    /// At the problem's prior.
    pub fn new(p: &Problem<NX>) -> Self {
        Self {
            f: conv(&p.a()),
            q: conv(&p.q()),
            h: conv(&p.c()),
            r: conv(&p.r()),
            kf: LinearKf::new(conv(&p.x0), conv(&p.p0)),
        }
    }
}

impl<const NX: usize> KfStep<NX> for Tk<NX> {
    #[inline(never)]
    fn step(&mut self, _k: usize, y: &Vector2<f32>) -> bool {
        // `predict` cannot fail; a refused `update` leaves the prediction in place.
        self.kf.predict(&self.f, &self.q);
        let y = SVector::<f32, NY>::new(y[0], y[1]);
        self.kf.update(&self.h, &y, &self.r).is_ok()
    }
    fn x(&self, i: usize) -> f32 {
        self.kf.state()[i]
    }
    fn p(&self, i: usize, j: usize) -> f32 {
        self.kf.covariance()[(i, j)]
    }
}
