//! The product's pipeline subcommands as a binary of the test package: `run`, `demo`,
//! `replay`, `stream-header` and the publisher (`channel-sim`), dispatched exactly as
//! `ipc-runner` does.

use clap::{Parser, Subcommand};

#[derive(Debug, Parser)]
struct Cli {
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Debug, Subcommand)]
enum Cmd {
    Demo(ipc_runner::demo::DemoArgs),
    Run(ipc_runner::run::RunArgs),
    Replay(ipc_runner::replay::ReplayArgs),
    StreamHeader(ipc_runner::stream_header::StreamHeaderArgs),
    ChannelSim(channel_sim::publisher::PublisherArgs),
    Bridge(estpipe_bridge::BridgeArgs),
}

fn main() {
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    let result = match Cli::parse().command {
        Cmd::Demo(a) => ipc_runner::demo::main(&a),
        Cmd::Run(a) => ipc_runner::run::main(&a),
        Cmd::Replay(a) => ipc_runner::replay::main(&a),
        Cmd::StreamHeader(a) => ipc_runner::stream_header::main(&a),
        Cmd::ChannelSim(a) => channel_sim::publisher::run(&a).map(|_| 0),
        Cmd::Bridge(a) => estpipe_bridge::main(&a),
    };
    match result {
        Ok(code) => std::process::exit(code),
        Err(e) => {
            eprintln!("pipeline-node: error: {e:#}");
            std::process::exit(ipc_runner::exit_code_of(&e));
        }
    }
}
