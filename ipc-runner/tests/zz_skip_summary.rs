//! The skipped tests of this `cargo test` run, at the end of its output (README, "Tests").
//!
//! Not a libtest harness (`harness = false` in Cargo.toml): libtest would capture what a
//! passing test prints, and this binary exists to print. Cargo runs the packages' test
//! binaries in name order, the targets of a package in name order, so this one, `zz_…` of
//! `ipc-runner`, comes last; only the doc-tests come after it. The lines were written by the
//! tests that skipped (`tests/skip_log.rs`), to the log of this cargo run; the log is removed
//! once printed, with those of runs that are over.

#[path = "../../tests/skip_log.rs"]
mod skip_log;

fn main() {
    // `cargo test -- --list` lists tests: there are none here, and no summary.
    if std::env::args().any(|a| a == "--list") {
        return;
    }
    let log = skip_log::run_log();
    let lines: Vec<String> = std::fs::read_to_string(&log)
        .unwrap_or_default()
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(str::to_string)
        .collect();
    let _ = std::fs::remove_file(&log);
    // Logs of runs that are over (stopped at a failing binary before this one ran).
    if let Ok(entries) = std::fs::read_dir(skip_log::dir()) {
        for e in entries.flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            if let Some(run) = name.strip_suffix(".log") {
                if !skip_log::run_alive(run) {
                    let _ = std::fs::remove_file(e.path());
                }
            }
        }
    }
    if lines.is_empty() {
        println!("\nskip summary: no test of this cargo run skipped");
        return;
    }
    println!(
        "\nskip summary: {} test(s) of this cargo run skipped and passed without checking \
         anything (README, \"Tests\": what the full suite needs, .ci/setup installs it):",
        lines.len()
    );
    for l in &lines {
        println!("SKIPPED {l}");
    }
}
