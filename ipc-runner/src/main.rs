//! `ipc-runner`: the real-time estimation loop, Monte-Carlo evaluation and the demo.
//!
//! One subcommand per module; bad flags or input print one line and exit with code 2.

use clap::{Parser, Subcommand};
use ipc_runner::eval::cli::{CommandError, EvalArgs};

#[derive(Debug, Parser)]
#[command(
    name = "ipc-runner",
    version,
    about = "Estimation over lossy, rationed channels: evaluation, real-time loop, demo"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Monte-Carlo evaluation of every estimator that applies to a scenario.
    Eval(EvalArgs),
    /// One-command demo of the shared-memory pipeline: starts the publisher as a child
    /// process, runs the real-time loop, prints the summary and writes a plot.
    Demo(ipc_runner::demo::DemoArgs),
    /// The real-time loop against a running channel-sim (same --prefix).
    Run(ipc_runner::run::RunArgs),
    /// Run the estimators over a recorded slot log (CSV, see docs/replay.md).
    Replay(ipc_runner::replay::ReplayArgs),
    /// Carry a prefix's services over zenoh to another host, every message checked on
    /// arrival (docs/bridge.md).
    Bridge(estpipe_bridge::BridgeArgs),
    /// Print the stream header a publisher of this scenario must write into every slot
    /// (JSON; see docs/wire.md).
    StreamHeader(ipc_runner::stream_header::StreamHeaderArgs),
    /// The channel-sim publisher built into this executable (what `demo` starts).
    #[command(hide = true)]
    ChannelSim(channel_sim::publisher::PublisherArgs),
}

/// Runs a pipeline subcommand: its exit code, or the error chain with code 2 when the peer
/// does not follow the wire contract (`ipc_runner::exit_code_of`), else 1.
fn pipeline(r: anyhow::Result<i32>) -> Result<(), CommandError> {
    match r {
        Ok(0) => Ok(()),
        Ok(code) => std::process::exit(code),
        Err(e) => Err(CommandError {
            code: ipc_runner::exit_code_of(&e),
            message: format!("{e:#}"),
        }),
    }
}

fn main() {
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            use clap::error::ErrorKind;
            if matches!(
                e.kind(),
                ErrorKind::DisplayHelp
                    | ErrorKind::DisplayVersion
                    | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
            ) {
                e.exit();
            }
            // clap's message has paragraphs (problem, tips, usage); keep the first, which names
            // the problem, on one line.
            let text = e.render().to_string();
            let problem: Vec<&str> = text
                .lines()
                .take_while(|l| !l.trim().is_empty())
                .map(str::trim)
                .collect();
            let problem = problem.join(" ");
            let problem = problem.strip_prefix("error: ").unwrap_or(&problem);
            eprintln!("ipc-runner: error: {problem} (see --help)");
            std::process::exit(2);
        }
    };
    let result = match cli.command {
        Command::Eval(args) => ipc_runner::eval::cli::run(args),
        Command::Demo(a) => pipeline(ipc_runner::demo::main(&a)),
        Command::Run(a) => pipeline(ipc_runner::run::main(&a)),
        Command::Replay(a) => pipeline(ipc_runner::replay::main(&a)),
        Command::Bridge(a) => pipeline(estpipe_bridge::main(&a)),
        Command::StreamHeader(a) => pipeline(ipc_runner::stream_header::main(&a)),
        Command::ChannelSim(a) => pipeline(channel_sim::publisher::run(&a).map(|_| 0)),
    };
    if let Err(CommandError { code, message }) = result {
        eprintln!("ipc-runner: error: {message}");
        std::process::exit(code);
    }
}
