//! The estimators, one per file, grouped by the paper whose problem they solve. Each keeps its
//! state private and changes it only when a step succeeds.
//!
//! * [`gate`]: the innovation gate every estimator with an innovation can run behind
//!   (docs/gate.md).
//! * Linear-Gaussian: [`kalman`] (the Kalman filter), [`intermittent`] (update only on
//!   arrival), [`sequential_kf`] (several nodes' measurements of one instant, one after the
//!   other), [`time_update`] (the prediction they all share).
//! * [`occlusion`] (seed 001): state-dependent dropouts — the cross-coupled estimator, an
//!   assumed-density filter and the KF-IO baseline.
//! * [`nn`] (seed 003): the NN estimator under the token bucket; [`coupled_kf`] holds its
//!   KF/EKF baselines for the same noise-coupled system (the paper's: the exact
//!   correlated-noise predictor), [`independent_kf`] the textbook KF/EKF that treat its two
//!   noise terms as independent; both are the one predictor of [`noise_coupled`] with a mode
//!   each.
//! * [`tobit`] (seed 004): local Tobit filters of censored measurements and their fusion.
//! * [`silence`]: what an event trigger's silence says (the product's, beside seed 004): the
//!   silence set's updates, the Kalman filter that reads them.

pub mod coupled_kf;
pub mod gate;
pub mod independent_kf;
pub mod intermittent;
pub mod kalman;
pub mod nn;
pub mod noise_coupled;
pub mod occlusion;
pub mod sequential_kf;
pub mod silence;
pub mod time_update;
pub mod tobit;

pub use crate::{CovarianceForm, CovarianceUpdate, JosephForm, StandardForm};
pub use coupled_kf::CoupledNoiseKf;
pub use gate::{GateCounts, Gated, GatedStep, InnovationGate};
pub use independent_kf::IndependentNoiseKf;
pub use intermittent::IntermittentKalmanFilter;
pub use kalman::KalmanFilter;
pub use nn::NnTbcpEstimator;
pub use noise_coupled::NoiseCoupledKf;
pub use occlusion::{AssumedDensityFilter, CrossCoupledEstimator, KfIo};
pub use sequential_kf::SequentialKf;
pub use silence::kalman::SilenceKf;
pub use tobit::{MirroredFusion, MomentMatchedTobit, TobitFilter, TobitFusion, TobitKf};
