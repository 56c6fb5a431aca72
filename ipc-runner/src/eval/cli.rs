//! `ipc-runner eval`: the command-line front of the Monte-Carlo evaluation.

use std::path::{Path, PathBuf};

use channel_sim::scenario;

use super::{evaluate, RunConfig};
use crate::estimators::{EvalOptions, FACTORIES};

/// Arguments of `ipc-runner eval`.
#[derive(Debug, clap::Args)]
pub struct EvalArgs {
    /// Preset scenario name (e.g. `linear`, `occlusion`, `nn-token-bucket`, `tobit-fusion`).
    #[arg(long, required_unless_present = "config", conflicts_with = "config")]
    pub scenario: Option<String>,
    /// Scenario TOML file (see channel-sim/scenarios/example.toml).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Number of Monte-Carlo runs.
    #[arg(long, default_value_t = 500, value_parser = clap::value_parser!(u64).range(1..))]
    pub runs: u64,
    /// Horizon T (instants k = 1..=T).
    #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u32).range(1..))]
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
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub threads: Option<u64>,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// Particles of the `pf` reference filter (single-node scenarios with occlusion regions,
    /// a preset or a TOML file, and `nn-token-bucket`). Off by default in
    /// `eval` (unless `--estimators` names `pf` or `pf-mix`: then 5000): at 5000 particles it
    /// costs ~3 CPU-ms per step, 100× the other estimators together, so a 2000-run
    /// evaluation would take minutes instead of seconds. Typical: `--particles 5000 --runs 200`.
    #[arg(long)]
    pub particles: Option<usize>,
    /// Estimators to evaluate, comma-separated (default: all that apply to the scenario).
    #[arg(long, value_delimiter = ',')]
    pub estimators: Vec<String>,
    /// Known loss rate P of the occlusion estimators' mixture option: `cce-mix`,
    /// `kf-io-mix`, `adf-mix` (and `pf-mix`) read a dropout as "occluded, or lost in
    /// transport with probability P" (docs/occlusion.md, "Losses"). 0 (default): not built.
    #[arg(long, default_value_t = 0.0, value_name = "P", value_parser = loss_probability)]
    pub loss_rate: f64,
    /// A transport stage after the channel that loses every slot with probability P (its own
    /// random stream: the channel's randomness is unchanged); the lost slots reach the
    /// estimators marked lost (no information).
    #[arg(long, default_value_t = 0.0, value_name = "P", value_parser = loss_probability)]
    pub transport_loss: f64,
    /// The transport losses look like channel dropouts (the receiver sees only "no packet").
    #[arg(long, requires = "transport_loss")]
    pub transport_loss_unmarked: bool,
}

/// A probability in `[0, 1)` (a loss rate).
pub fn loss_probability(s: &str) -> Result<f64, String> {
    let p: f64 = s.parse().map_err(|e| format!("{e}"))?;
    if p.is_finite() && (0.0..1.0).contains(&p) {
        Ok(p)
    } else {
        Err(format!("{p} is not in [0, 1)"))
    }
}

/// The particle count of `pf`: `--particles` when given, else 0 unless `names` asks for `pf`
/// or `pf-mix` by name (then the default count). The particle filter is opt-in for every
/// command: it is the one estimator too slow for the others' time budget.
pub fn particles(explicit: Option<usize>, names: &[String]) -> usize {
    explicit.unwrap_or(if names.iter().any(|n| n == "pf" || n == "pf-mix") {
        crate::estimators::pf::DEFAULT_PARTICLES
    } else {
        0
    })
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

/// Runs `ipc-runner eval`.
pub fn run(args: EvalArgs) -> Result<(), CommandError> {
    if args.scenario.is_none() && args.config.is_none() {
        return Err(CommandError::usage("give --scenario NAME or --config FILE"));
    }
    // clap lets through one of the two, never both.
    let scenario = scenario::resolve(
        args.scenario.as_deref().unwrap_or_default(),
        args.config.as_deref(),
    )
    .map_err(CommandError::usage)?;
    if let Some(plot) = &args.plot {
        crate::plot::check_extension(plot).map_err(CommandError::usage)?;
    }
    // Estimator families add fields (with their flags) to EvalOptions; the rest default.
    #[allow(clippy::needless_update)]
    let options = EvalOptions {
        runs: args.runs,
        horizon: args.horizon,
        seed: args.seed,
        particles: particles(args.particles, &args.estimators),
        estimators: args.estimators.clone(),
        loss_rate: args.loss_rate,
        transport_loss: args.transport_loss,
        transport_loss_unmarked: args.transport_loss_unmarked,
    };
    if !options.estimators.is_empty() {
        let all = EvalOptions {
            estimators: Vec::new(),
            ..options.clone()
        };
        let available: Vec<&str> =
            crate::estimators::build_all(FACTORIES, &*scenario, &all, options.seed, 0)
                .map_err(|e| CommandError::failure(format!("{e:#}")))?
                .iter()
                .map(|e| e.name())
                .collect();
        for n in &options.estimators {
            if !available.contains(&n.as_str()) {
                let hint = if n.ends_with("-mix") && options.loss_rate == 0.0 {
                    " (the -mix estimators need --loss-rate P)"
                } else {
                    ""
                };
                return Err(CommandError::usage(format!(
                    "estimator {n:?} does not apply to scenario {:?}{hint}; available: {}",
                    scenario.name(),
                    available.join(", ")
                )));
            }
        }
    }
    let run_config = RunConfig {
        threads: args.threads.map(|t| t as usize),
        progress: !args.quiet,
    };
    let mut result = evaluate(&*scenario, &options, FACTORIES, &run_config)
        .map_err(|e| CommandError::failure(format!("{e:#}")))?;
    super::nn_bound::after_eval(&mut result, &*scenario, args.plot.as_deref())
        .map_err(|e| CommandError::failure(format!("{e:#}")))?;
    if let Some(c) = scenario
        .as_any()
        .downcast_ref::<scenario::ComposedScenario>()
    {
        result.warnings = c.warnings();
    }
    print!("{}", result.summary());
    if let Some(path) = &args.json {
        write(path, &result.to_json())?;
    }
    if let Some(path) = &args.csv {
        write(path, &result.to_csv())?;
    }
    if let Some(path) = &args.plot {
        crate::plot::plot(&result, path)
            .map_err(|e| CommandError::failure(format!("{}: {e:#}", path.display())))?;
    }
    for path in [&args.json, &args.csv, &args.plot].into_iter().flatten() {
        println!("wrote {}", path.display());
    }
    // Scenarios with a shared token bucket (seed 004): Fig. 2 beside the plot.
    if let Some(path) = &args.plot {
        let written =
            crate::plot::tokens::plot_for(&*scenario, options.seed, options.horizon, path)
                .map_err(|e| CommandError::failure(format!("token plot: {e:#}")))?;
        if let Some(p) = written {
            println!("wrote {}", p.display());
        }
    }
    Ok(())
}

fn write(path: &Path, text: &str) -> Result<(), CommandError> {
    std::fs::write(path, text)
        .map_err(|e| CommandError::failure(format!("{}: {e}", path.display())))
}
