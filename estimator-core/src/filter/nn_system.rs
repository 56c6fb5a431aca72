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
//!   uses `∂f/∂x`);
//! * [`Seed003Example`]: the matrices and `f` of section IV.

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

/// The illustrative example of seed 003, section IV (3 states, 1 noise, 2 measurements).
///
/// The matrices are evaluated at the integer instant `k` (`cos(k)`, `sin(k)` in radians).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Seed003Example;

impl Seed003Example {
    /// `x₀ = [3.1, −2.65, 4]ᵀ` (deterministic).
    pub fn x0<T: Real>() -> SVector<T, 3> {
        SVector::<T, 3>::new(T::lit(3.1), T::lit(-2.65), T::lit(4.0))
    }
    /// `x̂₀ = 0`.
    pub fn xhat0<T: Real>() -> SVector<T, 3> {
        SVector::zeros()
    }
    /// `P₀ = Q₀ = 10 I`.
    pub fn p0<T: Real>() -> SMatrix<T, 3, 3> {
        SMatrix::<T, 3, 3>::identity() * T::lit(10.0)
    }
    /// The initial NN weight `Ĥ₀`.
    pub fn h0<T: Real>() -> SMatrix<T, 3, 3> {
        SMatrix::<T, 3, 3>::new(
            T::lit(1.5),
            T::lit(1.65),
            T::lit(1.5),
            T::lit(1.5),
            T::lit(1.8),
            T::lit(1.5),
            T::lit(0.75),
            T::lit(1.2),
            T::lit(1.35),
        )
    }
    /// `w̄² = 0.1`: the noise variance (DESIGN: `w_k ~ N(0, 0.1)`).
    pub const W_VAR: f64 = 0.1;
    /// Horizon `T = 300`.
    pub const HORIZON: usize = 300;
}

impl<T: Real> CoupledNoiseSystem<T, 3, 1, 2> for Seed003Example {
    fn a(&self, k: usize) -> SMatrix<T, 3, 3> {
        let (s, c) = (T::lit(k as f64).sin(), T::lit(k as f64).cos());
        SMatrix::<T, 3, 3>::new(
            T::lit(1.5) * c,
            T::lit(0.01),
            T::lit(0.02),
            T::lit(0.02),
            T::lit(-1.7) * s,
            T::lit(0.3),
            T::lit(0.01),
            T::lit(0.03),
            T::lit(1.9) * c,
        )
    }
    fn b(&self, k: usize) -> SMatrix<T, 3, 1> {
        SMatrix::<T, 3, 1>::new(T::one(), T::lit(k as f64).cos(), T::one())
    }
    fn c(&self, k: usize) -> SMatrix<T, 2, 3> {
        SMatrix::<T, 2, 3>::new(
            T::lit(0.9),
            T::lit(0.25) * T::lit(k as f64).cos(),
            T::one(),
            T::lit(0.9),
            T::lit(0.25),
            T::one(),
        )
    }
    fn d(&self, k: usize) -> SMatrix<T, 2, 1> {
        SMatrix::<T, 2, 1>::new(T::lit(0.95), T::lit(0.65) * T::lit(k as f64).sin())
    }
}

/// `f(x) = 8 [sin x₁ cos x₃, sin x₂, sin x₂ cos x₃]ᵀ` of section IV.
impl<T: Real> DifferentiableMap<T, 3> for Seed003Example {
    fn eval(&self, x: &SVector<T, 3>) -> SVector<T, 3> {
        let e = T::lit(8.0);
        let (s1, s2, c3) = (x[0].sin(), x[1].sin(), x[2].cos());
        SVector::<T, 3>::new(e * s1 * c3, e * s2, e * s2 * c3)
    }
    fn jacobian(&self, x: &SVector<T, 3>) -> SMatrix<T, 3, 3> {
        let e = T::lit(8.0);
        let (s1, c1) = (x[0].sin(), x[0].cos());
        let (s2, c2) = (x[1].sin(), x[1].cos());
        let (s3, c3) = (x[2].sin(), x[2].cos());
        let z = T::zero();
        SMatrix::<T, 3, 3>::new(
            e * c1 * c3,
            z,
            -e * s1 * s3,
            z,
            e * c2,
            z,
            z,
            e * c2 * c3,
            -e * s2 * s3,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jacobian_matches_central_differences() {
        let f = Seed003Example;
        let x = SVector::<f64, 3>::new(0.3, -1.2, 2.1);
        let j = DifferentiableMap::jacobian(&f, &x);
        let h = 1e-6;
        for c in 0..3 {
            let mut xp = x;
            let mut xm = x;
            xp[c] += h;
            xm[c] -= h;
            let col =
                (DifferentiableMap::eval(&f, &xp) - DifferentiableMap::eval(&f, &xm)) / (2.0 * h);
            // Central difference error ~ h²·|f'''| ≈ 8e-12, rounding ~ eps·8/h ≈ 2e-9.
            assert!((col - j.column(c)).amax() < 1e-8);
        }
    }

    #[test]
    fn example_matrices_at_k0_and_tanh_bound() {
        let a: SMatrix<f64, 3, 3> = Seed003Example.a(0);
        assert_eq!(a[(0, 0)], 1.5);
        assert_eq!(a[(2, 2)], 1.9);
        assert_eq!(a[(1, 1)], 0.0);
        let d: SMatrix<f64, 2, 1> = Seed003Example.d(0);
        assert_eq!(d[1], 0.0);
        let s: f64 = Activation::<f64, 3, 3>::sup_norm(&Tanh);
        assert!((s - 3f64.sqrt()).abs() < 1e-15);
        let big = SVector::<f64, 3>::new(30.0, -30.0, 30.0);
        assert!((Activation::<f64, 3, 3>::eval(&Tanh, &big).norm() - s).abs() < 1e-12);
    }
}
