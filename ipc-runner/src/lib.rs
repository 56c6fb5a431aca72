//! The application layer: estimator dispatch, Monte-Carlo evaluation, the real-time loop over
//! iceoryx2, metrics and the demo.

pub mod estimator;

pub use estimator::Estimator;
pub mod demo;
pub mod estimators;
pub mod eval;
pub mod latency;
pub mod plot;
pub mod plot_bound;
pub mod plot_latency;
pub mod plot_tokens;
pub mod plot_trace;
pub mod replay;
pub mod run;
pub mod tail;
pub mod transport;
