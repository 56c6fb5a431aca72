//! `ipc-runner`: the real-time estimation loop, Monte-Carlo evaluation and the demo.

use clap::{Parser, Subcommand};

/// Estimation over zero-copy shared memory.
#[derive(Debug, Parser)]
#[command(name = "ipc-runner", version)]
struct Cli {
    #[command(subcommand)]
    command: Option<Cmd>,
}

#[derive(Debug, Subcommand)]
enum Cmd {
    /// Run the whole pipeline (publisher child process + real-time loop) and summarise.
    Demo(ipc_runner::demo::DemoArgs),
    /// Run the real-time loop against a running channel-sim.
    Run(ipc_runner::run::RunArgs),
    /// Run the estimators over a recorded slot log (CSV).
    Replay(ipc_runner::replay::ReplayArgs),
    /// The channel-sim publisher, built into this executable (what `demo` starts).
    #[command(hide = true)]
    ChannelSim(channel_sim::publisher::PublisherArgs),
}

fn main() {
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    let cli = Cli::parse();
    let result = match cli.command {
        Some(Cmd::Demo(a)) => ipc_runner::demo::main(&a),
        None => ipc_runner::demo::main(
            &<ipc_runner::demo::DemoArgs as clap::FromArgMatches>::from_arg_matches(
                &<ipc_runner::demo::DemoArgs as clap::Args>::augment_args(clap::Command::new(
                    "demo",
                ))
                .get_matches_from(["demo"]),
            )
            .expect("defaults parse"),
        ),
        Some(Cmd::Run(a)) => ipc_runner::run::main(&a),
        Some(Cmd::Replay(a)) => ipc_runner::replay::main(&a),
        Some(Cmd::ChannelSim(a)) => {
            channel_sim::publisher::run(&a, channel_sim::publisher::resolve_scenario).map(|_| 0)
        }
    };
    match result {
        Ok(code) => std::process::exit(code),
        Err(e) => {
            eprintln!("ipc-runner: error: {e:#}");
            std::process::exit(1);
        }
    }
}
