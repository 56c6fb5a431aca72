//! The shipped `ipc-runner` (default features) carries none of the end-to-end tests' hooks
//! (feature `test-hooks`, docs/pipeline.md "Test hooks"): no help mentions one, and its
//! parser refuses them.

use std::process::Command;

#[path = "../../tests/skip_log.rs"]
mod skip_log;

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
    // Without `--features bridge`, `bridge` has no flags, `--help` neither: it answers every
    // command line with the build command (exit code 2).
    for sub in SUBCOMMANDS
        .into_iter()
        .filter(|s| cfg!(feature = "bridge") || *s != "bridge")
    {
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
        skip_log::skipped(
            "a_default_build_refuses_the_test_hooks",
            "this build has the test hooks (the workspace's, where tests/ turns them on); \
             `cargo test --release -p ipc-runner` runs it",
        );
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
        let refusal = if args[0] == "bridge" && !cfg!(feature = "bridge") {
            "built without the bridge"
        } else {
            "unexpected argument"
        };
        assert!(err.contains(refusal), "{args:?}: {err}");
    }
}

fn help(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_ipc-runner"))
        .args(args)
        .arg("--help")
        .output()
        .unwrap();
    assert!(out.status.success(), "{args:?} --help: {}", out.status);
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// The text of `flag` in a help: from its line up to the next flag's.
fn flag_text(help: &str, flag: &str) -> String {
    let start = help
        .find(&format!("      {flag} "))
        .or_else(|| help.find(&format!("      {flag}\n")))
        .unwrap_or_else(|| panic!("no {flag} in:\n{help}"));
    let rest = &help[start + flag.len() + 6..];
    let end = rest.find("\n      --").unwrap_or(rest.len());
    rest[..end].to_string()
}

/// Issue #38, "Help and defaults disagree": one name for the horizon (`--steps`), one meaning
/// of `--plot` (a file), one default prefix, scenario and rate, every subcommand listed, no
/// figure of one machine in a help text.
#[test]
fn the_subcommands_agree_on_names_and_defaults() {
    let top = help(&[]);
    for sub in SUBCOMMANDS {
        assert!(
            top.contains(&format!("  {sub} ")),
            "{sub} not listed:\n{top}"
        );
    }
    for sub in ["eval", "demo", "run", "channel-sim"] {
        let h = help(&[sub]);
        assert!(h.contains("--steps"), "{sub}: no --steps");
        assert!(!h.contains("--horizon"), "{sub} --help names --horizon");
        assert!(
            flag_text(&h, "--scenario").contains("occlusion"),
            "{sub}: --scenario's default is not occlusion:\n{}",
            flag_text(&h, "--scenario")
        );
    }
    // `bridge` has its flags only where it is built in (`--features bridge`).
    let bridge = if cfg!(feature = "bridge") {
        &["bridge"][..]
    } else {
        &[]
    };
    for &sub in ["demo", "run", "channel-sim"].iter().chain(bridge) {
        let h = help(&[sub]);
        assert!(
            flag_text(&h, "--prefix").contains("[default: estpipe]"),
            "{sub} --prefix:\n{}",
            flag_text(&h, "--prefix")
        );
    }
    for sub in ["demo", "channel-sim"] {
        let rate = flag_text(&help(&[sub]), "--rate");
        assert!(rate.contains("[default: 1000]"), "{sub} --rate:\n{rate}");
    }
    for sub in ["eval", "demo"] {
        let plot = flag_text(&help(&[sub]), "--plot");
        assert!(
            plot.contains("<FILE.svg|FILE.png>"),
            "{sub} --plot:\n{plot}"
        );
    }
    for sub in SUBCOMMANDS
        .into_iter()
        .filter(|s| cfg!(feature = "bridge") || *s != "bridge")
    {
        let h = help(&[sub]).to_lowercase();
        for figure in ["ms per step", "machine", "≈"] {
            assert!(!h.contains(figure), "{sub} --help quotes {figure:?}:\n{h}");
        }
    }
}

/// An empty run is refused as `eval --steps 0` is, by every subcommand that takes `--steps`:
/// one line naming the flag, exit code 2, before anything starts.
#[test]
fn zero_steps_are_refused_everywhere() {
    for sub in ["eval", "demo", "run", "channel-sim"] {
        let out = Command::new(env!("CARGO_BIN_EXE_ipc-runner"))
            .args([sub, "--steps", "0"])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{sub}: {err}");
        assert!(
            err.contains("--steps") && err.lines().count() == 1,
            "{sub}: {err}"
        );
        assert!(
            out.stdout.is_empty(),
            "{sub}: {}",
            String::from_utf8_lossy(&out.stdout)
        );
    }
}
