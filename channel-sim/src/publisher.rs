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

mod checks;
mod ports;
mod stream;

use crate::backpressure::{Backpressure, Gate};
use crate::scenario;
use crate::sensor_node::{Endpoint, NodeLoop};
use crate::sim::Scenario;
use crate::sim::Simulation;
use anyhow::{bail, Result};
use estpipe_wire::{self as wire, Truth};
use ports::Ports;
use std::time::Duration;
use stream::Stream;

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
fn report_unread(gate: &Gate, report: &mut PublisherReport, say: &dyn Fn(&str)) {
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

/// The ports of this process (node 0's publishes the truth), or `None` when a stop signal
/// cut their creation short (iceoryx2's `Interrupt`): the clean stop of a publisher that has
/// sent nothing, as before a subscriber came.
fn open_ports(
    args: &PublisherArgs,
    scenario: &dyn Scenario,
    say: &dyn Fn(&str),
) -> Result<Option<Ports>> {
    match Ports::open(args, scenario, args.node.is_none_or(|n| n == 0)) {
        Ok(ports) => Ok(Some(ports)),
        Err(_) if estpipe_process::signal::termination_requested() => {
            let signal = estpipe_process::signal::termination_signal().unwrap_or("?");
            say(&format!(
                "stopped by signal ({signal}) while opening the services"
            ));
            Ok(None)
        }
        Err(e) => Err(e),
    }
}

/// Runs the publisher on the scenario `--scenario`/`--config` name ([`scenario::resolve`]):
/// checks, ports, the source, the wait for a subscriber, the stream, its end.
pub fn run(args: &PublisherArgs) -> Result<PublisherReport> {
    checks::flags(args)?;
    let scenario = scenario::resolve(&args.scenario, args.config.as_deref())?;
    let endpoints = checks::sensor_endpoints(args, &*scenario)?;
    let nodes = checks::nodes(args, &*scenario)?;
    let steps = args.steps.unwrap_or(DEFAULT_STEPS);
    let say = |m: &str| {
        if !args.quiet {
            estpipe_process::errln!("channel-sim: {m}");
        }
    };
    // Before anything can wait: SIGINT/SIGTERM/SIGHUP set a flag from here on, nothing else stops.
    estpipe_process::signal::install();
    // The process that publishes node 0 publishes the truth.
    let Some(ports) = open_ports(args, &*scenario, &say)? else {
        return Ok(PublisherReport {
            interrupted: true,
            ..PublisherReport::default()
        });
    };
    // Sensor nodes are connected and configured before the wait for a subscriber, so that a
    // node that is not there is said at once.
    let mut source = start_source(args, &*scenario, &endpoints, &ports.gate, &say)?;
    let period_ns = if args.rate > 0.0 {
        (1e9 / args.rate).round() as u64
    } else {
        0
    };
    announce(args, &*scenario, steps, nodes, period_ns, &say);
    let mut report = PublisherReport::default();
    match wait_for_subscriber(
        &ports.node,
        &ports.gate,
        || ports.subscribers(),
        args.connect_timeout,
    ) {
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
                ports.gate.stop_reason().unwrap_or_default()
            ));
            return Ok(report);
        }
    }
    let (sid, nx) = (stream_id(), scenario.nx());
    let x0 = source.sim().initial_truth();
    ports.send_truth(Truth::new(0, sid, nx, &x0))?;
    let hooks = args.test_hooks();
    let mut stream = Stream::new(args, ports, report, hooks, nodes, sid, nx, period_ns, &say);
    stream.instants(&mut source, steps)?;
    let give_up = stream.end()?;
    if let Source::Nodes(nodes) = &mut source {
        nodes.finish();
        for line in nodes.report().lines() {
            estpipe_process::errln!("channel-sim: {line}");
        }
        if let Some(e) = nodes.failure() {
            bail!("sensor node: {e}");
        }
    }
    stream.linger(give_up);
    Ok(stream.report)
}

/// The simulated channel, or the sensor nodes on their serial lines.
fn start_source(
    args: &PublisherArgs,
    scenario: &dyn Scenario,
    endpoints: &[Endpoint],
    gate: &Gate,
    say: &dyn Fn(&str),
) -> Result<Source> {
    if endpoints.is_empty() {
        return Ok(Source::Simulated(scenario.start(args.seed, args.run)));
    }
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
    let nodes = NodeLoop::start(
        scenario,
        args.seed,
        args.run,
        endpoints,
        connect,
        Duration::from_secs_f64(args.node_timeout),
        &|| gate.stop_requested(),
    )
    .map_err(anyhow::Error::msg)?;
    Ok(Source::Nodes(Box::new(nodes)))
}

/// The line that says what is about to be published.
fn announce(
    args: &PublisherArgs,
    scenario: &dyn Scenario,
    steps: u32,
    nodes: u8,
    period_ns: u64,
    say: &dyn Fn(&str),
) {
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
}

pub use estpipe_wire::DEFAULT_STEPS;
