//! The stream itself: instants k = 1..=steps, each as truth then one slot per node of this
//! process, paced at `--rate`; a lost subscriber awaited; then every node's END (or ABORT)
//! marker, and the linger until the subscriber has read the tail.

use std::time::{Duration, Instant};

use anyhow::{bail, Result};
use estpipe_wire::{self as wire, Slot, Truth, SLOT_ABORT, SLOT_END};

use super::ports::Ports;
use super::{report_unread, PublisherArgs, PublisherReport, Source, TestHooks};
use crate::backpressure::Mode;
use crate::sim::{Instant as SimInstant, MAX_NY};
use crate::slot_sender::{wait, wait_for_subscriber, Sent, Stop};
use crate::wire::slot_of;

/// What ended an instant's sends early.
enum Flow {
    /// Go on with the next instant.
    Next,
    /// Stopped (signal, dead parent, a failed node): the ABORT markers follow.
    Stop,
}

/// One publishing process's stream.
pub(super) struct Stream<'a> {
    pub(super) args: &'a PublisherArgs,
    pub(super) ports: Ports,
    pub(super) report: PublisherReport,
    pub(super) hooks: TestHooks,
    pub(super) nodes: u8,
    pub(super) sid: u64,
    pub(super) nx: usize,
    /// 0 at full speed.
    pub(super) period_ns: u64,
    pub(super) say: &'a dyn Fn(&str),
    stream_start_ns: u64,
    last_check: u64,
    delivered: u64,
    /// Per node, the last instant whose slot was handed to the publisher: its END/ABORT
    /// marker's k (docs/wire.md, Stream rules).
    sent_k: [u32; wire::MAX_NODES],
}

impl<'a> Stream<'a> {
    /// A stream about to start (the subscriber is there, instant 0's truth is out).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn new(
        args: &'a PublisherArgs,
        ports: Ports,
        report: PublisherReport,
        hooks: TestHooks,
        nodes: u8,
        sid: u64,
        nx: usize,
        period_ns: u64,
        say: &'a dyn Fn(&str),
    ) -> Self {
        let t0 = wire::monotonic_ns();
        Self {
            args,
            ports,
            report,
            hooks,
            nodes,
            sid,
            nx,
            period_ns,
            say,
            stream_start_ns: t0,
            last_check: t0,
            delivered: 0,
            sent_k: [0; wire::MAX_NODES],
        }
    }

    /// Whether this process publishes node `m`'s slots.
    fn mine(node: Option<u8>, m: u8) -> bool {
        node.is_none_or(|n| n == m)
    }

    /// Instants 1..=`steps` from `source`; `report.interrupted` says whether they all went.
    pub(super) fn instants(&mut self, source: &mut Source, steps: u32) -> Result<()> {
        let t0 = self.stream_start_ns;
        for i in 1..=steps {
            if self.period_ns > 0 {
                let due = t0 + u64::from(i - 1) * self.period_ns;
                let now = wire::monotonic_ns();
                // Behind schedule (after a stop and continue) the instants due go at once.
                let until = Duration::from_nanos(due.saturating_sub(now));
                if wait(&self.ports.node, &self.ports.gate, until).is_err() {
                    self.report.interrupted = true;
                    return Ok(());
                }
            } else if i.is_multiple_of(256) && self.ports.gate.stop_requested() {
                self.report.interrupted = true;
                return Ok(());
            }
            let inst = source.sim().next_instant();
            if source.failure().is_some() {
                self.report.interrupted = true;
                return Ok(());
            }
            if let Flow::Stop = self.instant(&inst, i)? {
                self.report.interrupted = true;
                return Ok(());
            }
        }
        Ok(())
    }

    /// Instant `i`'s truth and slots, the ready event, and the look for a lost subscriber.
    fn instant(&mut self, inst: &SimInstant, i: u32) -> Result<Flow> {
        let mut x = inst.truth;
        if self.hooks.nan_truth_at == Some(inst.k) {
            x[0] = f64::NAN;
        }
        self.ports
            .send_truth(Truth::new(inst.k, self.sid, self.nx, &x))?;
        let mut subscriber_gone = false;
        let only = self.args.node;
        for obs in inst.obs.iter().filter(|o| Self::mine(only, o.node)) {
            let mut slot = slot_of(
                obs,
                self.nodes,
                self.sid,
                wire::monotonic_ns(),
                self.period_ns,
                self.stream_start_ns,
            );
            slot.version = self.hooks.wire_version.unwrap_or(wire::WIRE_VERSION);
            if obs.delivered {
                self.delivered += 1;
                if let Some(n) = self.hooks.nan_every {
                    if n > 0 && self.delivered.is_multiple_of(n) && usize::from(obs.ny) <= MAX_NY {
                        slot.y[0] = f64::NAN;
                    }
                }
            }
            match self.ports.sender.send(slot, None)? {
                Sent::Done => self.report.slots += 1,
                // The slot's seq is used: a later subscriber sees the gap.
                Sent::GaveUp => {
                    self.report.slots += 1;
                    subscriber_gone = true;
                }
                // Not sent: the ABORT marker's count ends before it.
                Sent::Stopped => return Ok(Flow::Stop),
            }
            self.sent_k[usize::from(obs.node)] = obs.k;
        }
        self.ports.notifier.notify()?;
        self.report.instants = i;
        report_unread(&self.ports.gate, &mut self.report, self.say);
        self.look_for_the_subscriber(i, subscriber_gone)
    }

    /// A dead subscriber stays registered (and keeps its queue) until someone cleans up.
    /// After the sends: the scan of the node directory (sub-millisecond) runs in the slack
    /// before the next instant is due rather than between its due time and its send.
    fn look_for_the_subscriber(&mut self, i: u32, gone: bool) -> Result<Flow> {
        let now = wire::monotonic_ns();
        if !gone && now - self.last_check <= 100_000_000 {
            return Ok(Flow::Next);
        }
        self.last_check = now;
        let _ = self.ports.node.try_cleanup_dead_nodes();
        if self.ports.subscribers() > 0 {
            return Ok(Flow::Next);
        }
        self.report.subscriber_losses += 1;
        (self.say)(&format!(
            "subscriber lost after instant {i}; waiting for a new one"
        ));
        let ports = &self.ports;
        match wait_for_subscriber(
            &ports.node,
            &ports.gate,
            || ports.subscribers(),
            self.args.connect_timeout,
        ) {
            Ok(true) => {
                (self.say)("subscriber back, continuing");
                Ok(Flow::Next)
            }
            Ok(false) => bail!(
                "no subscriber came back within {} s",
                self.args.connect_timeout
            ),
            Err(Stop::Signal) => Ok(Flow::Stop),
        }
    }

    /// Every node's END marker (ABORT after a stop), then the counts; returns the deadline
    /// that bounds both the markers and the linger after them (a subscriber that never
    /// leaves kept the publisher for both, one after the other).
    pub(super) fn end(&mut self) -> Result<Instant> {
        let kind = if self.report.interrupted {
            SLOT_ABORT
        } else {
            SLOT_END
        };
        // The marker waits for room whatever the mode (bounded by --linger): a discarded END
        // would leave the runner waiting for its deadline.
        self.ports.gate.set_mode(Mode::Final);
        let give_up = Instant::now() + Duration::from_secs_f64(self.args.linger.max(0.0));
        let only = self.args.node;
        for m in (0..self.nodes).filter(|&m| Self::mine(only, m)) {
            let k = self.sent_k[usize::from(m)];
            let marker = Slot {
                period_ns: self.period_ns,
                stream_start_ns: self.stream_start_ns,
                ..Slot::marker(kind, k, m, self.nodes, self.sid, 0)
            };
            self.ports.sender.send(marker, Some(give_up))?;
        }
        self.ports.notifier.notify()?;
        let (gate, report) = (&self.ports.gate, &mut self.report);
        report_unread(gate, report, self.say);
        report.unread_dropped = gate.unread_drops();
        report.discarded = self.ports.sender.discarded();
        report.resent = self.ports.sender.resent();
        if report.discarded > 0 {
            (self.say)(&format!(
                "{} slot(s) dropped for a subscriber whose queue was full (--backpressure \
                 discard)",
                report.discarded
            ));
        }
        (self.say)(&format!(
            "{} after {} instants ({} slots)",
            match gate.stop_reason() {
                Some(why) if report.interrupted => why,
                _ if report.interrupted => "stopped by signal".to_string(),
                _ => "done".to_string(),
            },
            report.instants,
            report.slots
        ));
        Ok(give_up)
    }

    /// Keeps the data segment alive until the subscriber has read the tail and detached (a
    /// subscriber that does not read is not waited for), at most until `give_up`.
    pub(super) fn linger(&self, give_up: Instant) {
        let ports = &self.ports;
        let mut last_cleanup = Instant::now();
        while ports.subscribers() > ports.gate.unread_receivers() && Instant::now() < give_up {
            if last_cleanup.elapsed() > Duration::from_millis(100) {
                let _ = ports.node.try_cleanup_dead_nodes();
                last_cleanup = Instant::now();
            }
            if wait(&ports.node, &ports.gate, Duration::from_millis(2)).is_err() {
                break;
            }
        }
    }
}
