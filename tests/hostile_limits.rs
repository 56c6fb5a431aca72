//! Issue #39, item 16: consumers that trust nothing at the machine's limits either — a tight
//! address-space limit (`ulimit -v`), a full disk, `--quiet`, and one forged restart slot
//! from any local process. Each test fails on the code before the item (docs/security.md,
//! "Limits of the machine" and "What the runner assumes").

#[path = "pipeline_common.rs"]
mod common;

use common::{prefix, report, scratch, Proc};
use estpipe_wire as wire;
use iceoryx2::prelude::*;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

fn rogue_exe() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_rogue-publisher"))
}

fn channel_sim<'a>(p: &'a str, steps: &'a str, rate: &'a str) -> Vec<&'a str> {
    vec![
        "channel-sim",
        "--scenario",
        "linear",
        "--prefix",
        p,
        "--steps",
        steps,
        "--rate",
        rate,
    ]
}

/// Waits (bounded) until the runner on `p` has published an estimate: its stream flows.
fn wait_for_an_estimate(p: &str, run: &Proc) {
    set_log_level(LogLevel::Error);
    let node = NodeBuilder::new().create::<ipc::Service>().unwrap();
    let est = wire::estimate_service(&node, p).unwrap();
    let sub = est.subscriber_builder().create().unwrap();
    let t = Instant::now();
    loop {
        if sub.receive().unwrap().is_some() {
            return;
        }
        assert!(
            t.elapsed() < Duration::from_secs(60),
            "no estimate within 60 s\n{}",
            run.err()
        );
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// One well-formed slot with a new stream id at k = 1 on node 0, from a second publisher
/// while channel-sim's stream flows, restarted the session: channel-sim's slots became
/// stale, the forged stream went silent and the run ended "publisher lost" (exit 3). Now it
/// is counted as `skipped.foreign_restart` and the run completes with every instant.
#[test]
fn one_forged_restart_slot_does_not_end_a_healthy_run() {
    let dir = scratch("forged-restart");
    let p = prefix("forged-restart");
    let json = dir.join("r.json");
    let steps = "1000";
    let mut run = Proc::start(
        &dir,
        "runner",
        &[
            "run",
            "--scenario",
            "linear",
            "--prefix",
            &p,
            "--steps",
            steps,
            "--json",
            json.to_str().unwrap(),
            "--stall-limit",
            "3",
        ],
    );
    run.wait_for_stderr("waiting for channel-sim", 30);
    // 5 s of stream at 200 Hz: the forged slot lands in the middle.
    let mut publ = Proc::start(&dir, "publisher", &channel_sim(&p, steps, "200"));
    wait_for_an_estimate(&p, &run);
    let script = dir.join("forged.json");
    std::fs::write(&script, r#"[{"k": 1, "stream_id": 4242}]"#).unwrap();
    let mut rogue = Proc::start_program(
        &dir,
        "rogue",
        &rogue_exe(),
        &[
            "--prefix",
            &p,
            "--scenario",
            "linear",
            "--script",
            script.to_str().unwrap(),
            // Stays registered 1 s after its slot, beside channel-sim.
            "--timeout",
            "1",
        ],
    );
    assert!(rogue.wait(60).success(), "{}", rogue.err());
    assert!(publ.wait(60).success(), "{}", publ.err());
    let st = run.wait(60);
    let err = run.err();
    assert_eq!(st.code(), Some(0), "{err}");
    let r = report(&json);
    assert_eq!(r["ending"], "completed", "{r}");
    assert_eq!(r["sessions"], 1, "{r}");
    assert_eq!(r["counts"]["instants"], 1000, "{r}");
    assert_eq!(r["counts"]["skipped"]["foreign_restart"], 1, "{r}");
    assert_eq!(r["counts"]["skipped"]["stale_stream"], 0, "{r}");
    assert!(err.contains("another publisher"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The rule that refuses a forged restart still lets a real one through before the data
/// deadline: channel-sim SIGKILLed and started again at once, with a deadline (5 s) the new
/// stream beats, is a restart because the dead publisher's port is gone once dead nodes are
/// cleaned up (without that cleanup it is still registered).
#[test]
fn a_publisher_restarted_before_the_deadline_is_still_a_restart() {
    let dir = scratch("quick-restart");
    let p = prefix("quick-restart");
    let json = dir.join("r.json");
    let mut run = Proc::start(
        &dir,
        "runner",
        &[
            "run",
            "--scenario",
            "linear",
            "--prefix",
            &p,
            "--steps",
            "100",
            "--json",
            json.to_str().unwrap(),
            "--deadline-ms",
            "5000",
        ],
    );
    run.wait_for_stderr("waiting for channel-sim", 30);
    let mut pub1 = Proc::start(&dir, "pub1", &channel_sim(&p, "100000", "200"));
    wait_for_an_estimate(&p, &run);
    pub1.signal(libc::SIGKILL);
    let _ = pub1.wait(10);
    let t = Instant::now();
    let mut pub2 = Proc::start(&dir, "pub2", &channel_sim(&p, "100", "0"));
    assert!(pub2.wait(60).success(), "{}", pub2.err());
    let st = run.wait(60);
    let err = run.err();
    assert_eq!(st.code(), Some(0), "{err}");
    let r = report(&json);
    assert_eq!(r["ending"], "completed", "{r}");
    assert_eq!(r["sessions"], 2, "{r}");
    assert_eq!(r["publisher_losses"], 0, "{r}");
    assert_eq!(r["counts"]["skipped"]["foreign_restart"], 0, "{r}");
    eprintln!("restart followed {:?} after the SIGKILL", t.elapsed());
    let _ = std::fs::remove_dir_all(&dir);
}

/// How a command under an address-space limit ended.
struct Limited {
    code: Option<i32>,
    signal: Option<i32>,
    stderr: String,
}

/// Runs `pipeline-node <args>` in `dir` under `ulimit -v kib` (bounded: killed after 60 s).
fn limited(dir: &Path, kib: u64, args: &[&str]) -> Limited {
    use std::os::unix::process::ExitStatusExt as _;
    let err = dir.join(format!("limited-{kib}.err"));
    let mut child = std::process::Command::new("sh")
        .arg("-c")
        .arg("ulimit -v \"$0\" && exec \"$@\"")
        .arg(kib.to_string())
        .arg(common::node_exe())
        .args(args)
        .current_dir(dir)
        .env("IOX2_LOG_LEVEL", "Error")
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .stderr(std::fs::File::create(&err).unwrap())
        .spawn()
        .unwrap();
    let t = Instant::now();
    let st = loop {
        if let Some(st) = child.try_wait().unwrap() {
            break st;
        }
        if t.elapsed() > Duration::from_secs(60) {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{args:?} under ulimit -v {kib} did not end within 60 s");
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    Limited {
        code: st.code(),
        signal: st.signal(),
        stderr: std::fs::read_to_string(&err).unwrap_or_default(),
    }
}

/// The smallest limit (KiB, in steps of `step`) under which the binary starts at all:
/// below it the loader or the kernel ends it before `main` (nothing of ours runs).
fn load_floor(dir: &Path, step: u64) -> u64 {
    let mut kib = 16_000;
    while limited(dir, kib, &["--version"]).code != Some(0) {
        kib += step;
        assert!(kib < 1_000_000, "--version does not run under 1 GB");
    }
    kib
}

/// `eval` aborted under a tight `ulimit -v` ("memory allocation of 80 bytes failed", exit
/// 134), at random near the limit: a worker thread that found no address space for a glibc
/// arena of its own mapped every allocation separately. Now every limit from the one the
/// binary starts under upward ends in a result (exit 0) or in one line naming the limit
/// (exit 2); never a signal.
#[test]
fn eval_under_an_address_space_limit_fits_or_refuses_in_one_line() {
    let dir = scratch("eval-ulimit");
    let step = 2_000;
    let floor = load_floor(&dir, step);
    // Two workers (this VM's cores) and eight: the reserve grows with the threads.
    for threads in ["2", "8"] {
        let (mut refused, mut first_ok) = (Vec::new(), None);
        for kib in (floor..floor + 100_000).step_by(step as usize) {
            let args = [
                "eval",
                "--scenario",
                "occlusion",
                "--runs",
                "60",
                "--threads",
                threads,
                "--quiet",
            ];
            for _ in 0..2 {
                let r = limited(&dir, kib, &args);
                let at = format!("--threads {threads} under ulimit -v {kib}");
                assert_eq!(r.signal, None, "{at}: killed\n{}", r.stderr);
                match r.code {
                    Some(0) => {
                        first_ok.get_or_insert(kib);
                    }
                    Some(2) => {
                        assert_eq!(r.stderr.lines().count(), 1, "{at}: {}", r.stderr);
                        assert!(r.stderr.contains("ulimit -v"), "{at}: {}", r.stderr);
                        assert!(first_ok.is_none(), "{at}: refused after a success below it");
                        refused.push(kib);
                    }
                    c => panic!("{at}: exit {c:?}\n{}", r.stderr),
                }
            }
        }
        let first_ok = first_ok.expect("eval fits under no limit of the sweep");
        eprintln!(
            "eval --threads {threads} under ulimit -v: starts from {floor} KiB, refused in one \
             line up to {:?} KiB, results from {first_ok} KiB",
            refused.last()
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// An iceoryx2 config of its own in `dir` (docs/security.md, "One pipeline per user"): a
/// root and a file prefix no other test uses, so that what is left in `/dev/shm` is known
/// to be this test's.
fn own_iceoryx2(dir: &Path, test: &str) -> String {
    let tag = format!("h16{}{test}_", std::process::id());
    std::fs::create_dir_all(dir.join("config")).unwrap();
    std::fs::write(
        dir.join("config/iceoryx2.toml"),
        format!(
            "[global]\nroot-path = \"{}/\"\nprefix = \"{tag}\"\n",
            dir.join("iox2-root").display()
        ),
    )
    .unwrap();
    tag
}

/// Files of `/dev/shm` whose name starts with `tag`.
fn shm_files(tag: &str) -> Vec<String> {
    std::fs::read_dir("/dev/shm")
        .unwrap()
        .flatten()
        .filter_map(|e| e.file_name().into_string().ok())
        .filter(|n| n.starts_with(tag))
        .collect()
}

/// `run` and `channel-sim` under a tight `ulimit -v`: the publisher's data segment could not
/// be mapped, the runner blamed "another runner using this --prefix" (the publisher "16
/// publishers already running"), and the segment's file stayed in `/dev/shm`, 16 MB each
/// time, removed by nobody; below that the runner aborted. Now every limit from the one the
/// binary starts under ends with exit 0/3 (it fitted; no publisher came) or one line naming
/// the limit, never a signal, and nothing of the test's iceoryx2 prefix is left in `/dev/shm`
/// but the shared node counter; a normal run on the same prefix afterwards completes.
#[test]
fn run_and_channel_sim_under_an_address_space_limit_say_so_and_leave_nothing() {
    let dir = scratch("run-ulimit");
    let tag = own_iceoryx2(&dir, "run");
    let p = prefix("run-ulimit");
    let step = 2_000;
    let floor = load_floor(&dir, step);
    let mut seen: Vec<(String, String, u64)> = Vec::new();
    let leftovers = |tag: &str| -> Vec<String> {
        shm_files(tag)
            .into_iter()
            .filter(|n| !n.ends_with("global_mgmt"))
            .collect()
    };
    for kib in (floor..floor + 80_000).step_by(step as usize) {
        let runs = [
            (
                "run",
                vec![
                    "run",
                    "--scenario",
                    "linear",
                    "--prefix",
                    &p,
                    "--steps",
                    "10",
                    "--connect-timeout",
                    "0.2",
                ],
            ),
            (
                "channel-sim",
                vec![
                    "channel-sim",
                    "--scenario",
                    "linear",
                    "--prefix",
                    &p,
                    "--steps",
                    "10",
                    "--rate",
                    "0",
                    "--connect-timeout",
                    "0.2",
                ],
            ),
        ];
        for (what, args) in &runs {
            let r = limited(&dir, kib, args);
            assert_eq!(
                r.signal, None,
                "{what} under ulimit -v {kib}: killed\n{}",
                r.stderr
            );
            let errors: Vec<&str> = r.stderr.lines().filter(|l| l.contains("error")).collect();
            // Fitted: the runner waited for a publisher, the publisher for a subscriber.
            let fitted =
                r.code == Some(3) || errors.len() == 1 && errors[0].contains("no subscriber on");
            match r.code {
                _ if fitted => {}
                Some(1) | Some(2) => {
                    assert_eq!(errors.len(), 1, "{what} {kib}: {}", r.stderr);
                    assert!(
                        errors[0].contains("ulimit -v"),
                        "{what} {kib}: {}",
                        r.stderr
                    );
                    assert!(
                        !errors[0].contains("already running")
                            && !errors[0].contains("another runner"),
                        "{what} {kib}: {}",
                        r.stderr
                    );
                }
                c => panic!("{what} under ulimit -v {kib}: exit {c:?}\n{}", r.stderr),
            }
            assert_eq!(
                leftovers(&tag),
                Vec::<String>::new(),
                "{what} under ulimit -v {kib} left files\n{}",
                r.stderr
            );
            // The first limit of each outcome: what ended it, by its first words.
            let how = match errors.first() {
                _ if fitted => "fitted",
                Some(e) if e.contains("cannot publish") => "publisher's segment not mapped",
                Some(e) if e.contains("needs at least") => "no room beside the program",
                Some(_) => "budget beyond the limit",
                None => "?",
            }
            .to_string();
            if !seen.iter().any(|(w, h, _)| w == what && *h == how) {
                seen.push((what.to_string(), how, kib));
            }
        }
    }
    eprintln!("under ulimit -v from {floor} KiB (first limit of each outcome): {seen:?}");
    // The same prefix and iceoryx2 root without the limit: nothing left blocks it.
    let json = dir.join("r.json");
    let mut run = Proc::start_in(
        &dir,
        "runner",
        &[
            "run",
            "--scenario",
            "linear",
            "--prefix",
            &p,
            "--steps",
            "200",
            "--json",
            json.to_str().unwrap(),
        ],
        &[],
        None,
    );
    run.wait_for_stderr("waiting for channel-sim", 30);
    let mut publ = Proc::start_in(&dir, "publisher", &channel_sim(&p, "200", "0"), &[], None);
    assert!(publ.wait(60).success(), "{}", publ.err());
    assert_eq!(run.wait(60).code(), Some(0), "{}", run.err());
    assert_eq!(report(&json)["counts"]["instants"], 200);
    assert_eq!(leftovers(&tag), Vec::<String>::new());
    for f in shm_files(&tag) {
        let _ = std::fs::remove_file(format!("/dev/shm/{f}"));
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// `run --quiet` hid the only line that said why the run ended "publisher lost" (exit 3):
/// the silence, the deadline and the publishers left. Quiet hides progress, not that.
#[test]
fn quiet_still_says_why_the_publisher_was_lost() {
    let dir = scratch("quiet-lost");
    let p = prefix("quiet-lost");
    let mut run = Proc::start(
        &dir,
        "runner",
        &[
            "run",
            "--scenario",
            "linear",
            "--prefix",
            &p,
            "--steps",
            "100000",
            "--quiet",
        ],
    );
    // Nothing says "waiting" under --quiet: the publisher waits for the runner instead.
    let mut publ = Proc::start(&dir, "publisher", &channel_sim(&p, "100000", "200"));
    wait_for_an_estimate(&p, &run);
    publ.signal(libc::SIGKILL);
    let _ = publ.wait(10);
    let st = run.wait(60);
    let err = run.err();
    assert_eq!(st.code(), Some(3), "{err}");
    let lines: Vec<&str> = err.lines().collect();
    assert_eq!(lines.len(), 1, "{err}");
    assert!(lines[0].contains("publisher lost: no slot for"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// On a full disk `eval --json` truncated the report before writing it: a 0-byte or cut
/// file replaced the previous one. Now it is written whole or not at all (a file beside it,
/// renamed over it), the error line names each file, and nothing else is left on the disk.
/// The full disk is a 256 KiB tmpfs in a mount namespace of its own (`unshare -m`, root).
#[test]
fn a_full_disk_keeps_the_previous_report_whole_and_names_the_files() {
    let dir = scratch("full-tmpfs");
    let ok = std::process::Command::new("unshare")
        .args(["-m", "sh", "-c", "mount -t tmpfs -o size=64k tmpfs /mnt"])
        .status()
        .is_ok_and(|s| s.success());
    if !ok {
        eprintln!(
            "skipped: no tmpfs in a mount namespace of our own here (needs root and unshare -m)"
        );
        return;
    }
    let full = dir.join("full");
    std::fs::create_dir_all(&full).unwrap();
    let old = "{\"old\": true}\n";
    let script = r#"
        mount -t tmpfs -o size=256k tmpfs "$1" || exit 90
        printf '%s' "$2" > "$1/r.json"
        dd if=/dev/zero of="$1/fill" bs=1k 2>/dev/null
        IOX2_LOG_LEVEL=Error "$3" eval --scenario linear --runs 20 --horizon 3000 --threads 1 \
            --quiet --json "$1/r.json" --csv "$1/mse.csv" 2> "$4/eval.err"
        echo $? > "$4/eval.code"
        cp "$1/r.json" "$4/after.json"
        ls -A "$1" > "$4/ls"
    "#;
    let st = std::process::Command::new("unshare")
        .args(["-m", "sh", "-c", script, "sh"])
        .arg(&full)
        .arg(old)
        .arg(common::node_exe())
        .arg(&dir)
        .status()
        .unwrap();
    assert!(st.success(), "{st}");
    let read = |f: &str| std::fs::read_to_string(dir.join(f)).unwrap();
    let err = read("eval.err");
    assert_eq!(read("eval.code").trim(), "1", "{err}");
    assert_eq!(read("after.json"), old, "{err}");
    let line = err
        .lines()
        .find(|l| l.contains("error"))
        .expect("an error line");
    assert_eq!(err.lines().count(), 1, "{err}");
    for name in ["r.json", "mse.csv"] {
        assert!(
            line.contains(&format!("{name}: No space left on device")),
            "{line}"
        );
    }
    assert_eq!(
        read("ls").split_whitespace().collect::<Vec<_>>(),
        ["fill", "r.json"]
    );
    let _ = std::fs::remove_dir_all(&dir);
}
