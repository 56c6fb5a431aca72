//! The application layer: estimator dispatch, Monte-Carlo evaluation, the real-time loop over
//! iceoryx2, metrics and the demo.

pub use estpipe_estimators::{CovarianceKind, Estimator, LateFold};
pub mod bridge;
pub mod cli;
pub mod demo;
pub mod estimator_args;
/// The estimators crate under the path the commands use.
pub use estpipe_estimators as estimators;
pub mod eval;
pub mod latency;
pub mod limits;
pub mod mcap_file;
pub mod plot;
pub mod replay;
pub mod run;
pub mod sensor_nodes;
pub mod slot_log;
pub mod source;
pub mod stream_header;
pub mod tail;
pub mod transport;
pub mod view;

// The paths before the plots moved under `plot/`, kept until the benches' report uses the new
// ones.
#[doc(hidden)]
pub use plot::{latency as plot_latency, trace as plot_trace};

/// The exit code of a failed pipeline command, the product's policy: the cause's
/// [`estpipe_wire::ContractError::exit_code`] (2 for a peer outside the wire contract), 2 for
/// bad input ([`limits::BadInput`]: flags, scenario, file content, outputs, memory budget;
/// what the simulator refuses is marked so where the runner calls it, [`source`]), the cause's
/// code for a run that failed after it had written its report ([`run::ExitWith`]), else 1.
pub fn exit_code_of(e: &anyhow::Error) -> i32 {
    if let Some(c) = e.downcast_ref::<estpipe_wire::ContractError>() {
        return c.exit_code();
    }
    if let Some(run::ExitWith(code, _)) = e.downcast_ref::<run::ExitWith>() {
        return *code;
    }
    if limits::BadInput::is_in(e) {
        2
    } else {
        1
    }
}
