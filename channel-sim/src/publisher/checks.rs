//! What the publisher refuses before it creates anything: flags out of range (for a caller
//! that builds [`PublisherArgs`] in code; the command line's parsers check the same), sensor
//! node lines that do not fit the scenario, a `--node` the scenario does not have.

use anyhow::{Context, Result};
use estpipe_process::flags::BadInput;
use estpipe_wire as wire;

use super::PublisherArgs;
use crate::sensor_node::Endpoint;
use crate::sim::Scenario;

/// The flags' own checks (issue #20: `Duration::from_secs_f64(inf)` panics).
pub(super) fn flags(args: &PublisherArgs) -> Result<()> {
    for (flag, value, check) in [
        (
            "--rate",
            args.rate,
            estpipe_process::flags::rate_hz as fn(&str) -> Result<f64, String>,
        ),
        (
            "--connect-timeout",
            args.connect_timeout,
            estpipe_process::flags::seconds,
        ),
        ("--linger", args.linger, estpipe_process::flags::seconds),
        (
            "--unread-limit",
            args.unread_limit,
            estpipe_process::flags::seconds,
        ),
    ] {
        if let Err(e) = check(&value.to_string()) {
            return Err(BadInput(format!("{flag}: {e}")).into());
        }
    }
    Ok(())
}

/// The `--sensor-node` lines, one per node of the scenario, and a scenario the nodes can run.
pub(super) fn sensor_endpoints(
    args: &PublisherArgs,
    scenario: &dyn Scenario,
) -> Result<Vec<Endpoint>> {
    let endpoints = args
        .sensor_node
        .iter()
        .map(|s| Endpoint::parse(s))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| BadInput(format!("--sensor-node {e}")))?;
    if endpoints.is_empty() {
        return Ok(endpoints);
    }
    if args.node_timeout <= 0.0 {
        return Err(BadInput("--node-timeout: must be positive".to_string()).into());
    }
    crate::sensor_node::config::loop_config(scenario)
        .map_err(|e| BadInput(format!("--sensor-node: {e}")))?;
    if endpoints.len() != scenario.nodes() {
        return Err(BadInput(format!(
            "--sensor-node: scenario {} has {} node(s), {} --sensor-node line(s) given",
            scenario.name(),
            scenario.nodes(),
            endpoints.len()
        ))
        .into());
    }
    Ok(endpoints)
}

/// The scenario's node count, and `--node` within it.
pub(super) fn nodes(args: &PublisherArgs, scenario: &dyn Scenario) -> Result<u8> {
    let nodes = u8::try_from(scenario.nodes()).context("too many nodes")?;
    match args.node {
        Some(n) if n >= nodes => Err(wire::ContractError::Refused(format!(
            "--node {n}: scenario {} has {nodes} node(s), 0..={}",
            scenario.name(),
            nodes - 1
        ))
        .into()),
        _ => Ok(nodes),
    }
}
