//! The textbook KF and EKF a practitioner would try first on seed 003's noise-coupled system
//! `x_{k+1} = A_k x_k + f(x_k) + B_k w_k`, `y_k = C_k x_k + D_k w_k`: they treat `B_k w_k` and
//! `D_k w_k` as two *independent* noises, with process covariance `Q_k = B_k W B_kᵀ` and
//! measurement covariance `R_k = D_k W D_kᵀ` (`W = E[w wᵀ]`), and ignore the cross-covariance
//! `B_k W D_kᵀ` that [`CoupledNoiseKf`](super::CoupledNoiseKf) (the paper's baselines) uses.
//!
//! * **KF** ([`IndependentMode::Kf`]): `A_k` only, `f` ignored (like the paper's KF).
//! * **EKF** ([`IndependentMode::Ekf`]): the textbook EKF with `f` known — time update
//!   `x̂ ↦ A_k x̂ + f(x̂)` at the *filtered* estimate, covariance through `A_k + ∂f/∂x` there.
//!
//! # One step
//! ```text
//! measurement update (y_k transmitted):   S = C P Cᵀ + R,  K = P Cᵀ S⁻¹,
//!                                         x̂_{k|k} = x̂ + K (y_k − C x̂),
//!                                         P_{k|k} = (I − K C) P (I − K C)ᵀ + K R Kᵀ
//! time update:                            x̂_{k+1|k} = A_k x̂_{k|k} (+ f(x̂_{k|k})),
//!                                         P_{k+1|k} = F P_{k|k} Fᵀ + Q,  F = A_k (+ ∂f/∂x)
//! ```
//! and, when the token bucket withheld `y_k`, the time update alone (`ȳ_k = 0` is not a
//! measurement). The reported estimate is the one-step prediction `x̂_{k+1|k}` (uses
//! `y_0 … y_k`), the quantity the NN estimator's `x̂_{k+1}` and the paper's baselines report,
//! so their MSEs compare the same thing. For the KF this is algebraically the predictor form
//! `x̂_{k+1} = A_k x̂ + A_k K (y_k − C_k x̂)`.
//!
//! # No regularisation
//! `R_k = D_k W D_kᵀ` has rank `NW` (1 in the example) in `NY = 2` dimensions, so it is
//! singular — but the update never inverts `R`, only `S = C P Cᵀ + R`, and `S` is positive
//! definite whenever `P` is unless some `v ≠ 0` has `Cᵀ v = 0` and `Dᵀ v = 0` (then
//! `vᵀ S v = 0`). In the section IV example `C_k` has full row rank for every integer `k ≥ 1`
//! (its rows differ in `0.25 cos k ≠ 0.25`), and at `k = 0` the only `v` with `C₀ᵀ v = 0` is
//! `[1, −1]ᵀ`, for which `Dᵀ v = 0.95`. So no regularisation is added: `S` is factorised by
//! Cholesky, and a step whose `S` is numerically singular fails with
//! [`Error::NotPositiveDefinite`](crate::Error::NotPositiveDefinite) (the estimator unchanged) instead of being patched.
//!
//! What the singular `R` does mean: the filter believes one combination of `y_k` is
//! noise-free, so `P_{k|k}` loses rank in one direction at every update; the time update's
//! `Q = B W Bᵀ` (rank 1) and the transition give it back. The Joseph form keeps `P`
//! symmetric PSD for any gain.
//!
//! # Timing
//! As [`CoupledNoiseKf`](super::CoupledNoiseKf): [`IndependentNoiseKf::step`] is driven by the
//! observation of instant `k + 1`, processes the stored `y_k` and stores `y_{k+1}`;
//! [`IndependentNoiseKf::with_initial_measurement`] supplies `y₀`.

use nalgebra::{SMatrix, SVector};

use crate::estimate::Estimate;
use crate::filter::nn::system::{CoupledNoiseSystem, DifferentiableMap};
use crate::filter::noise_coupled::{NoiseCoupledKf, NoiseCoupledStep};
use crate::linalg::{check_finite, solve_spd_right, symmetrize};
use crate::{Real, Result};

/// Which textbook filter.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum IndependentMode {
    /// KF: transition `A_k`, `f` ignored.
    #[default]
    Kf,
    /// EKF: mean `A_k x̂ + f(x̂)`, covariance through `A_k + ∂f/∂x`, both at the filtered
    /// estimate.
    Ekf,
}

/// Textbook KF/EKF with `B w` and `D w` taken as independent noises (seed 003's practitioner
/// baselines): the shared [`NoiseCoupledKf`] with the textbook algebra, [`IndependentMode`]
/// its mode. Holds `x̂_{k|k−1}` with the filter's own `P_{k|k−1}`.
pub type IndependentNoiseKf<T, const NX: usize, const NW: usize, const NY: usize> =
    NoiseCoupledKf<T, NX, NW, NY, IndependentMode>;

/// The textbook step (module docs): the measurement update with the stored `y_k` (Cholesky of
/// `S`, Joseph form), then the time update at the filtered estimate. An update uses all `NY`
/// innovation directions.
impl<T: Real, const NX: usize, const NW: usize, const NY: usize> NoiseCoupledStep<T, NX, NW, NY>
    for IndependentMode
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
        check_finite(&b, "B_k")?;
        check_finite(&c, "C_k")?;
        check_finite(&d, "D_k")?;
        // Measurement update with the stored y_k.
        let (xf, pf, rank) = match y {
            None => (x, p, 0u8),
            Some(y) => {
                let r = symmetrize(&(d * *w * d.transpose()));
                let s = symmetrize(&(c * p * c.transpose() + r));
                let gain = solve_spd_right(
                    &(p * c.transpose()),
                    &s,
                    "innovation covariance C P Cᵀ + D W Dᵀ",
                )?;
                let ikc = SMatrix::<T, NX, NX>::identity() - gain * c;
                (
                    x + gain * (y - c * x),
                    ikc * p * ikc.transpose() + gain * r * gain.transpose(),
                    NY as u8,
                )
            }
        };
        // Time update.
        let (x_next, jac) = match self {
            IndependentMode::Kf => (a * xf, a),
            IndependentMode::Ekf => (a * xf + f.eval(&xf), a + f.jacobian(&xf)),
        };
        check_finite(&jac, "transition Jacobian")?;
        let p_next = symmetrize(&(jac * pf * jac.transpose() + b * *w * b.transpose()));
        check_finite(&x_next, "state estimate")?;
        check_finite(&p_next, "covariance")?;
        Ok((x_next, p_next, rank))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimator::{Estimator, OnModel};
    use crate::filter::coupled_kf::NoNonlinearity;
    use crate::linalg::check_spd;
    use crate::packet::Packet;
    use crate::papers::Seed003Example;
    use crate::Error;
    use nalgebra::{matrix, vector};

    /// A linear time-invariant system with independent noises written in the coupled form:
    /// `w = [w₁, w₂]`, `B = [b 0]`, `D = [0 d]`, so `B W Dᵀ = 0` for diagonal `W`. On it the
    /// independent-noise KF is the exact KF and must equal the paper's correlated-noise
    /// predictor, whose cross term vanishes.
    struct Decoupled;
    impl CoupledNoiseSystem<f64, 2, 2, 1> for Decoupled {
        fn a(&self, _k: usize) -> SMatrix<f64, 2, 2> {
            matrix![0.9, 0.2; -0.1, 0.8]
        }
        fn b(&self, _k: usize) -> SMatrix<f64, 2, 2> {
            matrix![1.0, 0.0; 0.5, 0.0]
        }
        fn c(&self, _k: usize) -> SMatrix<f64, 1, 2> {
            matrix![1.0, -0.5]
        }
        fn d(&self, _k: usize) -> SMatrix<f64, 1, 2> {
            matrix![0.0, 0.7]
        }
    }

    #[test]
    fn equals_the_exact_predictor_when_the_noises_are_independent() {
        use crate::filter::coupled_kf::{CoupledNoiseKf, Linearisation};
        let w = matrix![0.4, 0.0; 0.0, 0.3];
        let (x0, p0) = (vector![1.0, -1.0], SMatrix::<f64, 2, 2>::identity() * 2.0);
        let mut ind = IndependentNoiseKf::new(x0, p0, w, IndependentMode::Kf)
            .unwrap()
            .with_initial_measurement(vector![0.4])
            .unwrap();
        let mut cor = CoupledNoiseKf::new(x0, p0, w, Linearisation::None)
            .unwrap()
            .with_initial_measurement(vector![0.4])
            .unwrap();
        let ys = [Some(-0.2), None, Some(1.3), Some(0.7), None, Some(-0.5)];
        for (t, y) in ys.iter().enumerate() {
            let y = y.map(|v| vector![v]);
            ind.step(&Decoupled, &NoNonlinearity, y.as_ref()).unwrap();
            cor.step(&Decoupled, &NoNonlinearity, y.as_ref()).unwrap();
            let (a, b) = (ind.estimate(), cor.estimate());
            assert!((a.state() - b.state()).amax() < 1e-12, "t = {t}");
            assert!((a.covariance() - b.covariance()).amax() < 1e-12, "t = {t}");
        }
    }

    #[test]
    fn first_step_by_hand_on_the_seed003_example() {
        // x̂₀ = 0, P₀ = 10 I, y₀ given, k = 0: C₀ = [0.9 0.25 1; 0.9 0.25 1], D₀ = [0.95, 0]ᵀ,
        // A₀ = [1.5 .01 .02; .02 0 .3; .01 .03 1.9], B₀ = [1 1 1]ᵀ, W = 0.1.
        // c = [0.9, 0.25, 1]: c P₀ cᵀ = 10 (0.81 + 0.0625 + 1) = 18.725, R = diag(0.09025, 0),
        // so S = [18.725 + 0.09025, 18.725; 18.725, 18.725] (det = 0.09025 · 18.725 > 0
        // although C₀ has two equal rows and R is singular). K y₀ = P₀ C₀ᵀ S⁻¹ y₀ with S⁻¹ y₀
        // from the 2×2 inverse formula below, not from the code's Cholesky solve.
        let y0 = vector![2.0, 1.5];
        let mut kf = IndependentNoiseKf::<f64, 3, 1, 2>::new(
            Seed003Example::xhat0(),
            Seed003Example::p0(),
            matrix![0.1],
            IndependentMode::Kf,
        )
        .unwrap()
        .with_initial_measurement(y0)
        .unwrap();
        kf.step(&Seed003Example, &NoNonlinearity, None).unwrap();
        let alpha = 18.725;
        let (s11, s12, s22) = (alpha + 0.09025, alpha, alpha);
        let det = s11 * s22 - s12 * s12;
        let sinv_y = vector![s22 * y0[0] - s12 * y0[1], -s12 * y0[0] + s11 * y0[1]] / det;
        // P₀ C₀ᵀ = 10 [c; c]ᵀ, so x̂_{0|0} = 10 cᵀ (sinv_y₁ + sinv_y₂).
        let c = vector![0.9, 0.25, 1.0];
        let xf = c * (10.0 * (sinv_y[0] + sinv_y[1]));
        let a0: SMatrix<f64, 3, 3> = Seed003Example.a(0);
        let want = a0 * xf;
        assert!(
            (kf.estimate().state() - want).amax() < 1e-12 * want.amax(),
            "{} vs {want}",
            kf.estimate().state()
        );
        // The filtered x̂_{0|0} reproduces the noise-free combination exactly:
        // (y₀ − C₀ x̂_{0|0})₂ = 0 because R₂₂ = 0 (the filter trusts y₀'s second row fully).
        assert!((y0[1] - c.dot(&xf)).abs() < 1e-12);
    }

    #[test]
    fn runs_the_example_with_rank_one_measurement_noise() {
        // The bucket's pattern, a noise-free linear plant: the KF must stay finite and SPD at
        // every step (no regularisation anywhere) and converge on the exact model.
        let sys = Seed003Example;
        let mut x = Seed003Example::x0::<f64>();
        let y0: SVector<f64, 2> = sys.c(0) * x;
        let mut kf = IndependentNoiseKf::<f64, 3, 1, 2>::new(
            Seed003Example::xhat0(),
            Seed003Example::p0(),
            matrix![0.1],
            IndependentMode::Kf,
        )
        .unwrap()
        .with_initial_measurement(y0)
        .unwrap();
        for k in 0..60 {
            x = sys.a(k) * x;
            let y: SVector<f64, 2> = sys.c(k + 1) * x;
            let sent = k + 1 < 6 || (k + 1) % 3 != 0;
            kf.step(&sys, &NoNonlinearity, sent.then_some(&y)).unwrap();
            check_spd(kf.estimate().covariance(), "P").unwrap();
        }
        assert!((kf.estimate().state() - x).amax() < 1e-6 * x.amax().max(1.0));
    }

    #[test]
    fn nan_is_rejected_without_change_and_modes_differ() {
        let sys = Seed003Example;
        let mk = |m| {
            IndependentNoiseKf::<f64, 3, 1, 2>::new(
                vector![0.5, -0.3, 0.2],
                Seed003Example::p0(),
                matrix![0.1],
                m,
            )
            .unwrap()
            .with_initial_measurement(vector![1.0, 0.8])
            .unwrap()
        };
        let mut e = mk(IndependentMode::Ekf);
        let before = e;
        assert_eq!(
            e.step(&sys, &sys, Some(&vector![f64::NAN, 1.0])),
            Err(Error::NonFinite {
                what: "measurement"
            })
        );
        assert_eq!(e, before);
        let mut kf = mk(IndependentMode::Kf);
        kf.step(&sys, &sys, None).unwrap();
        e.step(&sys, &sys, None).unwrap();
        assert!((kf.estimate().state() - e.estimate().state()).amax() > 1e-3);
        // Through the trait: only the next instant is accepted.
        let mut on = OnModel::<_, _, 2>::new((sys, sys), mk(IndependentMode::Ekf));
        assert_eq!(
            on.step(2, &Packet::Dropped),
            Err(Error::OutOfOrder {
                expected: 1,
                got: 2
            })
        );
        on.step(1, &Packet::Dropped).unwrap();
        assert_eq!(on.filter.instant(), 1);
    }
}
