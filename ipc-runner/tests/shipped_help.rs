//! The shipped `ipc-runner` (default features) carries none of the end-to-end tests' hooks
//! (feature `test-hooks`, docs/pipeline.md "Test hooks"): no help mentions one, and its
//! parser refuses them.

use std::process::Command;

const SUBCOMMANDS: [&str; 7] = [
    "eval",
    "demo",
    "run",
    "replay",
    "bridge",
    "stream-header",
    "channel-sim",
];

#[test]
fn no_help_mentions_a_debug_flag() {
    for sub in SUBCOMMANDS {
        let out = Command::new(env!("CARGO_BIN_EXE_ipc-runner"))
            .args([sub, "--help"])
            .output()
            .unwrap();
        assert!(out.status.success(), "{sub} --help: {}", out.status);
        let help = String::from_utf8_lossy(&out.stdout).to_lowercase();
        assert!(help.contains("usage"), "{sub}: {help}");
        assert!(
            !help.contains("debug"),
            "{sub} --help mentions debug:\n{help}"
        );
    }
}

#[test]
fn a_default_build_refuses_the_test_hooks() {
    if cfg!(feature = "test-hooks") {
        // A workspace test build, where the end-to-end tests turn the hooks on.
        return;
    }
    for args in [
        &["run", "--debug-slow-us", "1"][..],
        &["eval", "--scenario", "linear", "--progress-every", "1"],
        &["channel-sim", "--debug-wire-version", "1"],
        &["channel-sim", "--debug-nan-every", "1"],
        &["channel-sim", "--debug-nan-truth-at", "1"],
        &["bridge", "--side", "sensor", "--debug-corrupt-every", "1"],
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_ipc-runner"))
            .args(args)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains("unexpected argument"), "{args:?}: {err}");
    }
}
