//! The `channel-sim` binary's bad input (issue #20): one line on stderr, exit code 2, before
//! it opens any shared memory; no panic (`--linger inf` used to reach
//! `Duration::from_secs_f64(inf)` after the stream).

use std::process::Command;

fn refused(args: &[&str], needle: &str) {
    let out = Command::new(env!("CARGO_BIN_EXE_channel-sim"))
        .args(args)
        .env("IOX2_LOG_LEVEL", "Error")
        .output()
        .expect("start channel-sim");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
    assert_eq!(err.lines().count(), 1, "{args:?}: not one line: {err:?}");
    assert!(err.starts_with("channel-sim: error: "), "{err}");
    assert!(err.contains(needle), "{needle:?} missing from {err:?}");
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn bad_flags_and_scenarios_are_one_line_errors_with_code_2() {
    for v in ["nan", "inf", "-1"] {
        for flag in ["--rate", "--connect-timeout", "--linger"] {
            refused(&[&format!("{flag}={v}")], flag);
        }
    }
    refused(&["--bogus"], "--bogus");
    refused(&["--steps=-3"], "--steps");
    refused(&["--scenario", "nope"], "unknown scenario 'nope'");
    refused(&["--config", "/nonexistent/s.toml"], "/nonexistent/s.toml");
}
