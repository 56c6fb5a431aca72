//! The options of `ipc-runner run` (shared with `demo`).

use estpipe_wire as wire;
use serde::Serialize;
use std::path::PathBuf;

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
    /// Estimators to run, comma-separated (default: all real-time ones that apply to the
    /// scenario; `pf` only with `--particles N` or when named here).
    #[arg(long, value_delimiter = ',')]
    pub estimators: Vec<String>,
    /// Particles of the `pf` reference filter (single-node scenarios with occlusion regions,
    /// a preset or a TOML file, and `nn-token-bucket`; far slower per step than the other
    /// estimators). Default: `pf` is not run unless `--estimators` names it (then
    /// 5000).
    #[arg(long)]
    pub particles: Option<usize>,
    /// Known loss rate P for the occlusion estimators' mixture option: adds `cce-mix`,
    /// `kf-io-mix`, `adf-mix` (and `pf-mix`), which read a dropout as "occluded, or lost in
    /// transport with probability P" (docs/occlusion.md, "Losses").
    #[arg(long, default_value_t = 0.0, value_name = "P",
          value_parser = crate::eval::cli::loss_probability)]
    pub loss_rate: f64,
    /// Service-name prefix (must match channel-sim's).
    #[arg(long, default_value = wire::DEFAULT_PREFIX)]
    pub prefix: String,
    /// How to wait for slots.
    #[arg(long, value_enum, default_value_t = WaitMode::Spin)]
    pub wait: WaitMode,
    /// Data deadline: the publisher counts as lost this many ms after the expected slot.
    #[arg(long, default_value_t = 100.0)]
    pub deadline_ms: f64,
    /// Seconds to wait for the first slot (and for a restarted publisher); 0 = forever.
    #[arg(long, default_value_t = 30.0)]
    pub connect_timeout: f64,
    /// After losing the publisher, wait for channel-sim to come back instead of failing.
    #[arg(long)]
    pub wait_for_restart: bool,
    /// Slot queue length of the subscriber (older slots are overwritten when it is full).
    #[arg(long, default_value_t = 256)]
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
    #[arg(long, default_value_t = channel_sim::publisher::DEFAULT_STEPS)]
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
    #[arg(long, hide = true)]
    pub debug_slow_us: Option<u64>,
    /// Suppress progress messages.
    #[arg(long)]
    pub quiet: bool,
}

impl RunArgs {
    /// Defaults for `prefix` and `scenario` (as on the command line).
    pub fn new(scenario: &str, prefix: &str) -> Self {
        Self {
            scenario: scenario.to_string(),
            config: None,
            estimators: Vec::new(),
            particles: None,
            loss_rate: 0.0,
            prefix: prefix.to_string(),
            wait: WaitMode::Spin,
            deadline_ms: 100.0,
            connect_timeout: 30.0,
            wait_for_restart: false,
            buffer: 256,
            cpu: None,
            mlock: false,
            seed: 0,
            run: 0,
            steps: channel_sim::publisher::DEFAULT_STEPS,
            estimates_csv: None,
            slots_csv: None,
            latency_csv: None,
            json: None,
            no_publish_estimates: false,
            latest_estimates: false,
            debug_slow_us: None,
            quiet: false,
        }
    }
}
