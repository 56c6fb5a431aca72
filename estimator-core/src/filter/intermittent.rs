//! The intermittent Kalman filter (IKF): a Kalman filter that updates only on instants whose
//! packet arrived and otherwise only predicts (Sinopoli et al., 2004). It is the baseline that
//! ignores what a dropout says about the state.

use nalgebra::{SMatrix, SVector};

use crate::filter::kalman::KalmanFilter;
use crate::model::LinearSystem;
use crate::{Real, Result};

/// Kalman filter that skips the update when no measurement arrived.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IntermittentKalmanFilter<T: Real, const NX: usize> {
    kf: KalmanFilter<T, NX>,
    arrivals: u32,
    dropouts: u32,
}

impl<T: Real, const NX: usize> IntermittentKalmanFilter<T, NX> {
    /// Starts from `x0`, `p0` (validated as in [`KalmanFilter::new`]).
    pub fn new(x0: SVector<T, NX>, p0: SMatrix<T, NX, NX>) -> Result<Self> {
        Ok(Self {
            kf: KalmanFilter::new(x0, p0)?,
            arrivals: 0,
            dropouts: 0,
        })
    }

    /// Current estimate.
    #[inline]
    pub fn state(&self) -> &SVector<T, NX> {
        self.kf.state()
    }

    /// Current covariance.
    #[inline]
    pub fn covariance(&self) -> &SMatrix<T, NX, NX> {
        self.kf.covariance()
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
        assert!((ikf.state()[0] - 1.8).abs() < 1e-15);
        assert!((ikf.covariance()[(0, 0)] - 1.31).abs() < 1e-15);
        let mut kf = KalmanFilter::new(*ikf.state(), *ikf.covariance()).unwrap();
        ikf.step(&m, 2, Some(&vector![1.0])).unwrap();
        kf.step(&m, 2, &vector![1.0]).unwrap();
        assert_eq!(ikf.state(), kf.state());
        assert_eq!(ikf.counts(), (1, 1));
        let before = ikf;
        assert!(ikf.step(&m, 3, Some(&vector![f64::NAN])).is_err());
        assert_eq!(ikf, before);
    }
}
