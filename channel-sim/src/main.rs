//! `channel-sim`: simulates a plant, its sensors and the channel, and publishes the slots on
//! iceoryx2 shared memory (see `channel_sim::publisher`). The same publisher is reachable as
//! the hidden `ipc-runner channel-sim` subcommand, which is what `ipc-runner demo` starts.
//!
//! Exit codes (docs/pipeline.md, "Exit codes"): 0 done (also when stopped by a signal: the
//! stream ends with its ABORT marker), 2 bad input (flags, scenario), 1 any other failure.

use clap::Parser;

/// Publishes one scenario's slots and truth on iceoryx2 shared memory.
#[derive(Debug, Parser)]
#[command(name = "channel-sim", version)]
struct Cli {
    #[command(flatten)]
    args: channel_sim::publisher::PublisherArgs,
}

fn main() {
    // Before any thread: under `ulimit -v` every thread allocates from one heap.
    estpipe_process::address_space::share_one_heap();
    estpipe_process::console::set_iceoryx2_log_level("channel-sim");
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
            estpipe_process::errln!(
                "channel-sim: error: {} (see --help)",
                estpipe_process::flags::one_line(&e)
            );
            std::process::exit(2);
        }
    };
    if let Err(e) = channel_sim::publisher::run(&cli.args) {
        estpipe_process::errln!(
            "channel-sim: error: {}",
            estpipe_process::console::one_line(&format!("{e:#}"))
        );
        // 2 for bad input and for a refusal (a peer outside the contract, iceoryx2
        // directories of another user: docs/security.md), as `ipc-runner`; 1 for anything else.
        let code = if channel_sim::error::is_bad_input(&e) {
            2
        } else {
            e.downcast_ref::<estpipe_wire::ContractError>()
                .map_or(1, estpipe_wire::ContractError::exit_code)
        };
        std::process::exit(code);
    }
}
