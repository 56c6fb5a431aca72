//! The estimator registry: which estimators apply to a scenario, built fresh for every run.
//!
//! Each estimator family is one file with a [`Factory`]; a family returns an empty list for
//! scenarios it does not apply to. Adding a family is one file and one line in [`FACTORIES`].
//!
//! The families run estimator-core's estimators through the core's one interface
//! ([`estimator_core::Estimator`], mostly a filter paired with its model in an
//! [`estimator_core::OnModel`]); the application's [`Estimator`] over one is `adapter`'s, the
//! stepping from slot observations `fed`'s, the conversion of the observations into the core's
//! measurements `slots`', of the plant's model into fixed-size matrices `snapshot`'s. `pf` is
//! the application's own particle filter and implements [`Estimator`] directly.

mod adapter;
mod fed;
pub mod ikf;
pub mod kf;
pub mod nn;
pub mod occlusion;
pub mod pf;
mod slots;
mod snapshot;
pub mod tobit;

use std::borrow::Cow;

use channel_sim::plant::{LinearDescription, Plant};
use channel_sim::Scenario;
use estimator_core::Error;

use crate::Estimator;

/// The plant's linear description, or the error every linear adapter reports without one.
pub(crate) fn linear_of(plant: &dyn Plant) -> Result<&dyn LinearDescription, Error> {
    plant.linear().ok_or(Error::InvalidConfig {
        field: "plant",
        reason: "has no linear description",
    })
}

/// An adapter's fixed-size model of instant `k`: `cached` when the plant is time invariant
/// (converted once, at construction), otherwise converted now by `at` (converting nalgebra's
/// dynamic matrices allocates, so only time-varying plants pay it per step).
pub(crate) fn model_at<'a, M: Clone>(
    cached: &'a Option<M>,
    plant: &dyn Plant,
    k: usize,
    at: impl FnOnce(&dyn LinearDescription, usize) -> Result<M, Error>,
) -> Result<Cow<'a, M>, Error> {
    match cached {
        Some(m) => Ok(Cow::Borrowed(m)),
        None => at(linear_of(plant)?, k).map(Cow::Owned),
    }
}

/// Options of an evaluation that estimators may need. Families add their own fields (with a
/// default in [`Default`]) and the matching CLI flag.
#[derive(Clone, Debug)]
pub struct EvalOptions {
    /// Number of Monte-Carlo runs.
    pub runs: u64,
    /// Horizon T: instants k = 1..=T are simulated.
    pub horizon: u32,
    /// Experiment seed.
    pub seed: u64,
    /// Particles of the `pf` reference filter (0 disables it).
    pub particles: usize,
}

impl Default for EvalOptions {
    fn default() -> Self {
        Self {
            runs: 500,
            horizon: 100,
            seed: 0,
            particles: pf::DEFAULT_PARTICLES,
        }
    }
}

/// Builds a family's estimators for run `run` of `scenario` (empty when the family does not
/// apply). An error means the scenario's parameters are unusable for this family.
pub type Factory = fn(
    scenario: &dyn Scenario,
    options: &EvalOptions,
    seed: u64,
    run: u64,
) -> anyhow::Result<Vec<Box<dyn Estimator>>>;

/// Every estimator family, in the order they appear in tables, JSON and plots.
pub const FACTORIES: &[Factory] = &[
    kf::build,
    ikf::build,
    occlusion::build,
    pf::build,
    nn::build,
    tobit::build,
];

/// All estimators that apply to `scenario`, from `factories` in order.
pub fn build_all(
    factories: &[Factory],
    scenario: &dyn Scenario,
    options: &EvalOptions,
    seed: u64,
    run: u64,
) -> anyhow::Result<Vec<Box<dyn Estimator>>> {
    let mut all = Vec::new();
    for f in factories {
        all.extend(f(scenario, options, seed, run)?);
    }
    Ok(all)
}
