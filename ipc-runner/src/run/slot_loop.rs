//! The loop over slots: drain the slot queue (every received slot is pushed into the
//! [`Assembler`], then each instant it made ready is taken and handed to
//! [`Runner::on_instant`], in order), follow a restarted publisher, and when nothing is
//! pending check the data deadline and wait ([`super::wait`]).

use crate::latency::Latency;
use crate::transport::Transport;
use crate::Estimator;
use anyhow::{bail, Result};
use estpipe_spec::EstimatorSpec;
use estpipe_wire::Observation;
use estpipe_wire::{self as wire, SlotFault, StreamHeader, MAX_NODES};
use iceoryx2::port::update_connections::UpdateConnections;
use std::time::Duration;

use super::args::{RunArgs, WaitMode};
use super::assemble::{self, Assembler, Counts, Limits, Pushed, Reason};
use super::deadline::Deadline;
use super::instant::Runner;
use super::report::{Ending, RunReport, Stalls};
use super::restart::StreamOwners;
use super::system::Machine;
use super::trajectories::Trajectories;
use super::wait::{self, Waiter, Woke};

/// Progress callback: latest instant and the counts so far.
pub type Progress<'a> = dyn FnMut(u32, &Counts) + 'a;

/// Optional instrumentation of the loop.
#[derive(Default)]
pub struct Hooks<'a> {
    /// Returns the process's running allocation count (a counting global allocator); read
    /// after instant [`Hooks::warmup`] and at the end of the stream.
    pub alloc_probe: Option<fn() -> usize>,
    /// Instants before the allocation count starts (default 20).
    pub warmup: u64,
    /// Called at most every 100 ms with the latest instant and the counts.
    pub progress: Option<&'a mut Progress<'a>>,
    /// Asked about every [`PEER_CHECK_NS`] while the loop waits (`demo`: its child
    /// publisher): `Some(why)` when the publisher process has ended. The run then takes what
    /// is still queued and ends as [`Ending::PublisherLost`], or fails with `why` if no slot
    /// ever came.
    pub peer: Option<&'a mut dyn FnMut() -> Option<String>>,
}

impl std::fmt::Debug for Hooks<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Hooks")
            .field("warmup", &self.warmup)
            .finish()
    }
}

/// Longest single wait: the deadline is checked at least this often.
const MAX_WAIT_NS: u64 = 50_000_000;

/// A new estimate subscriber gets its history within this many ns while the loop is idle.
const UPDATE_CONNECTIONS_NS: u64 = 10_000_000;

/// Progress is reported at most this often.
const PROGRESS_EVERY_NS: u64 = 100_000_000;

/// A [`Hooks::peer`] is asked this often, and no wait is longer while there is one.
pub const PEER_CHECK_NS: u64 = 10_000_000;

/// Runs the loop with estimators from `make` (called again for every new stream) until the
/// stream ends. Errors are configuration/transport failures; a lost publisher is reported in
/// [`RunReport::ending`]. The estimators were built for `spec`: its stream header is the
/// shape and model a stream must announce (every node's ny among them: nodes may differ).
pub fn run_loop(
    args: &RunArgs,
    spec: &EstimatorSpec,
    make: &dyn Fn() -> Result<Vec<Box<dyn Estimator>>>,
    mut hooks: Hooks<'_>,
) -> Result<(RunReport, Trajectories)> {
    // The shape a stream must announce to feed these estimators (docs/wire.md, Stream header).
    let expected = spec.stream_header();
    let (nx, nodes) = (spec.nx(), u8::try_from(spec.nodes())?);
    let machine = Machine::set_up(args);
    let t = Transport::open(&args.prefix, args.buffer, args.wait != WaitMode::Spin)?;
    let runner = Runner::new(&t, args, make()?, nx, nodes)?;
    let mut asm = Assembler::new(&expected, limits(args)?);
    asm.set_subscribed_ns(t.subscribed_ns);
    let mut lp = Loop {
        args,
        t: &t,
        make,
        runner,
        asm,
        deadline: Deadline::new(args),
        allocs: Allocs::new(&hooks),
        publisher_losses: 0,
        stalls: Stalls::default(),
        last_peer_check: 0,
        last_progress: 0,
        expected,
        last_update_ns: 0,
        relay: Relay::default(),
        owners: StreamOwners::default(),
    };

    // Before announcing the wait: from here on SIGINT/SIGTERM/SIGHUP set the flag every wait mode
    // reads, and no other signal ends the run (docs/security.md, "Signals"). Earlier, a
    // signal takes its default action (the process ends without a report, as nothing ran).
    estpipe_process::signal::install();
    lp.say_waiting();
    let waitset = wait::waitset(args.wait, &t)?;
    let mut waiter = Waiter::new(&t, waitset.as_ref())?;

    // A failure once instants were processed ends the run with its report (report.rs): what
    // the run computed is not lost. Before the first instant there is nothing to report.
    let (ending, mut failure) = lp.run(&mut hooks, &mut waiter)?;
    if matches!(ending, Ending::Interrupted | Ending::Failed) {
        lp.flush();
    }
    let processed = lp.asm.counts.instants;
    if let Some(e) = failure.take_if(|_| processed == 0) {
        return Err(e);
    }
    let (mut report, traj) = lp.finish(ending, machine);
    if let Some(e) = failure {
        report.error_code = crate::exit_code_of(&e);
        report.error = Some(format!("{e:#}"));
    }
    // The spec's own name: a `--config` or `--estimator-spec` file's, not the `--scenario`
    // default.
    report.scenario = spec.name.clone();
    Ok((report, traj))
}

/// How far the assembler follows a stream, as `args` asks.
fn limits(args: &RunArgs) -> Result<Limits> {
    if !(args.instant_deadline_ms >= 0.0 && args.instant_deadline_ms.is_finite()) {
        return Err(wire::ContractError::Refused(format!(
            "--instant-deadline-ms must be a number ≥ 0 (0 = for ever), got {}",
            args.instant_deadline_ms
        ))
        .into());
    }
    Ok(Limits {
        max_gap: args.max_gap,
        instant_deadline_ns: (args.instant_deadline_ms * 1e6) as u64,
        lag: args.estimator.lag,
    })
}

/// The loop's state between slots.
struct Loop<'a> {
    args: &'a RunArgs,
    t: &'a Transport,
    make: &'a dyn Fn() -> Result<Vec<Box<dyn Estimator>>>,
    runner: Runner,
    asm: Assembler,
    deadline: Deadline,
    allocs: Allocs,
    publisher_losses: u32,
    stalls: Stalls,
    /// When [`Hooks::peer`] was last asked.
    last_peer_check: u64,
    last_progress: u64,
    /// The header of the scenario the estimators were built for.
    expected: StreamHeader,
    /// When the estimate publisher last looked for new subscribers.
    last_update_ns: u64,
    /// Which publisher forwards each node's stream.
    relay: Relay,
    /// Which publisher started each node's stream (which restarts are believed).
    owners: StreamOwners,
}

/// Which publisher each node's slots come from, and whether it is a bridge's estimator side
/// (a relay that may go away and come back with the same stream: docs/bridge.md, "A bridge
/// that goes away").
#[derive(Debug, Default)]
struct Relay {
    /// Per node: the publisher (`UniquePublisherId` value) of its last slot.
    origin: [Option<u128>; MAX_NODES],
    /// Publishers looked at (id, a bridge?), so that publishers taking turns on a node cost
    /// one lookup each.
    seen: [(u128, bool); 4],
    next: usize,
    /// The publisher of the last slot that came from a new one is a bridge.
    bridged: bool,
    /// "bridge gone" was said (again once a slot came from a new publisher).
    gone_said: bool,
}

impl Relay {
    /// Whether publisher `origin` is a bridge (looked up once per publisher).
    fn is_bridge(&mut self, t: &Transport, origin: u128) -> bool {
        if let Some(&(_, b)) = self.seen.iter().find(|(id, _)| *id == origin && *id != 0) {
            return b;
        }
        let b = t.is_bridge(origin);
        self.seen[self.next] = (origin, b);
        self.next = (self.next + 1) % self.seen.len();
        b
    }
}

impl Loop<'_> {
    fn say(&self, m: &str) {
        if !self.args.quiet {
            estpipe_process::errln!("ipc-runner: {m}");
        }
    }

    /// The line that says why the run ends with an error: `--quiet` hides progress, never
    /// this (it hid the reason of a "publisher lost", exit code 3).
    fn say_always(&self, m: &str) {
        estpipe_process::errln!("ipc-runner: {m}");
    }

    /// Says what the loop waits for, and how long.
    fn say_waiting(&self) {
        let args = self.args;
        self.say(&format!(
            "waiting for channel-sim (or any publisher) on prefix {:?} ({} wait; {})",
            args.prefix,
            args.wait.as_str(),
            if args.connect_timeout > 0.0 {
                format!(
                    "giving up after --connect-timeout {} s",
                    args.connect_timeout
                )
            } else {
                "no timeout: Ctrl-C stops, --connect-timeout S gives up after S s".to_string()
            }
        ));
    }

    /// Drains, checks the deadlines and waits until the run ends: how it ended, and the
    /// failure that ended it (`Ending::Failed`).
    fn run(
        &mut self,
        hooks: &mut Hooks<'_>,
        waiter: &mut Waiter<'_>,
    ) -> Result<(Ending, Option<anyhow::Error>)> {
        let max_wait_ns = if hooks.peer.is_some() {
            PEER_CHECK_NS
        } else {
            MAX_WAIT_NS
        };
        let ending = loop {
            match self.drain(hooks) {
                Ok(Some(ending)) => break ending,
                Ok(None) => {}
                Err(e) => return Ok((Ending::Failed, Some(e))),
            }
            // Nothing pending: check the deadline, then wait.
            let Some(now) = waiter.now() else {
                break Ending::Interrupted;
            };
            self.update_connections(now);
            if let Some(why) = self.peer_gone(hooks, now) {
                break self.peer_lost(hooks, &why)?;
            }
            self.expire(now);
            let due = self.deadline.due();
            if now > due {
                match self.missed(now) {
                    Some(ending) => break ending,
                    None => continue,
                }
            }
            let due = self.asm.next_expiry().map_or(due, |t| t.min(due));
            // No stream yet (or a lost one awaited): spinning would burn a core for as long as
            // the publisher takes to come, so every wait mode sleeps then.
            let idle = self.deadline.idle_since(now);
            match waiter.wait(due.saturating_sub(now).min(max_wait_ns), idle) {
                Ok(Woke::Ready) => {}
                Ok(Woke::Signal) => break Ending::Interrupted,
                Err(e) => return Ok((Ending::Failed, Some(e))),
            }
        };
        Ok((ending, None))
    }

    /// [`Hooks::peer`] said the publisher process ended (`why`).
    fn peer_lost(&mut self, hooks: &mut Hooks<'_>, why: &str) -> Result<Ending> {
        // Whatever the publisher sent before it ended is still queued: that first.
        if let Some(ending) = self.drain(hooks)? {
            return Ok(ending);
        }
        if self.asm.counts.received == 0 {
            bail!("{why} before it sent a slot");
        }
        self.say_always(&format!("publisher lost: {why}"));
        self.publisher_losses += 1;
        self.flush();
        Ok(Ending::PublisherLost)
    }

    /// Handles every slot that is there; `Some` when the stream ended.
    #[inline]
    fn drain(&mut self, hooks: &mut Hooks<'_>) -> Result<Option<Ending>> {
        loop {
            // Also between the slots of a long burst (a catch-up): a stop ends the run within
            // one slot's work, and what is still queued stays unread.
            if estpipe_process::signal::termination_requested() {
                return Ok(Some(Ending::Interrupted));
            }
            let sample = match self.t.slot_sub.receive() {
                Ok(Some(s)) => s,
                Ok(None) => return Ok(None),
                Err(e) => bail!("receive failed: {e:?}"),
            };
            let recv_ns = wire::monotonic_ns();
            let origin = sample.origin().value();
            let pushed = self.take(sample.payload(), sample.user_header(), origin, recv_ns)?;
            drop(sample);
            if let Some(ending) = self.after_slot(pushed, recv_ns, hooks)? {
                return Ok(Some(ending));
            }
        }
    }

    /// One slot, received at `recv_ns` from publisher `origin`, in place: pushed into the
    /// assembler, every instant it completed stepped and published, a late slot folded in.
    #[inline]
    fn take(
        &mut self,
        slot: &wire::Slot,
        header: &StreamHeader,
        origin: u128,
        recv_ns: u64,
    ) -> Result<Pushed> {
        let m = usize::from(slot.node);
        if m < MAX_NODES && self.relay.origin[m] != Some(origin) {
            self.new_origin(m, origin, slot.stream_id);
        }
        // Before any estimator has stepped, a stream of another shape or model is refused
        // (exit 2), never fed to estimators built for this one; later such a slot is
        // counted and skipped (docs/wire.md, What the runner does with a bad slot).
        if self.asm.counts.instants == 0
            && self.asm.counts.received == 0
            && !assemble::same_stream_shape(header, &self.expected)
        {
            header.check(&self.expected)?;
        }
        // Whatever it carries, a slot shows the publisher alive.
        if let Some(silence) = self.deadline.data(recv_ns) {
            self.stall_ended(silence);
        }
        let mut pushed = self.asm.push_slot(slot, header, recv_ns);
        if pushed == Pushed::NewStream {
            pushed = self.restart(slot, header, origin, recv_ns)?;
        }
        self.hand_on_ready();
        let stream = self.asm.stream_of(slot.node);
        self.owners.note(m, stream, slot.stream_id, origin, recv_ns);
        if let Some(r) = self.asm.take_first_seen() {
            self.warn(r, slot);
        }
        match pushed {
            Pushed::Late => self.fold_late(),
            Pushed::Data => self.data_slot(slot, recv_ns),
            _ => {}
        }
        Ok(pushed)
    }

    /// Steps and publishes every instant the assembler has ready, in order.
    #[inline]
    fn hand_on_ready(&mut self) {
        while let Some(instant) = self.asm.next_ready() {
            self.runner.on_instant(self.t, &instant);
        }
    }

    /// The slot starts a new stream of its node: believed (the publisher restarted), a new
    /// session with fresh estimators, the slot pushed again; not believed (another
    /// publisher's, while the stream's own is alive), counted and skipped.
    fn restart(
        &mut self,
        slot: &wire::Slot,
        header: &StreamHeader,
        origin: u128,
        recv_ns: u64,
    ) -> Result<Pushed> {
        if !self.owners.believe(
            usize::from(slot.node),
            self.asm.stream_of(slot.node),
            origin,
            self.t,
            recv_ns,
            self.deadline.period_ns + self.deadline.deadline_ns,
        ) {
            return Ok(self.asm.refuse_restart());
        }
        self.new_stream()?;
        Ok(self.asm.push_slot(slot, header, recv_ns))
    }

    /// A late slot within `--lag`: every estimator folds it into its history.
    fn fold_late(&mut self) {
        let mut obs = [Observation::dropped(0, 0, 0, 0); MAX_NODES];
        if let Some((k, nodes)) = self.asm.take_late(&mut obs) {
            self.runner.on_late(k, &obs[..nodes]);
        }
    }

    /// An accepted data slot: its period paces the data deadline, its send time gives a
    /// transport latency.
    #[inline]
    fn data_slot(&mut self, slot: &wire::Slot, recv_ns: u64) {
        // A period beyond the bound is not used for the data deadline.
        if slot.period_ns <= assemble::MAX_PERIOD_NS {
            self.deadline.period_ns = slot.period_ns;
        }
        // After the instant this slot may have completed was published.
        if assemble::usable_send_ns(slot, recv_ns).is_some() {
            Latency::record(&mut self.runner.latency.transport, slot.send_ns, recv_ns);
        }
    }

    /// After a slot was handled and its sample released: a publishing failure, the
    /// `--slow-consumer` pause, the allocation count, the end of the stream, progress.
    #[inline]
    fn after_slot(
        &mut self,
        pushed: Pushed,
        recv_ns: u64,
        hooks: &mut Hooks<'_>,
    ) -> Result<Option<Ending>> {
        if let Some(e) = self.runner.out.take_error() {
            return Err(e);
        }
        if let Some(us) = self.args.slow_consumer_us() {
            std::thread::sleep(Duration::from_micros(us));
        }
        self.allocs
            .after_slot(&self.asm.counts, self.runner.out.published);
        if matches!(pushed, Pushed::End | Pushed::Abort) {
            self.allocs.at_end = self.allocs.probe.map(|p| p());
            return Ok(Some(if pushed == Pushed::End {
                Ending::Completed
            } else {
                Ending::PublisherStopped
            }));
        }
        if let Some(p) = hooks.progress.as_mut() {
            if recv_ns - self.last_progress > PROGRESS_EVERY_NS {
                self.last_progress = recv_ns;
                p(self.runner.last_k, &self.asm.counts);
            }
        }
        Ok(None)
    }

    /// Says once per reason that slots are being counted and skipped (or a field ignored).
    fn warn(&self, r: Reason, slot: &wire::Slot) {
        let m = match r {
            Reason::Fault(SlotFault::Version) => wire::WireError::Version {
                found: slot.version,
            }
            .to_string(),
            r => r.describe(),
        };
        self.say(&format!("first {m} (further ones are counted silently)"));
    }

    /// Hands on every pending instant without its missing slots (the publishers are gone, or
    /// the run ends).
    fn flush(&mut self) {
        self.asm.flush();
        self.hand_on_ready();
    }

    /// Hands on the pending instants whose deadline passed (paced mode).
    #[inline]
    fn expire(&mut self, now: u64) {
        self.asm.expire_due(now);
        self.hand_on_ready();
    }

    /// While idle, at most every [`UPDATE_CONNECTIONS_NS`]: hands a subscriber that connected
    /// since the last estimate the estimate history (`docs/wire.md`, QoS), which iceoryx2
    /// otherwise delivers only with the next `send()`.
    #[inline]
    fn update_connections(&mut self, now: u64) {
        if now.saturating_sub(self.last_update_ns) > UPDATE_CONNECTIONS_NS {
            self.last_update_ns = now;
            let _ = self.t.estimate_pub.update_connections();
        }
    }

    /// channel-sim restarted: a new session with fresh estimators.
    fn new_stream(&mut self) -> Result<()> {
        let old = self.asm.stream_of(0);
        self.asm.reset();
        self.runner.session += 1;
        self.runner.renew((self.make)()?)?;
        self.say(&format!(
            "new stream from channel-sim (restarted; was {old:x?}): session {} with fresh estimators",
            self.runner.session
        ));
        Ok(())
    }

    /// [`Hooks::peer`]'s answer, asked at most every [`PEER_CHECK_NS`].
    fn peer_gone(&mut self, hooks: &mut Hooks<'_>, now: u64) -> Option<String> {
        let peer = hooks.peer.as_mut()?;
        if now.saturating_sub(self.last_peer_check) < PEER_CHECK_NS {
            return None;
        }
        self.last_peer_check = now;
        peer()
    }

    /// Node `m`'s slot came from publisher `origin`, not from the one of its last slot (or
    /// it is its first): if the node's stream goes on from a bridge, a bridge went away and
    /// one came back, and the node's slots missing before this one were lost while none
    /// forwarded them (counted as lost on the network).
    #[cold]
    #[inline(never)]
    fn new_origin(&mut self, m: usize, origin: u128, stream_id: u64) {
        let before = self.relay.origin[m].replace(origin);
        self.relay.gone_said = false;
        let bridge = self.relay.is_bridge(self.t, origin);
        self.relay.bridged = bridge;
        if bridge && before.is_some() && self.asm.stream_of(m as u8) == Some(stream_id) {
            self.asm.relay_changed(m as u8);
            self.say(&format!(
                "node {m}'s stream goes on from another bridge: its slots missed meanwhile \
                 count as lost on the network"
            ));
        }
    }

    /// A stall ended with a slot after `silence_ns` without one.
    fn stall_ended(&mut self, silence_ns: u64) {
        self.stalls.record(silence_ns);
        self.say(&format!(
            "publisher resumed after {:.1} ms of silence (stalled, not lost)",
            silence_ns as f64 / 1e6
        ));
    }

    /// The deadline passed at `now`: `Some` when the run ends, `None` when it waits on — for
    /// a stalled publisher, or for a restarted one (`--wait-for-restart`).
    ///
    /// Stalled or lost (docs/pipeline.md): a publisher is lost when no publisher is left on
    /// the slot service once dead nodes are cleaned up (iceoryx2 finds a dead process's node
    /// by its released monitoring lock; a publisher that exited dropped its port), or when
    /// its silence exceeds `--stall-limit`. A publisher whose node is alive is stalled (a
    /// SIGSTOP, a debugger, an overloaded machine): the loop waits on and looks again every
    /// `--deadline-ms`.
    fn missed(&mut self, now: u64) -> Option<Ending> {
        let Some(t_last) = self.deadline.last_data_ns else {
            // The run's only line about why it failed: said also under --quiet.
            estpipe_process::errln!(
                "ipc-runner: no data from channel-sim on prefix {:?} within {} s",
                self.args.prefix,
                self.args.connect_timeout
            );
            return Some(Ending::PublisherLost);
        };
        // The runner itself was late (stopped, not scheduled): the slots are there.
        if self.t.slot_sub.has_samples().unwrap_or(false) {
            return None;
        }
        let cleaned = self.t.node.try_cleanup_dead_nodes().cleanups;
        let publishers = self.t.publishers();
        let silence_ns = now - t_last;
        let over_limit = self.deadline.stall_ns > 0 && silence_ns > self.deadline.stall_ns;
        // A bridge that went away may come back with the stream: waited for as a stall.
        let relay_gone = publishers == 0 && self.relay.bridged;
        if relay_gone && !over_limit {
            if !self.relay.gone_said {
                self.relay.gone_said = true;
                self.say_relay_gone(silence_ns, cleaned);
            }
        } else if publishers > 0 && !over_limit {
            if self.deadline.recheck_ns.is_none() {
                self.say_stalled(silence_ns);
            }
        } else {
            return self.lost(now, silence_ns, publishers, relay_gone, cleaned);
        }
        self.deadline.recheck_ns = Some(now + self.deadline.deadline_ns.max(1_000_000));
        None
    }

    /// No slot for `silence_ns`, and the bridge that forwarded the stream is gone.
    fn say_relay_gone(&self, silence_ns: u64, cleaned: u64) {
        self.say(&format!(
            "publisher gone: no slot for {:.1} ms after instant {}, and the bridge that \
             forwarded the stream is gone (cleaned up {} dead node(s)); waiting for a \
             bridge to come back with it (lost after --stall-limit {} s)",
            silence_ns as f64 / 1e6,
            self.runner.last_k,
            cleaned,
            self.args.stall_limit
        ));
    }

    /// No slot for `silence_ns`, but the publisher's node is alive.
    fn say_stalled(&self, silence_ns: u64) {
        self.say(&format!(
            "publisher stalled: no slot for {:.1} ms after instant {} (deadline {} ms \
             past the expected slot), but its node is alive; waiting (lost after \
             --stall-limit {} s)",
            silence_ns as f64 / 1e6,
            self.runner.last_k,
            self.args.deadline_ms,
            self.args.stall_limit
        ));
    }

    /// The publisher is lost after `silence_ns` without a slot (`publishers` still
    /// registered, `cleaned` dead nodes cleaned up): the end of the run, or with
    /// `--wait-for-restart` a wait for a new one.
    fn lost(
        &mut self,
        now: u64,
        silence_ns: u64,
        publishers: usize,
        relay_gone: bool,
        cleaned: u64,
    ) -> Option<Ending> {
        let args = self.args;
        if self.deadline.recheck_ns.take().is_some() {
            self.stalls.record(silence_ns);
        }
        self.publisher_losses += 1;
        self.flush();
        let why = if publishers > 0 {
            format!(
                "; alive but silent longer than --stall-limit {} s",
                args.stall_limit
            )
        } else if relay_gone {
            format!(
                "; the bridge did not come back within --stall-limit {} s",
                args.stall_limit
            )
        } else {
            String::new()
        };
        let lost = format!(
            "publisher lost: no slot for {:.1} ms after instant {} (deadline {} ms past the \
             expected slot); cleaned up {cleaned} dead node(s), {publishers} publisher(s) \
             remain{why}",
            silence_ns as f64 / 1e6,
            self.runner.last_k,
            args.deadline_ms,
        );
        if !args.wait_for_restart {
            self.say_always(&lost);
            return Some(Ending::PublisherLost);
        }
        // Waited for: not the end of the run, so progress.
        self.say(&lost);
        self.say("waiting for channel-sim to restart (--wait-for-restart)");
        // The lost publisher's stream is over: a restarted one may begin anywhere (its
        // first slot may itself have been lost) and starts a new session.
        self.asm.lose_streams();
        self.deadline.last_data_ns = None;
        self.deadline.waiting_since = now;
        None
    }

    fn finish(mut self, ending: Ending, machine: Machine) -> (RunReport, Trajectories) {
        // A stall still going on when the run ends counts up to now.
        if let (Some(_), Some(t_last)) = (self.deadline.recheck_ns, self.deadline.last_data_ns) {
            self.stalls
                .record(wire::monotonic_ns().saturating_sub(t_last));
        }
        let (runner, counts, allocs) = (self.runner, self.asm.counts, self.allocs);
        let report = RunReport {
            scenario: self.args.scenario.clone(),
            wait: self.args.wait,
            counts,
            estimators: runner.estimator_reports(),
            latency: runner.latency.summary(),
            sessions: runner.session,
            publisher_losses: self.publisher_losses,
            stalls: self.stalls,
            truth_missing: runner.scores.truth_missing,
            truth_nonfinite: runner.scores.truth_nonfinite,
            allocations_after_warmup: match (allocs.at_warmup, allocs.at_end) {
                (Some(a), Some(b)) => Some(b - a),
                _ => None,
            },
            slots_after_warmup: counts.received - allocs.slots_at_warmup,
            published_after_warmup: runner.out.published - allocs.published_at_warmup,
            cpu_pinning: machine.cpu_pinning,
            memory_lock: machine.memory_lock,
            warnings: machine.warnings,
            ending,
            error: None,
            error_code: 0,
        };
        (report, runner.traj)
    }
}

/// The allocation count of [`Hooks::alloc_probe`] at warm-up and at the end.
struct Allocs {
    probe: Option<fn() -> usize>,
    warmup: u64,
    at_warmup: Option<usize>,
    at_end: Option<usize>,
    slots_at_warmup: u64,
    published_at_warmup: u64,
}

impl Allocs {
    fn new(hooks: &Hooks<'_>) -> Self {
        Self {
            probe: hooks.alloc_probe,
            warmup: if hooks.warmup == 0 { 20 } else { hooks.warmup },
            at_warmup: None,
            at_end: None,
            slots_at_warmup: 0,
            published_at_warmup: 0,
        }
    }

    #[inline]
    fn after_slot(&mut self, counts: &Counts, published: u64) {
        if let Some(probe) = self.probe {
            if self.at_warmup.is_none() && counts.instants >= self.warmup {
                self.at_warmup = Some(probe());
                self.slots_at_warmup = counts.received;
                self.published_at_warmup = published;
            }
        }
    }
}
