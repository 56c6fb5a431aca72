//! The `channel-sim` publisher process: runs one scenario and publishes its slots and truth
//! on iceoryx2 shared memory (see [`crate::wire`] for the services).
//!
//! Life cycle: create the services → wait for a subscriber (the first slots would otherwise
//! be lost before the connection exists) → publish instants k = 1..=steps, each as truth then
//! one slot per node, paced at `--rate` Hz, notifying the `slots-ready` event after each
//! instant → publish an END marker → linger until the subscriber has detached (bounded).
//!
//! Faults: dead peers are invisible in iceoryx2 until someone cleans them up, so the publisher
//! calls `try_cleanup_dead_nodes()` at startup (a SIGKILLed predecessor leaves its publisher
//! port behind) and every 100 ms; if the subscriber is gone it pauses and waits for a new one.
//! SIGINT/SIGTERM end the run cleanly with an ABORT marker.

use crate::scenario;
use crate::sim::MAX_NY;
use crate::wire::{self, Slot, Truth, SLOT_ABORT, SLOT_END};
use anyhow::{bail, Context, Result};
use iceoryx2::node::NodeWaitFailure;
use iceoryx2::prelude::*;
use std::time::Duration;

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
    /// Number of sampling instants to publish (default: 100, as `ipc-runner eval --horizon`).
    #[arg(long)]
    pub steps: Option<u32>,
    /// Sampling rate in Hz; 0 publishes as fast as possible.
    #[arg(long, default_value_t = 1000.0)]
    pub rate: f64,
    /// Service-name prefix (use distinct prefixes for parallel runs).
    #[arg(long, default_value = wire::DEFAULT_PREFIX)]
    pub prefix: String,
    /// Seconds to wait for a subscriber (at start and after losing one); 0 = forever.
    #[arg(long, default_value_t = 30.0)]
    pub connect_timeout: f64,
    /// Seconds to wait after the END marker for the subscriber to drain and detach.
    #[arg(long, default_value_t = 5.0)]
    pub linger: f64,
    /// Test hook: write this format version into every slot.
    #[arg(long, hide = true)]
    pub debug_wire_version: Option<u32>,
    /// Test hook: replace the first measurement entry of every N-th delivered slot by NaN.
    #[arg(long, hide = true)]
    pub debug_nan_every: Option<u64>,
    /// Suppress progress messages on stderr.
    #[arg(long)]
    pub quiet: bool,
}

/// What a publisher run did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PublisherReport {
    /// Data slots published.
    pub slots: u64,
    /// Instants published.
    pub instants: u32,
    /// Stopped by SIGINT/SIGTERM before the last instant.
    pub interrupted: bool,
    /// Times the subscriber was lost and a new one awaited.
    pub subscriber_losses: u32,
}

fn stream_id() -> u64 {
    (u64::from(std::process::id()) << 32) ^ wire::monotonic_ns()
}

enum Stop {
    Signal,
}

fn wait(node: &Node<ipc::Service>, d: Duration) -> Result<(), Stop> {
    match node.wait(d) {
        Ok(()) => Ok(()),
        Err(NodeWaitFailure::Interrupt | NodeWaitFailure::TerminationRequest) => Err(Stop::Signal),
    }
}

/// Waits until `count()` > 0, cleaning up dead nodes on the way. `Ok(false)` on timeout.
fn wait_for_subscriber(
    node: &Node<ipc::Service>,
    count: impl Fn() -> usize,
    timeout: f64,
) -> Result<bool, Stop> {
    let start = std::time::Instant::now();
    let mut last_cleanup = std::time::Instant::now();
    while count() == 0 {
        if timeout > 0.0 && start.elapsed().as_secs_f64() > timeout {
            return Ok(false);
        }
        if last_cleanup.elapsed() > Duration::from_millis(100) {
            let _ = node.try_cleanup_dead_nodes();
            last_cleanup = std::time::Instant::now();
        }
        wait(node, Duration::from_millis(2))?;
    }
    Ok(true)
}

/// Runs the publisher on the scenario `--scenario`/`--config` name ([`scenario::resolve`]).
pub fn run(args: &PublisherArgs) -> Result<PublisherReport> {
    if !(args.rate >= 0.0 && args.rate.is_finite()) {
        bail!(
            "--rate must be ≥ 0 (0 = as fast as possible), got {}",
            args.rate
        );
    }
    let scenario = scenario::resolve(&args.scenario, args.config.as_deref())?;
    let steps = args.steps.unwrap_or(DEFAULT_STEPS);
    let nodes = u8::try_from(scenario.nodes()).context("too many nodes")?;
    let nx = scenario.nx();
    let say = |m: &str| {
        if !args.quiet {
            eprintln!("channel-sim: {m}");
        }
    };

    let node = NodeBuilder::new()
        .name(&NodeName::new("channel-sim").map_err(|e| anyhow::anyhow!("{e:?}"))?)
        .create::<ipc::Service>()
        .map_err(|e| anyhow::anyhow!("cannot create iceoryx2 node: {e:?}"))?;
    // A SIGKILLed predecessor leaves its ports registered; remove them before we claim ours.
    let _ = node.try_cleanup_dead_nodes();

    let slots = wire::slot_service(&node, &args.prefix)?;
    let truth = wire::truth_service(&node, &args.prefix)?;
    let ready = wire::ready_event_service(&node, &args.prefix)?;
    let slot_pub = slots.publisher_builder().create().map_err(|e| {
        anyhow::anyhow!(
            "cannot publish on {}/slots ({e:?}): is another channel-sim running with this \
             --prefix?",
            args.prefix
        )
    })?;
    let truth_pub = truth
        .publisher_builder()
        .create()
        .map_err(|e| anyhow::anyhow!("cannot publish on {}/truth: {e:?}", args.prefix))?;
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
    let wire_version = args.debug_wire_version.unwrap_or(wire::WIRE_VERSION);
    let mut report = PublisherReport::default();
    let n_subs = || slots.dynamic_config().number_of_subscribers();

    say(&format!(
        "scenario {} (seed {}, run {}), {steps} instants × {nodes} nodes at {} on prefix {:?}; \
         waiting for a subscriber",
        scenario.name(),
        args.seed,
        args.run,
        if period_ns == 0 {
            "full speed".to_string()
        } else {
            format!("{} Hz", args.rate)
        },
        args.prefix
    ));
    match wait_for_subscriber(&node, n_subs, args.connect_timeout) {
        Ok(true) => {}
        Ok(false) => bail!(
            "no subscriber on {}/slots within {} s (start `ipc-runner run --prefix {}`)",
            args.prefix,
            args.connect_timeout,
            args.prefix
        ),
        Err(Stop::Signal) => {
            report.interrupted = true;
            return Ok(report);
        }
    }

    let mut sim = scenario.start(args.seed, args.run);
    let x0 = sim.initial_truth();
    truth_pub
        .loan_uninit()?
        .write_payload(Truth::new(0, sid, nx, &x0))
        .send()?;

    let t0 = wire::monotonic_ns();
    let stream_start_ns = t0;
    let mut last_check = t0;
    let mut delivered_count = 0u64;
    let mut k_done = 0u32;
    'instants: for i in 1..=steps {
        if period_ns > 0 {
            let due = t0 + u64::from(i - 1) * period_ns;
            let now = wire::monotonic_ns();
            if due > now && wait(&node, Duration::from_nanos(due - now)).is_err() {
                report.interrupted = true;
                break;
            }
        } else if i.is_multiple_of(256) && crate::signal::termination_requested() {
            report.interrupted = true;
            break;
        }
        let inst = sim.next_instant();
        truth_pub
            .loan_uninit()?
            .write_payload(Truth::new(inst.k, sid, nx, &inst.truth))
            .send()?;
        for obs in &inst.obs {
            let mut slot = Slot::data(
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
                if let Some(n) = args.debug_nan_every {
                    if n > 0 && delivered_count.is_multiple_of(n) && usize::from(obs.ny) <= MAX_NY {
                        slot.y[0] = f64::NAN;
                    }
                }
            }
            slot_pub.loan_uninit()?.write_payload(slot).send()?;
            report.slots += 1;
        }
        notifier.notify()?;
        k_done = inst.k;
        report.instants = i;
        // A dead subscriber stays registered (and keeps its queue) until someone cleans up.
        // After the send: the scan of the node directory (sub-millisecond) runs in the slack
        // before the next instant is due rather than between its due time and its send.
        let now = wire::monotonic_ns();
        if now - last_check > 100_000_000 {
            last_check = now;
            let _ = node.try_cleanup_dead_nodes();
            if n_subs() == 0 {
                report.subscriber_losses += 1;
                say(&format!(
                    "subscriber lost after instant {i}; waiting for a new one"
                ));
                match wait_for_subscriber(&node, n_subs, args.connect_timeout) {
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
    slot_pub
        .loan_uninit()?
        .write_payload(Slot::marker(
            kind,
            report.slots,
            k_done,
            nodes,
            sid,
            wire::monotonic_ns(),
        ))
        .send()?;
    notifier.notify()?;
    say(&format!(
        "{} after {} instants ({} slots)",
        if report.interrupted {
            "stopped by signal"
        } else {
            "done"
        },
        report.instants,
        report.slots
    ));

    // Keep the data segment alive until the subscriber has read the tail and detached.
    let start = std::time::Instant::now();
    let mut last_cleanup = std::time::Instant::now();
    while n_subs() > 0 && start.elapsed().as_secs_f64() < args.linger {
        if last_cleanup.elapsed() > Duration::from_millis(100) {
            let _ = node.try_cleanup_dead_nodes();
            last_cleanup = std::time::Instant::now();
        }
        if wait(&node, Duration::from_millis(2)).is_err() {
            break;
        }
    }
    Ok(report)
}

/// Instants published when `--steps` is not given: the same default horizon as
/// `ipc-runner eval`, so the two compute the same experiment by default.
pub const DEFAULT_STEPS: u32 = 100;
