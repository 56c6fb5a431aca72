//! The recursive NN-based state estimator under the token-bucket protocol (seed 003):
//! estimator (5), weight tuning law (6), bounds of Theorem 1 and the gain of Theorem 2.
//!
//! ```text
//! x̂_{k+1} = A_k x̂_k + Ĥ_k φ(x̂_k) + γ_k L_k (y_k − C_k x̂_k)                        (5)
//! Ĥ_{k+1} = Ĥ_k + θ₁ (γ_{k+1} C_{k+1}ᵀ (y_{k+1} − C_{k+1} x̂_{k+1}) φ̄ᵀ(x̂_k) − θ₂ Ĥ_k)   (6)
//! ```
//! with `γ_k = 1{μ_k ≥ 0}` (the packet of instant `k` was transmitted).
//!
//! # Timing
//! `x̂_k` is a one-step *prediction*: it uses `y_0 … y_{k−1}`, and `P̄_k` bounds
//! `E[(x_k − x̂_k)(x_k − x̂_k)ᵀ]`. The gain `L_k` of (35) needs `1{μ_{k+1} ≥ 0}` (through `δ̄₂`,
//! `δ̄₄`) and (6) needs `y_{k+1}`, so [`NnTbcpEstimator::step`] is driven by the observation of
//! instant `k + 1`: it computes `L_k` and `x̂_{k+1}` from the stored `y_k`, then tunes
//! `Ĥ_{k+1}` with `y_{k+1}`, then stores `y_{k+1}`. After the step for instant `k + 1` the
//! estimator therefore holds exactly the paper's `x̂_{k+1}, Ĥ_{k+1}, P̄_{k+1}, Q̄_{k+1}`.
//! Nothing but the arrival flag of `k + 1` is needed in advance, so a receiver that cannot run
//! a replica of the bucket works too.

use nalgebra::{SMatrix, SVector};

use super::bound::{
    normalised_regressor, optimal_gain, propagate_bounds, GainSolver, NnBoundConfig, StepMatrices,
};
use super::system::{Activation, CoupledNoiseSystem};
use crate::estimate::Estimate;
use crate::estimator::{Estimator, OnModel};
use crate::linalg::{check_finite, check_spd, symmetrize};
use crate::packet::Packet;
use crate::{Error, Real, Result};

/// The seed 003 estimator on `NX` states, `NW` noises, `NY` measurements and `NPHI` activation
/// outputs. `NP` must equal `NX·NY` (the Kronecker dimension of (35), checked at compile
/// time); `Act` is the activation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NnTbcpEstimator<
    T: Real,
    const NX: usize,
    const NW: usize,
    const NY: usize,
    const NPHI: usize,
    const NP: usize,
    Act,
> {
    cfg: NnBoundConfig<T>,
    act: Act,
    solver: GainSolver,
    k: usize,
    /// `x̂_k` with the bound `P̄_k`.
    est: Estimate<T, NX>,
    h: SMatrix<T, NX, NPHI>,
    q: SMatrix<T, NX, NX>,
    y: Option<SVector<T, NY>>,
    gain: SMatrix<T, NX, NY>,
    phi_norm: T,
}

impl<
        T: Real,
        const NX: usize,
        const NW: usize,
        const NY: usize,
        const NPHI: usize,
        const NP: usize,
        Act: Activation<T, NX, NPHI>,
    > NnTbcpEstimator<T, NX, NW, NY, NPHI, NP, Act>
{
    /// Starts at instant 0 from `x̂₀`, `Ĥ₀` and the bounds' initial values `P̄₀`, `Q̄₀`
    /// (finite, symmetric positive definite). No measurement of instant 0 is assumed; use
    /// [`Self::with_initial_measurement`] if there is one.
    pub fn new(
        cfg: NnBoundConfig<T>,
        act: Act,
        x0: SVector<T, NX>,
        h0: SMatrix<T, NX, NPHI>,
        p0: SMatrix<T, NX, NX>,
        q0: SMatrix<T, NX, NX>,
    ) -> Result<Self> {
        check_finite(&x0, "x̂₀")?;
        check_finite(&h0, "Ĥ₀")?;
        let est = Estimate::named(x0, p0, "x̂₀", "P̄₀")?;
        check_spd(&q0, "Q̄₀")?;
        let phi_norm = act.eval(&x0).norm();
        Ok(Self {
            cfg,
            act,
            solver: GainSolver::Kronecker,
            k: 0,
            est,
            h: h0,
            q: symmetrize(&q0),
            y: None,
            gain: SMatrix::zeros(),
            phi_norm,
        })
    }

    /// Uses `y₀` (transmitted at instant 0) in the first step.
    pub fn with_initial_measurement(mut self, y0: SVector<T, NY>) -> Result<Self> {
        check_finite(&y0, "y₀")?;
        self.y = Some(y0);
        Ok(self)
    }

    /// Selects how (38) is solved (the paper's Kronecker form by default).
    #[must_use]
    pub fn with_gain_solver(mut self, solver: GainSolver) -> Self {
        self.solver = solver;
        self
    }

    /// Instant `k` of the current estimate.
    #[inline]
    pub fn instant(&self) -> usize {
        self.k
    }
    /// `x̂_k` (uses measurements up to `k − 1`) with `P̄_k`, the bound on the
    /// estimation-error covariance.
    #[inline]
    pub fn estimate(&self) -> &Estimate<T, NX> {
        &self.est
    }
    /// `Ĥ_k`.
    #[inline]
    pub fn weights(&self) -> &SMatrix<T, NX, NPHI> {
        &self.h
    }
    /// `Q̄_k`, the bound on the NN-weight-error covariance.
    #[inline]
    pub fn bound_q(&self) -> &SMatrix<T, NX, NX> {
        &self.q
    }
    /// The configuration.
    #[inline]
    pub fn config(&self) -> &NnBoundConfig<T> {
        &self.cfg
    }
    /// The activation.
    #[inline]
    pub fn activation(&self) -> &Act {
        &self.act
    }
    /// `L_{k−1}` used by the last step (zero if that instant's packet was not transmitted).
    #[inline]
    pub fn last_gain(&self) -> &SMatrix<T, NX, NY> {
        &self.gain
    }
    /// `‖φ(x̂_k)‖` of the current estimate (the paper assumes it is at most `φ̄`).
    #[inline]
    pub fn phi_norm(&self) -> T {
        self.phi_norm
    }

    /// Advances from instant `k` to `k + 1` given the observation of instant `k + 1`
    /// (`None` when the token bucket withheld it). See the module docs for the timing.
    ///
    /// On error (non-finite input, a bound overflowing, a singular gain system) nothing
    /// changes.
    pub fn step<S: CoupledNoiseSystem<T, NX, NW, NY>>(
        &mut self,
        sys: &S,
        y_next: Option<&SVector<T, NY>>,
    ) -> Result<()> {
        if let Some(y) = y_next {
            check_finite(y, "measurement")?;
        }
        let k = self.k;
        let (x, p) = (*self.est.state(), *self.est.covariance());
        let s = StepMatrices {
            a: sys.a(k),
            b: sys.b(k),
            c: sys.c(k),
            d: sys.d(k),
            c_next: sys.c(k + 1),
            d_next: sys.d(k + 1),
            gamma: self.y.is_some(),
            gamma_next: y_next.is_some(),
        };
        check_finite(&s.a, "A_k")?;
        check_finite(&s.b, "B_k")?;
        check_finite(&s.c, "C_k")?;
        check_finite(&s.d, "D_k")?;
        check_finite(&s.c_next, "C_{k+1}")?;
        check_finite(&s.d_next, "D_{k+1}")?;
        // Theorem 2; L_k does not enter (5) or (14) when y_k was not transmitted.
        let l = match self.y {
            Some(_) => optimal_gain::<T, NX, NW, NY, NP>(&self.cfg, &p, &s, self.solver)?,
            None => SMatrix::zeros(),
        };
        // (5).
        let phi = self.act.eval(&x);
        check_finite(&phi, "activation φ(x̂_k)")?;
        let mut x_next = s.a * x + self.h * phi;
        if let Some(y) = &self.y {
            x_next += l * (y - s.c * x);
        }
        check_finite(&x_next, "state estimate")?;
        // Theorem 1.
        let (p_next, q_next) = propagate_bounds(&self.cfg, &p, &self.q, &l, &s)?;
        // (6), with ȳ_{k+1} = y_{k+1} − C_{k+1} x̂_{k+1}.
        let [t1, t2] = self.cfg.theta();
        let (_, m_norm) = s.m_and_norm()?;
        let mut h_next = self.h - self.h * (t1 * t2);
        if let Some(y) = y_next {
            let phib = normalised_regressor(&phi, m_norm);
            let innov = y - s.c_next * x_next;
            h_next += (s.c_next.transpose() * innov * phib.transpose()) * t1;
        }
        check_finite(&h_next, "NN weights Ĥ")?;
        let phi_norm = self.act.eval(&x_next).norm();
        // Commit.
        self.k = k + 1;
        self.est = Estimate::trusted(x_next, p_next);
        self.h = h_next;
        self.q = q_next;
        self.y = y_next.copied();
        self.gain = l;
        self.phi_norm = phi_norm;
        Ok(())
    }
}

/// Delivered: `γ_{k+1} = 1`; dropped (withheld by the token bucket) or lost: `γ_{k+1} = 0`.
/// The estimator counts its instants: `k` must be [`NnTbcpEstimator::instant`] + 1.
impl<
        T: Real,
        const NX: usize,
        const NW: usize,
        const NY: usize,
        const NPHI: usize,
        const NP: usize,
        Act: Activation<T, NX, NPHI>,
        S: CoupledNoiseSystem<T, NX, NW, NY>,
    > Estimator<T, NX> for OnModel<S, NnTbcpEstimator<T, NX, NW, NY, NPHI, NP, Act>, NY>
{
    type Measurement = Packet<T, NY>;

    /// [`NnTbcpEstimator::step`] with the observation of instant `k`; refused with
    /// [`Error::OutOfOrder`] unless `k` is the next instant.
    fn step(&mut self, k: usize, y: &Packet<T, NY>) -> Result<()> {
        let expected = self.filter.instant() + 1;
        if k != expected {
            return Err(Error::OutOfOrder { expected, got: k });
        }
        self.filter.step(&self.model, y.delivered())
    }

    #[inline]
    fn estimate(&self) -> &Estimate<T, NX> {
        self.filter.estimate()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::nn::system::Tanh;
    use crate::papers::{Seed003Example, Seed003Nn};
    use crate::protocol::token_bucket::{TokenBucket, TokenBucketConfig};
    use nalgebra::{matrix, vector};

    fn example_f64() -> Seed003Nn<f64> {
        Seed003Nn::seed003(NnBoundConfig::seed003_example()).unwrap()
    }

    #[test]
    fn first_step_by_hand() {
        // No y₀ (γ₀ = 0): x̂₁ = A₀ x̂₀ + Ĥ₀ tanh(x̂₀) = 0 for x̂₀ = 0, and with y₁ transmitted
        // Ĥ₁ = (1 − θ₁θ₂) Ĥ₀ + θ₁ C₁ᵀ y₁ φ̄ᵀ(x̂₀) = (1 − 1e-6) Ĥ₀ since φ(0) = 0.
        let mut nn = example_f64();
        nn.step(&Seed003Example, Some(&vector![1.0, 2.0])).unwrap();
        assert_eq!(nn.estimate().state(), &SVector::<f64, 3>::zeros());
        assert!((nn.weights() - Seed003Example::h0::<f64>() * (1.0 - 1e-6)).amax() < 1e-15);
        // P̄₁ = 1.2 A₀ P̄₀ A₀ᵀ + (1 + 10 + 0.2) Q̄₀ + 11 w̄² B₀B₀ᵀ + 21 (16.1)² I.
        let a0: SMatrix<f64, 3, 3> = Seed003Example.a(0);
        let b0: SMatrix<f64, 3, 1> = Seed003Example.b(0);
        let p1 = a0 * a0.transpose() * 12.0
            + SMatrix::<f64, 3, 3>::identity() * (11.2 * 10.0 + 21.0 * 16.1 * 16.1)
            + b0 * b0.transpose() * 1.1;
        assert!((nn.estimate().covariance() - p1).amax() < 1e-10);
        assert_eq!(nn.instant(), 1);
    }

    #[test]
    fn transmitted_step_uses_the_gain_and_tunes_weights() {
        let mut nn = example_f64();
        let y1 = vector![0.7, -0.3];
        nn.step(&Seed003Example, Some(&y1)).unwrap();
        let before = nn;
        let y2 = vector![1.1, 0.4];
        nn.step(&Seed003Example, Some(&y2)).unwrap();
        // Independent recomputation of (5) and (6) for this step.
        let sys = Seed003Example;
        let x1 = *before.estimate().state();
        let phi = x1.map(|v| v.tanh());
        let l = *nn.last_gain();
        let x2 = sys.a(1) * x1 + before.weights() * phi + l * (y1 - sys.c(1) * x1);
        assert!((nn.estimate().state() - x2).amax() < 1e-12);
        let c2: SMatrix<f64, 2, 3> = sys.c(2);
        let mnorm = (c2.transpose() * c2).symmetric_eigenvalues().max();
        let phib = phi / ((1.0 + phi.dot(&phi)) * mnorm);
        let h2 = before.weights()
            + (c2.transpose() * (y2 - c2 * x2) * phib.transpose() - before.weights() * 0.001)
                * 0.001;
        assert!((nn.weights() - h2).amax() < 1e-14);
        // A non-zero gain was used.
        assert!(l.amax() > 0.0);
    }

    #[test]
    fn nan_is_an_error_and_state_is_unchanged() {
        let mut nn = example_f64();
        nn.step(&Seed003Example, Some(&vector![0.7, -0.3])).unwrap();
        let before = nn;
        assert_eq!(
            nn.step(&Seed003Example, Some(&vector![f64::NAN, 0.0])),
            Err(Error::NonFinite {
                what: "measurement"
            })
        );
        assert_eq!(nn, before);
        assert!(NnTbcpEstimator::<f64, 3, 1, 2, 3, 6, Tanh>::new(
            NnBoundConfig::seed003_example(),
            Tanh,
            Seed003Example::xhat0(),
            Seed003Example::h0(),
            matrix![1.0, 0.0, 0.0; 0.0, 1.0, 0.0; 0.0, 0.0, -1.0],
            Seed003Example::p0(),
        )
        .is_err());
    }

    /// Runs the section IV example on a noise-free plant (w = 0) under the token bucket.
    fn run<T: Real>(
        cfg: NnBoundConfig<T>,
        solver: GainSolver,
        steps: usize,
    ) -> core::result::Result<Seed003Nn<T>, (usize, Error)> {
        use crate::filter::nn::system::DifferentiableMap;
        let sys = Seed003Example;
        let mut nn = Seed003Nn::seed003(cfg).unwrap().with_gain_solver(solver);
        let mut tb = TokenBucket::new(TokenBucketConfig::new(2, 3, 10, 6).unwrap());
        let mut x = Seed003Example::x0::<T>();
        for k in 0..steps {
            x = CoupledNoiseSystem::<T, 3, 1, 2>::a(&sys, k) * x + sys.eval(&x);
            let y = CoupledNoiseSystem::<T, 3, 1, 2>::c(&sys, k + 1) * x;
            let sent = tb.step().transmit;
            nn.step(&sys, sent.then_some(&y)).map_err(|e| (k, e))?;
        }
        Ok(nn)
    }

    #[test]
    fn kronecker_and_two_sided_runs_agree() {
        let cfg = NnBoundConfig::<f64>::seed003_example();
        let a = run(cfg, GainSolver::Kronecker, 40).unwrap();
        let b = run(cfg, GainSolver::TwoSided, 40).unwrap();
        let scale = a.estimate().state().amax().max(1.0);
        assert!((a.estimate().state() - b.estimate().state()).amax() < 1e-9 * scale);
    }

    #[test]
    fn f32_and_f64_both_run() {
        // A configuration whose bound does not grow geometrically (δ₁ < 1), so f32's range
        // suffices; the paper's own configuration overflows f32 (see the assumption checker).
        let cfg64 =
            NnBoundConfig::<f64>::new([0.5; 4], [0.5; 12], [0.05, 10.0], 8.0, 1.8, 0.1, 0.1)
                .unwrap();
        assert!(cfg64.delta1() < 1.0);
        let cfg32 =
            NnBoundConfig::<f32>::new([0.5; 4], [0.5; 12], [0.05, 10.0], 8.0, 1.8, 0.1, 0.1)
                .unwrap();
        // 40 steps: at k = 44 (cos 44 ≈ 0.99984) the two rows of C_k nearly coincide and
        // κ(Θ̄) ≈ 1e7 exceeds what f32 resolves; the Cholesky solve then refuses (tested below).
        let a = run(cfg64, GainSolver::Kronecker, 40).unwrap();
        let b = run(cfg32, GainSolver::Kronecker, 40).unwrap();
        assert!(a.estimate().covariance().trace().is_finite());
        assert!(b.estimate().covariance().trace().is_finite());
        // Bounds are deterministic functions of the configuration and transmission pattern:
        // f32 tracks f64 to single precision.
        let rel = (a.estimate().covariance().trace() - b.estimate().covariance().trace() as f64)
            .abs()
            / a.estimate().covariance().trace();
        assert!(rel < 1e-4, "{rel}");
        // f64 runs the whole horizon; f32 reports the ill-conditioned gain system instead of
        // returning a meaningless gain.
        assert!(run(cfg64, GainSolver::Kronecker, 300).is_ok());
        let err = run(cfg32, GainSolver::Kronecker, 300).unwrap_err();
        assert!(
            matches!(err.1, Error::NotPositiveDefinite { .. }),
            "{err:?}"
        );
    }
}
