//! `minikalman` 0.8 on a [`Problem`]: its regular filter, `predict` then `correct`, with
//! buffers owned by the filter (arrays, no `alloc`). Its update is the optimal-gain form
//! P − K (H P) (no Joseph form, P not symmetrised), and nothing is validated: a failed
//! Cholesky factorisation of S is not reported.

use minikalman::prelude::*;
use minikalman::regular::{RegularKalmanBuilder, RegularObservationBuilder};
use minikalman::{
    impl_buffer_A, impl_buffer_H, impl_buffer_K, impl_buffer_P, impl_buffer_Q_direct,
    impl_buffer_R, impl_buffer_S, impl_buffer_temp_HP, impl_buffer_temp_KHP, impl_buffer_temp_P,
    impl_buffer_temp_PHt, impl_buffer_temp_S_inv, impl_buffer_temp_x, impl_buffer_x, impl_buffer_y,
    impl_buffer_z,
};
use nalgebra::Vector2;

use super::{KfStep, Problem, NY};

/// A `minikalman` filter `F` with its observation `O` (the types the buffer macros make).
#[derive(Debug)]
pub struct Mk<F, O> {
    filter: F,
    obs: O,
}

impl<const NX: usize, F, O> KfStep<NX> for Mk<F, O>
where
    F: KalmanFilter<NX, f32> + KalmanFilterEstimateCovariance<NX, f32>,
    O: KalmanFilterObservation<NX, NY, f32>,
{
    #[inline(never)]
    fn step(&mut self, _k: usize, y: &Vector2<f32>) -> bool {
        self.filter.predict();
        let z = self.obs.measurement_vector_mut();
        z[0] = y[0];
        z[1] = y[1];
        self.filter.correct(&mut self.obs);
        true
    }
    fn x(&self, i: usize) -> f32 {
        self.filter.state_vector()[i]
    }
    fn p(&self, i: usize, j: usize) -> f32 {
        self.filter.estimate_covariance().as_matrix().get(i, j)
    }
}

macro_rules! mk_new {
    ($(#[$doc:meta])* $name:ident, $n:literal) => {
        $(#[$doc])*
        #[allow(non_snake_case)]
        pub fn $name(p: &Problem<$n>) -> impl KfStep<$n> {
            impl_buffer_x!(mut x, $n, f32, 0.0);
            impl_buffer_A!(mut A, $n, f32, 0.0);
            impl_buffer_P!(mut P, $n, f32, 0.0);
            impl_buffer_Q_direct!(mut Q, $n, f32, 0.0);
            impl_buffer_temp_x!(mut temp_x, $n, f32, 0.0);
            impl_buffer_temp_P!(mut temp_P, $n, f32, 0.0);
            impl_buffer_z!(mut z, NY, f32, 0.0);
            impl_buffer_H!(mut H, NY, $n, f32, 0.0);
            impl_buffer_R!(mut R, NY, f32, 0.0);
            impl_buffer_y!(mut y, NY, f32, 0.0);
            impl_buffer_S!(mut S, NY, f32, 0.0);
            impl_buffer_K!(mut K, $n, NY, f32, 0.0);
            impl_buffer_temp_S_inv!(mut temp_S_inv, NY, f32, 0.0);
            impl_buffer_temp_HP!(mut temp_HP, NY, $n, f32, 0.0);
            impl_buffer_temp_PHt!(mut temp_PHt, $n, NY, f32, 0.0);
            impl_buffer_temp_KHP!(mut temp_KHP, $n, f32, 0.0);
            let (a, q, c, r) = (p.a(), p.q(), p.c(), p.r());
            for i in 0..$n {
                x.as_matrix_mut().set(i, 0, p.x0[i]);
                for j in 0..$n {
                    A.as_matrix_mut().set(i, j, a[(i, j)]);
                    P.as_matrix_mut().set(i, j, p.p0[(i, j)]);
                    Q.as_matrix_mut().set(i, j, q[(i, j)]);
                }
            }
            for i in 0..NY {
                for j in 0..$n {
                    H.as_matrix_mut().set(i, j, c[(i, j)]);
                }
                for j in 0..NY {
                    R.as_matrix_mut().set(i, j, r[(i, j)]);
                }
            }
            Mk {
                filter: RegularKalmanBuilder::new::<$n, f32>(A, x, P, Q, temp_x, temp_P),
                obs: RegularObservationBuilder::new::<$n, NY, f32>(
                    H, z, R, y, S, K, temp_S_inv, temp_HP, temp_PHt, temp_KHP,
                ),
            }
        }
    };
}

mk_new!(
    /// `minikalman` at the 3x2 problem's prior.
    mk3x2,
    3
);
mk_new!(
    /// `minikalman` at the 4x2 problem's prior.
    mk4x2,
    4
);
