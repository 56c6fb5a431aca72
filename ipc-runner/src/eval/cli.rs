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
    /// Particles of the `pf` reference filter on occlusion scenarios. Off by default in
    /// `eval`: at 5000 particles it costs ~3 CPU-ms per step, 100× the other estimators
    /// together, so a 2000-run evaluation would take minutes instead of seconds.
    /// Typical: `--particles 5000 --runs 200`.
    #[arg(long, default_value_t = 0)]
    pub particles: usize,
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
        particles: args.particles,
        ..EvalOptions::default()
    };
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
