//! The estimators. One per file; each keeps its state private and changes it only when a step
//! succeeds.

pub mod intermittent;
pub mod kalman;

pub use intermittent::IntermittentKalmanFilter;
pub use kalman::{CovarianceUpdate, KalmanFilter};

pub mod fusion;
pub mod tobit;

pub use fusion::TobitFusion;
pub use tobit::TobitFilter;
