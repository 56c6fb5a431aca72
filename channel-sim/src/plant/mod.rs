//! The plant and its sensors: the first link of the data path.
//!
//! A [`Plant`] advances the true state x_k **and** produces every node's raw measurement z_{m,k}
//! in one call, because some papers draw both from the same noise sample (seed 003 eq. 1 uses
//! one w_k in the state and the measurement). What a linear filter may know about the plant
//! (A_k, C_{m,k} and the effective noise covariances) is a separate trait,
//! [`LinearDescription`], so a nonlinear plant can still offer its linear part to a KF.
//!
//! The plants: [`linear::LinearPlant`] (optionally time-varying, matrices as
//! [`time_matrix::TimeMatrix`]) and [`nn::Seed003Plant`] (seed 003's nonlinear plant). Their
//! noise comes from the run's plant stream ([`crate::rng`]).

pub mod control;
pub mod linear;
pub mod nn;
pub mod time_matrix;

use std::any::Any;
use std::fmt::Debug;

use estpipe_wire::Fnv1a64;
use nalgebra::DMatrix;

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
    /// Feeds the plant's kind and parameters to the stream's model fingerprint
    /// (`docs/wire.md`, "Model fingerprint"): two plants an estimator cannot tell apart must
    /// feed the same values, any other difference must change them.
    fn fingerprint(&self, h: &mut Fnv1a64);
    /// The linear-Gaussian description a Kalman-type filter may use, if the plant has one.
    fn linear(&self) -> Option<&dyn LinearDescription> {
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

/// Feeds `m` to a fingerprint: rows, cols, then the entries column by column.
pub fn fingerprint_matrix(h: &mut Fnv1a64, m: &DMatrix<f64>) {
    h.matrix(m.nrows(), m.ncols(), m.as_slice());
}

/// The linear-Gaussian part of a plant as a filter sees it:
/// `x_{k+1} = A_k x_k + B_u u_k + B_k w_k` (the input term only with a control input), `z_{m,k} = C_{m,k} x_k + D_{m,k} v_{m,k}`, nodes' noises
/// independent of each other.
pub trait LinearDescription: Send + Sync + Debug {
    /// A_k.
    fn a(&self, k: usize) -> DMatrix<f64>;
    /// Effective process-noise covariance B_k Q Bₖᵀ.
    fn process_cov(&self, k: usize) -> DMatrix<f64>;
    /// C_{m,k} of node `node`.
    fn c(&self, node: usize, k: usize) -> DMatrix<f64>;
    /// Effective measurement-noise covariance D_{m,k} R_m D_{m,k}ᵀ of node `node`.
    fn measurement_cov(&self, node: usize, k: usize) -> DMatrix<f64>;
    /// The known input term `B_u u_k` of `x_{k+1}` (a control input known to the plant and
    /// the estimators alike), `None` without one. Default: none.
    fn input(&self, _k: usize) -> Option<nalgebra::DVector<f64>> {
        None
    }
    /// `true` when neither a matrix nor the input depends on k, so a filter may convert the
    /// model once and never allocate per step.
    fn time_invariant(&self) -> bool {
        false
    }
}
