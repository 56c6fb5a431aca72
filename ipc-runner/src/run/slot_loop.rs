//! The loop over slots: drain the slot queue (every received slot goes through the
//! [`Assembler`]; each instant it completes is handed to [`Runner::on_instant`]), follow a
//! restarted publisher, and when nothing is pending check the data deadline and wait
//! ([`super::wait`]).

use crate::latency::Latency;
use crate::transport::Transport;
use crate::Estimator;
use anyhow::{bail, Result};
use channel_sim::Observation;
use estpipe_wire::{self as wire, SlotFault, StreamHeader};
use iceoryx2::port::update_connections::UpdateConnections;
use std::time::Duration;

use super::args::{RunArgs, WaitMode};
use super::assemble::{self, Assembler, Counts, Limits, Pushed, Reason};
use super::instant::Runner;
use super::report::{Ending, RunReport};
use super::system;
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

/// Runs the loop with estimators from `make` (called again for every new stream) until the
/// stream ends. Errors are configuration/transport failures; a lost publisher is reported in
/// [`RunReport::ending`]. Every node's ny comes from the scenario's stream header (`_ny` is
/// not used: nodes may differ).
pub fn run_loop(
    args: &RunArgs,
    nx: usize,
    nodes: u8,
    _ny: u8,
    make: &dyn Fn() -> Result<Vec<Box<dyn Estimator>>>,
    mut hooks: Hooks<'_>,
) -> Result<(RunReport, Trajectories)> {
    // The shape a stream must announce to feed these estimators (docs/wire.md, Stream header).
    let scenario = channel_sim::scenario::resolve(&args.scenario, args.config.as_deref())?;
    let expected = channel_sim::wire::stream_header(&*scenario);
    let machine = Machine::set_up(args);
    let t = Transport::open(&args.prefix, args.buffer, args.wait != WaitMode::Spin)?;
    let runner = Runner::new(&t, args, make()?, nx, nodes)?;
    if !(args.instant_deadline_ms >= 0.0 && args.instant_deadline_ms.is_finite()) {
        return Err(wire::ContractError::Refused(format!(
            "--instant-deadline-ms must be a number ≥ 0 (0 = for ever), got {}",
            args.instant_deadline_ms
        ))
        .into());
    }
    let limits = Limits {
        max_gap: args.max_gap,
        instant_deadline_ns: (args.instant_deadline_ms * 1e6) as u64,
    };
    let mut asm = Assembler::new(&expected, limits);
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
        last_progress: 0,
        expected,
        last_update_ns: 0,
    };

    // iceoryx2 installs its SIGINT/SIGTERM handler on the first `Node::wait`; do that before
    // announcing the wait, so Ctrl-C ends the run cleanly in every wait mode from here on
    // (the listener's wait would otherwise leave the signal to its default action, which
    // kills the process without a report). Before this call a signal ends the process, so
    // there is no earlier signal to carry over.
    let _ = t.node.wait(Duration::ZERO);
    lp.say(&format!(
        "waiting for channel-sim on prefix {:?} ({} wait)",
        args.prefix,
        args.wait.as_str()
    ));
    let waitset = wait::waitset(args.wait, &t)?;
    let mut waiter = Waiter::new(&t, waitset.as_ref())?;

    let ending = loop {
        if let Some(ending) = lp.drain(&mut hooks)? {
            break ending;
        }
        // Nothing pending: check the deadline, then wait.
        let Some(now) = waiter.now() else {
            break Ending::Interrupted;
        };
        lp.update_connections(now);
        lp.expire(now);
        let due = lp.deadline.due();
        if now > due {
            match lp.missed(now) {
                Some(ending) => break ending,
                None => continue,
            }
        }
        let due = lp.asm.next_expiry().map_or(due, |t| t.min(due));
        match waiter.wait(due.saturating_sub(now).min(MAX_WAIT_NS))? {
            Woke::Ready => {}
            Woke::Signal => break Ending::Interrupted,
        }
    };
    if ending == Ending::Interrupted {
        lp.flush();
    }
    let (mut report, traj) = lp.finish(ending, machine);
    // The scenario's own name: a `--config` file's, not the `--scenario` default.
    report.scenario = scenario.name().to_string();
    Ok((report, traj))
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
    last_progress: u64,
    /// The header of the scenario the estimators were built for.
    expected: StreamHeader,
    /// When the estimate publisher last looked for new subscribers.
    last_update_ns: u64,
}

impl Loop<'_> {
    fn say(&self, m: &str) {
        if !self.args.quiet {
            eprintln!("ipc-runner: {m}");
        }
    }

    /// Handles every slot that is there; `Some` when the stream ended.
    #[inline]
    fn drain(&mut self, hooks: &mut Hooks<'_>) -> Result<Option<Ending>> {
        loop {
            let sample = match self.t.slot_sub.receive() {
                Ok(Some(s)) => s,
                Ok(None) => return Ok(None),
                Err(e) => bail!("receive failed: {e:?}"),
            };
            let recv_ns = wire::monotonic_ns();
            let slot = sample.payload();
            let header = sample.user_header();
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
            self.deadline.last_data_ns = Some(recv_ns);
            self.runner.slot.send_ns = assemble::usable_send_ns(slot, recv_ns).unwrap_or(0);
            self.runner.slot.recv_ns = recv_ns;
            // Estimates and truth belong to node 0's stream (its process publishes the truth).
            self.runner.slot.stream_id = self.asm.stream_of(0).unwrap_or(slot.stream_id);
            let (t, runner) = (self.t, &mut self.runner);
            let mut pushed = self
                .asm
                .push(slot, header, recv_ns, &mut |k, obs: &[Observation]| {
                    runner.on_instant(t, k, obs);
                });
            if pushed == Pushed::NewStream {
                self.new_stream()?;
                self.runner.slot.stream_id = self.asm.stream_of(0).unwrap_or(slot.stream_id);
                let runner = &mut self.runner;
                pushed = self
                    .asm
                    .push(slot, header, recv_ns, &mut |k, obs: &[Observation]| {
                        runner.on_instant(t, k, obs);
                    });
            }
            if let Some(r) = self.asm.take_first_seen() {
                self.warn(r, slot);
            }
            if pushed == Pushed::Data {
                // A period beyond the bound is not used for the data deadline.
                if slot.period_ns <= assemble::MAX_PERIOD_NS {
                    self.deadline.period_ns = slot.period_ns;
                }
                // After the instant this slot may have completed was published.
                if self.runner.slot.send_ns != 0 {
                    Latency::record(&mut self.runner.latency.transport, slot.send_ns, recv_ns);
                }
            }
            drop(sample);
            if let Some(e) = self.runner.out.take_error() {
                return Err(e);
            }
            if let Some(us) = self.args.debug_slow_us {
                std::thread::sleep(Duration::from_micros(us));
            }
            self.allocs
                .after_slot(&self.asm.counts, self.runner.out.published);
            match pushed {
                Pushed::End | Pushed::Abort => {
                    self.allocs.at_end = self.allocs.probe.map(|p| p());
                    return Ok(Some(if pushed == Pushed::End {
                        Ending::Completed
                    } else {
                        Ending::PublisherStopped
                    }));
                }
                _ => {}
            }
            if let Some(p) = hooks.progress.as_mut() {
                if recv_ns - self.last_progress > PROGRESS_EVERY_NS {
                    self.last_progress = recv_ns;
                    p(self.runner.last_k, &self.asm.counts);
                }
            }
        }
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
        let (t, runner) = (self.t, &mut self.runner);
        self.asm.flush(&mut |k, obs: &[Observation]| {
            runner.on_instant(t, k, obs);
        });
    }

    /// Hands on the pending instants whose deadline passed (paced mode).
    #[inline]
    fn expire(&mut self, now: u64) {
        let (t, runner) = (self.t, &mut self.runner);
        self.asm.expire(now, &mut |k, obs: &[Observation]| {
            runner.on_instant(t, k, obs);
        });
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
        self.runner.estimators = (self.make)()?;
        self.say(&format!(
            "new stream from channel-sim (restarted; was {old:x?}): session {} with fresh estimators",
            self.runner.session
        ));
        Ok(())
    }

    /// The deadline passed at `now`: `Some` when the run ends, `None` when it waits for a
    /// restarted publisher (`--wait-for-restart`).
    fn missed(&mut self, now: u64) -> Option<Ending> {
        let args = self.args;
        let Some(t_last) = self.deadline.last_data_ns else {
            self.say(&format!(
                "no data from channel-sim on prefix {:?} within {} s",
                args.prefix, args.connect_timeout
            ));
            return Some(Ending::PublisherLost);
        };
        self.publisher_losses += 1;
        self.flush();
        let cleaned = self.t.node.try_cleanup_dead_nodes();
        self.say(&format!(
            "publisher lost: no slot for {:.1} ms after instant {} (deadline {} ms past the \
             expected slot); cleaned up {} dead node(s), {} publisher(s) remain",
            (now - t_last) as f64 / 1e6,
            self.runner.last_k,
            args.deadline_ms,
            cleaned.cleanups,
            self.t.publishers()
        ));
        if !args.wait_for_restart {
            return Some(Ending::PublisherLost);
        }
        self.say("waiting for channel-sim to restart (--wait-for-restart)");
        // The lost publisher's stream is over: a restarted one may begin anywhere (its
        // first slot may itself have been lost) and starts a new session.
        self.asm.lose_streams();
        self.deadline.last_data_ns = None;
        self.deadline.waiting_since = now;
        None
    }

    fn finish(self, ending: Ending, machine: Machine) -> (RunReport, Trajectories) {
        let (runner, counts, allocs) = (self.runner, self.asm.counts, self.allocs);
        let report = RunReport {
            scenario: self.args.scenario.clone(),
            wait: self.args.wait,
            counts,
            estimators: runner.estimator_reports(),
            latency: runner.latency.summary(),
            sessions: runner.session,
            publisher_losses: self.publisher_losses,
            truth_missing: runner.scores.truth_missing,
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
        };
        (report, runner.traj)
    }
}

/// When the next slot is due.
struct Deadline {
    deadline_ns: u64,
    connect_ns: u64,
    period_ns: u64,
    /// `None` while waiting for the first slot of a stream (the connect timeout applies).
    last_data_ns: Option<u64>,
    waiting_since: u64,
}

impl Deadline {
    fn new(args: &RunArgs) -> Self {
        Self {
            deadline_ns: (args.deadline_ms * 1e6) as u64,
            connect_ns: (args.connect_timeout * 1e9) as u64,
            period_ns: 0,
            last_data_ns: None,
            waiting_since: wire::monotonic_ns(),
        }
    }

    fn due(&self) -> u64 {
        match self.last_data_ns {
            Some(t_last) => t_last + self.period_ns + self.deadline_ns,
            None if self.connect_ns == 0 => u64::MAX,
            None => self.waiting_since + self.connect_ns,
        }
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

/// What `--cpu` and `--mlock` achieved, and set-up conditions that will show in the latency.
struct Machine {
    cpu_pinning: Option<String>,
    memory_lock: Option<String>,
    warnings: Vec<String>,
}

impl Machine {
    fn set_up(args: &RunArgs) -> Self {
        let cpu_pinning = args.cpu.map(|c| match system::pin_to_cpu(c) {
            Ok(()) => format!("pinned to CPU {c}"),
            Err(e) => format!("not pinned ({e})"),
        });
        let memory_lock = args.mlock.then(|| match system::lock_memory() {
            Ok(()) => "locked".to_string(),
            Err(e) => format!("not locked ({e})"),
        });
        if !args.quiet {
            for m in cpu_pinning.iter().chain(memory_lock.iter()) {
                eprintln!("ipc-runner: {m}");
            }
        }
        // After pinning: a warning, not a refusal (a machine with throttling off passes).
        let warnings: Vec<String> = (args.wait == WaitMode::Spin)
            .then(system::spin_under_rt_throttling)
            .flatten()
            .into_iter()
            .collect();
        for w in &warnings {
            eprintln!("ipc-runner: {w}");
        }
        Self {
            cpu_pinning,
            memory_lock,
            warnings,
        }
    }
}
