//! The intermittent Kalman filter (IKF): a Kalman filter that updates only on instants whose
//! packet arrived and otherwise only predicts (Sinopoli et al., 2004). It is the baseline that
//! ignores what a dropout says about the state.

use nalgebra::{SMatrix, SVector};

use crate::estimate::Estimate;
use crate::estimator::{Estimator, OnModel};
use crate::filter::gate::{GateCounts, GatedStep, InnovationGate};
use crate::filter::kalman::KalmanFilter;
use crate::model::LinearSystem;
use crate::packet::Packet;
use crate::{Real, Result};

/// Kalman filter that skips the update when no measurement arrived.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IntermittentKalmanFilter<T: Real, const NX: usize> {
    kf: KalmanFilter<T, NX>,
    arrivals: u32,
    dropouts: u32,
}

impl<T: Real, const NX: usize> IntermittentKalmanFilter<T, NX> {
    /// Starts from `x0`, `p0` (validated as in [`KalmanFilter::new`]). To run it with another
    /// covariance form, configure a [`KalmanFilter`] and convert it (`From`).
    pub fn new(x0: SVector<T, NX>, p0: SMatrix<T, NX, NX>) -> Result<Self> {
        Ok(Self {
            kf: KalmanFilter::new(x0, p0)?,
            arrivals: 0,
            dropouts: 0,
        })
    }

    /// Current estimate and covariance.
    #[inline]
    pub fn estimate(&self) -> &Estimate<T, NX> {
        self.kf.estimate()
    }

    /// Number of instants with and without a measurement so far.
    #[inline]
    pub fn counts(&self) -> (u32, u32) {
        (self.arrivals, self.dropouts)
    }

    /// One instant `k ≥ 1`: predict from `k − 1`; update iff `y` is `Some`.
    pub fn step<const NY: usize, M: LinearSystem<T, NX, NY>>(
        &mut self,
        model: &M,
        k: usize,
        y: Option<&SVector<T, NY>>,
    ) -> Result<()> {
        match y {
            Some(y) => {
                self.kf.step(model, k, y)?;
                self.arrivals = self.arrivals.saturating_add(1);
            }
            None => {
                self.kf.predict(model, k.saturating_sub(1))?;
                self.dropouts = self.dropouts.saturating_add(1);
            }
        }
        Ok(())
    }

    /// [`IntermittentKalmanFilter::step`] behind an innovation gate (docs/gate.md): a
    /// delivered `y` the gate rejects is treated as no measurement (prediction only, counted
    /// as an instant without one). Returns whether `y` was used (`false` without one). On
    /// error nothing changes.
    pub fn step_gated<const NY: usize, M: LinearSystem<T, NX, NY>>(
        &mut self,
        model: &M,
        k: usize,
        y: Option<&SVector<T, NY>>,
        gate: &InnovationGate<T>,
    ) -> Result<bool> {
        let Some(y) = y else {
            self.step::<NY, M>(model, k, None)?;
            return Ok(false);
        };
        let used = self.kf.step_gated(model, k, y, gate)?;
        if used {
            self.arrivals = self.arrivals.saturating_add(1);
        } else {
            self.dropouts = self.dropouts.saturating_add(1);
        }
        Ok(used)
    }
}

/// The Kalman filter's estimate and covariance form, with no instants counted yet.
impl<T: Real, const NX: usize> From<KalmanFilter<T, NX>> for IntermittentKalmanFilter<T, NX> {
    fn from(kf: KalmanFilter<T, NX>) -> Self {
        Self {
            kf,
            arrivals: 0,
            dropouts: 0,
        }
    }
}

/// A delivered packet is a Kalman step; a dropped or lost one a prediction.
impl<T: Real, const NX: usize, const NY: usize, M: LinearSystem<T, NX, NY>> Estimator<T, NX>
    for OnModel<M, IntermittentKalmanFilter<T, NX>, NY>
{
    type Measurement = Packet<T, NY>;

    #[inline]
    fn step(&mut self, k: usize, y: &Packet<T, NY>) -> Result<()> {
        self.filter.step(&self.model, k, y.delivered())
    }

    #[inline]
    fn estimate(&self) -> &Estimate<T, NX> {
        self.filter.estimate()
    }
}

/// A delivered packet passes the gate first; a rejected one is a prediction, like a lost one.
impl<T: Real, const NX: usize, const NY: usize, M: LinearSystem<T, NX, NY>> GatedStep<T, NX>
    for OnModel<M, IntermittentKalmanFilter<T, NX>, NY>
{
    fn step_gated(
        &mut self,
        k: usize,
        y: &Packet<T, NY>,
        gate: &InnovationGate<T>,
    ) -> Result<GateCounts> {
        let delivered = y.delivered();
        let used = self.filter.step_gated(&self.model, k, delivered, gate)?;
        Ok(match delivered {
            Some(_) => GateCounts::one(used),
            None => GateCounts::NONE,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::LinearModel;
    use nalgebra::{matrix, vector};

    #[test]
    fn dropout_is_pure_prediction_and_arrival_is_kf() {
        let m = LinearModel::<f64, 1, 1, 1, 1>::new(
            matrix![0.9],
            matrix![1.0],
            matrix![1.0],
            matrix![1.0],
            matrix![0.5],
            matrix![2.0],
        )
        .unwrap();
        let mut ikf = IntermittentKalmanFilter::new(vector![2.0], matrix![1.0]).unwrap();
        ikf.step::<1, _>(&m, 1, None).unwrap();
        assert!((ikf.estimate().state()[0] - 1.8).abs() < 1e-15);
        assert!((ikf.estimate().covariance()[(0, 0)] - 1.31).abs() < 1e-15);
        let mut kf =
            KalmanFilter::new(*ikf.estimate().state(), *ikf.estimate().covariance()).unwrap();
        ikf.step(&m, 2, Some(&vector![1.0])).unwrap();
        kf.step(&m, 2, &vector![1.0]).unwrap();
        assert_eq!(ikf.estimate().state(), kf.estimate().state());
        assert_eq!(ikf.counts(), (1, 1));
        let before = ikf;
        assert!(ikf.step(&m, 3, Some(&vector![f64::NAN])).is_err());
        assert_eq!(ikf, before);
    }
}
