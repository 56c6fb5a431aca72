//! Command-line values that come from outside the process: the float flags of both binaries
//! (`channel-sim` and every `ipc-runner` subcommand) and the error type that marks bad input.
//!
//! Rust's `f64` parser accepts `nan`, `inf` and `-0`, and a bare `f64` flag let them through
//! to code that turns them into durations: `--connect-timeout nan` waited forever and
//! `--deadline-ms nan` meant 0 (issue #20). Every float flag goes through one of these
//! parsers, so a meaningless value is a one-line error (exit code 2, docs/pipeline.md "Exit
//! codes") before anything starts.

use std::fmt;

/// Longest time a seconds-valued flag accepts (≈ 31.7 years): `Duration::from_secs_f64`
/// panics far beyond it, and no wait of this product is meant to be longer.
pub const MAX_SECONDS: f64 = 1e9;

/// Highest sampling rate (Hz) a rate flag accepts: a period of 1 ns, the clock's resolution.
pub const MAX_RATE_HZ: f64 = 1e9;

/// Bad input from outside the process (a flag, a file's content): the command exits with
/// code 2 and this one-line message.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BadInput(pub String);

impl fmt::Display for BadInput {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for BadInput {}

impl BadInput {
    /// Whether `e`'s chain holds a [`BadInput`]: the product's exit policy (code 2). The
    /// simulator's own binary also counts a scenario it could not build
    /// (`channel_sim::error::is_bad_input`); the runner marks that as a [`BadInput`] where it
    /// calls the simulator.
    pub fn is_in(e: &anyhow::Error) -> bool {
        e.chain().any(|c| c.is::<BadInput>())
    }
}

/// The problem clap reports, on one line: its message has paragraphs (problem, tips,
/// usage), and the first names the problem.
pub fn one_line(e: &clap::Error) -> String {
    let text = e.render().to_string();
    let problem: Vec<&str> = text
        .lines()
        .take_while(|l| !l.trim().is_empty())
        .map(str::trim)
        .collect();
    let problem = problem.join(" ");
    problem
        .strip_prefix("error: ")
        .unwrap_or(&problem)
        .to_string()
}

fn finite(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} is not a number"))?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(format!("{s:?} is not a finite number"))
    }
}

/// A duration in seconds, `0 ≤ s ≤` [`MAX_SECONDS`] (where the flag gives 0 a meaning, such
/// as "forever", its help says so).
pub fn seconds(s: &str) -> Result<f64, String> {
    let v = finite(s)?;
    if (0.0..=MAX_SECONDS).contains(&v) {
        Ok(v)
    } else {
        Err(format!("{v} s is not in [0, {MAX_SECONDS:e}] s"))
    }
}

/// A duration in milliseconds, `0 < ms ≤ 1000 ·` [`MAX_SECONDS`].
pub fn positive_millis(s: &str) -> Result<f64, String> {
    let v = finite(s)?;
    if v > 0.0 && v <= MAX_SECONDS * 1e3 {
        Ok(v)
    } else {
        Err(format!("{v} ms is not in (0, {:e}] ms", MAX_SECONDS * 1e3))
    }
}

/// A sampling rate in Hz, `0 ≤ r ≤` [`MAX_RATE_HZ`] (0: as fast as possible).
pub fn rate_hz(s: &str) -> Result<f64, String> {
    let v = finite(s)?;
    if (0.0..=MAX_RATE_HZ).contains(&v) {
        Ok(v)
    } else {
        Err(format!("{v} Hz is not in [0, {MAX_RATE_HZ:e}] Hz"))
    }
}

/// A probability in `[0, 1)` (a loss rate).
pub fn probability_below_one(s: &str) -> Result<f64, String> {
    let v = finite(s)?;
    if (0.0..1.0).contains(&v) {
        Ok(v)
    } else {
        Err(format!("{v} is not in [0, 1)"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn non_finite_and_out_of_range_values_are_refused() {
        for bad in [
            "nan", "NaN", "inf", "-inf", "infinity", "-1", "1e10", "x", "",
        ] {
            assert!(seconds(bad).is_err(), "seconds({bad:?})");
            assert!(rate_hz(bad).is_err(), "rate_hz({bad:?})");
        }
        for bad in ["nan", "inf", "0", "-0", "-5", "1e13"] {
            assert!(positive_millis(bad).is_err(), "positive_millis({bad:?})");
        }
        for bad in ["nan", "1", "-0.1", "inf"] {
            assert!(probability_below_one(bad).is_err(), "{bad:?}");
        }
        assert_eq!(seconds("0"), Ok(0.0));
        assert_eq!(seconds(" 2.5 "), Ok(2.5));
        assert_eq!(positive_millis("0.5"), Ok(0.5));
        assert_eq!(rate_hz("0"), Ok(0.0));
        assert_eq!(probability_below_one("0.2"), Ok(0.2));
        assert!(seconds("nan").unwrap_err().contains("finite"));
    }

    #[test]
    fn bad_input_is_found_anywhere_in_the_chain() {
        use anyhow::Context as _;
        let e = Err::<(), _>(BadInput("x".into()))
            .context("outer")
            .unwrap_err();
        assert!(BadInput::is_in(&e));
        assert!(!BadInput::is_in(&anyhow::anyhow!("io")));
    }
}
