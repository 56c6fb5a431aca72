//! The estimators. One per file; each keeps its state private and changes it only when a step
//! succeeds.

pub mod intermittent;
pub mod kalman;
pub mod prior;
pub mod time_update;

pub use crate::CovarianceUpdate;
pub use intermittent::IntermittentKalmanFilter;
pub use kalman::KalmanFilter;

pub mod cce;
pub use cce::CrossCoupledEstimator;

pub mod adf;
pub use adf::AssumedDensityFilter;

pub mod kf_io;
pub use kf_io::KfIo;
pub mod coupled_kf;
pub mod fusion;
pub mod nn_assumptions;
pub mod nn_bound;
pub mod nn_system;
pub mod nn_tbcp;
pub mod tobit;

pub use fusion::TobitFusion;
pub use tobit::TobitFilter;
