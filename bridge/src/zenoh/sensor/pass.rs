//! The sensor side's forwarding loop, one pass at a time: truth and a burst of slots out, the
//! markers' acknowledgements in and their repeats out, the estimates back, the `--once` end.

use super::{Local, Net};
use crate::args::BridgeArgs;
use crate::link::linger::Linger;
use crate::link::markers::{Ack, Markers};
use crate::link::report::BridgeReport;
use crate::link::shm;
use crate::stop::Stop;
use crate::zenoh::inbox::{self, BURST};
use crate::zenoh::session::put;
use anyhow::{anyhow, Result};
use estpipe_wire::{self as wire, net, Estimate, Slot, StreamHeader, SLOT_DATA};
use iceoryx2::port::publisher::Publisher;
use iceoryx2::prelude::*;
use std::time::{Duration, Instant};

/// Everything the loop reads and writes.
pub(super) struct Pass<'a> {
    pub args: &'a BridgeArgs,
    pub stop: &'a Stop,
    pub report: BridgeReport,
    pub net: &'a Net,
    pub local: &'a Local,
    pub estimates: &'a Publisher<ipc::Service, Estimate, ()>,
    pub markers: Markers,
    pub linger: Linger,
    /// Slot messages put, for `--debug-corrupt-every`.
    pub sent: u64,
}

impl Pass<'_> {
    /// Forwards until the stop or (`--once`) the stream's end; why it ended, for the report,
    /// or `None` when a stop cut a marker's repeat short.
    pub(super) fn forward_until_end(&mut self) -> Result<Option<&'static str>> {
        loop {
            if self.stop.requested() {
                return Ok(Some("interrupted"));
            }
            let mut busy = self.truth()?;
            busy |= self.slots()?;
            busy |= self.acks();
            if !self.repeat_marker()? {
                return Ok(None);
            }
            busy |= self.estimates()?;
            if self.args.once && self.markers.settled() && self.linger.over() {
                return Ok(Some("the stream ended"));
            }
            if !busy {
                // A wake-up per instant from the publisher; the timeout bounds the delay of
                // estimates, of the markers' re-sends and of the signal check.
                let _ = self
                    .local
                    .ready
                    .timed_wait(|_| {}, Duration::from_micros(500));
            }
        }
    }

    /// Forwards every truth sample waiting in shared memory (on the slots key: one zenoh
    /// publisher keeps the order); `Ok(true)` if there was one. Returns early when a stop
    /// closed the session.
    fn truth(&mut self) -> Result<bool> {
        let mut any = false;
        while let Some(t) = self
            .local
            .truth
            .receive()
            .map_err(|e| anyhow!("truth: {e:?}"))?
        {
            any = true;
            let t = *t.payload();
            if t.version != wire::WIRE_VERSION || t.nx == 0 || t.nx as usize > wire::MAX_NX {
                self.report.refuse("truth");
                continue;
            }
            if !put(&self.net.slots, &net::encode_truth(&t), self.stop, "truth")? {
                break;
            }
            self.report.truth += 1;
        }
        Ok(any)
    }

    /// A burst of slots from shared memory onto `<key>/slots`; `Ok(true)` if there was one.
    fn slots(&mut self) -> Result<bool> {
        let mut any = false;
        for _ in 0..BURST {
            let Some(sample) = self
                .local
                .slots
                .receive()
                .map_err(|e| anyhow!("slots: {e:?}"))?
            else {
                break;
            };
            any = true;
            let (h, s) = (*sample.user_header(), *sample.payload());
            drop(sample);
            // The publisher sends an instant's truth before its slots: whatever truth came
            // meanwhile goes first, so the far side sees the same order.
            // A put the stop cut short ends this pass at the slot's own put below.
            self.truth()?;
            if !self.slot(&h, &s)? {
                break;
            }
        }
        Ok(any)
    }

    /// Checks and puts one slot; `Ok(false)` when a stop cut the put short.
    fn slot(&mut self, h: &StreamHeader, s: &Slot) -> Result<bool> {
        // The same checks the far side makes: a bad slot never costs network bandwidth.
        let mut msg = net::encode_slot(h, s);
        if let Err(e) = net::decode_slot(&msg) {
            self.report.refuse(e.reason());
            return Ok(true);
        }
        self.sent += 1;
        if self
            .args
            .corrupt_every()
            .is_some_and(|n| n > 0 && self.sent.is_multiple_of(n))
        {
            msg[3] ^= 0x80;
        }
        if !put(&self.net.slots, &msg, self.stop, "slot")? {
            return Ok(false);
        }
        if s.kind == SLOT_DATA {
            self.report.slots += 1;
        } else {
            // Repeated until acknowledged: over UDP a lost END would leave the far side's
            // runner waiting for instants that never come (crate::markers).
            self.report.markers += 1;
            self.report.marker_puts += 1;
            self.markers.put(s, &msg, Instant::now());
            self.linger.ended();
        }
        Ok(true)
    }

    /// A burst of `<key>/acks`; `true` if there was one. At most a burst: a peer flooding
    /// `<key>/acks` faster than they are read must not keep this pass from the slots.
    fn acks(&mut self) -> bool {
        let mut any = false;
        for sample in inbox::burst(&self.net.acks) {
            any = true;
            match self.markers.ack(&sample.payload().to_bytes()) {
                Ok(Ack::Taken | Ack::Stale) => {}
                Err(reason) => self.report.refuse(reason),
            }
        }
        any
    }

    /// Puts again the marker that is due, if one is; `Ok(false)` when a stop cut the put short.
    fn repeat_marker(&mut self) -> Result<bool> {
        if let Some(msg) = self.markers.due(Instant::now()) {
            if !put(&self.net.slots, &msg, self.stop, "marker")? {
                return Ok(false);
            }
            self.report.marker_puts += 1;
        }
        Ok(true)
    }

    /// A burst of `<key>/estimates` into shared memory; `Ok(true)` if there was one. At most a
    /// burst: estimates flooded onto `<key>/estimates` (by the far side or by a foreign peer)
    /// must not keep this pass from the slots.
    fn estimates(&mut self) -> Result<bool> {
        let mut any = false;
        for sample in inbox::burst(&self.net.estimates) {
            any = true;
            self.linger.estimate();
            match net::decode_estimate(&sample.payload().to_bytes()) {
                Ok(e) => {
                    shm::write(self.estimates, e, "estimates")?;
                    self.report.estimates += 1;
                }
                Err(e) => self.report.refuse(e.reason()),
            }
        }
        Ok(any)
    }
}
