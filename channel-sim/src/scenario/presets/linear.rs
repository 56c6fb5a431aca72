//! `linear`: a small example scenario that needs no paper — a damped two-state oscillator
//! observed by one position sensor over a channel losing 20 % of the packets i.i.d.
//!
//! ```text
//! x_{k+1} = [0.95 0.10; −0.10 0.95] x_k + w_k,   w_k ~ N(0, diag(0.01, 0.04))
//! z_k     = [1 0] x_k + v_k,                     v_k ~ N(0, 0.25)
//! x_0 ~ N(0, I₂),  Bernoulli loss p = 0.2
//! ```

use std::sync::Arc;

use nalgebra::{dmatrix, dvector, DMatrix};

use crate::channel::loss::BernoulliLoss;
use crate::error::ScenarioError;
use crate::plant::linear::{LinearPlant, LinearSensor};
use crate::scenario::composed::ComposedScenario;
use crate::scenario::initial::InitialDistribution;
use crate::sim::Scenario;

/// Loss probability of the preset's channel.
pub const P_LOSS: f64 = 0.2;

/// The `linear` preset.
pub fn preset() -> Result<Box<dyn Scenario>, ScenarioError> {
    let plant = LinearPlant::new(
        dmatrix![0.95, 0.10; -0.10, 0.95],
        DMatrix::identity(2, 2),
        dmatrix![0.01, 0.0; 0.0, 0.04],
        vec![LinearSensor {
            c: dmatrix![1.0, 0.0],
            d: dmatrix![1.0],
            r: dmatrix![0.25],
        }],
    )?;
    let initial = InitialDistribution::gaussian(dvector![0.0, 0.0], DMatrix::identity(2, 2))?;
    Ok(Box::new(ComposedScenario::new(
        "linear",
        Arc::new(plant),
        initial,
        vec![Arc::new(BernoulliLoss { p_loss: P_LOSS })],
    )?))
}
