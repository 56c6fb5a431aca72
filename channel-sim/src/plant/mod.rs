//! The plant and its sensors: the first link of the data path.
//!
//! A [`Plant`] advances the true state x_k **and** produces every node's raw measurement z_{m,k}
//! in one call, because some papers draw both from the same noise sample (seed 003 eq. 1 uses
//! one w_k in the state and the measurement). What an estimator may know about the plant is
//! the estimator spec's [`Model`](estpipe_spec::Model) ([`Plant::model`]), so the
//! estimators never read the simulator.
//!
//! The plants: [`linear::LinearPlant`] (the spec's [`LinearModel`](estpipe_spec::LinearModel),
//! with an optional known input) and [`nn::Seed003Plant`] (seed 003's nonlinear plant). Their
//! noise comes from the run's plant stream ([`crate::rng`]).

pub mod control;
pub mod linear;
pub mod nn;

use std::any::Any;
use std::fmt::Debug;

use crate::rng::SimRng;
use crate::sim::MAX_NY;

/// Plant and sensors of a scenario (configuration; cheap to share between threads).
pub trait Plant: Send + Sync + Debug {
    /// State dimension.
    fn nx(&self) -> usize;
    /// The largest node's measurement dimension (every node's, unless the sensors differ).
    fn ny(&self) -> usize;
    /// Measurement dimension of node `node` (`node < nodes()`). Default: [`Plant::ny`].
    fn node_ny(&self, _node: usize) -> usize {
        self.ny()
    }
    /// Number of sensor nodes.
    fn nodes(&self) -> usize;
    /// Starts one run from the true initial state `x0`.
    fn start(&self, x0: &[f64]) -> Box<dyn PlantRun>;
    /// The model the estimators know of this plant (its part of the scenario's
    /// [`EstimatorSpec`](estpipe_spec::EstimatorSpec)); `None` for a plant no estimator
    /// models.
    fn model(&self) -> Option<estpipe_spec::Model>;
    /// The linear-Gaussian description a Kalman-type filter may use, if the plant has one.
    fn linear(&self) -> Option<&estpipe_spec::LinearModel> {
        None
    }
    /// For downcasting to the concrete plant.
    fn as_any(&self) -> &dyn Any;
}

/// One run of a plant: owns the true state and whatever noise memory the model needs.
pub trait PlantRun: Send {
    /// The current true state x_k.
    fn state(&self) -> &[f64];
    /// Advances from x_{k−1} to x_k and writes node m's raw measurement z_{m,k} into
    /// `z[m][..ny]` for every node.
    fn advance(&mut self, k: u32, rng: &mut SimRng, z: &mut [[f64; MAX_NY]]);
    /// For a plant whose sensors measure at k = 0 (seed 003: eq. (2) takes its first
    /// decision at k = 0 and eq. (5) uses y₀): writes every node's raw z_{m,0} into `z` and
    /// returns `true`. Called once, right after the run starts and before the first
    /// [`Self::advance`]. The default (every other plant: no measurement at k = 0, seed 001's
    /// convention) writes nothing, draws nothing and returns `false`.
    fn initial_measurement(&mut self, _rng: &mut SimRng, _z: &mut [[f64; MAX_NY]]) -> bool {
        false
    }
}
