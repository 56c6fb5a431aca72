//! The estimator side's way in: a message from the far side is checked, then written into
//! shared memory for the runner.
//!
//! Nothing reaches shared memory before `estpipe_wire::net`'s checks passed; the stream
//! header must also stay the same within a stream. What fails is counted by reason and
//! dropped. Sequence gaps become lost slots ([`crate::sequence`]).

use crate::link::report::{BridgeReport, Stage};
use crate::link::sequence::{lost_slot, Arrival, Sequence};
use crate::link::shm::{self, Services};
use crate::stop::Stop;
use anyhow::{anyhow, Result};
use estpipe_wire::{self as wire, net, Slot, StreamHeader, Truth, SLOT_DATA};
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::{BackpressureAction, BackpressureInfo};
use iceoryx2::prelude::*;
use std::time::Duration;

/// Longest a send into a full runner queue waits before the slot is dropped (counted): a
/// frozen runner must not freeze the bridge, and SIGINT must still end it.
const SEND_LIMIT: Duration = Duration::from_secs(1);

/// What one message from the far side was, for the acknowledgement of markers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Took {
    /// A data slot, a truth sample, or a refused message.
    Other,
    /// A node's END/ABORT, forwarded: its stream is over.
    Marker,
    /// A copy of a marker already taken.
    RepeatedMarker,
}

/// This host's ports a checked message is written to.
pub(crate) struct Outlets {
    slots: Publisher<ipc::Service, Slot, StreamHeader>,
    truth: Publisher<ipc::Service, Truth, ()>,
    ready: Notifier<ipc::Service>,
}

impl Outlets {
    /// The slot publisher (the runner's only one on `prefix`), the truth publisher and the
    /// slots-ready notifier.
    pub(crate) fn open(services: &Services, stop: &Stop, prefix: &str) -> Result<Self> {
        let handler_stop = stop.clone();
        let slots = services
            .slots
            .publisher_builder()
            .backpressure_strategy(BackpressureStrategy::RetryUntilDelivered)
            .set_backpressure_handler(move |info: &BackpressureInfo| {
                if handler_stop.requested() || info.elapsed_time >= SEND_LIMIT {
                    BackpressureAction::DiscardDataAndFail
                } else {
                    BackpressureAction::Retry
                }
            })
            .create()
            .map_err(|e| {
                anyhow!(
                    "cannot publish on {prefix}/slots ({e:?}): is a publisher or another bridge \
                     using this --prefix?"
                )
            })?;
        let truth = services
            .truth
            .publisher_builder()
            .create()
            .map_err(|e| anyhow!("cannot publish on {prefix}/truth: {e:?}"))?;
        let ready = services
            .ready
            .notifier_builder()
            .default_event_id(wire::READY_EVENT)
            .create()
            .map_err(|e| anyhow!("cannot notify on {prefix}/slots-ready: {e:?}"))?;
        Ok(Self {
            slots,
            truth,
            ready,
        })
    }
}

/// Writes checked slots and truth into shared memory, and counts what it did.
pub(crate) struct Forward {
    out: Outlets,
    /// The account of the run, kept here since nearly every count is this one's.
    pub report: BridgeReport,
    sequence: Sequence,
    header: Option<(u64, StreamHeader)>,
    hop: Stage,
    own: Stage,
    max_gap: u64,
}

impl Forward {
    /// Forwards into `out`, counting into `report`; gaps longer than `max_gap` are not filled.
    pub(crate) fn new(out: Outlets, report: BridgeReport, max_gap: u64) -> Self {
        Self {
            out,
            report,
            sequence: Sequence::default(),
            header: None,
            hop: Stage::default(),
            own: Stage::default(),
            max_gap,
        }
    }

    /// The report, with the latencies measured.
    pub(crate) fn into_report(self) -> BridgeReport {
        let mut report = self.report;
        report.network_hop = self.hop.percentiles();
        report.bridge_time = self.own.percentiles();
        report
    }

    /// One message of `<key>/slots`: a truth sample or a slot (one key, so that the truth of
    /// an instant arrives before its slots, as from the publisher itself).
    pub(crate) fn message(&mut self, bytes: &[u8]) -> Result<Took> {
        if bytes.get(2) == Some(&(net::Kind::Truth as u8)) {
            match net::decode_truth(bytes) {
                Ok(t) => {
                    shm::write(&self.out.truth, t, "truth")?;
                    self.report.truth += 1;
                }
                Err(e) => self.report.refuse(e.reason()),
            }
            return Ok(Took::Other);
        }
        self.arrive(bytes)
    }

    /// One slot message.
    fn arrive(&mut self, bytes: &[u8]) -> Result<Took> {
        let at = wire::monotonic_ns();
        let (h, s) = match net::decode_slot(bytes) {
            Ok(m) => m,
            Err(e) => {
                self.report.refuse(e.reason());
                return Ok(Took::Other);
            }
        };
        match self.header {
            Some((stream, ref known)) if stream == s.stream_id && *known != h => {
                self.report.refuse("header_changed");
                return Ok(Took::Other);
            }
            _ => self.header = Some((s.stream_id, h)),
        }
        match self.sequence.arrive(&s) {
            Arrival::RepeatedMarker => {
                // The sensor side sends every marker more than once (a lost END would hang
                // the runner); the copies after the first are expected, not refused.
                self.report.markers_repeated += 1;
                return Ok(Took::RepeatedMarker);
            }
            Arrival::Late if s.kind != SLOT_DATA => {
                // A marker of an instant this node's stream already passed: nothing to
                // forward, but echoed, so the far side stops repeating it.
                self.report.refuse("late");
                return Ok(Took::RepeatedMarker);
            }
            Arrival::Late => {
                self.report.refuse("late");
                return Ok(Took::Other);
            }
            Arrival::NewStream { lost } => self.lost(&h, &s, 1..=lost)?,
            Arrival::InOrder { lost: 0, .. } => {}
            Arrival::InOrder { lost, .. } if u64::from(lost) > self.max_gap => {
                self.report.refuse("gap_too_large");
            }
            Arrival::InOrder { from, lost } => self.lost(&h, &s, from..from + lost)?,
        }
        if s.send_ns != 0 && s.send_ns <= at {
            self.hop.record(at - s.send_ns);
        }
        self.send(&h, s)?;
        self.own.record(wire::monotonic_ns().saturating_sub(at));
        if s.kind == SLOT_DATA {
            self.report.slots += 1;
            Ok(Took::Other)
        } else {
            self.report.markers += 1;
            Ok(Took::Marker)
        }
    }

    /// Writes the instants `ks` of `like`'s node as lost on the network, before `like`.
    fn lost(&mut self, h: &StreamHeader, like: &Slot, ks: impl Iterator<Item = u32>) -> Result<()> {
        for k in ks {
            self.send(h, lost_slot(like, k))?;
            self.report.lost_on_network += 1;
        }
        Ok(())
    }

    fn send(&mut self, h: &StreamHeader, s: Slot) -> Result<()> {
        let mut sample = self
            .out
            .slots
            .loan_uninit()
            .map_err(|e| anyhow!("slots: {e:?}"))?;
        *sample.user_header_mut() = *h;
        match sample.write_payload(s).send() {
            Ok(_) => {}
            Err(_) if s.kind == SLOT_DATA => self.report.dropped_at_bridge += 1,
            Err(e) => {
                return Err(anyhow!(
                    "slots: the END/ABORT marker was not delivered: {e:?}"
                ))
            }
        }
        // A wake-up per slot: each node is its own stream, so any slot may complete an instant.
        let _ = self.out.ready.notify();
        Ok(())
    }
}
