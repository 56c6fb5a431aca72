//! `ipc-runner run`: the real-time loop over shared memory.
//!
//! Per slot: receive in place → reassemble the instant ([`assemble`]) → step every estimator →
//! publish each estimate in place (`loan_uninit` / `write_payload` / `send`) → record
//! latencies ([`crate::latency`]) and the squared error against the truth service (evaluation
//! beside the loop, never inside the estimator). Once the estimators exist nothing in this path
//! allocates except iceoryx2 0.10 itself, one small block per estimate loaned on the queue
//! (none on the `--latest-estimates` blackboard; `tests/pipeline_alloc.rs` counts).
//!
//! The queue samples of the next instant are loaned right after an instant's estimates are
//! published, off the latency path. At p50 this changes nothing (a first trial measured
//! end-to-end p50 only and dropped it), but a loan after 100 µs of idling is slow in the tail:
//! alone, paced at 10 kHz, `loan_uninit` took p50 0.26 µs, p99 1.8 µs (0.16 µs p99 back to
//! back — the memory it touches goes cold while the loop waits). In 6 interleaved
//! 30 000-instant spin runs at 10 kHz, the runner's own share (received → estimates
//! published, from `latency.csv`) had p99 1.86–2.62 µs (median 2.38) with the loans ahead
//! against 1.91–3.06 µs (median 2.70) without; lower in 5 of the 6 pairs.
//!
//! Waiting: `--wait spin` busy-polls `receive()`; `--wait block` sleeps in a WaitSet on the
//! `slots-ready` event and re-drains `receive()` after every wake-up (wake-ups can be spurious
//! and one notification may stand for several slots).
//!
//! Faults: when no slot arrives within `period + --deadline-ms` of the previous one the
//! runner cleans up dead nodes (`try_cleanup_dead_nodes`: a SIGKILLed publisher is otherwise
//! invisible), reports the publisher as lost and exits with [`EXIT_PUBLISHER_LOST`], or with
//! `--wait-for-restart` waits for a new channel-sim and starts a new session (fresh
//! estimators; the new process starts its stream at k = 1).

pub mod assemble;
pub mod select;
pub mod system;

use crate::latency::{Latency, LatencySummary};
use crate::transport::Transport;
use crate::Estimator;
use anyhow::{anyhow, bail, Context, Result};
use assemble::{Assembler, Counts, Pushed};
use channel_sim::sim::MAX_NX;
use channel_sim::wire::{self, Estimate, WIRE_VERSION};
use channel_sim::Observation;
use iceoryx2::port::listener::ListenerWaitError;
use iceoryx2::port::writer::{EntryHandleMut, Writer};
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::blackboard;
use iceoryx2::waitset::WaitSetRunResult;
use serde::Serialize;
use std::path::PathBuf;
use std::time::Duration;

/// Exit code when the publisher was lost (deadline passed) and no restart was awaited.
pub const EXIT_PUBLISHER_LOST: i32 = 3;

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
    /// Estimators to run, comma-separated (default: all that apply to the scenario).
    #[arg(long, value_delimiter = ',')]
    pub estimators: Vec<String>,
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

/// Per-estimator results.
#[derive(Clone, Debug, Serialize)]
pub struct EstimatorReport {
    /// Estimator name.
    pub name: String,
    /// Mean over instants of ‖x_k − x̂_k‖² (instants whose truth was received).
    pub mse: f64,
    /// Instants in the MSE.
    pub mse_instants: u64,
    /// Steps the estimator refused (e.g. non-finite measurement); its state was kept.
    pub rejected: u64,
}

/// How the run ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Ending {
    /// The publisher sent its END marker.
    Completed,
    /// The publisher was stopped early (ABORT marker).
    PublisherStopped,
    /// The runner got SIGINT/SIGTERM.
    Interrupted,
    /// The data deadline passed and no restart was awaited.
    PublisherLost,
}

/// What a run did.
#[derive(Clone, Debug, Serialize)]
pub struct RunReport {
    /// Scenario name.
    pub scenario: String,
    /// Wait mode.
    pub wait: WaitMode,
    /// Slot accounting.
    pub counts: Counts,
    /// Per-estimator results.
    pub estimators: Vec<EstimatorReport>,
    /// Latency percentiles.
    pub latency: LatencySummary,
    /// Streams followed (1 + publisher restarts).
    pub sessions: u32,
    /// Times the data deadline passed.
    pub publisher_losses: u32,
    /// Truth messages missing for processed instants.
    pub truth_missing: u64,
    /// Allocations after warm-up (only with an allocation probe).
    pub allocations_after_warmup: Option<usize>,
    /// Slots received after warm-up (denominator of the above).
    pub slots_after_warmup: u64,
    /// Estimates published after warm-up (iceoryx2 0.10's `loan_uninit` allocates one
    /// reference count per sample, inside the library).
    pub published_after_warmup: u64,
    /// Outcome of `--cpu` / `--mlock` (`None` if not requested).
    pub cpu_pinning: Option<String>,
    /// Outcome of `--mlock`.
    pub memory_lock: Option<String>,
    /// Set-up conditions that will show in the latency (e.g. spinning under RT throttling).
    pub warnings: Vec<String>,
    /// How the run ended.
    pub ending: Ending,
}

/// Recorded trajectories (preallocated; recording stops when full).
#[derive(Debug, Default)]
pub struct Trajectories {
    /// Session, k per recorded instant.
    pub keys: Vec<(u32, u32)>,
    /// Truth per instant (`nx` values, NaN when missing).
    pub truth: Vec<f64>,
    /// Estimates per instant and estimator (`n_est · nx` values).
    pub estimates: Vec<f64>,
    /// Per instant: the completing slot's send time, its receive time and the time the
    /// instant's estimates were all published (`CLOCK_MONOTONIC` ns).
    pub timing: Vec<[u64; 3]>,
    /// Received slots (for `replay`), if requested.
    pub slots: Vec<Observation>,
    /// State dimension.
    pub nx: usize,
    /// Estimator names.
    pub names: Vec<String>,
}

const TRUTH_RING: usize = 1024;

/// Spin mode reads the clock once per this many empty polls. A `clock_gettime` costs about
/// as much as a poll (a profile of the spin loop found 40 % of its time in the clock, twice
/// per poll), so reading it every poll doubles the time between polls, and with it the
/// delay before a landed slot is seen. The deadlines the clock serves are milliseconds;
/// 256 polls are some tens of µs.
const SPIN_CLOCK_EVERY: u32 = 256;

struct State {
    estimators: Vec<Box<dyn Estimator>>,
    nx: usize,
    /// The latest estimate of every estimator.
    xhat: Vec<[f64; MAX_NX]>,
    truth_k: Box<[u32; TRUTH_RING]>,
    truth_x: Box<[[f64; MAX_NX]; TRUTH_RING]>,
    truth_stream: u64,
    sq_err: Vec<f64>,
    err_n: Vec<u64>,
    rejected: Vec<u64>,
    names: Vec<[u8; 16]>,
    latency: Latency,
    est_seq: u64,
    truth_missing: u64,
    session: u32,
    traj: Trajectories,
    record_slots: bool,
    record_cap: usize,
    publish: bool,
    /// The latest-estimate board, when estimates go there instead of the queue.
    board: Option<LatestBoard>,
    /// Per estimator, when its step of the current instant started and ended (recorded in the
    /// histogram after publishing).
    step_ns: Vec<(u64, u64)>,
    /// Queue samples loaned after an instant for the next one's estimates (one per estimator,
    /// up to [`crate::transport::PRELOANED_ESTIMATES`]).
    held: Vec<Option<PreLoaned>>,
    /// Estimates published (after warm-up, for the allocation accounting).
    published: u64,
    // set per slot by the receive path
    last_send_ns: u64,
    last_recv_ns: u64,
    last_k: u32,
    stream_id: u64,
    err: Option<anyhow::Error>,
}

/// A queue sample loaned ahead of its estimate.
type PreLoaned = iceoryx2::sample_mut_uninit::SampleMutUninit<
    ipc::Service,
    core::mem::MaybeUninit<Estimate>,
    (),
>;

/// The writer side of `channel_sim::wire::latest_estimates_board`, one entry handle per
/// estimator (created once; updating an entry writes in place and allocates nothing).
struct LatestBoard {
    entries: Vec<EntryHandleMut<ipc::Service, u32, Estimate>>,
    _writer: Writer<ipc::Service, u32>,
    _service: blackboard::PortFactory<ipc::Service, u32>,
}

impl LatestBoard {
    fn create(t: &Transport, prefix: &str, names: &[[u8; 16]]) -> Result<Self> {
        let service = wire::latest_estimates_board(&t.node, prefix, names)?;
        let writer = service
            .writer_builder()
            .create()
            .map_err(|e| anyhow!("cannot write {prefix}/{}: {e:?}", wire::LATEST_ESTIMATES))?;
        let entries = (0..names.len() as u32)
            .map(|i| {
                writer
                    .entry::<Estimate>(&i)
                    .map_err(|e| anyhow!("estimate board entry {i}: {e:?}"))
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Self {
            entries,
            _writer: writer,
            _service: service,
        })
    }
}

impl State {
    fn drain_truth(&mut self, t: &Transport) {
        while let Ok(Some(s)) = t.truth_sub.receive() {
            let m = s.payload();
            if m.version != WIRE_VERSION {
                continue;
            }
            let i = m.k as usize % TRUTH_RING;
            self.truth_k[i] = m.k;
            self.truth_x[i] = m.x;
            self.truth_stream = m.stream_id;
        }
    }

    /// Steps every estimator on instant `k` and publishes the estimates; the evaluation
    /// against truth (MSE, recording) runs after publishing, off the latency path.
    fn on_instant(&mut self, t: &Transport, k: u32, obs: &[Observation]) {
        let nx = self.nx;
        for (e, est) in self.estimators.iter_mut().enumerate() {
            let t0 = wire::monotonic_ns();
            let status = match est.step(k, obs) {
                Ok(()) => 0,
                Err(_) => {
                    self.rejected[e] += 1;
                    1
                }
            };
            let xhat = &mut self.xhat[e];
            est.estimate(&mut xhat[..nx]);
            let t1 = wire::monotonic_ns();
            self.step_ns[e] = (t0, t1);
            let seq = self.est_seq;
            self.est_seq += 1;
            if !self.publish {
                continue;
            }
            self.published += 1;
            let msg = Estimate {
                version: WIRE_VERSION,
                k,
                stream_id: self.stream_id,
                seq,
                estimator: e as u32,
                nx: nx as u32,
                name: self.names[e],
                status,
                reserved: 0,
                x: *xhat,
                slot_send_ns: self.last_send_ns,
                receive_ns: self.last_recv_ns,
                step_done_ns: t1,
            };
            if let Some(b) = &self.board {
                b.entries[e].update_with_copy(msg);
                continue;
            }
            let sent = match self.held.get_mut(e).and_then(Option::take) {
                Some(s) => Ok(s),
                None => t.estimate_pub.loan_uninit(),
            }
            .map_err(|e| anyhow!("loan for estimate: {e:?}"))
            .and_then(|s| {
                s.write_payload(msg)
                    .send()
                    .map_err(|e| anyhow!("send estimate: {e:?}"))
            });
            if let Err(e) = sent {
                self.err.get_or_insert(e);
            }
        }
        let done_ns = wire::monotonic_ns();
        // Statistics after the estimates are out: a histogram bucket can be a cache miss.
        for &(t0, t1) in &self.step_ns {
            Latency::record(&mut self.latency.step, t0, t1);
        }
        Latency::record(&mut self.latency.end_to_end, self.last_send_ns, done_ns);
        self.last_k = k;
        self.evaluate(t, k, done_ns);
        self.preloan(t);
    }

    /// Loans the next instant's queue samples now, off the latency path. A failed loan is
    /// left to the send, which then loans itself and reports the error.
    fn preloan(&mut self, t: &Transport) {
        if !self.publish || self.board.is_some() {
            return;
        }
        for h in self.held.iter_mut().filter(|h| h.is_none()) {
            match t.estimate_pub.loan_uninit() {
                Ok(s) => *h = Some(s),
                Err(_) => break,
            }
        }
    }

    /// Errors against truth and the recorded trajectories of instant `k`, whose estimates
    /// were published at `done_ns`.
    fn evaluate(&mut self, t: &Transport, k: u32, done_ns: u64) {
        self.drain_truth(t);
        let i = k as usize % TRUTH_RING;
        let truth = (self.truth_k[i] == k && self.truth_stream == self.stream_id)
            .then_some(self.truth_x[i]);
        if truth.is_none() {
            self.truth_missing += 1;
        }
        let nx = self.nx;
        let record = self.traj.keys.len() < self.record_cap;
        if record {
            self.traj.keys.push((self.session, k));
            self.traj
                .timing
                .push([self.last_send_ns, self.last_recv_ns, done_ns]);
            for j in 0..nx {
                self.traj.truth.push(truth.map_or(f64::NAN, |x| x[j]));
            }
        }
        for (e, xhat) in self.xhat.iter().enumerate() {
            if let Some(x) = truth {
                let d: f64 = (0..nx).map(|j| (x[j] - xhat[j]).powi(2)).sum();
                self.sq_err[e] += d;
                self.err_n[e] += 1;
            }
            if record {
                self.traj.estimates.extend_from_slice(&xhat[..nx]);
            }
        }
    }
}

enum Woke {
    Ready,
    Signal,
}

/// Runs the loop with estimators from `make` (called again for every new stream) until the
/// stream ends. Errors are configuration/transport failures; a lost publisher is reported in
/// [`RunReport::ending`].
pub fn run_loop(
    args: &RunArgs,
    nx: usize,
    nodes: u8,
    ny: u8,
    make: &dyn Fn() -> Result<Vec<Box<dyn Estimator>>>,
    mut hooks: Hooks<'_>,
) -> Result<(RunReport, Trajectories)> {
    let cpu_pinning = args.cpu.map(|c| match system::pin_to_cpu(c) {
        Ok(()) => format!("pinned to CPU {c}"),
        Err(e) => format!("not pinned ({e})"),
    });
    let memory_lock = args.mlock.then(|| match system::lock_memory() {
        Ok(()) => "locked".to_string(),
        Err(e) => format!("not locked ({e})"),
    });
    let say = |m: &str| {
        if !args.quiet {
            eprintln!("ipc-runner: {m}");
        }
    };
    for m in cpu_pinning.iter().chain(memory_lock.iter()) {
        say(m);
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

    let t = Transport::open(&args.prefix, args.buffer, args.wait != WaitMode::Spin)?;
    let estimators = make()?;
    let n_est = estimators.len();
    let record_cap = args.steps as usize;
    let mut st = State {
        names: estimators
            .iter()
            .map(|e| Estimate::encode_name(e.name()))
            .collect(),
        traj: Trajectories {
            keys: Vec::with_capacity(record_cap),
            truth: Vec::with_capacity(record_cap * nx),
            estimates: Vec::with_capacity(record_cap * nx * n_est),
            timing: Vec::with_capacity(record_cap),
            slots: Vec::with_capacity(if args.slots_csv.is_some() {
                record_cap * usize::from(nodes)
            } else {
                0
            }),
            nx,
            names: estimators.iter().map(|e| e.name().to_string()).collect(),
        },
        estimators,
        nx,
        xhat: vec![[0.0; MAX_NX]; n_est],
        truth_k: Box::new([u32::MAX; TRUTH_RING]),
        truth_x: Box::new([[0.0; MAX_NX]; TRUTH_RING]),
        truth_stream: 0,
        sq_err: vec![0.0; n_est],
        err_n: vec![0; n_est],
        rejected: vec![0; n_est],
        latency: Latency::new(),
        est_seq: 0,
        truth_missing: 0,
        session: 1,
        record_slots: args.slots_csv.is_some(),
        record_cap,
        publish: !args.no_publish_estimates,
        board: None,
        step_ns: vec![(0, 0); n_est],
        held: (0..n_est.min(crate::transport::PRELOANED_ESTIMATES))
            .map(|_| None)
            .collect(),
        published: 0,
        last_send_ns: 0,
        last_recv_ns: 0,
        last_k: 0,
        stream_id: 0,
        err: None,
    };
    if args.latest_estimates {
        st.board = Some(LatestBoard::create(&t, &args.prefix, &st.names)?);
    }
    let mut asm = Assembler::new(nodes, ny);
    asm.set_subscribed_ns(t.subscribed_ns);
    let deadline_ns = (args.deadline_ms * 1e6) as u64;
    let connect_ns = (args.connect_timeout * 1e9) as u64;
    let warmup = if hooks.warmup == 0 { 20 } else { hooks.warmup };
    let mut allocs_at_warmup: Option<usize> = None;
    let mut allocs_at_end: Option<usize> = None;
    let mut slots_at_warmup = 0u64;
    let mut published_at_warmup = 0u64;
    let mut publisher_losses = 0u32;
    let mut period_ns = 0u64;
    let mut last_progress = 0u64;
    // `None` while waiting for the first slot of a stream (connect timeout applies).
    let mut last_data_ns: Option<u64> = None;
    let mut waiting_since = wire::monotonic_ns();

    // iceoryx2 installs its SIGINT/SIGTERM handler on the first `Node::wait`; do that before
    // announcing the wait, so Ctrl-C ends the run cleanly in every wait mode from here on
    // (the listener's wait would otherwise leave the signal to its default action, which
    // kills the process without a report). Before this call a signal ends the process, so
    // there is no earlier signal to carry over.
    let _ = t.node.wait(Duration::ZERO);
    say(&format!(
        "waiting for channel-sim on prefix {:?} ({} wait)",
        args.prefix,
        args.wait.as_str()
    ));

    // The wait primitive: spin or WaitSet on the event listener.
    let waitset = match &t.listener {
        Some(_) if args.wait == WaitMode::Block => Some(
            WaitSetBuilder::new()
                .create::<ipc::Service>()
                .map_err(|e| anyhow!("cannot create WaitSet: {e:?}"))?,
        ),
        _ => None,
    };
    let guard = match (&waitset, &t.listener) {
        (Some(ws), Some(l)) => Some(
            ws.attach_notification(l)
                .map_err(|e| anyhow!("cannot attach listener to WaitSet: {e:?}"))?,
        ),
        _ => None,
    };
    let mut last_signal_check = 0u64;
    let spinning = waitset.is_none() && t.listener.is_none();
    let mut idle_polls = 0u32;
    let mut spin_clock = wire::monotonic_ns();
    let mut spin_signal_check = spin_clock;
    let mut wait = |timeout_ns: u64| -> Result<Woke> {
        match (&waitset, &guard, &t.listener) {
            (Some(ws), Some(g), Some(l)) => {
                let r = ws
                    .wait_and_process_once_with_timeout(
                        |id| {
                            if id.has_event_from(g) {
                                // Consume the notifications; the data is drained by the caller.
                                let _ = l.try_wait(|_| {});
                            }
                            CallbackProgression::Continue
                        },
                        Duration::from_nanos(timeout_ns.max(1000)),
                    )
                    .map_err(|e| anyhow!("WaitSet failed: {e:?}"))?;
                Ok(match r {
                    WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt => {
                        Woke::Signal
                    }
                    _ => Woke::Ready,
                })
            }
            (None, None, Some(l)) => {
                match l.timed_wait(|_| {}, Duration::from_nanos(timeout_ns.max(1000))) {
                    Ok(_) => {}
                    // A signal interrupts the wait itself; it is the user's Ctrl-C, not a failure.
                    Err(ListenerWaitError::InterruptSignal) => return Ok(Woke::Signal),
                    Err(e) => bail!("listener wait failed: {e:?}"),
                }
                let now = wire::monotonic_ns();
                if now - last_signal_check > 1_000_000 {
                    last_signal_check = now;
                    if channel_sim::signal::termination_requested() {
                        return Ok(Woke::Signal);
                    }
                }
                Ok(Woke::Ready)
            }
            _ => {
                // One PAUSE per poll: a longer back-off (32 were here) costs up to ~1.5 µs of
                // latency on a slot that lands just after a poll. Signals are checked by the
                // caller with the clock, every SPIN_CLOCK_EVERY polls.
                core::hint::spin_loop();
                Ok(Woke::Ready)
            }
        }
    };

    let ending = 'outer: loop {
        // Drain everything that is there.
        loop {
            let sample = match t.slot_sub.receive() {
                Ok(Some(s)) => s,
                Ok(None) => break,
                Err(e) => bail!("receive failed: {e:?}"),
            };
            let recv_ns = wire::monotonic_ns();
            let slot = sample.payload();
            if slot.version != WIRE_VERSION {
                bail!(
                    "{}",
                    wire::WireError::Version {
                        found: slot.version
                    }
                );
            }
            last_data_ns = Some(recv_ns);
            if slot.kind == wire::SLOT_DATA {
                period_ns = slot.period_ns;
                st.last_send_ns = slot.send_ns;
                st.last_recv_ns = recv_ns;
            }
            st.stream_id = slot.stream_id;
            let mut pushed = asm.push(slot, &mut |k, obs: &[Observation]| {
                st.on_instant(&t, k, obs);
            });
            if pushed == Ok(Pushed::NewStream) {
                let old = asm.stream();
                asm.reset();
                st.session += 1;
                st.estimators = make()?;
                say(&format!(
                    "new stream from channel-sim (restarted; was {old:x?}): session {} with fresh estimators",
                    st.session
                ));
                pushed = asm.push(slot, &mut |k, obs: &[Observation]| {
                    st.on_instant(&t, k, obs);
                });
            }
            let pushed = pushed.with_context(|| "refusing slot from channel-sim")?;
            // After the instant this slot may have completed was published.
            if slot.kind == wire::SLOT_DATA {
                Latency::record(&mut st.latency.transport, slot.send_ns, recv_ns);
            }
            if st.record_slots
                && pushed == Pushed::Data
                && st.traj.slots.len() < st.traj.slots.capacity()
            {
                if let Ok(o) = slot.observation() {
                    st.traj.slots.push(o);
                }
            }
            drop(sample);
            if let Some(e) = st.err.take() {
                return Err(e);
            }
            if let Some(us) = args.debug_slow_us {
                std::thread::sleep(Duration::from_micros(us));
            }
            if let Some(probe) = hooks.alloc_probe {
                if allocs_at_warmup.is_none() && asm.counts.instants >= warmup {
                    allocs_at_warmup = Some(probe());
                    slots_at_warmup = asm.counts.received;
                    published_at_warmup = st.published;
                }
            }
            match pushed {
                Pushed::End | Pushed::Abort => {
                    allocs_at_end = hooks.alloc_probe.map(|p| p());
                    break 'outer if pushed == Pushed::End {
                        Ending::Completed
                    } else {
                        Ending::PublisherStopped
                    };
                }
                _ => {}
            }
            if let Some(p) = hooks.progress.as_mut() {
                if recv_ns - last_progress > 100_000_000 {
                    last_progress = recv_ns;
                    p(st.last_k, &asm.counts);
                }
            }
        }

        // Nothing pending: check the deadline, then wait. Spinning reads the clock (and
        // checks for signals, every ms) only every SPIN_CLOCK_EVERY polls; a stale `now` can
        // only make a deadline fire later.
        let now = if spinning {
            idle_polls = idle_polls.wrapping_add(1);
            if idle_polls.is_multiple_of(SPIN_CLOCK_EVERY) {
                spin_clock = wire::monotonic_ns();
                if spin_clock - spin_signal_check > 1_000_000 {
                    spin_signal_check = spin_clock;
                    if channel_sim::signal::termination_requested() {
                        break 'outer Ending::Interrupted;
                    }
                }
            }
            spin_clock
        } else {
            wire::monotonic_ns()
        };
        let due = match last_data_ns {
            Some(t_last) => t_last + period_ns + deadline_ns,
            None if connect_ns == 0 => u64::MAX,
            None => waiting_since + connect_ns,
        };
        if now > due {
            let Some(t_last) = last_data_ns else {
                say(&format!(
                    "no data from channel-sim on prefix {:?} within {} s",
                    args.prefix, args.connect_timeout
                ));
                break 'outer Ending::PublisherLost;
            };
            publisher_losses += 1;
            let cleaned = t.node.try_cleanup_dead_nodes();
            say(&format!(
                "publisher lost: no slot for {:.1} ms after instant {} (deadline {} ms past the \
                 expected slot); cleaned up {} dead node(s), {} publisher(s) remain",
                (now - t_last) as f64 / 1e6,
                st.last_k,
                args.deadline_ms,
                cleaned.cleanups,
                t.publishers()
            ));
            if !args.wait_for_restart {
                break 'outer Ending::PublisherLost;
            }
            say("waiting for channel-sim to restart (--wait-for-restart)");
            last_data_ns = None;
            waiting_since = now;
            continue;
        }
        match wait(due.saturating_sub(now).min(50_000_000))? {
            Woke::Ready => {}
            Woke::Signal => break 'outer Ending::Interrupted,
        }
    };

    let estimators = st
        .estimators
        .iter()
        .enumerate()
        .map(|(e, est)| EstimatorReport {
            name: est.name().to_string(),
            mse: if st.err_n[e] > 0 {
                st.sq_err[e] / st.err_n[e] as f64
            } else {
                f64::NAN
            },
            mse_instants: st.err_n[e],
            rejected: st.rejected[e],
        })
        .collect();
    let report = RunReport {
        scenario: args.scenario.clone(),
        wait: args.wait,
        counts: asm.counts,
        estimators,
        latency: st.latency.summary(),
        sessions: st.session,
        publisher_losses,
        truth_missing: st.truth_missing,
        allocations_after_warmup: match (allocs_at_warmup, allocs_at_end) {
            (Some(a), Some(b)) => Some(b - a),
            _ => None,
        },
        slots_after_warmup: asm.counts.received - slots_at_warmup,
        published_after_warmup: st.published - published_at_warmup,
        cpu_pinning,
        memory_lock,
        warnings,
        ending,
    };
    Ok((report, st.traj))
}

impl RunReport {
    /// The summary a person reads at the end of a run.
    pub fn summary(&self) -> String {
        let c = &self.counts;
        let mut s = format!(
            "scenario {} · {} instants · {} wait · ended: {:?}\n\
             slots: {} received ({} delivered, {} dropped by the channel), {} lost in IPC, {} missed before join\n",
            self.scenario,
            c.instants,
            self.wait.as_str(),
            self.ending,
            c.received,
            c.delivered,
            c.dropped_by_channel,
            c.lost_in_ipc,
            c.missed_before_join,
        );
        if self.sessions > 1 || self.publisher_losses > 0 {
            s.push_str(&format!(
                "publisher lost {} time(s); {} session(s)\n",
                self.publisher_losses, self.sessions
            ));
        }
        s.push_str("estimator         MSE vs truth   instants   rejected\n");
        for e in &self.estimators {
            s.push_str(&format!(
                "{:<16} {:>13.6} {:>10} {:>10}\n",
                e.name, e.mse, e.mse_instants, e.rejected
            ));
        }
        s.push_str(&self.latency.table());
        if let Some(a) = self.allocations_after_warmup {
            s.push_str(&format!(
                "allocations after warm-up: {a} over {} slots ({} estimates published)\n",
                self.slots_after_warmup, self.published_after_warmup
            ));
        }
        for w in &self.warnings {
            s.push_str(w);
            s.push('\n');
        }
        s
    }
}

impl Trajectories {
    /// Writes `session,k,truth_0..,<est>_0..` rows.
    pub fn write_estimates_csv(&self, path: &std::path::Path) -> Result<()> {
        use std::io::Write;
        let mut w = std::io::BufWriter::new(
            std::fs::File::create(path).with_context(|| format!("cannot create {path:?}"))?,
        );
        let mut head = String::from("session,k");
        for j in 0..self.nx {
            head.push_str(&format!(",truth_{j}"));
        }
        for n in &self.names {
            for j in 0..self.nx {
                head.push_str(&format!(",{n}_{j}"));
            }
        }
        writeln!(w, "{head}")?;
        let ne = self.names.len();
        for (i, (session, k)) in self.keys.iter().enumerate() {
            write!(w, "{session},{k}")?;
            for v in &self.truth[i * self.nx..(i + 1) * self.nx] {
                write!(w, ",{v:e}")?;
            }
            for v in &self.estimates[i * self.nx * ne..(i + 1) * self.nx * ne] {
                write!(w, ",{v:e}")?;
            }
            writeln!(w)?;
        }
        Ok(())
    }

    /// Writes `session,k,t_s,transport_us,end_to_end_us` rows, one per instant: `t_s` is the
    /// send time of the slot that completed the instant, in seconds since the first recorded
    /// one; the latencies are that slot sent → received and sent → all estimates published.
    /// The end-to-end column is the end-to-end histogram's samples in order; the transport
    /// histogram also holds the other nodes' slots.
    pub fn write_latency_csv(&self, path: &std::path::Path) -> Result<()> {
        use std::io::Write;
        let mut w = std::io::BufWriter::new(
            std::fs::File::create(path).with_context(|| format!("cannot create {path:?}"))?,
        );
        writeln!(w, "session,k,t_s,transport_us,end_to_end_us")?;
        for ((session, k), tr) in self.keys.iter().zip(&self.timing) {
            let (t_s, transport, e2e) = self.latency_point(tr);
            writeln!(w, "{session},{k},{t_s:.6},{transport:.3},{e2e:.3}")?;
        }
        Ok(())
    }

    /// `(seconds since the first recorded send, transport µs, end to end µs)` of one
    /// recorded instant.
    pub fn latency_point(&self, tr: &[u64; 3]) -> (f64, f64, f64) {
        let t0 = self.timing.first().map_or(0, |t| t[0]);
        (
            tr[0].saturating_sub(t0) as f64 * 1e-9,
            tr[1].saturating_sub(tr[0]) as f64 * 1e-3,
            tr[2].saturating_sub(tr[0]) as f64 * 1e-3,
        )
    }

    /// Writes the received slots in the `replay` format (see `docs/replay.md`).
    pub fn write_slots_csv(&self, path: &std::path::Path, ny: usize) -> Result<()> {
        crate::replay::write_slots(path, &self.slots, ny)
    }
}

/// `ipc-runner run`: resolves scenario and estimators, runs the loop, prints the summary.
/// Returns the process exit code.
pub fn main(args: &RunArgs) -> Result<i32> {
    let (scenario, _) = select::scenario(&args.scenario, args.config.as_deref())?;
    let scenario: std::sync::Arc<dyn channel_sim::Scenario> = scenario.into();
    let make = select::estimators(
        scenario.clone(),
        &args.estimators,
        select::Experiment {
            seed: args.seed,
            run: args.run,
            horizon: args.steps,
        },
    )?;
    let (report, traj) = run_loop(
        args,
        scenario.nx(),
        u8::try_from(scenario.nodes())?,
        u8::try_from(scenario.ny())?,
        &make,
        Hooks::default(),
    )?;
    finish(args, &report, &traj, scenario.ny())?;
    println!("{}", report.summary());
    Ok(exit_code(&report))
}

/// Writes the requested output files.
pub fn finish(args: &RunArgs, report: &RunReport, traj: &Trajectories, ny: usize) -> Result<()> {
    if let Some(p) = &args.estimates_csv {
        traj.write_estimates_csv(p)?;
    }
    if let Some(p) = &args.slots_csv {
        traj.write_slots_csv(p, ny)?;
    }
    if let Some(p) = &args.latency_csv {
        traj.write_latency_csv(p)?;
    }
    if let Some(p) = &args.json {
        std::fs::write(p, serde_json::to_string_pretty(report)?)
            .with_context(|| format!("cannot write {p:?}"))?;
    }
    Ok(())
}

/// 0 for a completed (or cleanly stopped) run, [`EXIT_PUBLISHER_LOST`] when the publisher was
/// lost, 130 when interrupted.
pub fn exit_code(r: &RunReport) -> i32 {
    match r.ending {
        Ending::Completed | Ending::PublisherStopped => 0,
        Ending::PublisherLost => EXIT_PUBLISHER_LOST,
        Ending::Interrupted => 130,
    }
}
