//! `ipc-runner demo`: the whole pipeline with one command.
//!
//! Starts the publisher as a child process, runs the real-time loop in this process, and at
//! the end prints the summary (slots, MSE against truth per estimator, latency table) and
//! writes a plot of true vs estimated trajectories plus CSV/JSON files.
//!
//! The child is this very executable, started with the hidden `channel-sim` subcommand (the
//! publisher of the `channel-sim` crate, identical to the `channel-sim` binary). That makes
//! `cargo run --release -p ipc-runner -- demo` work on a fresh clone: cargo builds only the
//! `ipc-runner` binary for `cargo run -p ipc-runner`, so a separate `channel-sim` executable
//! might not exist or might be stale, whereas `std::env::current_exe()` always is the binary
//! that is running. `--channel-sim PATH` uses an external publisher binary instead.
//!
//! The child lives and dies with the demo (docs/security.md, "Signals"): it gets the demo's
//! pid as `--parent-pid` and stops by itself when the demo is gone, even SIGKILLed; SIGINT
//! and SIGTERM to the demo are passed on to it; and the loop polls it (every
//! [`run::PEER_CHECK_NS`], also while it waits for the first slot), so a child that exits or
//! crashes is noticed at once and named with its exit status.

use crate::estimator_args::EstimatorArgs;
use crate::run::{self, select, Hooks, RunArgs, WaitMode};
use crate::source::scenario as resolve;
use crate::source::Source;
use anyhow::{anyhow, bail, Context, Result};
use channel_sim::publisher::DEFAULT_STEPS;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// Default scenario of the demo.
pub const DEFAULT_SCENARIO: &str = "occlusion";
/// Used when [`DEFAULT_SCENARIO`] is not in the preset registry of this build.
pub const FALLBACK_SCENARIO: &str = "linear";
/// Where the demo writes by default: under `out/`, the one output directory the repository
/// ignores (README, "Two commands").
pub const DEFAULT_OUT: &str = "out/demo";

/// Options of `ipc-runner demo`.
#[derive(Clone, Debug, clap::Args)]
pub struct DemoArgs {
    /// Scenario preset (default: occlusion).
    #[arg(long)]
    pub scenario: Option<String>,
    /// Scenario TOML file (instead of a preset).
    #[arg(long, conflicts_with = "scenario")]
    pub config: Option<PathBuf>,
    /// Number of sampling instants (default: 100, as `eval` and `channel-sim`).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
    pub steps: Option<u32>,
    /// Sampling rate in Hz (0 = as fast as possible; the default is channel-sim's). An
    /// estimator slower than the period (the particle filter of `--particles`) queues slots
    /// behind it, which the latency table then shows.
    #[arg(long, default_value_t = estpipe_wire::DEFAULT_RATE_HZ,
          value_parser = estpipe_process::flags::rate_hz)]
    pub rate: f64,
    /// Experiment seed (same meaning and default as `eval --seed`).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Run index within the seed.
    #[arg(long, default_value_t = 0)]
    pub run: u64,
    /// The estimators and their options (as in `run`).
    #[command(flatten)]
    pub estimator: EstimatorArgs,
    /// How the loop waits for slots.
    #[arg(long, value_enum, default_value_t = WaitMode::Spin)]
    pub wait: WaitMode,
    /// Directory for the CSV and JSON outputs and the latency plots (created if missing).
    #[arg(long, default_value = DEFAULT_OUT)]
    pub out: PathBuf,
    /// The live view (docs/view.md; with the `view` feature).
    #[command(flatten)]
    pub view: crate::view::ViewArgs,
    /// Also write the run as an MCAP file (docs/mcap.md).
    #[arg(long, value_name = "FILE")]
    pub mcap: Option<PathBuf>,
    /// Write the plot of true vs estimated trajectories here (`.svg`, or `.png` for a
    /// bitmap), as `eval --plot`; default: `trajectories.svg` in `--out`.
    #[arg(long, value_name = "FILE.svg|FILE.png")]
    pub plot: Option<PathBuf>,
    /// Service-name prefix (the default of every subcommand; refused when another process
    /// uses it: give another one to run demos side by side).
    #[arg(long, default_value = estpipe_wire::DEFAULT_PREFIX)]
    pub prefix: String,
    /// `shm`: publisher and runner share one prefix. `zenoh`: the publisher on
    /// `<prefix>-sensor`, the runner on `<prefix>`, joined only by two `ipc-runner bridge`
    /// processes over zenoh on loopback (docs/bridge.md; in builds with `--features
    /// bridge`); the summary adds the network hop.
    #[arg(long, value_enum, default_value_t = Via::Shm)]
    pub via: Via,
    /// Sensor nodes in the loop (docs/sensor-node.md): `qemu` starts one emulated
    /// Cortex-M4F per node of the scenario running the node firmware (`--node-firmware`);
    /// the publisher feeds each its raw samples over its UART and publishes its decisions.
    #[arg(long, value_enum, value_name = "HOW")]
    pub sensor_node: Option<SensorNodes>,
    /// The sensor-node firmware (an ELF for QEMU's mps2-an386).
    #[arg(long, value_name = "ELF", default_value = crate::sensor_nodes::DEFAULT_FIRMWARE)]
    pub node_firmware: PathBuf,
    /// Publisher executable (default: this executable's hidden `channel-sim` subcommand).
    #[arg(long)]
    pub channel_sim: Option<PathBuf>,
    /// Pin the loop to this CPU (best effort).
    #[arg(long)]
    pub cpu: Option<usize>,
    /// Publish estimates on the latest-estimate blackboard instead of the queue (see
    /// `run --latest-estimates`: no allocation per slot).
    #[arg(long)]
    pub latest_estimates: bool,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// Memory the runner may preallocate, in MiB (as `run --max-memory`): the recording of
    /// `--steps` instants and the particles.
    #[arg(long, value_name = "MIB", default_value_t = crate::limits::DEFAULT_MAX_MEMORY_MIB,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub max_memory: u64,
}

/// Where the sensor nodes of `--sensor-node` run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum SensorNodes {
    /// One QEMU `mps2-an386` per node.
    Qemu,
}

/// How the demo's slots reach its runner.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Via {
    /// Shared memory on one prefix.
    Shm,
    /// Two bridges over zenoh (TCP on loopback) between two prefixes.
    Zenoh,
}

/// The files `demo` writes into `--out`.
const OUT_FILES: [&str; 6] = [
    "estimates.csv",
    "slots.csv",
    "latency.csv",
    "report.json",
    "latency.svg",
    "latency-trace.svg",
];

impl DemoArgs {
    /// Before anything starts: `--out` can be filled (created if missing; every file the
    /// demo writes there, and the plot, can be written), the plot has a known extension, and
    /// `particles` particles fit the memory budget (they are allocated when the estimators
    /// are built).
    pub fn check_outputs(&self, nx: usize, particles: usize) -> Result<()> {
        let plot = self.plot_path();
        crate::plot::check_extension(&plot).map_err(crate::limits::BadInput)?;
        crate::limits::check_output_dir("--out", &self.out)?;
        for f in OUT_FILES.iter().map(Path::new) {
            crate::limits::check_output("--out", &self.out.join(f))?;
        }
        crate::limits::check_output(
            if self.plot.is_some() {
                "--plot"
            } else {
                "--out"
            },
            &plot,
        )?;
        if let Some(m) = &self.mcap {
            crate::limits::check_output("--mcap", m)?;
        }
        self.check_memory(nx, 0, 0, particles)
    }

    /// The trajectory plot: `--plot`, else `trajectories.svg` in `--out`.
    pub fn plot_path(&self) -> PathBuf {
        self.plot
            .clone()
            .unwrap_or_else(|| self.out.join("trajectories.svg"))
    }

    /// What the runner preallocates for `steps` instants of `n_est` estimators and `nodes`
    /// nodes (it records the slots), against `--max-memory` ([`RunArgs::check_memory`]).
    pub fn check_memory(
        &self,
        nx: usize,
        nodes: usize,
        n_est: usize,
        particles: usize,
    ) -> Result<()> {
        let mut r = RunArgs::new("", "");
        r.steps = self.steps.unwrap_or(DEFAULT_STEPS);
        r.slots_csv = Some(self.out.join("slots.csv"));
        r.mcap = self.mcap.clone();
        r.max_memory = self.max_memory;
        Ok(r.check_memory(nx, nodes, n_est, particles)?)
    }
}

/// Ends the child if the demo bails out early.
struct ChildGuard(Option<Child>);

impl Drop for ChildGuard {
    fn drop(&mut self) {
        if let Some(c) = self.0.as_mut() {
            let _ = end_child(c, true, CHILD_GRACE);
        }
    }
}

/// How long the child has to exit after SIGTERM before it is killed. It stops within one of
/// its wait slices (50 ms); the rest is room for a loaded machine.
const CHILD_GRACE: Duration = Duration::from_millis(900);

/// How long a child that completed its stream has to exit by itself (it leaves as soon as the
/// demo's subscriber is gone) before it is sent SIGTERM.
const CHILD_LINGER: Duration = Duration::from_secs(2);

/// Ends `c`: SIGTERM first if `terminate`, else only after `grace` without an exit; then
/// `grace` again, then SIGKILL. Its exit status.
fn end_child(c: &mut Child, terminate: bool, grace: Duration) -> std::io::Result<ExitStatus> {
    if terminate {
        signal_child(c, libc::SIGTERM);
    }
    for term in [!terminate, false] {
        let start = Instant::now();
        while start.elapsed() < grace {
            if let Some(s) = c.try_wait()? {
                return Ok(s);
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        if term {
            signal_child(c, libc::SIGTERM);
        }
    }
    let _ = c.kill();
    c.wait()
}

/// Sends `sig` to the child (a no-op once it has been waited for).
fn signal_child(c: &mut Child, sig: libc::c_int) {
    if matches!(c.try_wait(), Ok(None)) {
        if let Ok(pid) = libc::pid_t::try_from(c.id()) {
            // SAFETY: kill(2) on our own child, not yet waited for: the pid is still its.
            #[allow(unsafe_code)]
            let _ = unsafe { libc::kill(pid, sig) };
        }
    }
}

/// Starts the two bridges of `--via zenoh` (reports in `out/bridge-*.json`): the publisher's
/// prefix and the bridges' children.
fn start_bridges(prefix: &str, out: &Path) -> Result<(String, Vec<(&'static str, ChildGuard)>)> {
    let me = std::env::current_exe()
        .map_err(|e| anyhow!("cannot locate the running executable for the bridges ({e})"))?;
    // A loopback port nobody listens on now (the sensor side listens on it).
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .context("no free loopback port for the bridges")?
        .port();
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let sensor_prefix = format!("{prefix}-sensor");
    let key = format!("estpipe/{prefix}");
    let mut bridges = Vec::new();
    for (side, on, role) in [
        ("estimator", prefix, "--connect"),
        ("sensor", sensor_prefix.as_str(), "--listen"),
    ] {
        let report = out.join(format!("bridge-{side}.json"));
        let child = Command::new(&me)
            .args(["bridge", "--side", side, "--prefix", on, "--key", &key])
            .args([role, &endpoint])
            .args(["--once", "--quiet", "--connect-timeout", "30"])
            .args(["--parent-pid", &std::process::id().to_string()])
            .arg("--report")
            .arg(&report)
            .stdin(Stdio::null())
            .spawn()
            .with_context(|| format!("cannot start the {side} bridge"))?;
        bridges.push((side, ChildGuard(Some(child))));
    }
    Ok((sensor_prefix, bridges))
}

/// The network part of the summary, from the bridges' reports.
fn bridge_summary(out: &Path) -> String {
    let read = |side: &str| -> Option<serde_json::Value> {
        let s = std::fs::read_to_string(out.join(format!("bridge-{side}.json"))).ok()?;
        serde_json::from_str(&s).ok()
    };
    let Some(e) = read("estimator") else {
        return "network: no report from the estimator-side bridge".into();
    };
    let us = |v: &serde_json::Value, q: &str| v[q].as_f64().unwrap_or(f64::NAN);
    let (hop, own) = (&e["network_hop"], &e["bridge_time"]);
    let refused: u64 = e["refused"].as_object().map_or(0, |m| {
        m.values().filter_map(serde_json::Value::as_u64).sum()
    });
    format!(
        "network (zenoh, loopback): slot sent → far bridge p50 {:.1} µs, p99 {:.1} µs; far \
         bridge's own time p50 {:.1} µs, p99 {:.1} µs; {} slots lost on the network, {refused} \
         refused",
        us(hop, "p50_us"),
        us(hop, "p99_us"),
        us(own, "p50_us"),
        us(own, "p99_us"),
        e["lost_on_network"].as_u64().unwrap_or(0),
    )
}

/// Refuses `prefix` when its slot service exists once dead processes' leftovers are cleaned
/// up: another demo, a `run` or a publisher uses it, and sharing it would mix two streams
/// (one prefix is one pipeline: docs/wire.md, Services and QoS).
fn refuse_busy_prefix(prefix: &str) -> Result<()> {
    use iceoryx2::prelude::*;
    let node = estpipe_process::node::create("ipc-runner")?;
    let _ = node.try_cleanup_dead_nodes();
    let name = estpipe_wire::service_name(prefix, estpipe_wire::SLOTS)?;
    let busy = ipc::Service::does_exist(&name, node.config(), MessagingPattern::PublishSubscribe)
        .map_err(|e| anyhow!("cannot look up the service {name} ({e:?})"))?;
    if busy {
        return Err(crate::limits::BadInput(format!(
            "prefix {prefix:?} is in use ({name} exists: another demo, a `run` or a publisher \
             on it); give the demo its own with --prefix NAME"
        ))
        .into());
    }
    Ok(())
}

/// The publisher command: `--channel-sim PATH`, else this executable + `channel-sim`.
fn publisher_command(explicit: Option<&Path>) -> Result<Command> {
    if let Some(p) = explicit {
        if !p.exists() {
            bail!(
                "--channel-sim {p:?} does not exist; build it with `cargo build --release -p \
                 channel-sim` (target/release/channel-sim) or omit --channel-sim to use the \
                 publisher built into ipc-runner"
            );
        }
        return Ok(Command::new(p));
    }
    let me = std::env::current_exe().map_err(|e| {
        anyhow!(
            "cannot locate the running executable ({e}); start the publisher yourself with \
             `cargo run --release -p channel-sim -- --prefix P` and use `ipc-runner run --prefix P`"
        )
    })?;
    let mut c = Command::new(me);
    c.arg("channel-sim");
    Ok(c)
}

/// `ipc-runner demo`: the scenario, the children (bridges, sensor nodes, the publisher), the
/// runner's loop in this process, the children's end, the outputs. Returns the exit code.
pub fn main(args: &DemoArgs) -> Result<i32> {
    if args.via == Via::Zenoh {
        crate::bridge::available()?;
    }
    // SIGINT/SIGTERM/SIGHUP set a flag from here on (the loop ends, the child is told).
    estpipe_process::signal::install();
    let setup = Setup::check(args)?;
    let mut children = Children::start(args, &setup)?;
    let mut rargs = runner_args(args, &setup.scenario_name, &setup.prefix, setup.steps);
    let view = crate::view::View::start(&args.view)?;
    rargs.view_tap = view.tap();
    announce(
        args,
        &setup.scenario_name,
        setup.steps,
        children.child_pid,
        children.nodes.as_ref(),
    );
    let Some((report, traj)) = stream(args, &rargs, &setup, &mut children)? else {
        return Ok(2);
    };
    // The loop's subscriber is gone: a child that completed its stream leaves by itself; one
    // that is still running after a stop or a loss is told (SIGTERM), and killed if it must.
    let completed = matches!(
        report.ending,
        run::Ending::Completed | run::Ending::PublisherStopped
    );
    end_children(
        &mut children.guard,
        &children.publisher,
        children.nodes.as_mut(),
        &mut children.bridges,
        completed,
    )?;
    run::finish(&rargs, &report, &traj, setup.spec.ny())?;
    write_outputs(args, &setup, &report, &traj);
    view.end();
    Ok(run::exit_code(&report))
}

/// What the demo runs, once its flags, memory and prefix are checked and its output
/// directory made.
struct Setup {
    scenario_name: String,
    scenario: Box<dyn channel_sim::Scenario>,
    steps: u32,
    spec: std::sync::Arc<estpipe_spec::EstimatorSpec>,
    make: select::EstimatorFactory,
    prefix: String,
}

impl Setup {
    fn check(args: &DemoArgs) -> Result<Self> {
        let (scenario_name, scenario) = demo_scenario(args)?;
        // Without --steps, the default horizon of `channel-sim` and `eval`.
        let steps = args.steps.unwrap_or(DEFAULT_STEPS);
        let particles = args.estimator.particle_count();
        args.check_outputs(scenario.nx(), particles)?;
        let source = std::sync::Arc::new(Source::of_scenario(&*scenario, args.seed, args.run));
        let spec = std::sync::Arc::clone(&source.spec);
        let make = select::estimators_with(
            source,
            &args.estimator,
            select::Experiment {
                seed: args.seed,
                run: args.run,
                horizon: steps,
            },
        )
        .map_err(|e| crate::limits::BadInput(format!("{e:#}")))?;
        args.check_memory(spec.nx(), spec.nodes(), make()?.len(), particles)?;
        let prefix = args.prefix.clone();
        refuse_busy_prefix(&prefix)?;
        std::fs::create_dir_all(&args.out)
            .with_context(|| format!("cannot create output directory {:?}", args.out))?;
        Ok(Self {
            scenario_name,
            scenario,
            steps,
            spec,
            make,
            prefix,
        })
    }
}

/// The demo's children. Dropped in field order, as they were when they were locals of
/// `main`: the publisher first, then the sensor nodes, then the bridges.
struct Children {
    guard: ChildGuard,
    nodes: Option<crate::sensor_nodes::QemuNodes>,
    bridges: Vec<(&'static str, ChildGuard)>,
    child_pid: u32,
    /// The publisher as the messages name it.
    publisher: String,
}

impl Children {
    fn start(args: &DemoArgs, setup: &Setup) -> Result<Self> {
        // With --via zenoh the publisher writes to its own prefix and two bridges carry its
        // slots to the runner's (the estimator side first: it waits for the runner, the
        // sensor side for it, and the publisher starts when the sensor side subscribes).
        let (pub_prefix, bridges) = match args.via {
            Via::Shm => (setup.prefix.clone(), Vec::new()),
            Via::Zenoh => start_bridges(&setup.prefix, &args.out)?,
        };
        let nodes = match args.sensor_node {
            Some(SensorNodes::Qemu) => Some(crate::sensor_nodes::QemuNodes::start(
                &args.node_firmware,
                setup.spec.nodes(),
                &args.out,
            )?),
            None => None,
        };
        let mut cmd = publisher_args(
            args,
            &setup.scenario_name,
            setup.steps,
            &pub_prefix,
            nodes.as_ref(),
        )?;
        let child = cmd
            .spawn()
            .with_context(|| format!("cannot start the publisher {cmd:?}"))?;
        let child_pid = child.id();
        let publisher = match &args.channel_sim {
            Some(p) => format!("the publisher {}", p.display()),
            None => "the publisher (ipc-runner channel-sim)".to_string(),
        };
        Ok(Self {
            guard: ChildGuard(Some(child)),
            nodes,
            bridges,
            child_pid,
            publisher,
        })
    }
}

/// The runner's loop over the publisher's stream, with the progress bar; `None` when the
/// publisher ended before its first slot (the error is printed: exit code 2).
fn stream(
    args: &DemoArgs,
    rargs: &RunArgs,
    setup: &Setup,
    children: &mut Children,
) -> Result<Option<(run::RunReport, run::Trajectories)>> {
    let bar = progress_bar(args.quiet, setup.steps);
    let mut progress = |k: u32, c: &run::assemble::Counts| {
        bar.set_position(u64::from(k));
        bar.set_message(format!(
            "{} delivered, {} dropped, {} lost in IPC",
            c.delivered, c.dropped_by_channel, c.lost_in_ipc
        ));
    };
    let mut exited: Option<ExitStatus> = None;
    let (guard, publisher) = (&mut children.guard, &children.publisher);
    let mut peer = || -> Option<String> {
        let s = guard.0.as_mut()?.try_wait().ok()??;
        exited = Some(s);
        Some(format!("{publisher} exited with {s}"))
    };
    let hooks = Hooks {
        progress: Some(&mut progress),
        peer: Some(&mut peer),
        ..Hooks::default()
    };
    let result = run::run_loop(rargs, &setup.spec, &setup.make, hooks);
    bar.finish_and_clear();
    match result {
        Ok(r) => Ok(Some(r)),
        // The publisher ended before its first slot: a `--channel-sim` that is no publisher,
        // or one that refused its arguments or its environment (its own error came first).
        Err(e) if exited.is_some() => {
            estpipe_process::errln!("demo: error: {e:#}");
            Ok(None)
        }
        Err(e) => Err(e),
    }
}

/// The plots and the summary, after `run::finish` wrote the CSVs and the report.
fn write_outputs(
    args: &DemoArgs,
    setup: &Setup,
    report: &run::RunReport,
    traj: &run::Trajectories,
) {
    let plot = args.plot_path();
    if let Err(e) = crate::plot::trajectories::plot(traj, &plot, setup.scenario.name()) {
        estpipe_process::errln!("demo: no plot ({e:#})");
    }
    latency_plots(args, &setup.scenario_name, report, traj);
    estpipe_process::outln!("{}", report.summary());
    if args.via == Via::Zenoh {
        estpipe_process::outln!("{}", bridge_summary(&args.out));
    }
    estpipe_process::outln!(
        "wrote {} (true vs estimated); latency.svg (percentiles), latency-trace.svg (over \
         time), estimates.csv, latency.csv, slots.csv (replayable), report.json in {}",
        plot.display(),
        args.out.display()
    );
}

/// The scenario by `--scenario`, `--config`, or the default (its fallback where this build
/// lacks it), with the name the demo shows.
fn demo_scenario(args: &DemoArgs) -> Result<(String, Box<dyn channel_sim::Scenario>)> {
    Ok(match (&args.scenario, &args.config) {
        (Some(n), _) => (n.clone(), resolve(n, None)?),
        (None, Some(c)) => (c.display().to_string(), resolve(DEFAULT_SCENARIO, Some(c))?),
        (None, None) => match resolve(DEFAULT_SCENARIO, None) {
            Ok(s) => (DEFAULT_SCENARIO.to_string(), s),
            Err(e) => {
                let fallback = FALLBACK_SCENARIO;
                estpipe_process::errln!(
                    "demo: the default scenario {DEFAULT_SCENARIO:?} is not available in this \
                     build ({e:#}); running {fallback:?} instead"
                );
                (fallback.to_string(), resolve(fallback, None)?)
            }
        },
    })
}

/// The publisher's command line: the scenario, the run, the pace, its prefix, the sensor
/// nodes' lines, this process as its parent.
fn publisher_args(
    args: &DemoArgs,
    scenario_name: &str,
    steps: u32,
    pub_prefix: &str,
    nodes: Option<&crate::sensor_nodes::QemuNodes>,
) -> Result<Command> {
    let mut cmd = publisher_command(args.channel_sim.as_deref())?;
    if let Some(n) = nodes {
        for line in n.lines() {
            cmd.args(["--sensor-node", line]);
        }
    }
    if let Some(c) = &args.config {
        cmd.arg("--config").arg(c);
    } else {
        cmd.arg("--scenario").arg(scenario_name);
    }
    cmd.args(["--seed", &args.seed.to_string()])
        .args(["--run", &args.run.to_string()])
        .args(["--steps", &steps.to_string()])
        .args(["--rate", &args.rate.to_string()])
        .args(["--prefix", pub_prefix])
        .args(["--parent-pid", &std::process::id().to_string()])
        .arg("--quiet")
        .stdin(Stdio::null());
    Ok(cmd)
}

/// What `run` would be given for the same stream, its outputs in `--out`.
fn runner_args(args: &DemoArgs, scenario_name: &str, prefix: &str, steps: u32) -> RunArgs {
    let mut rargs = RunArgs::new(scenario_name, prefix);
    rargs.config = args.config.clone();
    rargs.estimator = args.estimator.clone();
    rargs.wait = args.wait;
    rargs.cpu = args.cpu;
    rargs.latest_estimates = args.latest_estimates;
    rargs.quiet = true;
    rargs.connect_timeout = 30.0;
    rargs.steps = steps;
    rargs.seed = args.seed;
    rargs.run = args.run;
    rargs.buffer = 1024;
    rargs.estimates_csv = Some(args.out.join("estimates.csv"));
    rargs.slots_csv = Some(args.out.join("slots.csv"));
    rargs.latency_csv = Some(args.out.join("latency.csv"));
    rargs.json = Some(args.out.join("report.json"));
    rargs.mcap = args.mcap.clone();
    rargs
}

/// The lines that say what the demo runs.
fn announce(
    args: &DemoArgs,
    scenario_name: &str,
    steps: u32,
    child_pid: u32,
    nodes: Option<&crate::sensor_nodes::QemuNodes>,
) {
    if let Some(n) = nodes {
        estpipe_process::errln!(
            "demo: {} sensor node(s) on QEMU mps2-an386 running {}",
            n.lines().len(),
            args.node_firmware.display()
        );
    }
    estpipe_process::errln!(
        "demo: scenario {scenario_name}, {steps} instants at {} with seed {} run {}, {} wait \
         (prefix {}, publisher pid {child_pid})",
        if args.rate > 0.0 {
            format!("{} Hz", args.rate)
        } else {
            "full speed".into()
        },
        args.seed,
        args.run,
        args.wait.as_str(),
        args.prefix
    );
}

/// The instants' progress on a terminal (hidden with `--quiet`).
fn progress_bar(quiet: bool, steps: u32) -> indicatif::ProgressBar {
    if quiet {
        return indicatif::ProgressBar::hidden();
    }
    indicatif::ProgressBar::new(u64::from(steps)).with_style(
        indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} instants · {msg}")
            .expect("static template"),
    )
}

/// Ends the publisher (told with SIGTERM unless its stream `completed`), the sensor nodes'
/// emulators and the bridges, saying which did not end cleanly.
fn end_children(
    guard: &mut ChildGuard,
    publisher: &str,
    nodes: Option<&mut crate::sensor_nodes::QemuNodes>,
    bridges: &mut [(&'static str, ChildGuard)],
    completed: bool,
) -> Result<()> {
    if let Some(mut c) = guard.0.take() {
        let linger = if completed { CHILD_LINGER } else { CHILD_GRACE };
        let s = end_child(&mut c, !completed, linger)?;
        if !s.success() {
            estpipe_process::errln!("demo: {publisher} exited with {s}");
        }
    }
    // The gateway ended every node's run (Finish): the emulators leave by themselves.
    if let Some(n) = nodes {
        let total = n.lines().len();
        let clean = n.finish(CHILD_LINGER);
        if clean < total {
            estpipe_process::errln!(
                "demo: {} of {total} sensor node(s) did not end cleanly",
                total - clean
            );
        }
    }
    // The bridges leave by themselves once the stream ended and the estimates went quiet.
    for (name, g) in bridges {
        if let Some(mut c) = g.0.take() {
            let s = end_child(&mut c, !completed, Duration::from_secs(3))?;
            if !s.success() {
                estpipe_process::errln!("demo: the {name} bridge exited with {s}");
            }
        }
    }
    Ok(())
}

/// `latency.svg` (percentiles per stage) and `latency-trace.svg` (over the run); a plot that
/// cannot be drawn is said, and the rest goes on.
fn latency_plots(
    args: &DemoArgs,
    scenario_name: &str,
    report: &run::RunReport,
    traj: &run::Trajectories,
) {
    let lat = &report.latency;
    let wait = args.wait.as_str();
    if let Err(e) = crate::plot::latency::plot_ladder(
        &format!("{scenario_name}: latency per instant, {wait} wait"),
        &[
            (
                "slot sent → received (transport)".to_string(),
                lat.transport,
            ),
            ("estimator step".to_string(), lat.step),
            (
                "slot sent → estimates published".to_string(),
                lat.end_to_end,
            ),
        ],
        &args.out.join("latency.svg"),
    ) {
        estpipe_process::errln!("demo: no latency plot ({e:#})");
    }
    let points: Vec<_> = traj.timing.iter().map(|t| traj.latency_point(t)).collect();
    if let Err(e) = crate::plot::trace::plot_trace(
        &format!("{scenario_name}: latency over the run, {wait} wait"),
        &points,
        &args.out.join("latency-trace.svg"),
    ) {
        estpipe_process::errln!("demo: no latency trace ({e:#})");
    }
}
