//! `channel-sim`: simulates a plant, its sensors and the channel, and publishes the slots on
//! iceoryx2 shared memory (see `channel_sim::publisher`). The same publisher is reachable as
//! the hidden `ipc-runner channel-sim` subcommand, which is what `ipc-runner demo` starts.

use clap::Parser;

/// Publishes one scenario's slots and truth on iceoryx2 shared memory.
#[derive(Debug, Parser)]
#[command(name = "channel-sim", version)]
struct Cli {
    #[command(flatten)]
    args: channel_sim::publisher::PublisherArgs,
}

fn main() {
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    let cli = Cli::parse();
    match channel_sim::publisher::run(&cli.args) {
        Ok(_) => {}
        Err(e) => {
            eprintln!("channel-sim: error: {e:#}");
            // A scenario that cannot be built is bad input (exit code 2), as in ipc-runner.
            let bad_input = e.downcast_ref::<channel_sim::ScenarioError>().is_some();
            std::process::exit(if bad_input { 2 } else { 1 });
        }
    }
}
