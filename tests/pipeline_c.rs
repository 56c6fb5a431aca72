//! The C client (`clients/c`) against the real runner: the two example programs are compiled
//! with the system `cc` against the C client library (`estpipe-c`, `clients/c/ffi`), the
//! publisher feeds `ipc-runner run` with the slots of a recorded log, the subscriber prints the
//! estimates, and both the runner's and the subscriber's estimates equal `ipc-runner replay`
//! of the same slots bit for bit; the subscriber printed every instant.
//!
//! The library: `estpipe-c` is a dependency of this package, so cargo builds its staticlib
//! (`libestpipe_c-<hash>.a` in `target/<profile>/deps`) with these tests; the newest of them
//! is linked (or `$ESTPIPE_C_LIB`). No nested cargo build. Without `cc` the test says so on
//! one line and passes.

#[path = "pipeline_common.rs"]
mod common;
#[path = "replay_check.rs"]
mod replay_check;
#[path = "skip_log.rs"]
mod skip_log;

use common::{prefix, scratch, Proc};
use std::path::{Path, PathBuf};
use std::process::Command;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// What the Rust standard library of the staticlib needs from the system, as
/// `rustc --print native-static-libs` lists it for this target (and clients/c/Makefile).
const NATIVE_LIBS: [&str; 6] = ["-lgcc_s", "-lutil", "-lrt", "-lpthread", "-lm", "-ldl"];

/// The staticlib built with these tests: `$ESTPIPE_C_LIB`, else the newest
/// `libestpipe_c-*.a` beside this test's executable.
fn library() -> PathBuf {
    if let Some(p) = std::env::var_os("ESTPIPE_C_LIB") {
        return PathBuf::from(p);
    }
    let exe = std::env::current_exe().unwrap();
    let deps = exe.parent().unwrap();
    std::fs::read_dir(deps)
        .unwrap()
        .filter_map(Result::ok)
        .filter(|e| {
            let n = e.file_name();
            let n = n.to_string_lossy();
            n.starts_with("libestpipe_c-") && n.ends_with(".a")
        })
        .max_by_key(|e| e.metadata().and_then(|m| m.modified()).ok())
        .map(|e| e.path())
        .unwrap_or_else(|| {
            panic!("no libestpipe_c-*.a in {deps:?} (estpipe-c is a dependency of e2e-tests)")
        })
}

/// `cc`, or `None` (and the one-line reason) when there is none.
fn cc() -> Option<String> {
    let cc = std::env::var("CC").unwrap_or_else(|_| "cc".into());
    if Command::new(&cc)
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success())
    {
        return Some(cc);
    }
    skip_log::skipped(
        &skip_log::current_test("c"),
        &format!("no C compiler (`{cc} --version` fails; set CC or install gcc)"),
    );
    None
}

/// Compiles `clients/c/examples/<name>.c` into `dir/<name>` as clients/c/Makefile does.
fn compile(cc: &str, dir: &Path, name: &str) -> PathBuf {
    let c = repo().join("clients/c");
    let exe = dir.join(name);
    let out = Command::new(cc)
        .args(["-O2", "-std=c11", "-Wall", "-Wextra", "-Werror", "-I"])
        .arg(&c)
        .arg("-o")
        .arg(&exe)
        .arg(c.join(format!("examples/{name}.c")))
        .arg(library())
        .args(NATIVE_LIBS)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{cc} {name}.c: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    exe
}

/// Feeds `slots` (a slot log of `scenario`) through the C publisher at `rate` into the runner
/// and checks the estimates against a replay.
fn c_feeds_the_runner(
    exes: &(PathBuf, PathBuf),
    name: &str,
    scenario: &[&str],
    slots: &Path,
    rate: &str,
) {
    let dir = scratch(&format!("c-{name}"));
    let p = prefix(&format!("c-{name}"));
    let instants = replay_check::last_instant(slots);
    let steps = instants.to_string();

    let mut header = Proc::start(&dir, "header", &[&["stream-header"][..], scenario].concat());
    assert!(header.wait(30).success(), "{}", header.err());
    let header_json = dir.join("header.json");
    std::fs::write(&header_json, header.out()).unwrap();

    let est_csv = dir.join("run-estimates.csv");
    let json = dir.join("run.json");
    let mut run_args = vec!["run", "--prefix", &p, "--steps", &steps];
    run_args.extend_from_slice(scenario);
    run_args.extend_from_slice(&[
        "--estimates-csv",
        est_csv.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ]);
    let mut run = Proc::start(&dir, "runner", &run_args);
    run.wait_for_stderr("waiting for channel-sim", 30);

    let mut sub = Proc::start_program(
        &dir,
        "subscriber",
        &exes.1,
        &["--prefix", &p, "--csv", "--idle-exit", "3"],
    );
    sub.wait_for_stderr("ready", 30);
    let mut publ = Proc::start_program(
        &dir,
        "publisher",
        &exes.0,
        &[
            "--prefix",
            &p,
            "--header",
            header_json.to_str().unwrap(),
            "--slots",
            slots.to_str().unwrap(),
            "--rate",
            rate,
        ],
    );
    assert!(run.wait(120).success(), "runner: {}", run.err());
    assert!(publ.wait(60).success(), "publisher: {}", publ.err());
    assert!(sub.wait(60).success(), "subscriber: {}", sub.err());

    let names = replay_check::equal_to_replay(
        &dir,
        name,
        "C",
        &json,
        &est_csv,
        slots,
        scenario,
        instants,
        &sub.out(),
    );
    eprintln!(
        "{name}: {instants} instants × {} estimator(s) from the C publisher at --rate {rate} \
         equal the replay bit for bit, and the C subscriber printed every one",
        names.len()
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_c_publisher_feeds_the_runner_and_the_estimates_equal_the_replay() {
    let Some(cc) = cc() else { return };
    let bin = scratch("c-bin");
    let exes = (
        compile(&cc, &bin, "publish_slots"),
        compile(&cc, &bin, "print_estimates"),
    );

    // A two-node TOML scenario with its recorded log (docs/replay.md), paced.
    let example = repo().join("channel-sim/scenarios/example.toml");
    c_feeds_the_runner(
        &exes,
        "example",
        &["--config", example.to_str().unwrap()],
        &repo().join("docs/examples/example-slots.csv"),
        "500",
    );

    // A longer log of the linear preset, recorded by the runner from channel-sim, as fast as
    // possible: 2000 instants fill the runner's queue (--buffer 256), so the sends block and
    // a slot that found the queue full before the runner connected goes again.
    let (dir, log) = replay_check::record_linear_log("c-record");
    c_feeds_the_runner(&exes, "linear", &["--scenario", "linear"], &log, "0");
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_dir_all(&bin);
}

/// The library refuses what the contract refuses, with an error code and a message, never a
/// crash: a slot that is not the header's (checked before anything is sent), a header JSON
/// of another wire version, and no runner within the timeout.
#[test]
fn the_c_publisher_refuses_bad_input_in_one_line() {
    let Some(cc) = cc() else { return };
    let bin = scratch("c-bad-bin");
    let publish = compile(&cc, &bin, "publish_slots");
    let dir = scratch("c-bad");
    let p = prefix("c-bad");
    let mut header = Proc::start(&dir, "header", &["stream-header", "--scenario", "linear"]);
    assert!(header.wait(30).success(), "{}", header.err());
    let good = header.out();
    let header_json = dir.join("header.json");
    std::fs::write(&header_json, &good).unwrap();
    let slots = dir.join("slots.csv");
    std::fs::write(&slots, "k,node,delivered,y_0\n1,0,1,0.5\n2,0,1,0.25\n").unwrap();

    // Another wire version in the header: exit 2, the field named.
    let old = dir.join("old.json");
    std::fs::write(
        &old,
        good.replace("\"wire_version\":6", "\"wire_version\":5"),
    )
    .unwrap();
    let mut publ = Proc::start_program(
        &dir,
        "old-header",
        &publish,
        &[
            "--prefix",
            &p,
            "--header",
            old.to_str().unwrap(),
            "--slots",
            slots.to_str().unwrap(),
        ],
    );
    assert_eq!(publ.wait(30).code(), Some(2), "{}", publ.err());
    assert!(publ.err().contains("wire_version 5"), "{}", publ.err());

    // A malformed row: exit 2 with its line, before anything is opened.
    let bad = dir.join("bad.csv");
    std::fs::write(&bad, "k,node,delivered,y_0\n1,0,1,0.5\n1,0,1,0.25\n").unwrap();
    let mut publ = Proc::start_program(
        &dir,
        "bad-row",
        &publish,
        &[
            "--prefix",
            &p,
            "--header",
            header_json.to_str().unwrap(),
            "--slots",
            bad.to_str().unwrap(),
        ],
    );
    assert_eq!(publ.wait(30).code(), Some(2), "{}", publ.err());
    assert!(publ.err().contains("line 3: node"), "{}", publ.err());

    // No runner: exit 3 after --connect-timeout, one line naming the command to start.
    let mut publ = Proc::start_program(
        &dir,
        "no-runner",
        &publish,
        &[
            "--prefix",
            &p,
            "--header",
            header_json.to_str().unwrap(),
            "--slots",
            slots.to_str().unwrap(),
            "--connect-timeout",
            "0.5",
        ],
    );
    assert_eq!(publ.wait(30).code(), Some(3), "{}", publ.err());
    assert!(
        publ.err().contains("ipc-runner run --prefix"),
        "{}",
        publ.err()
    );
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_dir_all(&bin);
}
