//! Seed 004's Tobit censoring (eq. 2) as the estimators know it: per node the thresholds τ_m
//! below which a measurement component arrives as τ_m.

use nalgebra::SVector;

use crate::error::SpecError;
use estpipe_wire::{MAX_NODES, MAX_NY};

/// Padding for unused measurement components: never censors, never counts in a norm.
pub const NO_THRESHOLD: f64 = -f64::MAX;

/// Tobit censoring (eq. 2) with per-node thresholds τ_m.
#[derive(Clone, Debug, PartialEq)]
pub struct TobitCensoring {
    thresholds: Vec<Vec<f64>>,
}

impl TobitCensoring {
    /// `thresholds[m]` is τ_m (finite, one entry per measurement component of node m,
    /// 1 to MAX_NY; nodes may measure different numbers of components).
    pub fn new(thresholds: Vec<Vec<f64>>) -> Result<Self, SpecError> {
        if thresholds.is_empty() || thresholds.len() > MAX_NODES {
            return Err(SpecError::invalid(
                "tobit.thresholds",
                "need one threshold vector per node",
            ));
        }
        for (m, t) in thresholds.iter().enumerate() {
            if t.is_empty() || t.len() > MAX_NY {
                return Err(SpecError::invalid(
                    format!("tobit.thresholds[{m}]"),
                    format!("needs 1 to {MAX_NY} thresholds, got {}", t.len()),
                ));
            }
            if t.iter().any(|v| !v.is_finite()) {
                return Err(SpecError::invalid(
                    format!("tobit.thresholds[{m}]"),
                    "contains NaN or ±∞",
                ));
            }
        }
        Ok(Self { thresholds })
    }

    /// τ_m of node `m`.
    pub fn tau(&self, m: usize) -> &[f64] {
        &self.thresholds[m]
    }

    /// Number of nodes.
    pub fn nodes(&self) -> usize {
        self.thresholds.len()
    }

    pub fn padded(&self, m: usize) -> SVector<f64, MAX_NY> {
        let mut t = SVector::<f64, MAX_NY>::repeat(NO_THRESHOLD);
        let tau = &self.thresholds[m];
        t.as_mut_slice()[..tau.len()].copy_from_slice(tau);
        t
    }
}
