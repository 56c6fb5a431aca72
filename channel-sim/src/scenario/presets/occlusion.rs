//! `occlusion`: the numerical example of seed 001 (Liu, Wang, Dong, Jiang — cross-coupled
//! estimation with state-dependent packet dropouts), Section IV, with the decisions of
//! docs/design.md, Seed 001, where the paper is silent.
//!
//! ```text
//! x_{k+1} = A x_k + B w_k,  A = [1.01 0.1 0; 0 1.01 0.1; 0 0 −1.02],  B = I₃,  Q = 0.3 I₃
//! z_k     = C x_k + D v_k,  C = [2 3 1; 1 0 0.98],                    D = I₂,  R = 0.2 I₂
//! x_0 ~ N([5 5 5]ᵀ, 4 I₃);  estimators start from x̂_0 = μ_0, P_0 = Σ_0
//! u_k = x_{1,k} + n_k,  n_k ~ N(0, 0.1);  dropout iff u_k ∈ [20i − 5, 20i + 5], i = 1..4
//! ```

use std::sync::Arc;

use nalgebra::{dmatrix, dvector, DMatrix};

use crate::channel::occlusion::OcclusionSpec;
use crate::error::ScenarioError;
use crate::plant::linear::{LinearPlant, LinearSensor};
use crate::scenario::composed::ComposedScenario;
use crate::scenario::initial::InitialDistribution;
use crate::sim::Scenario;

/// Number of occlusion regions of the preset.
pub const REGIONS: usize = 4;

/// The preset's occlusion stage (also used by estimators and tests).
pub fn stage() -> Result<OcclusionSpec<REGIONS>, ScenarioError> {
    OcclusionSpec::new(
        vec![1.0, 0.0, 0.0],
        0.1,
        [20.0, 40.0, 60.0, 80.0],
        [5.0; REGIONS],
        3,
    )
}

/// The `occlusion` preset.
pub fn preset() -> Result<Box<dyn Scenario>, ScenarioError> {
    let plant = LinearPlant::new(
        dmatrix![1.01, 0.1, 0.0; 0.0, 1.01, 0.1; 0.0, 0.0, -1.02],
        DMatrix::identity(3, 3),
        DMatrix::identity(3, 3) * 0.3,
        vec![LinearSensor {
            c: dmatrix![2.0, 3.0, 1.0; 1.0, 0.0, 0.98],
            d: DMatrix::identity(2, 2),
            r: DMatrix::identity(2, 2) * 0.2,
        }],
    )?;
    let initial =
        InitialDistribution::gaussian(dvector![5.0, 5.0, 5.0], DMatrix::identity(3, 3) * 4.0)?;
    Ok(Box::new(ComposedScenario::new(
        "occlusion",
        Arc::new(plant),
        initial,
        vec![Arc::new(stage()?)],
    )?))
}
