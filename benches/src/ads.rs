//! The same problems run through [`adskalman`], the Kalman filter a Rust user would most
//! likely pick instead.
//!
//! `adskalman` 0.18 is built on nalgebra 0.35 while the core uses 0.34: the matrices are
//! converted once here, at setup, never inside a timed loop.

use adskalman::{
    CovarianceUpdateMethod, Error, KalmanFilterNoControl, ObservationModel, StateAndCovariance,
    TransitionModelLinearNoControl,
};
use estimator_core::model::LinearSystem;
use estimator_core::Real;
use na35::{Const, DimMin, RealField, SMatrix, SVector};

use crate::problems::KfProblem;

fn conv<T: Real + na35::Scalar, const R: usize, const C: usize>(
    m: &nalgebra::SMatrix<T, R, C>,
) -> SMatrix<T, R, C> {
    SMatrix::from_column_slice(m.as_slice())
}

/// What one `adskalman` step returns.
pub type AdsState<T, const NX: usize> = Result<StateAndCovariance<T, Const<NX>>, Error>;

/// A linear model in `adskalman`'s shape (`F`, `Fᵀ`, `Q`, `H`, `Hᵀ`, `R` stored).
#[derive(Clone, Debug)]
pub struct AdsModel<T: RealField + Copy, const NX: usize, const NY: usize> {
    f: SMatrix<T, NX, NX>,
    ft: SMatrix<T, NX, NX>,
    q: SMatrix<T, NX, NX>,
    h: SMatrix<T, NY, NX>,
    ht: SMatrix<T, NX, NY>,
    r: SMatrix<T, NY, NY>,
}

impl<T: RealField + Copy, const NX: usize, const NY: usize>
    TransitionModelLinearNoControl<T, Const<NX>> for AdsModel<T, NX, NY>
{
    fn F(&self) -> &SMatrix<T, NX, NX> {
        &self.f
    }
    fn FT(&self) -> &SMatrix<T, NX, NX> {
        &self.ft
    }
    fn Q(&self) -> &SMatrix<T, NX, NX> {
        &self.q
    }
}

impl<T: RealField + Copy, const NX: usize, const NY: usize>
    ObservationModel<T, Const<NX>, Const<NY>> for AdsModel<T, NX, NY>
where
    Const<NY>: DimMin<Const<NY>, Output = Const<NY>>,
{
    fn H(&self) -> &SMatrix<T, NY, NX> {
        &self.h
    }
    fn HT(&self) -> &SMatrix<T, NX, NY> {
        &self.ht
    }
    fn R(&self) -> &SMatrix<T, NY, NY> {
        &self.r
    }
}

/// A [`KfProblem`] converted for `adskalman`: the same model, prior and measurement.
#[derive(Clone, Debug)]
pub struct AdsProblem<T: RealField + Copy, const NX: usize, const NY: usize> {
    /// The model.
    pub model: AdsModel<T, NX, NY>,
    /// The same converged prior as the core's problem.
    pub prior: StateAndCovariance<T, Const<NX>>,
    /// The same measurement.
    pub y: SVector<T, NY>,
}

impl<T, const NX: usize, const NY: usize> AdsProblem<T, NX, NY>
where
    T: Real + RealField + Copy,
    Const<NY>: DimMin<Const<NY>, Output = Const<NY>>,
{
    /// Converts the core's problem (done once, outside any timed loop).
    pub fn from_core(p: &KfProblem<T, NX, NY>) -> Self
    where
        T: na35::Scalar,
    {
        let a = p.model.a(0);
        let c = p.model.c(0);
        let model = AdsModel {
            f: conv(&a),
            ft: conv(&a.transpose()),
            q: conv(&p.model.process_cov(0)),
            h: conv(&c),
            ht: conv(&c.transpose()),
            r: conv(&p.model.measurement_cov(0)),
        };
        let prior = StateAndCovariance::<T, Const<NX>>::new(
            conv::<T, NX, 1>(p.prior.estimate().state()),
            conv::<T, NX, NX>(p.prior.estimate().covariance()),
        );
        Self {
            model,
            prior,
            y: conv(&p.y),
        }
    }

    /// One `adskalman` step (predict + Joseph-form update), the same work as
    /// [`KfProblem::kf_step`].
    #[inline]
    pub fn step(&self) -> Result<StateAndCovariance<T, Const<NX>>, Error> {
        self.step_with(CovarianceUpdateMethod::JosephForm)
    }

    /// One `adskalman` step with the optimal-gain form made symmetric,
    /// `((I − KH) P + ((I − KH) P)ᵀ) / 2`: the same work as [`KfProblem::kf_standard_step`].
    #[inline]
    pub fn step_symmetric(&self) -> Result<StateAndCovariance<T, Const<NX>>, Error> {
        self.step_with(CovarianceUpdateMethod::OptimalKalmanForcedSymmetric)
    }

    #[inline]
    fn step_with(
        &self,
        method: CovarianceUpdateMethod,
    ) -> Result<StateAndCovariance<T, Const<NX>>, Error> {
        let kf = KalmanFilterNoControl::<T, Const<NX>, Const<NY>>::new(&self.model, &self.model);
        kf.step_with_options(&self.prior, &self.y, method)
    }

    /// The posterior of [`AdsProblem::step`] (`joseph`) or [`AdsProblem::step_symmetric`] as
    /// nalgebra-0.34 matrices (for agreement checks).
    pub fn posterior(
        &self,
        joseph: bool,
    ) -> Option<(nalgebra::SVector<T, NX>, nalgebra::SMatrix<T, NX, NX>)> {
        let post = if joseph {
            self.step()
        } else {
            self.step_symmetric()
        }
        .ok()?;
        Some((
            nalgebra::SVector::from_column_slice(post.state().as_slice()),
            nalgebra::SMatrix::from_column_slice(post.covariance().as_slice()),
        ))
    }
}
