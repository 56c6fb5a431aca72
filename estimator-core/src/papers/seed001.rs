//! Seed 001, Section IV: the unstable three-state plant observed through two measurements
//! whose packets drop while `x₁` lies in one of four occlusion regions (docs/design.md,
//! "Seed 001").
//!
//! ```
//! use estimator_core::papers::Seed001Example;
//! use estimator_core::filter::CrossCoupledEstimator;
//! use estimator_core::gsum::GaussSum;
//! use nalgebra::vector;
//!
//! let model = Seed001Example::model::<f64>()?;
//! let mut cce = CrossCoupledEstimator::new(
//!     Seed001Example::x0(),
//!     Seed001Example::p0(),
//!     Seed001Example::occlusion()?,
//!     &GaussSum::<f64, 1, 15>::uniform()?,
//! )?;
//! // A dropout at k = 1: the estimate moves into the most probable region.
//! let label = cce.step::<2, _>(&model, 1, None)?;
//! assert!((1..=4).contains(&label));
//! // An arrival: the Kalman update, label 0.
//! assert_eq!(cce.step(&model, 2, Some(&vector![30.0, 10.0]))?, 0);
//! # Ok::<(), estimator_core::Error>(())
//! ```

use nalgebra::{Matrix1, Matrix1x3, Matrix2x3, Matrix3, SMatrix, SVector, Vector1};

use crate::model::LinearModel;
use crate::protocol::occlusion::{Occlusion, OcclusionRegions};
use crate::{Real, Result};

/// Seed 001, Section IV: three states, two measurements, four occlusion intervals of
/// radius 5 centred at 20, 40, 60, 80 on `u = x₁ + n`, `n ~ N(0, 0.1)`.
#[derive(Clone, Copy, Debug)]
pub struct Seed001Example;

impl Seed001Example {
    /// `A`, `C` as printed, `B = D = I`, `Q = 0.3 I₃`, `R = 0.2 I₂`. `A` has eigenvalues
    /// 1.01 (twice) and −1.02: the plant is unstable, as in the paper.
    ///
    /// Returns `Result` like every constructor in the core (it cannot fail for these values).
    pub fn model<T: Real>() -> Result<LinearModel<T, 3, 3, 2, 2>> {
        let l = T::lit;
        LinearModel::new(
            Matrix3::new(
                l(1.01),
                l(0.1),
                l(0.0),
                l(0.0),
                l(1.01),
                l(0.1),
                l(0.0),
                l(0.0),
                l(-1.02),
            ),
            SMatrix::identity(),
            Matrix2x3::new(l(2.0), l(3.0), l(1.0), l(1.0), l(0.0), l(0.98)),
            SMatrix::identity(),
            SMatrix::identity() * l(0.3),
            SMatrix::identity() * l(0.2),
        )
    }

    /// `E = [1 0 0]`, `Ψ = 0.1`, regions `[ζ − 5, ζ + 5]` for `ζ = 20, 40, 60, 80`.
    pub fn occlusion<T: Real>() -> Result<Occlusion<T, 3, 1, 4>> {
        let l = T::lit;
        Occlusion::new(
            Matrix1x3::new(l(1.0), l(0.0), l(0.0)),
            Matrix1::new(l(0.1)),
            OcclusionRegions::new(
                [20.0, 40.0, 60.0, 80.0].map(|c| Vector1::new(l(c))),
                [l(5.0); 4],
            )?,
        )
    }

    /// The estimators' initial mean `x̂₀ = [5 5 5]ᵀ`.
    pub fn x0<T: Real>() -> SVector<T, 3> {
        SVector::repeat(T::lit(5.0))
    }

    /// The estimators' initial covariance `P₀ = 4 I₃`.
    pub fn p0<T: Real>() -> SMatrix<T, 3, 3> {
        SMatrix::identity() * T::lit(4.0)
    }
}
