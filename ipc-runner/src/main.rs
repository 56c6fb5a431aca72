//! `ipc-runner`: the real-time estimation loop, Monte-Carlo evaluation and the demo.
//!
//! One subcommand per module ([`ipc_runner::cli`]); bad flags or input print one line and
//! exit with code 2 (the exit codes: docs/pipeline.md, "Exit codes and limits").

fn main() {
    ipc_runner::cli::main("ipc-runner")
}
