//! The application layer: estimator dispatch, Monte-Carlo evaluation, the real-time loop over
//! iceoryx2, metrics and the demo.

pub mod estimator;

pub use estimator::{CovarianceKind, Estimator};
pub mod demo;
pub mod estimators;
pub mod eval;
pub mod latency;
pub mod plot;
pub mod replay;
pub mod run;
pub mod slot_log;
pub mod tail;
pub mod transport;

// The paths before the plots moved under `plot/`, kept until the benches' report uses the new
// ones.
#[doc(hidden)]
pub use plot::{latency as plot_latency, trace as plot_trace};
