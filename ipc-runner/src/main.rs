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
    /// One-command demo of the shared-memory pipeline.
    Demo,
}

fn main() {
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
            // clap's message is several lines (usage, tips); keep the first, which names the
            // problem.
            let text = e.render().to_string();
            let first = text.lines().next().unwrap_or("invalid arguments");
            let first = first.strip_prefix("error: ").unwrap_or(first);
            eprintln!("ipc-runner: error: {first} (see --help)");
            std::process::exit(2);
        }
    };
    let result = match cli.command {
        Command::Eval(args) => ipc_runner::eval::cli::run(args),
        Command::Demo => {
            println!("ipc-runner demo: not yet available (the pipeline issue adds it)");
            Ok(())
        }
    };
    if let Err(CommandError { code, message }) = result {
        eprintln!("ipc-runner: error: {message}");
        std::process::exit(code);
    }
}
