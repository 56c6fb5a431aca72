//! `ipc-runner bridge`: a prefix's iceoryx2 services carried over zenoh to another host, and
//! every message checked against the wire contract on arrival (`docs/bridge.md`).
//!
//! ```text
//! host A: channel-sim ─► [A/slots, A/truth] ─► bridge --side sensor ──┐
//!                                                                     │ zenoh <key>/slots (slots and truth; markers echoed on <key>/acks)
//! host B: ipc-runner run ◄─ [B/slots, B/truth] ◄─ bridge --side estimator ◄┘
//!         ipc-runner run ─► [B/estimates] ─► bridge --side estimator ─► zenoh <key>/estimates ─► bridge --side sensor ─► [A/estimates]
//! ```
//!
//! Two folders: `link/` is what the bridge does to the stream whatever carries it between the
//! hosts, and names no zenoh type; `zenoh/` is what does, the two sides among them.
//!
//! | module | file | what |
//! |---|---|---|
//! | [`args`] | `args.rs` | the command line and the zenoh configuration it makes |
//! | `security` | `security.rs` | the checks of a `--zenoh-config`'s TLS, user/password and endpoints (docs/security.md) |
//! | `stop` | `stop.rs` | the stop request: a stop signal, or a parent gone |
//! | [`sequence`] | `link/sequence.rs` | per-node sequence tracking: what the network lost, as lost slots |
//! | [`markers`] | `link/markers.rs` | the sensor side's END/ABORT markers, repeated until acknowledged |
//! | [`report`] | `link/report.rs` | counts by reason and the bridge's latency histograms |
//! | `forward` | `link/forward.rs` | the estimator side's way in: a message checked, then written into shared memory |
//! | `shm` | `link/shm.rs` | this host's iceoryx2 services of the prefix, and a sample written into one |
//! | `linger` | `link/linger.rs` | when a `--once` bridge ends |
//! | `wait` | `link/wait.rs` | waiting for the other end within `--connect-timeout` |
//! | [`sensor`] | `zenoh/sensor/` | the sensor side: shared memory → zenoh (slots, truth), zenoh → shared memory (estimates) |
//! | [`estimator`] | `zenoh/estimator/` | the estimator side: zenoh → checked → shared memory (slots, truth), estimates back; the sensor side's liveliness |
//! | `session` | `zenoh/session.rs` | the session opened, its publishers, a put a stop may cut short, a close that does not wait on a congested link |
//! | `inbox` | `zenoh/inbox.rs` | a subscriber's queue, read a burst at a time |
//!
//! The message encoding and its checks are the wire crate's (`estpipe_wire::net`): the bridge
//! never writes into shared memory a message that those checks refused. Its lines on stderr,
//! its stop signals and its iceoryx2 node are the product's (`estpipe_process`).

pub mod args;
mod link;
mod security;
mod stop;
mod zenoh;

pub use self::zenoh::{estimator, sensor};
pub use link::{markers, report, sequence};

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
    ::zenoh::try_init_log_from_env();
    match args.side {
        Side::Sensor => sensor::run(args),
        Side::Estimator => estimator::run(args),
    }
}
