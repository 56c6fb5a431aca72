//! `ipc-runner bridge`: a prefix's iceoryx2 services carried over zenoh to another host, and
//! every message checked against the wire contract on arrival (`docs/bridge.md`).
//!
//! ```text
//! host A: channel-sim ─► [A/slots, A/truth] ─► bridge --side sensor ──┐
//!                                                                     │ zenoh <key>/slots, <key>/truth
//! host B: ipc-runner run ◄─ [B/slots, B/truth] ◄─ bridge --side estimator ◄┘
//!         ipc-runner run ─► [B/estimates] ─► bridge --side estimator ─► zenoh <key>/estimates ─► bridge --side sensor ─► [A/estimates]
//! ```
//!
//! | module | what |
//! |---|---|
//! | [`args`] | the command line and the zenoh configuration it makes |
//! | [`sensor`] | the sensor side: shared memory → zenoh (slots, truth), zenoh → shared memory (estimates) |
//! | [`estimator`] | the estimator side: zenoh → checked → shared memory (slots, truth), estimates back |
//! | [`markers`] | the sensor side's END/ABORT markers, repeated until acknowledged |
//! | [`sequence`] | per-node sequence tracking: what the network lost, as lost slots |
//! | [`report`] | counts by reason and the bridge's latency histograms |
//! | `security` | the checks of a `--zenoh-config`'s TLS, user/password and endpoints (docs/security.md) |
//!
//! The message encoding and its checks are the wire crate's (`estpipe_wire::net`): the bridge
//! never writes into shared memory a message that those checks refused. Its lines on stderr,
//! its stop signals and its iceoryx2 node are the product's (`estpipe_process`).

pub mod args;
pub mod estimator;
pub mod markers;
pub mod report;
mod security;
pub mod sensor;
pub mod sequence;
mod session;
mod stop;

pub use args::{BridgeArgs, Side};
pub use report::BridgeReport;

/// The name of a bridge's iceoryx2 node (both sides), by which the runner tells a relay
/// ([`estpipe_process::node::BRIDGE_NODE_NAME`]).
pub const NODE_NAME: &str = estpipe_process::node::BRIDGE_NODE_NAME;

/// `ipc-runner bridge`: runs the bridge, prints its one-line summary, writes `--report`.
pub fn main(args: &BridgeArgs) -> anyhow::Result<i32> {
    let report = run(args)?;
    if !args.quiet {
        estpipe_process::errln!("bridge: {}", report.summary());
    }
    if let Some(p) = &args.report {
        let json = serde_json::to_string_pretty(&report)?;
        estpipe_process::whole_file::write(p, &(json + "\n"))
            .map_err(|e| anyhow::anyhow!("--report {}: {e}", p.display()))?;
    }
    Ok(if report.ending == estimator::FAR_SIDE_LOST {
        3
    } else {
        0
    })
}

/// Runs the bridge until its stream ends (`--once`) or SIGINT/SIGTERM; the report of what
/// it forwarded and refused.
pub fn run(args: &BridgeArgs) -> anyhow::Result<BridgeReport> {
    args.check()?;
    // zenoh's own log on stderr when RUST_LOG asks for it (`RUST_LOG=zenoh=debug`).
    zenoh::try_init_log_from_env();
    match args.side {
        Side::Sensor => sensor::run(args),
        Side::Estimator => estimator::run(args),
    }
}
