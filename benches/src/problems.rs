//! The benchmark problems: one Kalman step at the papers' dimensions, from a converged prior.

use estimator_core::filter::{CovarianceUpdate, IntermittentKalmanFilter, KalmanFilter};
use estimator_core::model::{LinearModel, LinearSystem};
use estimator_core::papers::Seed001Example;
use estimator_core::{Estimator, OnModel, Packet, Real, Result};
use nalgebra::{matrix, vector, SMatrix, SVector};

/// A linear-Gaussian problem with `B = I`, `D = I`, a converged prior and the measurement
/// of the timed step.
#[derive(Clone, Copy, Debug)]
pub struct KfProblem<T: Real, const NX: usize, const NY: usize> {
    /// Short name used in bench ids and tables.
    pub name: &'static str,
    /// The model (`B = I`, `D = I`).
    pub model: LinearModel<T, NX, NX, NY, NY>,
    /// The filter at steady state, the prior of every timed step.
    pub prior: KalmanFilter<T, NX>,
    /// The same prior as an intermittent Kalman filter.
    pub prior_ikf: IntermittentKalmanFilter<T, NX>,
    /// The measurement of the timed step (a realistic innovation, not zero).
    pub y: SVector<T, NY>,
}

impl<T: Real, const NX: usize, const NY: usize> KfProblem<T, NX, NY> {
    /// Builds the problem and runs the filter to steady state on a deterministic measurement
    /// sequence, so that the timed step is the step a long-running filter takes.
    fn converge(
        name: &'static str,
        model: LinearModel<T, NX, NX, NY, NY>,
        x0: SVector<T, NX>,
        p0: SMatrix<T, NX, NX>,
    ) -> Self {
        let mut kf = KalmanFilter::new(x0, p0).expect("valid prior");
        let meas = |k: usize, x: &SVector<T, NX>| -> SVector<T, NY> {
            // y = C A x̂ + a bounded deterministic wiggle: innovations of order one.
            let mut y = model.c(k) * (model.a(k) * x);
            for i in 0..NY {
                y[i] += T::lit(((k * (i + 1)) as f64 * 0.7).sin());
            }
            y
        };
        for k in 1..400 {
            let y = meas(k, kf.estimate().state());
            kf.step(&model, k, &y).expect("convergence run");
        }
        let y = meas(400, kf.estimate().state());
        let prior_ikf =
            IntermittentKalmanFilter::new(*kf.estimate().state(), *kf.estimate().covariance())
                .expect("valid prior");
        Self {
            name,
            model,
            prior: kf,
            prior_ikf,
            y,
        }
    }

    /// One KF step (predict + Joseph update) from the fixed prior.
    #[inline]
    pub fn kf_step(&self) -> Result<KalmanFilter<T, NX>> {
        let mut f = OnModel::<_, _, NY>::new(&self.model, self.prior);
        f.step(1, &self.y)?;
        Ok(f.filter)
    }

    /// One KF step with the optimal-gain covariance form `P − K Gᵀ` ([`CovarianceUpdate::Standard`],
    /// exactly symmetric), the like-for-like partner of `adskalman`'s
    /// `OptimalKalmanForcedSymmetric`.
    #[inline]
    pub fn kf_standard_step(&self) -> Result<KalmanFilter<T, NX>> {
        let standard = self
            .prior
            .with_covariance_update(CovarianceUpdate::Standard);
        let mut f = OnModel::<_, _, NY>::new(&self.model, standard);
        f.step(1, &self.y)?;
        Ok(f.filter)
    }

    /// One IKF step with the packet delivered (predict + update).
    #[inline]
    pub fn ikf_arrival_step(&self) -> Result<IntermittentKalmanFilter<T, NX>> {
        let mut f = OnModel::<_, _, NY>::new(&self.model, self.prior_ikf);
        f.step(1, &Packet::Delivered(self.y))?;
        Ok(f.filter)
    }

    /// One IKF step with the packet dropped (predict only).
    #[inline]
    pub fn ikf_dropout_step(&self) -> Result<IntermittentKalmanFilter<T, NX>> {
        let mut f = OnModel::<_, _, NY>::new(&self.model, self.prior_ikf);
        f.step(1, &Packet::Dropped)?;
        Ok(f.filter)
    }
}

/// Seed 001's numerical example (Section IV): 3 states, 2 measurements, f64.
/// `A` and `C` as printed, `Q = 0.3 I₃`, `R = 0.2 I₂`, `x₀ = [5 5 5]ᵀ`, `Σ₀ = 4 I₃`.
pub fn occlusion_3x2_f64() -> KfProblem<f64, 3, 2> {
    KfProblem::converge(
        "3x2_f64",
        Seed001Example::model().expect("valid model"),
        Seed001Example::x0(),
        Seed001Example::p0(),
    )
}

/// A planar constant-velocity tracker (the `adskalman` example's model): state
/// `[x, y, ẋ, ẏ]`, positions measured, `dt = 0.01`, white-acceleration `Q`, f32.
pub fn tracking_4x2_f32() -> KfProblem<f32, 4, 2> {
    let dt = 0.01f32;
    let q = 100.0f32; // acceleration noise intensity
    let (t3, t2) = (dt * dt * dt / 3.0 * q, dt * dt / 2.0 * q);
    let model = LinearModel::new(
        matrix![1.0, 0.0, dt, 0.0; 0.0, 1.0, 0.0, dt; 0.0, 0.0, 1.0, 0.0; 0.0, 0.0, 0.0, 1.0],
        SMatrix::identity(),
        matrix![1.0, 0.0, 0.0, 0.0; 0.0, 1.0, 0.0, 0.0],
        SMatrix::identity(),
        matrix![t3, 0.0, t2, 0.0; 0.0, t3, 0.0, t2; t2, 0.0, dt * q, 0.0; 0.0, t2, 0.0, dt * q],
        SMatrix::identity() * 0.01,
    )
    .expect("valid model");
    KfProblem::converge(
        "4x2_f32",
        model,
        vector![0.0, 0.0, 0.0, 0.0],
        SMatrix::identity() * 10.0,
    )
}

/// Seed 001's problem in f32 (for the f32/f64 comparison on the same dimensions).
pub fn occlusion_3x2_f32() -> KfProblem<f32, 3, 2> {
    let p = occlusion_3x2_f64();
    let model = p.model.cast::<f32>().expect("valid model");
    KfProblem::converge(
        "3x2_f32",
        model,
        vector![5.0, 5.0, 5.0],
        SMatrix::identity() * 4.0,
    )
}

/// The tracker in f64.
pub fn tracking_4x2_f64() -> KfProblem<f64, 4, 2> {
    let p = tracking_4x2_f32();
    let model = p.model.cast::<f64>().expect("valid model");
    KfProblem::converge(
        "4x2_f64",
        model,
        vector![0.0, 0.0, 0.0, 0.0],
        SMatrix::identity() * 10.0,
    )
}
