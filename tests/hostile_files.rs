//! What a command reads and writes, from a hostile user's side (the audit of session 14):
//! files too big to hold, outputs that are an input or each other, outputs that cannot take
//! the data, budgets beyond the machine, an environment that asks for 3000 threads. Each
//! case is a real process (`pipeline-node`); each was a panic, an abort, a silent loss or a
//! wrong exit code before, and must now be one line on stderr with its exit code.

#[path = "pipeline_common.rs"]
mod common;

use common::{prefix, report, scratch, start_channel_sim, Proc};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// A finished `pipeline-node`: exit code and stderr.
struct Done {
    code: Option<i32>,
    err: String,
}

/// Runs `pipeline-node <args>` in `dir` with `env` added and stdout to `stdout` (a file of
/// `dir` when `None`); killed and failed after 60 s. Fails on a panic, an abort or a death
/// by signal.
fn node(dir: &Path, args: &[&str], env: &[(&str, &str)], stdout: Option<&Path>) -> Done {
    let out = stdout.map(|p| std::fs::OpenOptions::new().write(true).open(p).unwrap());
    let mut p = Proc::start_in(dir, "node", args, env, out);
    let status = p.wait(60);
    let err = p.err();
    assert!(!err.contains("panicked"), "{args:?} panicked:\n{err}");
    assert!(
        !matches!(status.code(), None | Some(101 | 134)),
        "{args:?}: {status}\n{err}"
    );
    Done {
        code: status.code(),
        err,
    }
}

/// Exit `code` and one stderr line `pipeline-node: error: …` holding every needle.
fn assert_one_line(d: &Done, code: i32, needles: &[&str]) {
    assert_eq!(d.code, Some(code), "stderr: {}", d.err);
    let lines: Vec<&str> = d.err.lines().collect();
    assert_eq!(lines.len(), 1, "not one line: {:?}", d.err);
    assert!(lines[0].starts_with("pipeline-node: error: "), "{lines:?}");
    for n in needles {
        assert!(lines[0].contains(n), "{n:?} missing from {:?}", lines[0]);
    }
}

fn example_toml() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../channel-sim/scenarios/example.toml")
}

fn example_slots() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/examples/example-slots.csv")
}

const U64_MAX: &str = "18446744073709551615";

#[test]
fn no_budget_exceeds_the_machine() {
    let dir = scratch("hf-budget");
    // Was: exit 101, "capacity overflow" (the particles' bytes saturated to u64::MAX, which
    // fit a budget of u64::MAX).
    let d = node(
        &dir,
        &[
            "eval",
            "--scenario",
            "occlusion",
            "--runs",
            "2",
            "--steps",
            "5",
            "--quiet",
            "--particles",
            U64_MAX,
            "--max-memory",
            U64_MAX,
        ],
        &[],
        None,
    );
    assert_one_line(&d, 2, &["--particles", "more than 16 EiB"]);
    // Was: exit 134, "memory allocation of 68719476736 bytes failed".
    let d = node(
        &dir,
        &[
            "eval",
            "--scenario",
            "linear",
            "--runs",
            "2",
            "--steps",
            "4294967295",
            "--quiet",
            "--max-memory",
            U64_MAX,
        ],
        &[],
        None,
    );
    assert_one_line(&d, 2, &["--steps 4294967295", "this machine has"]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn rayon_num_threads_is_checked_like_the_flag() {
    let dir = scratch("hf-rayon");
    let args = [
        "eval",
        "--scenario",
        "linear",
        "--runs",
        "4",
        "--steps",
        "5",
        "--quiet",
    ];
    // Was: exit 101 after 7 s, rayon's "The global thread pool has not been initialized".
    for bad in ["3000", "many"] {
        let d = node(&dir, &args, &[("RAYON_NUM_THREADS", bad)], None);
        assert_one_line(&d, 2, &["RAYON_NUM_THREADS=", "0..=1024"]);
    }
    // rayon's own meaning of the variable still holds: 0 is the default, 1 one thread.
    for ok in ["0", "1"] {
        let d = node(&dir, &args, &[("RAYON_NUM_THREADS", ok)], None);
        assert_eq!(d.code, Some(0), "{ok}: {}", d.err);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_scenario_file_is_read_within_a_bound() {
    let dir = scratch("hf-config");
    // Was: 2.1 GB read from /dev/zero before "out of memory" (no bound without a ulimit).
    for cmd in [&["stream-header"][..], &["eval", "--runs", "2", "--quiet"]] {
        let t0 = Instant::now();
        let d = node(&dir, &[cmd, &["--config", "/dev/zero"]].concat(), &[], None);
        assert_one_line(&d, 2, &["/dev/zero", "larger than 1024 KiB"]);
        assert!(t0.elapsed() < Duration::from_secs(10), "{:?}", t0.elapsed());
    }
    // Just over the bound, as a TOML comment (an 80 MB file aborted the process).
    let big = dir.join("big.toml");
    let mut text = std::fs::read_to_string(example_toml()).unwrap();
    text.push_str(&format!("# {}\n", "x".repeat(1 << 20)));
    std::fs::write(&big, text).unwrap();
    let d = node(&dir, &["stream-header", "--config", "big.toml"], &[], None);
    assert_one_line(&d, 2, &["big.toml", "larger than"]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn no_output_replaces_an_input_or_another_output() {
    let dir = scratch("hf-same");
    let log = std::fs::read_to_string(example_slots()).unwrap();
    std::fs::write(dir.join("in.csv"), &log).unwrap();
    std::os::unix::fs::symlink(dir.join("in.csv"), dir.join("link.csv")).unwrap();
    let toml = example_toml();
    let toml = toml.to_str().unwrap();
    // Was: exit 0, and in.csv held the estimates (the slot log gone), also via a symlink.
    for out in ["in.csv", "./link.csv"] {
        let d = node(
            &dir,
            &[
                "replay", "--config", toml, "--input", "in.csv", "--output", out,
            ],
            &[],
            None,
        );
        assert_one_line(&d, 2, &["--output", "the same file as --input"]);
        assert_eq!(std::fs::read_to_string(dir.join("in.csv")).unwrap(), log);
    }
    // Was: exit 0 with the scenario file replaced by the JSON report.
    let cfg = std::fs::read_to_string(example_toml()).unwrap();
    std::fs::write(dir.join("cfg.toml"), &cfg).unwrap();
    let d = node(
        &dir,
        &[
            "eval", "--config", "cfg.toml", "--runs", "2", "--quiet", "--json", "cfg.toml",
        ],
        &[],
        None,
    );
    assert_one_line(&d, 2, &["--json cfg.toml", "the same file as --config"]);
    assert_eq!(std::fs::read_to_string(dir.join("cfg.toml")).unwrap(), cfg);
    // Was: exit 0, "wrote same.out" twice, and only the CSV in it.
    let d = node(
        &dir,
        &[
            "eval",
            "--scenario",
            "linear",
            "--runs",
            "2",
            "--steps",
            "5",
            "--quiet",
            "--json",
            "same.out",
            "--csv",
            "same.out",
        ],
        &[],
        None,
    );
    assert_one_line(&d, 2, &["--csv same.out", "the same file as --json"]);
    assert!(!dir.join("same.out").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn an_output_that_cannot_take_the_data_fails_the_command() {
    let dir = scratch("hf-full");
    let toml = example_toml();
    let slots = example_slots();
    // Was: exit 0, "estimates written to \"/dev/full\"" (the BufWriter's error dropped).
    let d = node(
        &dir,
        &[
            "replay",
            "--config",
            toml.to_str().unwrap(),
            "--input",
            slots.to_str().unwrap(),
            "--output",
            "/dev/full",
        ],
        &[],
        None,
    );
    assert_one_line(&d, 1, &["/dev/full", "No space left on device"]);
    // The stream header is the command's whole output: exit 0 with nothing written was a lie.
    let d = node(
        &dir,
        &["stream-header", "--scenario", "occlusion"],
        &[],
        Some(Path::new("/dev/full")),
    );
    assert_one_line(&d, 1, &["cannot write the stream header", "No space left"]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_scenario_no_estimator_can_start_from_is_bad_input_naming_the_file() {
    let dir = scratch("hf-p0");
    // P0 = 1e-320 I passes the file's checks, but no filter can factor it: was exit 1
    // without the file's name (replay gave 2 for the same file).
    let text = std::fs::read_to_string(example_toml())
        .unwrap()
        .replace("cov = [[1.0", "cov = [[1e-320");
    assert!(
        text.contains("1e-320"),
        "example.toml changed its initial cov"
    );
    std::fs::write(dir.join("p0.toml"), text).unwrap();
    let d = node(
        &dir,
        &["eval", "--config", "p0.toml", "--runs", "3", "--quiet"],
        &[],
        None,
    );
    assert_one_line(&d, 2, &["--config p0.toml", "P0"]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_run_whose_csv_cannot_be_written_says_so_and_keeps_its_json() {
    let dir = scratch("hf-run-full");
    let p = prefix("hf-run-full");
    // Was: exit 0 and nothing on stderr, the CSV lost (the BufWriter's error dropped).
    for flag in ["--estimates-csv", "--latency-csv", "--slots-csv"] {
        let json = dir.join("run.json");
        let mut run = Proc::start(
            &dir,
            "run",
            &[
                "run",
                "--scenario",
                "linear",
                "--prefix",
                &p,
                "--steps",
                "50",
                "--quiet",
                "--json",
                json.to_str().unwrap(),
                flag,
                "/dev/full",
            ],
        );
        let _publisher = start_channel_sim(&dir, &p, "linear", 50, 0);
        let st = run.wait(60);
        let err = run.err();
        assert_eq!(st.code(), Some(1), "{flag}: {st}\n{err}");
        assert!(!err.contains("panicked"), "{err}");
        let lines: Vec<&str> = err.lines().filter(|l| l.contains("error:")).collect();
        assert_eq!(lines.len(), 1, "{flag}: {err}");
        assert!(
            lines[0].contains("/dev/full") && lines[0].contains("No space"),
            "{err}"
        );
        assert_eq!(report(&json)["counts"]["received"], 50, "{flag}");
        let _ = std::fs::remove_file(&json);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_variance_no_estimator_can_factor_is_refused_by_its_field() {
    let dir = scratch("hf-psi");
    // Was: exit 1, "occlusion stage does not match the plant", neither file nor field.
    let toml = "[model]\na = [[1.0, 1.0], [0.0, 1.0]]\nq = [[0.1, 0.0], [0.0, 0.1]]\n\
                [initial]\nmean = [0.0, 0.0]\ncov = [[1.0, 0.0], [0.0, 1.0]]\n\
                [[sensors]]\nc = [[1.0, 0.0]]\nr = [[0.1]]\n\
                [[stages]]\nkind = \"occlusion\"\ne = [1.0, 0.0]\npsi = 1e308\n\
                centres = [1.0]\nradii = [0.5]\n";
    std::fs::write(dir.join("psi.toml"), toml).unwrap();
    let d = node(
        &dir,
        &["eval", "--config", "psi.toml", "--runs", "2", "--quiet"],
        &[],
        None,
    );
    assert_one_line(&d, 2, &["psi.toml", "stages[0].psi", "1e308"]);
    // The same file with psi = 0.1 runs: the refusal is the variance's.
    std::fs::write(dir.join("ok.toml"), toml.replace("1e308", "0.1")).unwrap();
    let d = node(
        &dir,
        &["eval", "--config", "ok.toml", "--runs", "2", "--quiet"],
        &[],
        None,
    );
    assert_eq!(d.code, Some(0), "{}", d.err);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn an_unknown_iceoryx2_log_level_is_one_warning_line() {
    let dir = scratch("hf-iox2");
    // Was: iceoryx2's four lines ("Invalid value for 'IOX2_LOG_LEVEL' …").
    let args = [
        "eval",
        "--scenario",
        "linear",
        "--runs",
        "2",
        "--steps",
        "3",
        "--quiet",
    ];
    let d = node(&dir, &args, &[("IOX2_LOG_LEVEL", "garbage\nx")], None);
    assert_eq!(d.code, Some(0), "{}", d.err);
    let lines: Vec<&str> = d.err.lines().collect();
    assert_eq!(lines.len(), 1, "{:?}", d.err);
    assert!(
        lines[0].starts_with("pipeline-node: warning: IOX2_LOG_LEVEL=")
            && lines[0].contains("using error"),
        "{lines:?}"
    );
    let d = node(&dir, &args, &[("IOX2_LOG_LEVEL", "Warn")], None);
    assert_eq!((d.code, d.err.as_str()), (Some(0), ""));
    let _ = std::fs::remove_dir_all(&dir);
}
