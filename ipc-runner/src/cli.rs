//! The command line of `ipc-runner` (and of the test binary `pipeline-node`, which is the
//! same dispatch under another name): subcommands, and how an ending becomes an exit code.
//!
//! Exit codes (docs/pipeline.md, "Exit codes and limits"): 0 ok; 1 a failure while running
//! (transport, I/O after the checks); 2 bad input (flags, scenario, CSV/slot-log content,
//! unwritable outputs, memory budget, a peer outside the wire contract); 3 `run`/`demo`:
//! the publisher was lost; 130 `run`/`demo`: interrupted (SIGINT/SIGTERM/SIGHUP). A clap error, a
//! bad value or a refused file is one line on stderr, `<name>: error: …`.

use clap::{Parser, Subcommand};

use crate::eval::cli::{CommandError, EvalArgs};

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
    Demo(crate::demo::DemoArgs),
    /// The real-time loop against a running channel-sim (same --prefix).
    Run(crate::run::RunArgs),
    /// Run the estimators over a recorded slot log (CSV, see docs/replay.md).
    Replay(crate::replay::ReplayArgs),
    /// Carry a prefix's services over zenoh to another host, every message checked on
    /// arrival (docs/bridge.md; in builds with `--features bridge`).
    Bridge(crate::bridge::BridgeArgs),
    /// Print the stream header a publisher of this scenario must write into every slot
    /// (JSON; see docs/wire.md).
    StreamHeader(crate::stream_header::StreamHeaderArgs),
    /// Simulate a scenario's plant, sensors and channel and publish its slots and truth on
    /// `--prefix` (the publisher `demo` starts; the same as the `channel-sim` binary).
    ChannelSim(channel_sim::publisher::PublisherArgs),
}

/// Runs a pipeline subcommand: its exit code, or the error chain with the code of
/// [`crate::exit_code_of`].
fn pipeline(r: anyhow::Result<i32>) -> Result<(), CommandError> {
    match r {
        Ok(0) => Ok(()),
        Ok(code) => std::process::exit(code),
        Err(e) => Err(CommandError {
            code: crate::exit_code_of(&e),
            message: format!("{e:#}"),
        }),
    }
}

/// Parses the command line, runs the subcommand and exits; `name` prefixes the one-line
/// error messages.
pub fn main(name: &str) -> ! {
    // Before any thread: under `ulimit -v` every thread allocates from one heap.
    estpipe_process::address_space::share_one_heap();
    estpipe_process::console::set_iceoryx2_log_level(name);
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
                "{name}: error: {} (see --help)",
                estpipe_process::flags::one_line(&e)
            );
            std::process::exit(2);
        }
    };
    let result = match cli.command {
        Command::Eval(args) => crate::eval::cli::run(args),
        Command::Demo(a) => pipeline(crate::demo::main(&a)),
        Command::Run(a) => pipeline(crate::run::main(&a)),
        Command::Replay(a) => pipeline(crate::replay::main(&a)),
        Command::Bridge(a) => pipeline(crate::bridge::main(&a)),
        Command::StreamHeader(a) => pipeline(crate::stream_header::main(&a)),
        Command::ChannelSim(a) => pipeline(crate::source::publish(&a)),
    };
    match result {
        Ok(()) => std::process::exit(0),
        Err(CommandError { code, message }) => {
            // One line, whatever a message quoted from a file or a peer contained.
            let message = estpipe_process::console::one_line(&message);
            estpipe_process::errln!("{name}: error: {message}");
            std::process::exit(code);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    /// The hidden flags that only the end-to-end tests use.
    fn is_test_hook(long: &str) -> bool {
        long.starts_with("debug") || long == "progress-every"
    }

    /// Every long flag of `cmd` and its subcommands, as `subcommand --flag`.
    fn flags(cmd: &clap::Command, path: &str, out: &mut Vec<String>) {
        for a in cmd.get_arguments() {
            if let Some(long) = a.get_long() {
                out.push(format!("{path} --{long}"));
            }
        }
        for sub in cmd.get_subcommands() {
            flags(sub, sub.get_name(), out);
        }
    }

    /// The shipped build (default features) has no test hook in its parser, so none in any
    /// help; the `test-hooks` build, which the end-to-end tests run, has all six.
    #[test]
    fn test_hooks_exist_only_with_their_feature() {
        let mut all = Vec::new();
        flags(&Cli::command(), "ipc-runner", &mut all);
        let hooks: Vec<&String> = all
            .iter()
            .filter(|f| f.split_once(" --").is_some_and(|(_, l)| is_test_hook(l)))
            .collect();
        if cfg!(feature = "test-hooks") {
            assert_eq!(
                hooks,
                [
                    "eval --progress-every",
                    "run --debug-slow-us",
                    "bridge --debug-corrupt-every",
                    "channel-sim --debug-wire-version",
                    "channel-sim --debug-nan-every",
                    "channel-sim --debug-nan-truth-at",
                ]
            );
        } else {
            assert!(hooks.is_empty(), "{hooks:?}");
            let e = Cli::try_parse_from(["ipc-runner", "run", "--debug-slow-us", "1"]).unwrap_err();
            assert_eq!(e.kind(), clap::error::ErrorKind::UnknownArgument);
        }
        let mut cmd = Cli::command();
        cmd.build();
        for sub in cmd.get_subcommands_mut() {
            let help = sub.render_long_help().to_string();
            assert!(!help.to_lowercase().contains("debug"), "{}", sub.get_name());
        }
    }
}
