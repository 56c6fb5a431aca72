//! The system class of seed 003, eq. (1), and the pieces the NN estimator is generic over:
//!
//! ```text
//! x_{k+1} = A_k x_k + f(x_k) + B_k w_k
//! y_k     = C_k x_k + D_k w_k            (the same w_k in both equations)
//! ```
//!
//! * [`CoupledNoiseSystem`]: the known, time-varying `A_k, B_k, C_k, D_k`;
//! * [`Activation`]: the NN activation `φ` of `f(x) ≈ H φ(x) + ε` (II-C), with [`Tanh`];
//! * [`DifferentiableMap`]: a nonlinearity with its Jacobian (the EKF baseline of section IV
//!   uses `∂f/∂x`).
//!
//! The matrices and `f` of section IV are [`crate::papers::Seed003Example`].

use nalgebra::{SMatrix, SVector};

use crate::Real;

/// Known time-varying matrices of (1). One noise `w_k ∈ R^NW` drives state and measurement,
/// so the state and measurement noises are correlated (cross-covariance `B_k W D_kᵀ`).
pub trait CoupledNoiseSystem<T: Real, const NX: usize, const NW: usize, const NY: usize> {
    /// `A_k`.
    fn a(&self, k: usize) -> SMatrix<T, NX, NX>;
    /// `B_k`.
    fn b(&self, k: usize) -> SMatrix<T, NX, NW>;
    /// `C_k`.
    fn c(&self, k: usize) -> SMatrix<T, NY, NX>;
    /// `D_k`.
    fn d(&self, k: usize) -> SMatrix<T, NY, NW>;
    /// `(A_k, B_k, C_k, D_k)` together, each as its own method gives it: a system whose four
    /// matrices share work (seed 003's `sin k` and `cos k`) overrides this to do it once.
    #[inline]
    fn matrices(&self, k: usize) -> SystemMatrices<T, NX, NW, NY> {
        (self.a(k), self.b(k), self.c(k), self.d(k))
    }
}

/// `(A_k, B_k, C_k, D_k)` of [`CoupledNoiseSystem::matrices`].
pub type SystemMatrices<T, const NX: usize, const NW: usize, const NY: usize> = (
    SMatrix<T, NX, NX>,
    SMatrix<T, NX, NW>,
    SMatrix<T, NY, NX>,
    SMatrix<T, NY, NW>,
);

/// A borrowed system is the system (so that an [`OnModel`](crate::OnModel) can borrow it).
impl<T, const NX: usize, const NW: usize, const NY: usize, S> CoupledNoiseSystem<T, NX, NW, NY>
    for &S
where
    T: Real,
    S: CoupledNoiseSystem<T, NX, NW, NY> + ?Sized,
{
    #[inline]
    fn a(&self, k: usize) -> SMatrix<T, NX, NX> {
        (**self).a(k)
    }
    #[inline]
    fn b(&self, k: usize) -> SMatrix<T, NX, NW> {
        (**self).b(k)
    }
    #[inline]
    fn c(&self, k: usize) -> SMatrix<T, NY, NX> {
        (**self).c(k)
    }
    #[inline]
    fn d(&self, k: usize) -> SMatrix<T, NY, NW> {
        (**self).d(k)
    }
    #[inline]
    fn matrices(&self, k: usize) -> SystemMatrices<T, NX, NW, NY> {
        (**self).matrices(k)
    }
}

/// NN activation `φ: R^NX → R^NPHI` (seed 003, II-C: `f(·) = H φ(x) + ε`).
pub trait Activation<T: Real, const NX: usize, const NPHI: usize> {
    /// `φ(x)`.
    fn eval(&self, x: &SVector<T, NX>) -> SVector<T, NPHI>;
    /// `sup_x ‖φ(x)‖` (possibly approached but not attained). The paper assumes
    /// `‖φ(·)‖ ≤ φ̄`; the assumption checker compares this with the configured `φ̄`.
    fn sup_norm(&self) -> T;
}

/// Element-wise `tanh`, the activation of the section IV example. `sup ‖φ‖ = √NX`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Tanh;

impl<T: Real, const N: usize> Activation<T, N, N> for Tanh {
    #[inline]
    fn eval(&self, x: &SVector<T, N>) -> SVector<T, N> {
        x.map(|v| v.tanh())
    }
    #[inline]
    fn sup_norm(&self) -> T {
        T::lit(N as f64).sqrt()
    }
}

/// A nonlinearity `f: R^N → R^N` with its Jacobian.
pub trait DifferentiableMap<T: Real, const N: usize> {
    /// `f(x)`.
    fn eval(&self, x: &SVector<T, N>) -> SVector<T, N>;
    /// `∂f/∂x` at `x`.
    fn jacobian(&self, x: &SVector<T, N>) -> SMatrix<T, N, N>;
}

/// A borrowed map is the map.
impl<T: Real, const N: usize, F: DifferentiableMap<T, N> + ?Sized> DifferentiableMap<T, N> for &F {
    #[inline]
    fn eval(&self, x: &SVector<T, N>) -> SVector<T, N> {
        (**self).eval(x)
    }
    #[inline]
    fn jacobian(&self, x: &SVector<T, N>) -> SMatrix<T, N, N> {
        (**self).jacobian(x)
    }
}
