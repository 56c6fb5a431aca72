//! The estimator side's forwarding loop, one pass at a time: the stop, the far side, a burst
//! of slots, the estimates back, and the `--once` end.

use super::far_side::{FarSide, FAR_SIDE_LOST};
use crate::args::BridgeArgs;
use crate::link::forward::{Forward, Took};
use crate::link::linger::Linger;
use crate::stop::Stop;
use crate::zenoh::inbox::{self, Inbox, BURST};
use anyhow::{anyhow, Result};
use estpipe_wire::{net, Estimate};
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use std::time::Duration;
use zenoh::pubsub::Publisher;
use zenoh::Wait;

/// Everything the loop reads and writes.
pub(super) struct Pass<'a> {
    pub args: &'a BridgeArgs,
    /// `args.key()`, made once.
    pub key: &'a str,
    pub stop: &'a Stop,
    pub fwd: Forward,
    pub estimates: Subscriber<ipc::Service, Estimate, ()>,
    pub far: FarSide,
    pub z_slots: &'a Inbox,
    pub z_estimates: &'a Publisher<'static>,
    pub z_acks: &'a Publisher<'static>,
    pub linger: Linger,
}

impl Pass<'_> {
    /// Forwards until the stop, the far side's loss or (`--once`) the stream's end; why it
    /// ended, for the report.
    pub(super) fn forward_until_end(&mut self) -> Result<&'static str> {
        loop {
            if self.stop.requested() {
                return Ok("interrupted");
            }
            self.far.check(&mut self.fwd.report, self.args.quiet);
            if self.far.lost(self.args, self.key, self.linger.is_ended())? {
                return Ok(FAR_SIDE_LOST);
            }
            let mut busy = self.slots()?;
            busy |= self.estimates()?;
            if self.args.once && !busy && self.linger.over() {
                return Ok("the stream ended");
            }
        }
    }

    /// A burst of `<key>/slots`, each checked and forwarded, each marker echoed; `Ok(true)`
    /// if there was one.
    fn slots(&mut self) -> Result<bool> {
        // Waits for the first (bounded, so estimates and signals are served).
        let first = self
            .z_slots
            .recv_timeout(Duration::from_micros(500))
            .map_err(|e| anyhow!("zenoh {}/slots: {e}", self.key))?;
        let Some(first) = first else {
            return Ok(false);
        };
        self.far.heard_now();
        for sample in std::iter::once(first)
            .chain(inbox::burst(self.z_slots))
            .take(BURST)
        {
            let bytes = sample.payload().to_bytes();
            let took = self.fwd.message(&bytes)?;
            if took != Took::Other {
                // Best effort: a lost echo only means one more repeat from the far side.
                let _ = self.z_acks.put(&bytes[..]).wait();
                self.fwd.report.acks += 1;
            }
            if took == Took::Marker {
                self.linger.ended();
            }
        }
        Ok(true)
    }

    /// Every estimate the runner published, sent back; `Ok(true)` if there was one.
    fn estimates(&mut self) -> Result<bool> {
        let mut any = false;
        while let Some(e) = self
            .estimates
            .receive()
            .map_err(|e| anyhow!("estimates: {e:?}"))?
        {
            any = true;
            self.linger.estimate();
            self.z_estimates
                .put(&net::encode_estimate(e.payload())[..])
                .wait()
                .map_err(|e| anyhow!("zenoh put estimate: {e}"))?;
            self.fwd.report.estimates += 1;
        }
        Ok(any)
    }
}
