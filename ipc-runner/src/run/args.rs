//! The options of `ipc-runner run` (shared with `demo`).

use crate::estimator_args::EstimatorArgs;
use crate::limits::{check_outputs, given, product, BadInput, Budget};
use estpipe_wire as wire;
use serde::Serialize;
use std::path::PathBuf;

/// Largest `--max-gap` (as the bridge's): every instant of a gap is stepped, so a larger
/// bound let one forged slot keep a core busy for minutes.
pub const MAX_MAX_GAP: u32 = 1_000_000;

/// Estimate samples the runner's publisher may loan at once (docs/wire.md, Services and QoS).
const ESTIMATE_LOANS: usize = 17;

/// Longest slot queue `--buffer` accepts (iceoryx2 preallocates it in shared memory).
pub const MAX_BUFFER: usize = 1 << 16;

/// How the loop waits for the next slot.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum WaitMode {
    /// Busy-poll `receive()` (lowest latency, one core at 100 %).
    Spin,
    /// Sleep on the `slots-ready` event in a WaitSet (iceoryx2's event multiplexer; it
    /// allocates a little per wake-up inside iceoryx2).
    Block,
    /// Sleep on the `slots-ready` listener directly (one file descriptor, no WaitSet): the
    /// same kernel wake-up as `block` without its per-wake-up allocations. Termination
    /// requests are checked after each wake-up (at least every 50 ms).
    Listener,
}

impl WaitMode {
    /// Lower-case name as on the command line.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Spin => "spin",
            Self::Block => "block",
            Self::Listener => "listener",
        }
    }
}

/// Options of `ipc-runner run` (shared with `demo`).
#[derive(Clone, Debug, clap::Args)]
pub struct RunArgs {
    /// Scenario the publisher runs (the estimators need its model).
    #[arg(long, default_value = "occlusion")]
    pub scenario: String,
    /// Scenario TOML file (instead of a preset).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Estimator spec TOML file: the model, prior and channel knowledge of your own sensors,
    /// with no simulation section (docs/pipeline.md, "Estimator specs"); the stream must
    /// announce the same model. Instead of `--scenario`/`--config`.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["config", "scenario"])]
    pub estimator_spec: Option<PathBuf>,
    /// The estimators and their options (as in `eval`, `demo` and `replay`).
    #[command(flatten)]
    pub estimator: EstimatorArgs,
    /// Service-name prefix (must match channel-sim's).
    #[arg(long, default_value = wire::DEFAULT_PREFIX)]
    pub prefix: String,
    /// How to wait for slots.
    #[arg(long, value_enum, default_value_t = WaitMode::Spin)]
    pub wait: WaitMode,
    /// Data deadline: this many ms after the expected slot the publisher is looked at: stalled
    /// if its iceoryx2 node is alive (waited for, see `--stall-limit`), else lost.
    #[arg(long, default_value_t = 100.0, value_parser = estpipe_process::flags::positive_millis)]
    pub deadline_ms: f64,
    /// Instants a node's k (or its END/ABORT's) may advance past its last instant; the gap is
    /// filled with lost slots, a larger jump is a counted stream error (docs/wire.md).
    /// At most 1000000: every instant of a gap is stepped.
    #[arg(long, default_value_t = super::assemble::DEFAULT_MAX_GAP,
          value_parser = clap::value_parser!(u32).range(0..=MAX_MAX_GAP as i64))]
    pub max_gap: u32,
    /// Paced streams: how long an instant waits for its other nodes' slots after its first
    /// one arrived before it is handed on without them (counted as lost by the deadline);
    /// 0 = for ever. Blocking streams (`--rate 0`) never lose a slot by this deadline.
    #[arg(long, default_value_t = super::assemble::DEFAULT_INSTANT_DEADLINE_MS)]
    pub instant_deadline_ms: f64,
    /// Seconds to wait for the first slot (and for a restarted publisher); 0 = for ever, the
    /// default: the runner is started first and waits, asleep, for whoever publishes (a
    /// person may take minutes to start it). Publishers wait 30 s for a runner.
    #[arg(long, default_value_t = 0.0, value_parser = estpipe_process::flags::seconds)]
    pub connect_timeout: f64,
    /// A publisher whose iceoryx2 node is alive but that sent nothing past the deadline is
    /// *stalled* (waited for, reported); it counts as lost after this many seconds of silence
    /// (0 = never). A dead node is lost at the deadline (docs/pipeline.md, "Stalled or lost").
    #[arg(long, default_value_t = 10.0, value_name = "SECONDS", value_parser = estpipe_process::flags::seconds)]
    pub stall_limit: f64,
    /// After losing the publisher, wait for channel-sim to come back instead of failing.
    #[arg(long)]
    pub wait_for_restart: bool,
    /// Slot queue length of the subscriber. The slot service never overwrites: a full queue
    /// makes a blocking publisher wait and a discarding one drop the slot, which the runner
    /// counts as lost in the IPC (docs/wire.md, Back-pressure).
    #[arg(long, default_value_t = 256, value_parser = buffer_len)]
    pub buffer: usize,
    /// Pin the loop to this CPU (best effort).
    #[arg(long)]
    pub cpu: Option<usize>,
    /// Lock memory with mlockall (best effort).
    #[arg(long)]
    pub mlock: bool,
    /// Experiment seed the estimators are built for (as `eval --seed`; channel-sim's).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Run index the estimators are built for (channel-sim's `--run`).
    #[arg(long, default_value_t = 0)]
    pub run: u64,
    /// Instants channel-sim publishes: the horizon the estimators are built for, and the
    /// size of the preallocated trajectory recording (later instants are processed but not
    /// recorded).
    #[arg(long, default_value_t = wire::DEFAULT_STEPS,
          value_parser = clap::value_parser!(u32).range(1..))]
    pub steps: u32,
    /// Write estimates and truth per instant to this CSV file at the end.
    #[arg(long)]
    pub estimates_csv: Option<PathBuf>,
    /// Write the received slots to this CSV file at the end (input for `replay`).
    #[arg(long)]
    pub slots_csv: Option<PathBuf>,
    /// Write the latency of every instant (slot sent → received → estimates published) to
    /// this CSV file at the end: where the tail of the histograms happened, and when.
    #[arg(long)]
    pub latency_csv: Option<PathBuf>,
    /// Write the run report as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write the run as an MCAP file at the end: the slots, the truth and every estimate with
    /// its covariance, for Foxglove and the `mcap` readers (docs/mcap.md).
    #[arg(long, value_name = "FILE")]
    pub mcap: Option<PathBuf>,
    /// Do not publish estimates on `<prefix>/estimates` (iceoryx2 0.10 allocates a small
    /// reference count per loaned sample; without publishing the loop allocates nothing).
    #[arg(long)]
    pub no_publish_estimates: bool,
    /// Publish estimates on the blackboard `<prefix>/estimates-latest` (the newest estimate
    /// per estimator; readers see skipped ones as jumps in `seq`) instead of the
    /// `<prefix>/estimates` queue. Writing a blackboard entry allocates nothing, so the whole
    /// slot path is allocation-free while publishing.
    #[arg(long, conflicts_with = "no_publish_estimates")]
    pub latest_estimates: bool,
    /// Test hook: sleep this many µs after each slot (a deliberately slow consumer).
    #[cfg(feature = "test-hooks")]
    #[arg(long, hide = true)]
    pub debug_slow_us: Option<u64>,
    /// Suppress progress messages.
    #[arg(long)]
    pub quiet: bool,
    /// The live view (docs/view.md; with the `view` feature).
    #[command(flatten)]
    pub view: crate::view::ViewArgs,
    /// Where the loop tells the live view what the estimates service does not carry (set
    /// when a view runs).
    #[arg(skip)]
    pub view_tap: crate::view::ViewTap,
    /// Memory the run may preallocate, in MiB: the recording of `--steps` instants (truth,
    /// estimates, timing, slots) and the particles. Flags that need more are refused before
    /// the loop starts, with the numbers.
    #[arg(long, value_name = "MIB", default_value_t = crate::limits::DEFAULT_MAX_MEMORY_MIB,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub max_memory: u64,
}

fn buffer_len(s: &str) -> Result<usize, String> {
    match s.trim().parse::<usize>() {
        Ok(n) if (1..=MAX_BUFFER).contains(&n) => Ok(n),
        Ok(n) => Err(format!("{n} is not in 1..={MAX_BUFFER}")),
        Err(e) => Err(format!("{s:?}: {e}")),
    }
}

impl RunArgs {
    /// Defaults for `prefix` and `scenario` (as on the command line).
    pub fn new(scenario: &str, prefix: &str) -> Self {
        Self {
            scenario: scenario.to_string(),
            config: None,
            estimator_spec: None,
            estimator: EstimatorArgs::default(),
            prefix: prefix.to_string(),
            wait: WaitMode::Spin,
            deadline_ms: 100.0,
            connect_timeout: 0.0,
            stall_limit: 10.0,
            max_gap: super::assemble::DEFAULT_MAX_GAP,
            instant_deadline_ms: super::assemble::DEFAULT_INSTANT_DEADLINE_MS,
            wait_for_restart: false,
            buffer: 256,
            cpu: None,
            mlock: false,
            seed: 0,
            run: 0,
            steps: wire::DEFAULT_STEPS,
            estimates_csv: None,
            slots_csv: None,
            latency_csv: None,
            json: None,
            mcap: None,
            no_publish_estimates: false,
            latest_estimates: false,
            #[cfg(feature = "test-hooks")]
            debug_slow_us: None,
            quiet: false,
            view: crate::view::ViewArgs::default(),
            view_tap: crate::view::ViewTap::default(),
            max_memory: crate::limits::DEFAULT_MAX_MEMORY_MIB,
        }
    }

    /// `--debug-slow-us` (feature `test-hooks`).
    #[cfg(feature = "test-hooks")]
    #[inline]
    pub fn slow_consumer_us(&self) -> Option<u64> {
        self.debug_slow_us
    }

    /// A shipped build parses no test hook.
    #[cfg(not(feature = "test-hooks"))]
    #[inline]
    pub fn slow_consumer_us(&self) -> Option<u64> {
        None
    }

    /// Checks, before the loop starts, that every output file can be written (a file that
    /// cannot would otherwise fail after the whole stream, losing it).
    pub fn check_outputs(&self) -> Result<(), BadInput> {
        let outputs = given(&[
            ("--estimates-csv", self.estimates_csv.as_deref()),
            ("--slots-csv", self.slots_csv.as_deref()),
            ("--latency-csv", self.latency_csv.as_deref()),
            ("--json", self.json.as_deref()),
            ("--mcap", self.mcap.as_deref()),
        ]);
        let inputs = given(&[("--config", self.config.as_deref())]);
        check_outputs(&outputs, &inputs)
    }

    /// Checks what the loop preallocates for `n_est` estimators on a scenario of `nx` states
    /// and `nodes` nodes (`run/trajectories.rs`: per instant its key, timing, truth and
    /// estimates, and with `--slots-csv` every node's slot) and what `particles` particles
    /// hold, against `--max-memory`.
    pub fn check_memory(
        &self,
        nx: usize,
        nodes: usize,
        n_est: usize,
        particles: usize,
    ) -> Result<(), BadInput> {
        let (nx, nodes, n_est) = (nx as u64, nodes as u64, n_est as u64);
        let per_instant = 8 + 24 + nodes + 8 * nx * (1 + 2 * n_est);
        let slots = if self.slots_csv.is_some() {
            product(&[u64::from(self.steps), nodes, observation_bytes()])
        } else {
            0
        };
        // `--mcap`: every node's observation, each estimator's nx × nx covariance and kind.
        let mcap = if self.mcap.is_some() {
            let per = nodes * observation_bytes() + n_est * (8 * nx * nx + 4);
            product(&[u64::from(self.steps), per])
        } else {
            0
        };
        let recording = product(&[u64::from(self.steps), per_instant])
            .saturating_add(slots)
            .saturating_add(mcap);
        let pf = product(&[
            particles as u64,
            crate::estimators::pf_bytes_per_particle(nx as usize),
        ]);
        // The estimate publisher's data segment: iceoryx2 sizes it by the QoS of whoever
        // created `<prefix>/estimates`, accepted up to `QOS_LIMIT` (docs/wire.md).
        let shm = if self.no_publish_estimates || self.latest_estimates {
            0
        } else {
            wire::services::QOS_LIMIT.segment_bytes(size_of::<wire::Estimate>(), ESTIMATE_LOANS)
        };
        Budget::mib(self.max_memory)
            .within_address_space(RUN_ADDRESS_RESERVE, "run")?
            .check(
                &(format!(
                    "--steps {} ({}{nx} states{}{})",
                    self.steps,
                    if n_est > 0 {
                        format!("{n_est} estimators × ")
                    } else {
                        String::new()
                    },
                    if self.slots_csv.is_some() {
                        format!(", --slots-csv of {nodes} node(s)")
                    } else {
                        String::new()
                    },
                    if particles > 0 {
                        format!(", --particles {particles}")
                    } else {
                        String::new()
                    },
                ) + if shm > 0 {
                    " and the estimate queue's shared memory at the accepted QoS limit"
                } else {
                    ""
                }),
                recording.saturating_add(pf).saturating_add(shm),
            )
    }
}

/// Address space the loop maps beyond what `--max-memory` counts, under `ulimit -v`: the
/// assembler's window of pending instants, the publisher's slot segment and the services'
/// shared state it maps, its threads and the writers of its outputs (docs/security.md,
/// "Limits of the machine", has the measurements behind this figure).
const RUN_ADDRESS_RESERVE: u64 = 12 << 20;

fn observation_bytes() -> u64 {
    size_of::<wire::Observation>() as u64
}
