//! The product's subcommands as a binary of the test package (`eval`, `run`, `demo`,
//! `replay`, `stream-header` and the publisher, `channel-sim`), dispatched by the very
//! function `ipc-runner` runs (`ipc_runner::cli::main`), errors prefixed `pipeline-node:`.

fn main() {
    ipc_runner::cli::main("pipeline-node")
}
