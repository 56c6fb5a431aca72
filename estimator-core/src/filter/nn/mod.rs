//! Seed 003: the recursive NN-based estimator of a noise-coupled nonlinear system under the
//! token bucket, with the upper bounds and the gain of its Theorems 1-2.
//!
//! * [`system`]: the system class (1) and what the estimator is generic over (activation,
//!   differentiable nonlinearity);
//! * [`bound`]: the bounds (14)-(17) and the gain (33)-(35) with their configuration;
//! * [`estimator`]: the estimator (5) and the tuning law (6);
//! * [`assumptions`]: which sufficient conditions fail, before and during a run.
//!
//! The section IV example is [`crate::papers::Seed003Example`]; its KF/EKF baselines are
//! [`crate::filter::coupled_kf`].

pub mod assumptions;
pub mod bound;
pub mod estimator;
pub mod system;

pub use assumptions::{check_before_run, BucketParams, PreRunVerdict, RunMonitor, Violation};
pub use bound::{GainSolver, NnBoundConfig};
pub use estimator::NnTbcpEstimator;
pub use system::{Activation, CoupledNoiseSystem, DifferentiableMap, SystemMatrices, Tanh};
