//! Whether the sensor side is there: its zenoh liveliness token `<key>/alive/sensor`
//! (declared by the sensor side, withdrawn by zenoh when its session ends, also when it is
//! killed). A bridge that vanishes is logged and counted; the stream goes on when it returns,
//! its gap counted as lost on the network.
//!
//! `--connect-timeout` holds whenever the far side is absent (issue #39: once one had been
//! seen the estimator side waited for ever, and a rogue liveliness token kept it waiting
//! with no sensor side at all): absent from the start until a message arrives, and again
//! from the token's withdrawal until the next message. A token alone is not presence.

use crate::args::BridgeArgs;
use crate::link::report::BridgeReport;
use crate::zenoh::inbox::Inbox;
use anyhow::{bail, Result};
use std::time::Instant;
use zenoh::sample::SampleKind;

/// `BridgeReport::ending` when the sensor side stayed away for `--connect-timeout` (exit
/// code 3, as a runner's lost publisher).
pub const FAR_SIDE_LOST: &str = "the sensor side was lost";

/// The sensor side as this side knows it.
pub(crate) struct FarSide {
    /// The liveliness subscriber of `<key>/alive/sensor`.
    alive: Inbox,
    /// A token was declared at some point.
    seen: bool,
    /// A message came at some point.
    heard: bool,
    /// Since when no sensor side is known to be there (`None`: one is).
    absent_since: Option<Instant>,
}

impl FarSide {
    /// Absent from now, until a message comes.
    pub(crate) fn new(alive: Inbox) -> Self {
        Self {
            alive,
            seen: false,
            heard: false,
            absent_since: Some(Instant::now()),
        }
    }

    /// A message from the far side arrived.
    pub(crate) fn heard_now(&mut self) {
        self.heard = true;
        self.absent_since = None;
    }

    /// Takes the token's news: a sensor side that came back, or one that went.
    pub(crate) fn check(&mut self, report: &mut BridgeReport, quiet: bool) {
        while let Ok(Some(s)) = self.alive.try_recv() {
            match s.kind() {
                SampleKind::Put => {
                    if self.seen && !quiet {
                        estpipe_process::errln!("bridge: sensor side back");
                    }
                    self.seen = true;
                }
                SampleKind::Delete => {
                    report.far_side_lost += 1;
                    self.absent_since.get_or_insert_with(Instant::now);
                    if !quiet {
                        estpipe_process::errln!(
                            "bridge: sensor side gone (its slots count as lost on the network \
                             until it returns)"
                        );
                    }
                }
            }
        }
    }

    /// Whether the sensor side has been absent for longer than `--connect-timeout` (then
    /// said on stderr): an error if none was ever heard. Once the stream's END came
    /// (`ended`), the sensor side may leave: a `--once` bridge ends by its linger instead.
    pub(crate) fn lost(&self, args: &BridgeArgs, key: &str, ended: bool) -> Result<bool> {
        let Some(since) = self.absent_since else {
            return Ok(false);
        };
        let absent = since.elapsed().as_secs_f64();
        if ended || args.connect_timeout <= 0.0 || absent <= args.connect_timeout {
            return Ok(false);
        }
        if !self.heard {
            bail!(
                "no sensor side on {key} within --connect-timeout {} s{}",
                args.connect_timeout,
                if self.seen {
                    " (a liveliness token was there, but no message came)"
                } else {
                    ""
                }
            );
        }
        estpipe_process::errln!(
            "bridge: error: the sensor side on {key} is gone since {absent:.1} s \
             (--connect-timeout {} s)",
            args.connect_timeout
        );
        Ok(true)
    }
}
