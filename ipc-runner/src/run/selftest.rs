//! The estimator of the `pipeline-selftest` scenario: a Kalman filter for the scalar random
//! walk that fuses the delivered measurements of both nodes (sequential updates) and only
//! predicts for dropped ones. It lets the transport be tested on its own.

use crate::Estimator;
use channel_sim::publisher::selftest::{Q, R, X0};
use channel_sim::Observation;
use estimator_core::filter::kalman::KalmanFilter;
use nalgebra::{SMatrix, SVector};

/// Fusing KF for `pipeline-selftest`.
#[derive(Debug)]
pub struct SelfTestKf {
    kf: KalmanFilter<f64, 1>,
}

impl SelfTestKf {
    /// Starts from the scenario's prior.
    pub fn new() -> Self {
        Self {
            kf: KalmanFilter::new(SVector::from([X0.0]), SMatrix::from([[X0.1]]))
                .expect("valid prior"),
        }
    }
}

impl Default for SelfTestKf {
    fn default() -> Self {
        Self::new()
    }
}

impl Estimator for SelfTestKf {
    fn name(&self) -> &'static str {
        "kf"
    }

    fn step(&mut self, _k: u32, obs: &[Observation]) -> Result<(), estimator_core::Error> {
        let mut next = self.kf;
        let one = SMatrix::<f64, 1, 1>::identity();
        next.predict_with(&one, &SMatrix::from([[Q]]))?;
        for o in obs {
            if let Some(y) = o.measurement() {
                next.update_with(&one, &SMatrix::from([[R]]), &SVector::from([y[0]]))?;
            }
        }
        self.kf = next;
        Ok(())
    }

    fn estimate(&self, out: &mut [f64]) {
        out[0] = self.kf.state()[0];
    }
}
