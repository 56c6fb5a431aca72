//! `ipc-runner eval`: the command-line front of the Monte-Carlo evaluation.

use std::path::{Path, PathBuf};

use channel_sim::scenario;

use super::{evaluate_with, Control, EvalEnding, RunConfig};
use crate::estimator_args::{EstimatorArgs, Feed};
use crate::estimators::FACTORIES;
use crate::eval::EvalOptions;
use crate::limits::{check_outputs, given, Budget};

/// Arguments of `ipc-runner eval`.
#[derive(Debug, clap::Args)]
pub struct EvalArgs {
    /// Preset scenario name (e.g. `linear`, `occlusion`, `nn-token-bucket`, `tobit-fusion`;
    /// default: occlusion, as every other subcommand).
    #[arg(long, conflicts_with = "config")]
    pub scenario: Option<String>,
    /// Scenario TOML file (see channel-sim/scenarios/example.toml).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Number of Monte-Carlo runs.
    #[arg(long, default_value_t = 500, value_parser = clap::value_parser!(u64).range(1..))]
    pub runs: u64,
    /// Instants per run, the horizon T (k = 1..=T), as `--steps` of every subcommand (the
    /// flag's former name is accepted too).
    #[arg(long = "steps", alias = "horizon", value_name = "T",
          default_value_t = estpipe_wire::DEFAULT_STEPS,
          value_parser = clap::value_parser!(u32).range(1..))]
    pub horizon: u32,
    /// Experiment seed (same seed → identical results).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Write the JSON result here.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Write MSE(k) per estimator as CSV here.
    #[arg(long, value_name = "FILE")]
    pub csv: Option<PathBuf>,
    /// Write the MSE and trajectory plot here (`.svg` or `.png`).
    #[arg(long, value_name = "FILE.svg|FILE.png")]
    pub plot: Option<PathBuf>,
    /// Worker threads (default: one per core).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..=MAX_THREADS))]
    pub threads: Option<u64>,
    /// No progress (by default a bar on a terminal, else a line every few seconds on stderr
    /// with done/total and ETA).
    #[arg(long)]
    pub quiet: bool,
    /// Memory the evaluation may hold, in MiB: the per-k sums over the horizon, the per-run
    /// averages, the particles. Flags that need more are refused before any work, with the
    /// numbers.
    #[arg(long, value_name = "MIB", default_value_t = crate::limits::DEFAULT_MAX_MEMORY_MIB,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub max_memory: u64,
    /// Test hook: seconds between the progress lines written when stderr is not a terminal.
    #[cfg(feature = "test-hooks")]
    #[arg(long, hide = true, default_value_t = crate::limits::PROGRESS_LINE_EVERY.as_secs_f64(),
          value_parser = estpipe_process::flags::seconds)]
    pub progress_every: f64,
    /// A transport stage after the channel that loses every slot with probability P (its own
    /// random stream: the channel's randomness is unchanged); the lost slots reach the
    /// estimators marked lost (no information).
    #[arg(long, default_value_t = 0.0, value_name = "P", value_parser = loss_probability)]
    pub transport_loss: f64,
    /// The transport losses look like channel dropouts (the receiver sees only "no packet").
    #[arg(long, requires = "transport_loss")]
    pub transport_loss_unmarked: bool,
    /// A transport stage after the channel that delays slots by whole instants (its own random
    /// stream): `mix:P:D` late with probability P, then 1..=D instants late uniformly; or
    /// `geom:P`, each further instant with probability P. A late slot is missing at its
    /// instant; with `--lag L` the estimators fold it in when it arrives (docs/pipeline.md,
    /// "Late packets").
    #[arg(long, value_name = "DIST")]
    pub transport_delay: Option<super::delay::Delay>,
    /// Print every estimator's paired difference from the estimator NAME over the same runs
    /// (mean of the per-run differences of the run-averaged MSE, its standard error, and the
    /// difference relative to NAME), under the summary. NAME must be one of the estimators run.
    #[arg(long, value_name = "NAME")]
    pub paired: Option<String>,
    /// The estimators and their options (as in `run`, `demo` and `replay`); the summary and
    /// JSON count the gate's rejections.
    #[command(flatten)]
    pub estimator: EstimatorArgs,
}

impl EvalArgs {
    /// `--progress-every` (feature `test-hooks`).
    #[cfg(feature = "test-hooks")]
    fn progress_every(&self) -> std::time::Duration {
        std::time::Duration::from_secs_f64(self.progress_every)
    }

    /// A shipped build parses no test hook: the progress lines' own interval.
    #[cfg(not(feature = "test-hooks"))]
    fn progress_every(&self) -> std::time::Duration {
        crate::limits::PROGRESS_LINE_EVERY
    }
}

/// Most worker threads `--threads` accepts (each holds a run's records).
pub const MAX_THREADS: u64 = 1024;

/// The worker threads without `--threads`: `RAYON_NUM_THREADS` when it is set (rayon's
/// convention, `0` meaning the default), else one per core. The variable is checked like
/// the flag: rayon itself panicked on `RAYON_NUM_THREADS=3000` when it could not start them.
pub fn default_threads(env: Option<&std::ffi::OsStr>) -> Result<usize, String> {
    let cores = || std::thread::available_parallelism().map_or(1, |n| n.get());
    let Some(value) = env else {
        return Ok(cores());
    };
    let bad = || {
        format!(
            "RAYON_NUM_THREADS={}: a worker count 0..={MAX_THREADS} (0: one per core) or unset",
            value.to_string_lossy()
        )
    };
    match value.to_str().and_then(|v| v.trim().parse::<u64>().ok()) {
        Some(0) => Ok(cores()),
        Some(n) if n <= MAX_THREADS => Ok(n as usize),
        _ => Err(bad()),
    }
}

/// Address space `eval` on `threads` workers needs beyond its budget, under a limit: every
/// worker's stack (2 MiB, Rust's default) and the scratch of the run it computes, and the
/// pool, the progress and the writers of the results (docs/security.md, "Limits of the
/// machine", has the measurements behind these figures).
pub fn address_reserve(threads: usize) -> u64 {
    const MIB: u64 = 1 << 20;
    ADDRESS_RESERVE_MIB * MIB + (threads as u64).saturating_mul(ADDRESS_PER_THREAD_MIB * MIB)
}

/// [`address_reserve`]'s fixed part, MiB.
const ADDRESS_RESERVE_MIB: u64 = 6;
/// [`address_reserve`]'s part per worker thread, MiB.
const ADDRESS_PER_THREAD_MIB: u64 = 3;

/// A probability in `[0, 1)` (a loss rate).
pub fn loss_probability(s: &str) -> Result<f64, String> {
    estpipe_process::flags::probability_below_one(s)
}

/// A failed command: exit code 2 for bad input (flags, scenario, configuration), 1 otherwise.
#[derive(Debug)]
pub struct CommandError {
    /// Process exit code.
    pub code: i32,
    /// One-line message.
    pub message: String,
}

impl CommandError {
    /// Bad input (exit code 2).
    pub fn usage(message: impl std::fmt::Display) -> Self {
        Self {
            code: 2,
            message: message.to_string(),
        }
    }

    /// A failure while running (exit code 1).
    pub fn failure(message: impl std::fmt::Display) -> Self {
        Self {
            code: 1,
            message: message.to_string(),
        }
    }
}

/// Runs `ipc-runner eval`. Every output is checked before the first run; once runs are
/// done, the summary, JSON and CSV are written whatever ends the evaluation (a signal: exit
/// code 130; a failed run: 1), with the ending in both.
pub fn run(args: EvalArgs) -> Result<(), CommandError> {
    check_output_flags(&args)?;
    // clap lets through one of the two, never both; neither is the default preset.
    let scenario = scenario::resolve(
        args.scenario
            .as_deref()
            .unwrap_or(crate::demo::DEFAULT_SCENARIO),
        args.config.as_deref(),
    )
    .map_err(CommandError::usage)?;
    let (threads, budget) = threads_and_budget(&args, &*scenario)?;
    let options = options(&args, &*scenario)?;
    let run_config = RunConfig {
        // Always a count: rayon would read RAYON_NUM_THREADS again, unchecked.
        threads: Some(threads),
        progress: !args.quiet,
    };
    // The first call installs the handler (iceoryx2's, as `run` uses): from here on SIGINT
    // and SIGTERM stop the evaluation after the runs in progress instead of killing it.
    let _ = estpipe_process::signal::termination_requested();
    let stop = estpipe_process::signal::termination_requested;
    let control = Control {
        budget,
        progress_every: args.progress_every(),
        stop: Some(&stop),
    };
    let mut result = evaluate_with(&*scenario, &options, FACTORIES, &run_config, &control)
        .map_err(|e| {
            if crate::limits::BadInput::is_in(&e) {
                CommandError::usage(format!("{e:#}"))
            } else {
                CommandError::failure(format!("{e:#}"))
            }
        })?;
    if let Some(c) = scenario
        .as_any()
        .downcast_ref::<scenario::ComposedScenario>()
    {
        result.warnings = c.warnings();
    }
    let failures = write_results(&args, &mut result, &*scenario, &options);
    ending(&result, &options, failures)
}

/// `--plot`'s extension, and no output over an input or another output.
fn check_output_flags(args: &EvalArgs) -> Result<(), CommandError> {
    if let Some(plot) = &args.plot {
        crate::plot::check_extension(plot).map_err(CommandError::usage)?;
    }
    let outputs = given(&[
        ("--json", args.json.as_deref()),
        ("--csv", args.csv.as_deref()),
        ("--plot", args.plot.as_deref()),
    ]);
    let inputs = given(&[("--config", args.config.as_deref())]);
    check_outputs(&outputs, &inputs).map_err(CommandError::usage)
}

/// The worker threads, and the memory budget once the particles of every thread fit in it.
fn threads_and_budget(
    args: &EvalArgs,
    scenario: &dyn channel_sim::Scenario,
) -> Result<(usize, Budget), CommandError> {
    let threads = match args.threads {
        Some(t) => t as usize,
        None => default_threads(std::env::var_os("RAYON_NUM_THREADS").as_deref())
            .map_err(CommandError::usage)?,
    };
    let budget = Budget::mib(args.max_memory)
        .within_address_space(address_reserve(threads), "eval")
        .map_err(CommandError::usage)?;
    let particles = args.estimator.particle_count();
    // Before any estimator is built (the selection below builds them): a particle filter
    // allocates its particles at once.
    budget
        .check(
            &format!("--particles {particles} on {threads} thread(s)"),
            crate::limits::product(&[
                particles as u64,
                crate::estimators::pf_bytes_per_particle_for(&scenario.estimator_spec()),
                threads as u64 + 1,
            ]),
        )
        .map_err(CommandError::usage)?;
    Ok((threads, budget))
}

/// The evaluation's options, with the estimators selected among those that build.
fn options(
    args: &EvalArgs,
    scenario: &dyn channel_sim::Scenario,
) -> Result<EvalOptions, CommandError> {
    let mut options = EvalOptions {
        runs: args.runs,
        horizon: args.horizon,
        seed: args.seed,
        transport_loss: args.transport_loss,
        transport_loss_unmarked: args.transport_loss_unmarked,
        transport_delay: args.transport_delay,
        ..args.estimator.options()
    };
    // Every estimator that applies, built once for run 0 before any work: what refuses to
    // build (a P0 that is not positive definite, a model no occlusion filter has a size
    // for) is the scenario's fault, so it is bad input (exit 2) naming its origin.
    let all = crate::estimators::build_all(
        FACTORIES,
        &scenario.estimator_spec(),
        &options,
        &crate::estimators::RunStart {
            seed: options.seed,
            run: 0,
            initial: None,
        },
    )
    .map_err(|e| {
        let origin = match &args.config {
            Some(c) => format!("--config {}", c.display()),
            None => format!("--scenario {}", scenario.name()),
        };
        CommandError::usage(format!("{origin}: {e:#}"))
    })?;
    options.estimators = args
        .estimator
        .select(&all, scenario.name(), Feed::Simulation)
        .map_err(CommandError::usage)?;
    if let Some(reference) = &args.paired {
        if !options.estimators.iter().any(|n| n == reference) {
            return Err(CommandError::usage(format!(
                "--paired {reference}: not one of the estimators run ({})",
                options.estimators.join(", ")
            )));
        }
    }
    Ok(options)
}

/// Prints the summary and writes every output asked for; returns what failed.
fn write_results(
    args: &EvalArgs,
    result: &mut super::EvalResult,
    scenario: &dyn channel_sim::Scenario,
    options: &EvalOptions,
) -> Vec<String> {
    // What the runs computed goes out first, each output on its own: one that fails does
    // not keep the others from being written.
    let mut failures = Vec::new();
    let bound = super::nn_bound::after_eval(result, scenario, args.plot.as_deref());
    if let Err(e) = bound {
        failures.push(format!("{e:#}"));
    }
    estpipe_process::out!("{}", result.summary());
    if let Some(reference) = &args.paired {
        estpipe_process::out!("{}", super::paired::table(result, reference));
    }
    let mut wrote = Vec::new();
    if let Some(path) = &args.json {
        match write(path, &result.to_json()) {
            Ok(()) => wrote.push(path.clone()),
            Err(e) => failures.push(e),
        }
    }
    if let Some(path) = &args.csv {
        match write(path, &result.to_csv()) {
            Ok(()) => wrote.push(path.clone()),
            Err(e) => failures.push(e),
        }
    }
    if let Some(path) = &args.plot {
        match crate::plot::plot(result, path) {
            Ok(()) => wrote.push(path.clone()),
            Err(e) => failures.push(format!("{}: {e:#}", path.display())),
        }
        // Scenarios with a shared token bucket (seed 004): Fig. 2 beside the plot.
        match crate::plot::tokens::plot_for(scenario, options.seed, options.horizon, path) {
            Ok(Some(p)) => wrote.push(p),
            Ok(None) => {}
            Err(e) => failures.push(format!("token plot: {e:#}")),
        }
    }
    for path in &wrote {
        estpipe_process::outln!("wrote {}", path.display());
    }
    failures
}

/// The command's outcome from how the evaluation ended and what failed to be written.
fn ending(
    result: &super::EvalResult,
    options: &EvalOptions,
    mut failures: Vec<String>,
) -> Result<(), CommandError> {
    match result.ending {
        EvalEnding::Interrupted => {
            return Err(CommandError {
                code: 130,
                message: format!(
                    "interrupted after {} of {} runs (their results were written)",
                    result.runs, options.runs
                ),
            });
        }
        EvalEnding::Failed => failures.insert(
            0,
            format!(
                "run {} failed: {}",
                result.runs,
                result.error.as_deref().unwrap_or("?")
            ),
        ),
        EvalEnding::Completed => {}
    }
    if failures.is_empty() {
        Ok(())
    } else {
        Err(CommandError::failure(failures.join("; ")))
    }
}

/// Whole or not at all: a full disk must not leave a 0-byte or half-written `--json`.
fn write(path: &Path, text: &str) -> Result<(), String> {
    estpipe_process::whole_file::write(path, text).map_err(|e| format!("{}: {e}", path.display()))
}
