//! Waiting for the other end to be there before anything flows: the publisher starts its
//! stream when its first subscriber appears, so each side subscribes only once the next link
//! of the chain exists (docs/bridge.md, "Start-up order").

use crate::stop::Stop;
use anyhow::Result;
use std::time::{Duration, Instant};

/// How a wait for the other end ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Waited {
    /// It is there.
    Came,
    /// A stop was requested first.
    Stopped,
    /// `--connect-timeout` passed first.
    TimedOut,
}

/// Asks `came` every `poll` until it holds, a stop is requested, or `timeout` seconds have
/// passed (0: no limit). `came` is asked before the stop: an end that is already there is
/// taken, whatever else happened meanwhile.
pub(crate) fn wait_for(
    stop: &Stop,
    timeout: f64,
    poll: Duration,
    mut came: impl FnMut() -> Result<bool>,
) -> Result<Waited> {
    let started = Instant::now();
    loop {
        if came()? {
            return Ok(Waited::Came);
        }
        if stop.requested() {
            return Ok(Waited::Stopped);
        }
        if timeout > 0.0 && started.elapsed().as_secs_f64() > timeout {
            return Ok(Waited::TimedOut);
        }
        std::thread::sleep(poll);
    }
}
