//! The `channel-sim` publisher process: runs one scenario and publishes its slots and truth
//! on iceoryx2 shared memory (see [`crate::wire`] for the services).
//!
//! Life cycle: create the services → wait for a subscriber (the first slots would otherwise
//! be lost before the connection exists) → publish instants k = 1..=steps, each as truth then
//! one slot per node, paced at `--rate` Hz, notifying the `slots-ready` event after each
//! instant → publish every node's END marker → linger until the subscriber has detached
//! (bounded).
//!
//! `--node N` publishes node N's slots only, as one sensor node's own process would (wire
//! version 3: every node is its own stream, `docs/wire.md`, Stream rules). The simulation
//! still runs every node with the same seeds, so node N's slots are bit for bit those of the
//! all-nodes publisher; the process that publishes node 0 also publishes the truth. One
//! process per node, started in any order, feeds the runner exactly what one publisher does.
//!
//! Every slot carries the scenario's [`StreamHeader`](estpipe_wire::StreamHeader) (its shape and model fingerprint) as
//! its user header, so a runner built for another scenario refuses the stream before it steps
//! an estimator. A full subscriber queue blocks the send at `--rate 0` and drops the slot when
//! paced ([`crate::backpressure`]).
//!
//! Faults: dead peers are invisible in iceoryx2 until someone cleans them up, so the publisher
//! calls `try_cleanup_dead_nodes()` at startup (a SIGKILLed predecessor leaves its publisher
//! port behind), every 100 ms and whenever a blocked send gives up after
//! [`crate::backpressure::BLOCK_SLICE`]; if the subscriber is gone it pauses and
//! waits for a new one. SIGINT/SIGTERM/SIGHUP end the run cleanly with an ABORT marker, also while a
//! send is blocked, and so does the end of the `--parent-pid` process (`ipc-runner demo`
//! passes its own: a SIGKILLed demo leaves no publisher behind). No other signal stops it
//! (SIGCONT, SIGSTOP/SIGCONT, SIGUSR1, …): a wait it cuts short is taken up again, so the
//! stream is the same as an undisturbed one. Every wait is cut into slices of at most
//! [`STOP_SLICE`], so a stop is seen within one (docs/security.md, "Signals").

use crate::backpressure::{Backpressure, Gate, Mode};
use crate::scenario;
use crate::sensor_node::{Endpoint, NodeLoop};
use crate::sim::{Simulation, MAX_NY};
use crate::wire::{slot_of, stream_header};
use anyhow::{bail, Context, Result};
use estpipe_wire::{self as wire, Slot, Truth, SLOT_ABORT, SLOT_END};
use iceoryx2::prelude::*;
use std::sync::Arc;
use std::time::Duration;

pub use crate::slot_sender::{wait, wait_for_subscriber, Sent, SlotSender, Stop, STOP_SLICE};

/// Command-line options of the publisher (`channel-sim …` or `ipc-runner channel-sim …`).
#[derive(Clone, Debug, clap::Args)]
pub struct PublisherArgs {
    /// Scenario preset name.
    #[arg(long, default_value = "occlusion", conflicts_with = "config")]
    pub scenario: String,
    /// Scenario TOML file (instead of a preset).
    #[arg(long)]
    pub config: Option<std::path::PathBuf>,
    /// Experiment seed (same meaning and default as `ipc-runner eval --seed`).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Run index within the seed (runs are independent streams).
    #[arg(long, default_value_t = 0)]
    pub run: u64,
    /// Number of sampling instants to publish (default: 100, as `ipc-runner eval --steps`).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
    pub steps: Option<u32>,
    /// Sampling rate in Hz; 0 publishes as fast as possible.
    #[arg(long, default_value_t = wire::DEFAULT_RATE_HZ, value_parser = estpipe_process::flags::rate_hz)]
    pub rate: f64,
    /// What a full subscriber queue does: `block` waits (nothing is lost), `discard` drops the
    /// slot (the runner counts the gap); `auto` blocks at `--rate 0` and discards when paced.
    #[arg(long, value_enum, default_value_t = Backpressure::Auto)]
    pub backpressure: Backpressure,
    /// Publish only this sensor node's slots (0-based; default: every node). The process that
    /// publishes node 0 also publishes the truth.
    #[arg(long)]
    pub node: Option<u8>,
    /// Sensor nodes on serial lines as the channel (docs/sensor-node.md): node m's line,
    /// `unix:PATH` or `tcp:HOST:PORT`, once per node in node order. The plant runs here with
    /// the seed's random numbers, each node decides from its raw samples, the slots carry the
    /// nodes' decisions, and every decision is compared with the simulated channel's.
    #[arg(long = "sensor-node", value_name = "LINE", conflicts_with = "node")]
    pub sensor_node: Vec<String>,
    /// Seconds to wait for a sensor node's answer before sending its sample again.
    #[arg(long, default_value_t = 2.0, value_parser = estpipe_process::flags::seconds)]
    pub node_timeout: f64,
    /// Service-name prefix (use distinct prefixes for parallel runs).
    #[arg(long, default_value = wire::DEFAULT_PREFIX)]
    pub prefix: String,
    /// Seconds to wait for a subscriber (at start and after losing one); 0 = forever.
    #[arg(long, default_value_t = 30.0, value_parser = estpipe_process::flags::seconds)]
    pub connect_timeout: f64,
    /// Seconds to wait after the last instant for the subscriber to take the END markers,
    /// drain and detach (one deadline for all of it).
    #[arg(long, default_value_t = 5.0, value_parser = estpipe_process::flags::seconds)]
    pub linger: f64,
    /// Seconds a subscriber's full queue may hold a blocking send before it counts as a
    /// subscriber that does not read: from then on a slot that finds its queue full is
    /// dropped for it (counted, one line) instead of holding the run (0 = never).
    #[arg(long, value_name = "SECONDS",
          default_value_t = crate::backpressure::DEFAULT_UNREAD_LIMIT_S,
          value_parser = estpipe_process::flags::seconds)]
    pub unread_limit: f64,
    /// Test hook: write this format version into every slot.
    #[cfg(feature = "test-hooks")]
    #[arg(long, hide = true)]
    pub debug_wire_version: Option<u32>,
    /// Test hook: replace the first measurement entry of every N-th delivered slot by NaN.
    #[cfg(feature = "test-hooks")]
    #[arg(long, hide = true)]
    pub debug_nan_every: Option<u64>,
    /// Test hook: publish the truth of instant K with its first component NaN (what a
    /// foreign publisher's bug would send; the runner must count it, not average it).
    #[cfg(feature = "test-hooks")]
    #[arg(long, hide = true, value_name = "K")]
    pub debug_nan_truth_at: Option<u32>,
    /// Stop (as on SIGTERM: ABORT marker, exit 0) as soon as the process PID is no longer
    /// this publisher's parent, e.g. because it died. `ipc-runner demo` passes its own pid.
    #[arg(long, value_name = "PID")]
    pub parent_pid: Option<u32>,
    /// Suppress progress messages on stderr.
    #[arg(long)]
    pub quiet: bool,
}

/// The test hooks a command line gave (feature `test-hooks`: a shipped build parses none,
/// and this is all `None`).
#[derive(Clone, Copy, Debug, Default)]
struct TestHooks {
    wire_version: Option<u32>,
    nan_every: Option<u64>,
    nan_truth_at: Option<u32>,
}

impl PublisherArgs {
    #[cfg(feature = "test-hooks")]
    fn test_hooks(&self) -> TestHooks {
        TestHooks {
            wire_version: self.debug_wire_version,
            nan_every: self.debug_nan_every,
            nan_truth_at: self.debug_nan_truth_at,
        }
    }

    #[cfg(not(feature = "test-hooks"))]
    fn test_hooks(&self) -> TestHooks {
        TestHooks::default()
    }
}

/// What a publisher run did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PublisherReport {
    /// Data slots published.
    pub slots: u64,
    /// Instants published.
    pub instants: u32,
    /// Stopped by SIGINT/SIGTERM/SIGHUP before the last instant.
    pub interrupted: bool,
    /// Times the subscriber was lost and a new one awaited.
    pub subscriber_losses: u32,
    /// Slots a subscriber did not receive because its queue was full (`--backpressure
    /// discard`), one per slot and subscriber.
    pub discarded: u64,
    /// Sends that blocked for a whole slice and were sent again (`--backpressure block`).
    pub resent: u64,
    /// Slots dropped for a subscriber that does not read (`--unread-limit`), one per slot
    /// and such subscriber.
    pub unread_dropped: u64,
    /// Subscribers found not reading.
    pub unread_subscribers: u32,
}

fn stream_id() -> u64 {
    (u64::from(std::process::id()) << 32) ^ wire::monotonic_ns()
}

/// Says once per subscriber that it does not read (`--unread-limit`), and counts it.
fn report_unread(gate: &Gate, report: &mut PublisherReport, say: &impl Fn(&str)) {
    let new = gate.take_newly_unread();
    if new > 0 {
        report.unread_subscribers += new;
        say(&format!(
            "{new} subscriber(s) of the slots did not read for --unread-limit; slots are \
             dropped for them while their queue is full instead of holding the stream \
             ({} so far)",
            gate.unread_drops()
        ));
    }
}

/// Where the instants come from: the simulated channel, or sensor nodes on serial lines.
enum Source {
    Simulated(Box<dyn Simulation>),
    Nodes(Box<NodeLoop>),
}

impl Source {
    fn sim(&mut self) -> &mut dyn Simulation {
        match self {
            Self::Simulated(s) => s.as_mut(),
            Self::Nodes(n) => n.as_mut(),
        }
    }

    fn failure(&self) -> Option<&str> {
        match self {
            Self::Simulated(_) => None,
            Self::Nodes(n) => n.failure(),
        }
    }
}

/// Runs the publisher on the scenario `--scenario`/`--config` name ([`scenario::resolve`]).
pub fn run(args: &PublisherArgs) -> Result<PublisherReport> {
    // The flags' parsers check these on the command line; a caller building the arguments
    // in code gets the same refusal (issue #20: `Duration::from_secs_f64(inf)` panics).
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
            return Err(estpipe_process::flags::BadInput(format!("{flag}: {e}")).into());
        }
    }
    let scenario = scenario::resolve(&args.scenario, args.config.as_deref())?;
    let endpoints = args
        .sensor_node
        .iter()
        .map(|s| Endpoint::parse(s))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| estpipe_process::flags::BadInput(format!("--sensor-node {e}")))?;
    if !endpoints.is_empty() {
        if args.node_timeout <= 0.0 {
            return Err(estpipe_process::flags::BadInput(
                "--node-timeout: must be positive".to_string(),
            )
            .into());
        }
        crate::sensor_node::config::loop_config(&*scenario)
            .map_err(|e| estpipe_process::flags::BadInput(format!("--sensor-node: {e}")))?;
        if endpoints.len() != scenario.nodes() {
            return Err(estpipe_process::flags::BadInput(format!(
                "--sensor-node: scenario {} has {} node(s), {} --sensor-node line(s) given",
                scenario.name(),
                scenario.nodes(),
                endpoints.len()
            ))
            .into());
        }
    }
    let steps = args.steps.unwrap_or(DEFAULT_STEPS);
    let nodes = u8::try_from(scenario.nodes()).context("too many nodes")?;
    if let Some(n) = args.node {
        if n >= nodes {
            return Err(wire::ContractError::Refused(format!(
                "--node {n}: scenario {} has {nodes} node(s), 0..={}",
                scenario.name(),
                nodes - 1
            ))
            .into());
        }
    }
    // The nodes this process publishes, and whether it publishes the truth (node 0's).
    let mine = |m: u8| args.node.is_none_or(|n| n == m);
    let with_truth = mine(0);
    let nx = scenario.nx();
    let say = |m: &str| {
        if !args.quiet {
            estpipe_process::errln!("channel-sim: {m}");
        }
    };

    // Before anything can wait: SIGINT/SIGTERM/SIGHUP set a flag from here on, nothing else stops.
    estpipe_process::signal::install();
    let node = Arc::new(estpipe_process::node::create("channel-sim")?);
    // A SIGKILLed predecessor leaves its ports registered; remove them before we claim ours.
    let _ = node.try_cleanup_dead_nodes();

    let header = stream_header(&*scenario);
    let slots = Arc::new(wire::slot_service(&node, &args.prefix)?);
    let truth = wire::truth_service(&node, &args.prefix)?;
    let ready = wire::ready_event_service(&node, &args.prefix)?;
    let gate = Gate::new();
    gate.set_unread_limit(args.unread_limit);
    if let Some(pid) = args.parent_pid {
        gate.set_parent(pid);
    }
    let data_mode = if args.backpressure.blocks(args.rate) {
        Mode::Block
    } else {
        Mode::Discard
    };
    gate.set_mode(data_mode);
    // What a failed creation left in /dev/shm is removed (estpipe_process::shm_leftovers).
    let since = std::time::SystemTime::now() - Duration::from_secs(1);
    let publisher = slots
        .publisher_builder()
        .backpressure_strategy(BackpressureStrategy::RetryUntilDelivered)
        .set_backpressure_handler(gate.handler())
        .create()
        .map_err(|e| {
            anyhow::anyhow!(estpipe_process::shm_leftovers::publisher_error(
                e,
                node.config(),
                since,
                &format!("{}/slots", args.prefix),
                &format!(
                    "are {} publishers already running with this --prefix?",
                    wire::MAX_NODES
                ),
            ))
        })?;
    let truth_pub = if with_truth {
        Some(truth.publisher_builder().create().map_err(|e| {
            anyhow::anyhow!(estpipe_process::shm_leftovers::publisher_error(
                e,
                node.config(),
                since,
                &format!("{}/truth", args.prefix),
                "is another publisher of node 0 running with this --prefix?",
            ))
        })?)
    } else {
        None
    };
    let send_truth = |t: Truth| -> Result<()> {
        if let Some(p) = &truth_pub {
            p.loan_uninit()?.write_payload(t).send()?;
        }
        Ok(())
    };
    let notifier = ready
        .notifier_builder()
        .default_event_id(wire::READY_EVENT)
        .create()
        .map_err(|e| anyhow::anyhow!("cannot notify on {}/slots-ready: {e:?}", args.prefix))?;

    let sid = stream_id();
    let period_ns = if args.rate > 0.0 {
        (1e9 / args.rate).round() as u64
    } else {
        0
    };
    let hooks = args.test_hooks();
    let wire_version = hooks.wire_version.unwrap_or(wire::WIRE_VERSION);
    let mut report = PublisherReport::default();
    let n_subs = || slots.dynamic_config().number_of_subscribers();
    let mut sender = SlotSender::new(
        publisher,
        header,
        Arc::clone(&gate),
        Arc::clone(&node),
        Arc::clone(&slots),
    );

    // Sensor nodes are connected and configured before the wait for a subscriber, so that a
    // node that is not there is said at once.
    let mut source = if endpoints.is_empty() {
        Source::Simulated(scenario.start(args.seed, args.run))
    } else {
        // connect-timeout 0 means "wait for ever" for the subscriber; for a node's line, a day.
        let connect = Duration::from_secs_f64(if args.connect_timeout > 0.0 {
            args.connect_timeout
        } else {
            86_400.0
        });
        say(&format!(
            "{} sensor node(s) on {}",
            endpoints.len(),
            args.sensor_node.join(", ")
        ));
        Source::Nodes(Box::new(
            NodeLoop::start(
                &*scenario,
                args.seed,
                args.run,
                &endpoints,
                connect,
                Duration::from_secs_f64(args.node_timeout),
                &|| gate.stop_requested(),
            )
            .map_err(anyhow::Error::msg)?,
        ))
    };
    say(&format!(
        "scenario {} (seed {}, run {}), {steps} instants × {} at {} on prefix {:?}; \
         waiting for a subscriber",
        scenario.name(),
        args.seed,
        args.run,
        match args.node {
            Some(n) => format!("node {n} of {nodes}"),
            None => format!("{nodes} nodes"),
        },
        if period_ns == 0 {
            "full speed".to_string()
        } else {
            format!("{} Hz", args.rate)
        },
        args.prefix
    ));
    match wait_for_subscriber(&node, &gate, n_subs, args.connect_timeout) {
        Ok(true) => {}
        Ok(false) => bail!(
            "no subscriber on {}/slots within {} s (start `ipc-runner run --prefix {}`)",
            args.prefix,
            args.connect_timeout,
            args.prefix
        ),
        Err(Stop::Signal) => {
            report.interrupted = true;
            say(&format!(
                "{} before a subscriber came",
                gate.stop_reason().unwrap_or_default()
            ));
            return Ok(report);
        }
    }

    let x0 = source.sim().initial_truth();
    send_truth(Truth::new(0, sid, nx, &x0))?;

    let t0 = wire::monotonic_ns();
    let stream_start_ns = t0;
    let mut last_check = t0;
    let mut delivered_count = 0u64;
    // Per node, the last instant whose slot was handed to the publisher: its END/ABORT
    // marker's k and seq (docs/wire.md, Stream rules).
    let mut sent_k = [0u32; wire::MAX_NODES];
    'instants: for i in 1..=steps {
        if period_ns > 0 {
            let due = t0 + u64::from(i - 1) * period_ns;
            let now = wire::monotonic_ns();
            // Behind schedule (after a stop and continue) the instants due go at once.
            if wait(&node, &gate, Duration::from_nanos(due.saturating_sub(now))).is_err() {
                report.interrupted = true;
                break;
            }
        } else if i.is_multiple_of(256) && gate.stop_requested() {
            report.interrupted = true;
            break;
        }
        let inst = source.sim().next_instant();
        if source.failure().is_some() {
            report.interrupted = true;
            break;
        }
        let mut x = inst.truth;
        if hooks.nan_truth_at == Some(inst.k) {
            x[0] = f64::NAN;
        }
        send_truth(Truth::new(inst.k, sid, nx, &x))?;
        let mut subscriber_gone = false;
        for obs in inst.obs.iter().filter(|o| mine(o.node)) {
            let mut slot = slot_of(
                obs,
                nodes,
                sid,
                wire::monotonic_ns(),
                period_ns,
                stream_start_ns,
            );
            slot.version = wire_version;
            if obs.delivered {
                delivered_count += 1;
                if let Some(n) = hooks.nan_every {
                    if n > 0 && delivered_count.is_multiple_of(n) && usize::from(obs.ny) <= MAX_NY {
                        slot.y[0] = f64::NAN;
                    }
                }
            }
            match sender.send(slot, None)? {
                Sent::Done => report.slots += 1,
                // The slot's seq is used: a later subscriber sees the gap.
                Sent::GaveUp => {
                    report.slots += 1;
                    subscriber_gone = true;
                }
                // Not sent: the ABORT marker's count ends before it.
                Sent::Stopped => {
                    report.interrupted = true;
                    break 'instants;
                }
            }
            sent_k[usize::from(obs.node)] = obs.k;
        }
        notifier.notify()?;
        report.instants = i;
        report_unread(&gate, &mut report, &say);
        // A dead subscriber stays registered (and keeps its queue) until someone cleans up.
        // After the send: the scan of the node directory (sub-millisecond) runs in the slack
        // before the next instant is due rather than between its due time and its send.
        let now = wire::monotonic_ns();
        if subscriber_gone || now - last_check > 100_000_000 {
            last_check = now;
            let _ = node.try_cleanup_dead_nodes();
            if n_subs() == 0 {
                report.subscriber_losses += 1;
                say(&format!(
                    "subscriber lost after instant {i}; waiting for a new one"
                ));
                match wait_for_subscriber(&node, &gate, n_subs, args.connect_timeout) {
                    Ok(true) => say("subscriber back, continuing"),
                    Ok(false) => bail!("no subscriber came back within {} s", args.connect_timeout),
                    Err(Stop::Signal) => {
                        report.interrupted = true;
                        break 'instants;
                    }
                }
            }
        }
    }

    let kind = if report.interrupted {
        SLOT_ABORT
    } else {
        SLOT_END
    };
    // The marker waits for room whatever the mode (bounded by --linger): a discarded END
    // would leave the runner waiting for its deadline.
    gate.set_mode(Mode::Final);
    // One deadline for the markers and the linger after them (a subscriber that never
    // leaves kept the publisher for both, one after the other).
    let give_up = std::time::Instant::now() + Duration::from_secs_f64(args.linger.max(0.0));
    for m in (0..nodes).filter(|&m| mine(m)) {
        let marker = Slot {
            period_ns,
            stream_start_ns,
            ..Slot::marker(kind, sent_k[usize::from(m)], m, nodes, sid, 0)
        };
        sender.send(marker, Some(give_up))?;
    }
    notifier.notify()?;
    report_unread(&gate, &mut report, &say);
    report.unread_dropped = gate.unread_drops();
    report.discarded = sender.discarded();
    report.resent = sender.resent();
    if report.discarded > 0 {
        say(&format!(
            "{} slot(s) dropped for a subscriber whose queue was full (--backpressure discard)",
            report.discarded
        ));
    }
    say(&format!(
        "{} after {} instants ({} slots)",
        match gate.stop_reason() {
            Some(why) if report.interrupted => why,
            _ if report.interrupted => "stopped by signal".to_string(),
            _ => "done".to_string(),
        },
        report.instants,
        report.slots
    ));

    if let Source::Nodes(nodes) = &mut source {
        nodes.finish();
        for line in nodes.report().lines() {
            estpipe_process::errln!("channel-sim: {line}");
        }
        if let Some(e) = nodes.failure() {
            bail!("sensor node: {e}");
        }
    }

    // Keep the data segment alive until the subscriber has read the tail and detached (a
    // subscriber that does not read is not waited for).
    let mut last_cleanup = std::time::Instant::now();
    while n_subs() > gate.unread_receivers() && std::time::Instant::now() < give_up {
        if last_cleanup.elapsed() > Duration::from_millis(100) {
            let _ = node.try_cleanup_dead_nodes();
            last_cleanup = std::time::Instant::now();
        }
        if wait(&node, &gate, Duration::from_millis(2)).is_err() {
            break;
        }
    }
    Ok(report)
}

pub use estpipe_wire::DEFAULT_STEPS;
