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
            // 2 for a refusal (a peer outside the contract, iceoryx2 directories of another
            // user: docs/security.md), as `ipc-runner`; 1 for anything else.
            let code = e
                .downcast_ref::<estpipe_wire::ContractError>()
                .map_or(1, estpipe_wire::ContractError::exit_code);
            std::process::exit(code);
        }
    }
}
