//! `adskalman` 0.18 on a [`Problem`]: `KalmanFilterNoControl::step_with_options` with the
//! Joseph form, the model stored as `adskalman` wants it (F, Fᵀ, Q, H, Hᵀ, R), as
//! `benches/src/ads.rs` drives it on the host.

use adskalman::{
    CovarianceUpdateMethod, KalmanFilterNoControl, ObservationModel, StateAndCovariance,
    TransitionModelLinearNoControl,
};
use na35::{Const, SMatrix, SVector};
use nalgebra::Vector2;

use super::{KfStep, Problem, NY};

/// nalgebra 0.34 to 0.35 (same column-major layout), at construction only.
fn conv<const R: usize, const C: usize>(m: &nalgebra::SMatrix<f32, R, C>) -> SMatrix<f32, R, C> {
    SMatrix::from_column_slice(m.as_slice())
}

/// The model in `adskalman`'s shape.
#[derive(Clone, Debug)]
pub struct AdsModel<const NX: usize> {
    f: SMatrix<f32, NX, NX>,
    ft: SMatrix<f32, NX, NX>,
    q: SMatrix<f32, NX, NX>,
    h: SMatrix<f32, NY, NX>,
    ht: SMatrix<f32, NX, NY>,
    r: SMatrix<f32, NY, NY>,
}

impl<const NX: usize> TransitionModelLinearNoControl<f32, Const<NX>> for AdsModel<NX> {
    fn F(&self) -> &SMatrix<f32, NX, NX> {
        &self.f
    }
    fn FT(&self) -> &SMatrix<f32, NX, NX> {
        &self.ft
    }
    fn Q(&self) -> &SMatrix<f32, NX, NX> {
        &self.q
    }
}

impl<const NX: usize> ObservationModel<f32, Const<NX>, Const<NY>> for AdsModel<NX> {
    fn H(&self) -> &SMatrix<f32, NY, NX> {
        &self.h
    }
    fn HT(&self) -> &SMatrix<f32, NX, NY> {
        &self.ht
    }
    fn R(&self) -> &SMatrix<f32, NY, NY> {
        &self.r
    }
}

/// `adskalman`'s filter state with its model.
#[derive(Clone, Debug)]
pub struct Ads<const NX: usize> {
    model: AdsModel<NX>,
    est: StateAndCovariance<f32, Const<NX>>,
}

impl<const NX: usize> Ads<NX> {
    /// At the problem's prior.
    pub fn new(p: &Problem<NX>) -> Self {
        let (a, c) = (p.a(), p.c());
        Self {
            model: AdsModel {
                f: conv(&a),
                ft: conv(&a.transpose()),
                q: conv(&p.q()),
                h: conv(&c),
                ht: conv(&c.transpose()),
                r: conv(&p.r()),
            },
            est: StateAndCovariance::new(conv(&p.x0), conv(&p.p0)),
        }
    }
}

impl<const NX: usize> KfStep<NX> for Ads<NX> {
    #[inline(never)]
    fn step(&mut self, _k: usize, y: &Vector2<f32>) -> bool {
        let kf = KalmanFilterNoControl::<f32, Const<NX>, Const<NY>>::new(&self.model, &self.model);
        let y = SVector::<f32, NY>::new(y[0], y[1]);
        match kf.step_with_options(&self.est, &y, CovarianceUpdateMethod::JosephForm) {
            Ok(est) => {
                self.est = est;
                true
            }
            Err(_) => false,
        }
    }
    fn x(&self, i: usize) -> f32 {
        self.est.state()[i]
    }
    fn p(&self, i: usize, j: usize) -> f32 {
        self.est.covariance()[(i, j)]
    }
}
