//! The KF and EKF baselines of seed 003, section IV, for the noise-coupled system (1)
//! `x_{k+1} = A_k x_k + f(x_k) + B_k w_k`, `y_k = C_k x_k + D_k w_k` under the token bucket.
//!
//! * **KF** uses `A_k` and ignores `f` ([`Linearisation::None`]).
//! * **EKF** uses `A_k + F_k`, `F_k = ∂f/∂x` at the predicted state `x̂_{k|k−1}`, "for the linear
//!   component in its state equation" ([`Linearisation::PaperJacobian`]: the transition
//!   `x ↦ (A_k + F_k) x` for both mean and covariance, as the paper writes it).
//! * A standard EKF ([`Linearisation::Ekf`], the product's option beside the paper's):
//!   mean `A_k x̂ + f(x̂)`, covariance through `A_k + F_k`.
//!
//! # Correlated noise
//! The same `w_k` drives state and measurement, so the process and measurement noises are
//! correlated with cross-covariance `B_k W D_kᵀ` (`W = E[w wᵀ]`). All three run the exact
//! one-step *predictor* for correlated noise (Anderson & Moore, *Optimal Filtering*, §5.5):
//!
//! ```text
//! S_k = C_k P_k C_kᵀ + D_k W D_kᵀ
//! K_k = (F̃_k P_k C_kᵀ + B_k W D_kᵀ) S_k⁺
//! x̂_{k+1} = m_k(x̂_k) + K_k (y_k − C_k x̂_k)
//! P_{k+1} = (F̃_k − K_k C_k) P_k (F̃_k − K_k C_k)ᵀ + (B_k − K_k D_k) W (B_k − K_k D_k)ᵀ
//! ```
//! and, when the token bucket withheld `y_k`, `K_k = 0` (prediction only; the paper does not
//! say how its baselines treat a withheld packet, and `ȳ_k = 0` is not a measurement).
//! The covariance form is a sum of two PSD terms for any gain (Joseph-like), never a
//! subtraction.
//!
//! # Why a pseudo-inverse, and why it is sound
//! `D W Dᵀ` has rank `NW` (1 in the example) in `NY = 2` dimensions: one combination of `y_k`
//! is noise-free, `P_k` loses a rank per transmitted measurement and `S_k` itself becomes
//! singular after a few steps. `S_k` is therefore decomposed `U Λ Uᵀ` and only directions with
//! `λ > √ε · λ_max` are used (`S_k⁺`); in the others the innovation has (numerically) zero
//! variance and carries no information the filter can weigh. No inverse of a near-singular
//! matrix is ever formed.
//!
//! # Timing
//! Like the NN estimator, [`CoupledNoiseKf::step`] is driven by the observation of instant
//! `k + 1`; it processes the stored `y_k` and yields `x̂_{k+1|k}`, so all three estimators of
//! the comparison use the same information (`y_0 … y_k`) for `x̂_{k+1}`.

use nalgebra::{SMatrix, SVector};

use crate::estimate::Estimate;
use crate::filter::nn::system::{CoupledNoiseSystem, DifferentiableMap};
use crate::filter::noise_coupled::{NoiseCoupledKf, NoiseCoupledStep};
use crate::linalg::check_finite;
use crate::linalg::eig::symmetric_eigen;
use crate::linalg::symmetrize;
use crate::{Error, Real, Result};

/// How the baseline treats the nonlinearity `f`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Linearisation {
    /// KF: `A_k` only, `f` ignored.
    #[default]
    None,
    /// The paper's EKF: transition `A_k + F_k(x̂_{k|k−1})` for mean and covariance.
    PaperJacobian,
    /// Standard EKF: mean `A_k x̂ + f(x̂)`, covariance through `A_k + F_k(x̂)`.
    Ekf,
}

/// Correlated-noise one-step predictor (KF/EKF baselines of seed 003): the shared
/// [`NoiseCoupledKf`] with the paper's algebra, [`Linearisation`] its mode.
pub type CoupledNoiseKf<T, const NX: usize, const NW: usize, const NY: usize> =
    NoiseCoupledKf<T, NX, NW, NY, Linearisation>;

/// A nonlinearity that is identically zero (for the plain KF).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct NoNonlinearity;

impl<T: Real, const N: usize> DifferentiableMap<T, N> for NoNonlinearity {
    fn eval(&self, _x: &SVector<T, N>) -> SVector<T, N> {
        SVector::zeros()
    }
    fn jacobian(&self, _x: &SVector<T, N>) -> SMatrix<T, N, N> {
        SMatrix::zeros()
    }
}

/// The exact correlated-noise predictor (module docs): the transition by the mode, then the
/// update through the pseudo-inverse of `S_k` with `y_k`, or the prediction alone without it.
impl<T: Real, const NX: usize, const NW: usize, const NY: usize> NoiseCoupledStep<T, NX, NW, NY>
    for Linearisation
{
    fn advance<S, F>(
        &self,
        sys: &S,
        f: &F,
        k: usize,
        est: &Estimate<T, NX>,
        w: &SMatrix<T, NW, NW>,
        y: Option<&SVector<T, NY>>,
    ) -> Result<(SVector<T, NX>, SMatrix<T, NX, NX>, u8)>
    where
        S: CoupledNoiseSystem<T, NX, NW, NY>,
        F: DifferentiableMap<T, NX>,
    {
        let (x, p) = (*est.state(), *est.covariance());
        let (a, b, c, d) = (sys.a(k), sys.b(k), sys.c(k), sys.d(k));
        check_finite(&a, "A_k")?;
        let (trans, mean) = match self {
            Linearisation::None => (a, a * x),
            Linearisation::PaperJacobian => {
                let t = a + f.jacobian(&x);
                (t, t * x)
            }
            Linearisation::Ekf => (a + f.jacobian(&x), a * x + f.eval(&x)),
        };
        check_finite(&trans, "transition Jacobian")?;
        let (x_next, p_next, rank) = match y {
            None => (
                mean,
                trans * p * trans.transpose() + b * *w * b.transpose(),
                0u8,
            ),
            Some(y) => {
                let s = symmetrize(&(c * p * c.transpose() + d * *w * d.transpose()));
                let g = trans * p * c.transpose() + b * *w * d.transpose();
                let (kgain, rank) = pseudo_inverse_gain(&g, &s)?;
                let x_next = mean + kgain * (y - c * x);
                let fa = trans - kgain * c;
                let fb = b - kgain * d;
                (
                    x_next,
                    fa * p * fa.transpose() + fb * *w * fb.transpose(),
                    rank,
                )
            }
        };
        check_finite(&x_next, "state estimate")?;
        check_finite(&p_next, "covariance")?;
        Ok((x_next, project_psd(&p_next)?, rank))
    }
}

/// `K = G U Λ⁺ Uᵀ` for `S = U Λ Uᵀ`, only the well-determined directions (`λ > √ε · λ_max`),
/// and how many there are.
fn pseudo_inverse_gain<T: Real, const NX: usize, const NY: usize>(
    g: &SMatrix<T, NX, NY>,
    s: &SMatrix<T, NY, NY>,
) -> Result<(SMatrix<T, NX, NY>, u8)> {
    let (lam, u) = symmetric_eigen(s, "innovation covariance")?;
    let lmax = lam.max();
    if !lmax.finite() {
        return Err(Error::NonFinite {
            what: "innovation covariance",
        });
    }
    if lmax <= T::zero() {
        return Err(Error::NotPositiveDefinite {
            what: "innovation covariance (all directions noise-free and certain)",
        });
    }
    let tol = T::EPS.sqrt() * lmax;
    let mut inv = SVector::<T, NY>::zeros();
    let mut rank = 0u8;
    for i in 0..NY {
        if lam[i] > tol {
            inv[i] = T::one() / lam[i];
            rank += 1;
        }
    }
    // K = G U Λ⁺ Uᵀ (only well-determined directions).
    let gu = g * u;
    let mut gul = gu;
    for j in 0..NY {
        let sc = inv[j];
        for i in 0..NX {
            gul[(i, j)] *= sc;
        }
    }
    Ok((gul * u.transpose(), rank))
}

/// Symmetrises `P` and clamps its negative eigenvalues to zero.
///
/// Both terms of the covariance recursion are PSD, but once `P` has collapsed in some
/// directions (exactly known combinations, see the module docs) rounding leaves eigenvalues of
/// order `−ε‖P‖`, and a transition with gain `|A_k + F_k| ≈ 10` amplifies them into a
/// negative-definite "covariance" within a few dozen steps (observed on the section IV
/// example). Projecting onto the PSD cone after every step removes exactly that rounding.
fn project_psd<T: Real, const N: usize>(p: &SMatrix<T, N, N>) -> Result<SMatrix<T, N, N>> {
    let (lam, u) = symmetric_eigen(p, "covariance")?;
    if lam.iter().all(|&l| l >= T::zero()) {
        return Ok(symmetrize(p));
    }
    let clamped = lam.map(|l| if l > T::zero() { l } else { T::zero() });
    Ok(symmetrize(
        &(u * SMatrix::<T, N, N>::from_diagonal(&clamped) * u.transpose()),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::papers::Seed003Example;
    use nalgebra::{matrix, vector};

    /// A time-invariant linear coupled system (f = 0) with D of full rank, so the standard
    /// independent-noise KF can be checked against it after decorrelation.
    struct Lin;
    impl CoupledNoiseSystem<f64, 2, 2, 1> for Lin {
        fn a(&self, _k: usize) -> SMatrix<f64, 2, 2> {
            matrix![0.9, 0.2; 0.0, 0.8]
        }
        fn b(&self, _k: usize) -> SMatrix<f64, 2, 2> {
            matrix![1.0, 0.0; 0.0, 1.0]
        }
        fn c(&self, _k: usize) -> SMatrix<f64, 1, 2> {
            matrix![1.0, 0.5]
        }
        fn d(&self, _k: usize) -> SMatrix<f64, 1, 2> {
            matrix![0.3, 0.4]
        }
    }

    #[test]
    fn matches_the_decorrelated_standard_kf() {
        // Independent check: with S = B W Dᵀ and R = D W Dᵀ, rewrite
        // x_{k+1} = (A − S R⁻¹ C) x_k + S R⁻¹ y_k + (B w_k − S R⁻¹ D w_k), whose noise is
        // uncorrelated with D w_k; run the textbook predict/update by hand and compare.
        let w = matrix![0.5, 0.1; 0.1, 0.3];
        let sys = Lin;
        let mut kf = CoupledNoiseKf::new(
            vector![1.0, -1.0],
            SMatrix::identity() * 2.0,
            w,
            Linearisation::None,
        )
        .unwrap()
        .with_initial_measurement(vector![0.4])
        .unwrap();
        let (a, b, c, d) = (sys.a(0), sys.b(0), sys.c(0), sys.d(0));
        let s = b * w * d.transpose();
        let r = (d * w * d.transpose())[(0, 0)];
        let q = b * w * b.transpose() - s * s.transpose() / r;
        let mut x = vector![1.0, -1.0];
        let mut p = SMatrix::<f64, 2, 2>::identity() * 2.0;
        let ys = [0.4, -0.2, 1.3, 0.7, 0.0, -0.5];
        for t in 0..5 {
            // Filtered estimate at t with y_t, then the decorrelated prediction.
            let sc = (c * p * c.transpose())[(0, 0)] + r;
            let kk = p * c.transpose() / sc;
            let innov = ys[t] - (c * x)[0];
            let xf = x + kk * innov;
            let pf = (SMatrix::<f64, 2, 2>::identity() - kk * c) * p;
            let a2 = a - s * c / r;
            x = a2 * xf + s * ys[t] / r;
            p = a2 * pf * a2.transpose() + q;
            kf.step(&sys, &NoNonlinearity, Some(&vector![ys[t + 1]]))
                .unwrap();
            assert!((kf.estimate().state() - x).amax() < 1e-12, "t={t}");
            assert!((kf.estimate().covariance() - p).amax() < 1e-12, "t={t}");
        }
    }

    #[test]
    fn seed003_singular_measurement_noise_is_handled() {
        // f ignored, noise-free data: P collapses in ≤ 3 transmitted steps (one scalar noise,
        // two measurements), S_k becomes singular, and the pseudo-inverse keeps going.
        let sys = Seed003Example;
        let mut kf = CoupledNoiseKf::<f64, 3, 1, 2>::new(
            Seed003Example::xhat0(),
            Seed003Example::p0(),
            matrix![0.1],
            Linearisation::None,
        )
        .unwrap();
        let mut x = Seed003Example::x0::<f64>();
        let mut rank_one_updates = 0;
        for k in 0..60 {
            x = sys.a(k) * x;
            let y: SVector<f64, 2> = sys.c(k + 1) * x;
            let sent = k % 3 != 2;
            kf.step(&sys, &NoNonlinearity, sent.then_some(&y)).unwrap();
            if kf.last_rank() == 1 {
                rank_one_updates += 1;
            }
        }
        // With the model exact (linear plant, w = 0) the predictor recovers x exactly.
        assert!((kf.estimate().state() - x).amax() < 1e-6 * x.amax().max(1.0));
        // S_k was numerically rank 1 at some updates: the pseudo-inverse path was exercised.
        assert!(rank_one_updates > 0);
    }

    #[test]
    fn nan_is_rejected_without_change_and_modes_differ() {
        let sys = Seed003Example;
        let mk = |m| {
            CoupledNoiseKf::<f64, 3, 1, 2>::new(
                vector![0.5, -0.3, 0.2],
                Seed003Example::p0(),
                matrix![0.1],
                m,
            )
            .unwrap()
            .with_initial_measurement(vector![1.0, 0.8])
            .unwrap()
        };
        let mut kf = mk(Linearisation::PaperJacobian);
        let before = kf;
        assert_eq!(
            kf.step(&sys, &sys, Some(&vector![f64::NAN, 1.0])),
            Err(Error::NonFinite {
                what: "measurement"
            })
        );
        assert_eq!(kf, before);
        let mut e1 = mk(Linearisation::None);
        let mut e2 = mk(Linearisation::PaperJacobian);
        let mut e3 = mk(Linearisation::Ekf);
        for e in [&mut e1, &mut e2, &mut e3] {
            e.step(&sys, &sys, None).unwrap();
        }
        assert!((e1.estimate().state() - e2.estimate().state()).amax() > 1e-3);
        assert!((e2.estimate().state() - e3.estimate().state()).amax() > 1e-3);
    }
}
