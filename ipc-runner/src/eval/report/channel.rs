//! The summary's lines on what became of the slots: the transport stages after the channel,
//! how the `-mix` estimators read a dropout, and every node's counts.

use std::fmt::Write as _;

use super::EvalResult;

/// The transport after the channel (`--transport-loss`, `--transport-delay`) and
/// `--loss-rate`, each when set.
pub(super) fn transport_lines(r: &EvalResult, s: &mut String) {
    let nodes = &r.channel.nodes;
    if r.transport_loss > 0.0 {
        let lost: u64 = nodes.iter().map(|c| c.transport_lost).sum();
        let slots: u64 = nodes.iter().map(|c| c.instants).sum();
        let _ = writeln!(
            s,
            "transport after the channel: {lost} of {slots} slots lost (p = {}), {}",
            r.transport_loss,
            if r.transport_loss_unmarked {
                "unmarked (the estimators see a dropout)"
            } else {
                "marked lost (the estimators see a loss)"
            }
        );
    }
    if let Some(d) = r.transport_delay {
        let late: u64 = nodes.iter().map(|c| c.transport_late).sum();
        let old: u64 = nodes.iter().map(|c| c.transport_too_old).sum();
        let slots: u64 = nodes.iter().map(|c| c.instants).sum();
        let _ = writeln!(
            s,
            "transport delay {d}: {late} of {slots} slots late; with --lag {} the estimators \
             folded in {} and {old} were too old (lost)",
            r.lag,
            late - old
        );
    }
    if r.loss_rate > 0.0 {
        let _ = writeln!(
            s,
            "the -mix estimators read a dropout as occluded or lost with p_loss = {}",
            r.loss_rate
        );
    }
}

/// One line per node: delivered, and why the rest was not.
pub(super) fn node_lines(r: &EvalResult, s: &mut String) {
    for c in &r.channel.nodes {
        let _ = writeln!(
            s,
            "node {}: delivered {:.1} % ({} of {}), random loss {}, occluded {}, blocked {}, \
             triggered {}, censored {}",
            c.node,
            100.0 * c.delivery_rate,
            c.delivered,
            c.instants,
            c.random_loss,
            c.occluded,
            c.blocked,
            c.triggered,
            c.censored
        );
    }
}
