//! `ipc-runner bridge` (docs/bridge.md), and what a build without it says instead.
//!
//! The bridge is the `bridge` feature: zenoh is about half of a fresh build's CPU time, which
//! `demo`, `run`, `eval` and `replay` do not need. Without the feature the subcommand and
//! `demo --via zenoh` are still there, and answer with [`NOT_BUILT`] (exit code 2).

/// What `ipc-runner bridge` and `demo --via zenoh` answer in a build without the bridge.
pub const NOT_BUILT: &str = "this ipc-runner was built without the bridge: cargo build \
                             --release -p ipc-runner --features bridge";

/// The command line of `ipc-runner bridge`.
#[cfg(feature = "bridge")]
pub type BridgeArgs = estpipe_bridge::BridgeArgs;

/// `ipc-runner bridge` in a build without the bridge: any arguments (`--help` too), all
/// answered by [`NOT_BUILT`].
#[cfg(not(feature = "bridge"))]
#[derive(Debug, clap::Args)]
#[command(disable_help_flag = true)]
pub struct BridgeArgs {
    #[arg(trailing_var_arg = true, allow_hyphen_values = true, hide = true)]
    args: Vec<String>,
}

/// `ipc-runner bridge`: its flags (and the files they name) are checked first; what they
/// refuse is bad input, exit code 2, before any port or session is opened.
#[cfg(feature = "bridge")]
pub fn main(a: &BridgeArgs) -> anyhow::Result<i32> {
    use estpipe_process::flags::BadInput;
    a.check()
        .map_err(|e| anyhow::Error::new(BadInput(format!("{e:#}"))))?;
    // The product's stop signals (SIGHUP too, which killed the bridge without its report)
    // and ignored stray killers, as for every other subcommand.
    estpipe_process::signal::install();
    estpipe_bridge::main(a)
}

/// `ipc-runner bridge` without the bridge: [`NOT_BUILT`], exit code 2.
#[cfg(not(feature = "bridge"))]
pub fn main(_: &BridgeArgs) -> anyhow::Result<i32> {
    available()?;
    Ok(0)
}

/// `Ok` when this build has the bridge; otherwise [`NOT_BUILT`] as bad input (exit code 2).
pub fn available() -> Result<(), estpipe_process::flags::BadInput> {
    if cfg!(feature = "bridge") {
        Ok(())
    } else {
        Err(estpipe_process::flags::BadInput(NOT_BUILT.into()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, clap::Parser)]
    struct Cli {
        #[command(subcommand)]
        command: Command,
    }

    #[derive(Debug, clap::Subcommand)]
    enum Command {
        Bridge(BridgeArgs),
    }

    /// Any `bridge` command line reaches [`main`], which a build without the bridge answers
    /// with the one line of how to get it, as bad input (exit code 2).
    #[test]
    fn a_build_without_the_bridge_says_how_to_get_it() {
        use clap::Parser as _;
        let parsed = Cli::try_parse_from(["ipc-runner", "bridge", "--side", "sensor"]);
        if cfg!(feature = "bridge") {
            assert!(available().is_ok());
            assert!(parsed.is_ok());
            return;
        }
        for line in [
            &["bridge"][..],
            &["bridge", "--help"],
            &["bridge", "--side", "x", "-q"],
        ] {
            let Command::Bridge(a) = Cli::try_parse_from(["ipc-runner"].iter().chain(line))
                .unwrap_or_else(|e| panic!("{line:?}: {e}"))
                .command;
            let e = main(&a).unwrap_err();
            assert!(estpipe_process::flags::BadInput::is_in(&e), "{e:#}");
            assert_eq!(format!("{e:#}"), NOT_BUILT);
        }
        assert!(NOT_BUILT.contains("cargo build --release -p ipc-runner --features bridge"));
    }
}
