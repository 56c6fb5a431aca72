//! Seed 003, section IV: the noise-coupled system with the nonlinearity
//! `f(x) = 8 [sin x₁ cos x₃, sin x₂, sin x₂ cos x₃]ᵀ` under the token bucket, the NN
//! estimator's initial values and the bounds' configuration (docs/design.md, "Seed 003").

use nalgebra::{SMatrix, SVector};

use crate::filter::nn::bound::NnBoundConfig;
use crate::filter::nn::estimator::NnTbcpEstimator;
use crate::filter::nn::system::{CoupledNoiseSystem, DifferentiableMap, SystemMatrices, Tanh};
use crate::{Real, Result};

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
    /// `w̄² = 0.1`: the noise variance (docs/design.md, "Seed 003": `w_k ~ N(0, 0.1)`).
    pub const W_VAR: f64 = 0.1;
    /// Horizon `T = 300`.
    pub const HORIZON: usize = 300;
}

impl<T: Real> CoupledNoiseSystem<T, 3, 1, 2> for Seed003Example {
    fn a(&self, k: usize) -> SMatrix<T, 3, 3> {
        seed003_a(sin_k(k), cos_k(k))
    }
    fn b(&self, k: usize) -> SMatrix<T, 3, 1> {
        seed003_b(cos_k(k))
    }
    fn c(&self, k: usize) -> SMatrix<T, 2, 3> {
        seed003_c(cos_k(k))
    }
    fn d(&self, k: usize) -> SMatrix<T, 2, 1> {
        seed003_d(sin_k(k))
    }
    /// `sin k` and `cos k` once for the four, together (on a single-precision FPU each is a
    /// software double-precision kernel, and `sin_cos` reduces the argument once for both);
    /// the same values, so the same matrices bit for bit.
    fn matrices(&self, k: usize) -> SystemMatrices<T, 3, 1, 2> {
        let (s, c) = sin_cos_k(k);
        (seed003_a(s, c), seed003_b(c), seed003_c(c), seed003_d(s))
    }
}

/// `sin k` of section IV's matrices.
fn sin_k<T: Real>(k: usize) -> T {
    T::lit(k as f64).sin()
}

/// `cos k` of section IV's matrices.
fn cos_k<T: Real>(k: usize) -> T {
    T::lit(k as f64).cos()
}

/// `(sin k, cos k)`, each bit for bit [`sin_k`] and [`cos_k`] (`libm`'s `sincos` and
/// `sincosf` share the argument reduction and the kernels of `sin`, `cos`; tested below).
fn sin_cos_k<T: Real>(k: usize) -> (T, T) {
    T::lit(k as f64).sin_cos()
}

/// `A_k` from `sin k`, `cos k`.
fn seed003_a<T: Real>(s: T, c: T) -> SMatrix<T, 3, 3> {
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

/// `B_k` from `cos k`.
fn seed003_b<T: Real>(c: T) -> SMatrix<T, 3, 1> {
    SMatrix::<T, 3, 1>::new(T::one(), c, T::one())
}

/// `C_k` from `cos k`.
fn seed003_c<T: Real>(c: T) -> SMatrix<T, 2, 3> {
    SMatrix::<T, 2, 3>::new(
        T::lit(0.9),
        T::lit(0.25) * c,
        T::one(),
        T::lit(0.9),
        T::lit(0.25),
        T::one(),
    )
}

/// `D_k` from `sin k`.
fn seed003_d<T: Real>(s: T) -> SMatrix<T, 2, 1> {
    SMatrix::<T, 2, 1>::new(T::lit(0.95), T::lit(0.65) * s)
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

/// The section IV instance: 3 states, 1 noise, 2 measurements, `tanh` on 3 outputs.
pub type Seed003Nn<T> = NnTbcpEstimator<T, 3, 1, 2, 3, 6, Tanh>;

impl<T: Real> Seed003Nn<T> {
    /// Seed 003's estimator from the paper's initial values (section IV: `x̂₀`, `Ĥ₀`, and
    /// `P̄₀ = Q̄₀` = [`Seed003Example::p0`]) with
    /// the bounds' configuration `cfg` (the paper's is [`NnBoundConfig::seed003_example`]).
    pub fn seed003(cfg: NnBoundConfig<T>) -> Result<Self> {
        Self::new(
            cfg,
            Tanh,
            Seed003Example::xhat0(),
            Seed003Example::h0(),
            Seed003Example::p0(),
            Seed003Example::p0(),
        )
    }
}

impl<T: Real> NnBoundConfig<T> {
    /// Section IV: `α_i = 0.1`, `β_i = 0.9`, `θ_i = 0.001`, `H̄ = 8`, `φ̄ = 1`, `ε̄ = 0.1`,
    /// `w̄² = 0.1`.
    pub fn seed003_example() -> Self {
        Self {
            alpha: [T::lit(0.1); 4],
            beta: [T::lit(0.9); 12],
            theta: [T::lit(0.001); 2],
            h_bar: T::lit(8.0),
            phi_bar: T::lit(1.0),
            eps_bar: T::lit(0.1),
            w_bar_sq: T::lit(0.1),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::nn::system::Activation;

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
    fn sin_cos_of_k_is_sin_and_cos_bit_for_bit() {
        for k in 0..200_000 {
            let (s, c) = sin_cos_k::<f32>(k);
            assert_eq!(s.to_bits(), sin_k::<f32>(k).to_bits(), "sin {k}");
            assert_eq!(c.to_bits(), cos_k::<f32>(k).to_bits(), "cos {k}");
            let (s, c) = sin_cos_k::<f64>(k);
            assert_eq!(s.to_bits(), sin_k::<f64>(k).to_bits(), "sin {k}");
            assert_eq!(c.to_bits(), cos_k::<f64>(k).to_bits(), "cos {k}");
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
