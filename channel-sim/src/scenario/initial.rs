//! The initial distribution of a scenario: the truth's x_0 and the prior the estimators
//! start from, which the papers sometimes choose differently (seed 003).

use nalgebra::{DMatrix, DVector};

use crate::error::ScenarioError;
use crate::rng::{standard_normal, SimRng};
use crate::validate::{check_pd, check_psd, check_shape};

/// The initial distribution: the true x_0 ~ N(mean, cov) (cov may be zero: a known start) and
/// the prior the estimators start from (x̂_0, P_0), which the papers sometimes choose
/// differently from the truth's distribution (seed 003).
#[derive(Clone, Debug)]
pub struct InitialDistribution {
    /// Mean of x_0.
    pub mean: DVector<f64>,
    /// Covariance of x_0 (positive semi-definite).
    pub cov: DMatrix<f64>,
    /// x̂_0.
    pub estimator_mean: DVector<f64>,
    /// P_0 (positive definite).
    pub estimator_cov: DMatrix<f64>,
    factor: DMatrix<f64>,
}

impl InitialDistribution {
    /// Validates dimensions and definiteness; field names are under `initial.`.
    pub fn new(
        mean: DVector<f64>,
        cov: DMatrix<f64>,
        estimator_mean: DVector<f64>,
        estimator_cov: DMatrix<f64>,
    ) -> Result<Self, ScenarioError> {
        let n = mean.len();
        if mean.iter().any(|v| !v.is_finite()) {
            return Err(ScenarioError::invalid("initial.mean", "contains NaN or ±∞"));
        }
        if estimator_mean.iter().any(|v| !v.is_finite()) {
            return Err(ScenarioError::invalid(
                "initial.estimator_mean",
                "contains NaN or ±∞",
            ));
        }
        if estimator_mean.len() != n {
            return Err(ScenarioError::invalid(
                "initial.estimator_mean",
                format!("must have {n} entries, got {}", estimator_mean.len()),
            ));
        }
        check_shape(cov.shape(), (n, n), "initial.cov")?;
        check_shape(estimator_cov.shape(), (n, n), "initial.estimator_cov")?;
        let factor = check_psd(&cov, "initial.cov")?;
        check_pd(&estimator_cov, "initial.estimator_cov")?;
        Ok(Self {
            mean,
            cov,
            estimator_mean,
            estimator_cov,
            factor,
        })
    }

    /// The common case: the estimator's prior is the truth's distribution.
    pub fn gaussian(mean: DVector<f64>, cov: DMatrix<f64>) -> Result<Self, ScenarioError> {
        Self::new(mean.clone(), cov.clone(), mean, cov)
    }

    /// Draws x_0.
    pub fn sample(&self, rng: &mut SimRng) -> DVector<f64> {
        &self.mean + &self.factor * standard_normal(self.mean.len(), rng)
    }
}
