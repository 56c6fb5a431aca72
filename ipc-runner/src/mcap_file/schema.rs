//! The JSON schemas and messages of the MCAP recording (docs/mcap.md): one schema per topic,
//! JSON-encoded messages, which Foxglove and the `mcap` readers decode without a plugin.

use estpipe_wire::Observation;
use estpipe_wire::{FLAG_IPC_LOST, FLAG_NET_LOST};
use serde::Serialize;

/// Schema name and JSON schema of `/slots`.
pub const SLOT_SCHEMA: (&str, &str) = (
    "estpipe.Slot",
    r#"{"type":"object","title":"estpipe.Slot","properties":{
"session":{"type":"integer"},"k":{"type":"integer"},"node":{"type":"integer"},
"status":{"type":"string","enum":["delivered","dropped","lost"]},
"delivered":{"type":"boolean"},"flags":{"type":"integer"},
"y":{"type":"array","items":{"type":["number","null"]}}}}"#,
);

/// Schema name and JSON schema of `/truth`.
pub const TRUTH_SCHEMA: (&str, &str) = (
    "estpipe.Truth",
    r#"{"type":"object","title":"estpipe.Truth","properties":{
"session":{"type":"integer"},"k":{"type":"integer"},
"x":{"type":"array","items":{"type":["number","null"]}}}}"#,
);

/// Schema name and JSON schema of `/estimates/<name>`.
pub const ESTIMATE_SCHEMA: (&str, &str) = (
    "estpipe.Estimate",
    r#"{"type":"object","title":"estpipe.Estimate","properties":{
"session":{"type":"integer"},"k":{"type":"integer"},"estimator":{"type":"string"},
"x":{"type":"array","items":{"type":["number","null"]}},
"cov_kind":{"type":"string","enum":["none","covariance","bound"]},
"sigma":{"type":"array","items":{"type":["number","null"]}},
"p":{"type":"array","items":{"type":["number","null"]}}}}"#,
);

/// What became of a node's slot: `delivered`, `dropped` (by the channel) or `lost` (in the
/// IPC or on the network: the runner never had it).
pub fn slot_status(o: &Observation) -> &'static str {
    if o.delivered {
        "delivered"
    } else if o.flags & (FLAG_IPC_LOST | FLAG_NET_LOST) != 0 {
        "lost"
    } else {
        "dropped"
    }
}

/// A `/slots` message.
#[derive(Debug, Serialize)]
pub struct SlotMsg<'a> {
    /// Session of the runner (1, then one more per restarted publisher).
    pub session: u32,
    /// The instant.
    pub k: u32,
    /// Sensor node.
    pub node: u8,
    /// [`slot_status`].
    pub status: &'static str,
    /// Whether a measurement reached the estimators.
    pub delivered: bool,
    /// Channel-side flags (docs/wire.md, Constants).
    pub flags: u32,
    /// The measurement (empty when not delivered).
    pub y: &'a [f64],
}

/// A `/truth` message.
#[derive(Debug, Serialize)]
pub struct TruthMsg<'a> {
    /// Session.
    pub session: u32,
    /// The instant.
    pub k: u32,
    /// x_k.
    pub x: &'a [f64],
}

/// An `/estimates/<name>` message. Non-finite numbers are written as `null` (JSON has no NaN).
#[derive(Debug, Serialize)]
pub struct EstimateMsg<'a> {
    /// Session.
    pub session: u32,
    /// The instant.
    pub k: u32,
    /// Estimator name.
    pub estimator: &'a str,
    /// x̂_k.
    pub x: &'a [f64],
    /// What `p` is: `none`, `covariance` or `bound` (docs/wire.md, Estimate).
    pub cov_kind: &'static str,
    /// √P_ii, for a ±2σ band.
    pub sigma: &'a [f64],
    /// P (or its bound), nx × nx row-major.
    pub p: &'a [f64],
}

/// The name of a covariance kind as written in `cov_kind` (the wire's `cov_kind` value).
pub fn cov_kind_name(kind: u32) -> &'static str {
    match kind {
        estpipe_wire::COV_ESTIMATE => "covariance",
        estpipe_wire::COV_BOUND => "bound",
        _ => "none",
    }
}
