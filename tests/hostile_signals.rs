//! Issue #20 across real processes: signals, dead children, stalled publishers and a second
//! user (docs/security.md, docs/pipeline.md "Stalled or lost").
//!
//! Every test uses its own service prefix; `Proc` kills its process and cleans up dead nodes
//! on drop, also when a test fails. Time bounds are generous upper bounds for a noisy 2-core
//! VM: the product's target is 100 ms for a stop and at once for a dead child; the tests
//! assert < 1 s (and < 2 s for a SIGKILLed demo's child).

#[path = "pipeline_common.rs"]
mod common;
#[path = "skip_log.rs"]
mod skip_log;

use common::{node_exe, prefix, report, scratch, Proc};
use std::path::Path;
use std::process::ExitStatus;
use std::time::{Duration, Instant};

const MODES: [&str; 3] = ["spin", "block", "listener"];
const S: &str = "linear";

fn runner(dir: &Path, name: &str, p: &str, extra: &[&str]) -> Proc {
    let json = dir.join(format!("{name}.json"));
    let csv = dir.join(format!("{name}.csv"));
    let mut args = vec![
        "run",
        "--scenario",
        S,
        "--prefix",
        p,
        "--json",
        json.to_str().unwrap(),
        "--estimates-csv",
        csv.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let run = Proc::start(dir, name, &args);
    run.wait_for_stderr("waiting for channel-sim", 30);
    run
}

fn publisher(dir: &Path, name: &str, p: &str, extra: &[&str]) -> Proc {
    let mut args = vec!["channel-sim", "--scenario", S, "--prefix", p];
    args.extend_from_slice(extra);
    Proc::start(dir, name, &args)
}

/// Polls until `p` exits: its status and how long that took (panics after 20 s).
fn exit_of(p: &mut Proc) -> (ExitStatus, Duration) {
    let t = Instant::now();
    let c = p.child.as_mut().expect("running");
    loop {
        if let Some(s) = c.try_wait().unwrap() {
            p.child = None;
            return (s, t.elapsed());
        }
        assert!(
            t.elapsed() < Duration::from_secs(20),
            "{} did not exit\nstderr:\n{}",
            p.name,
            p.err()
        );
        std::thread::sleep(Duration::from_millis(1));
    }
}

fn no_panic(p: &Proc) {
    let err = p.err();
    assert!(!err.contains("panicked"), "{} panicked:\n{err}", p.name);
}

/// Whether process `pid` has ended (gone, or a zombie nobody reaps).
fn ended(pid: u32) -> bool {
    match std::fs::read_to_string(format!("/proc/{pid}/stat")) {
        Err(_) => true,
        // "pid (comm) S …": the state follows the last ')'.
        Ok(s) => s
            .rsplit_once(')')
            .is_some_and(|(_, rest)| rest.trim_start().starts_with(['Z', 'X'])),
    }
}

/// The child's pid from the demo's first line ("… publisher pid N)").
fn child_pid(demo: &Proc) -> u32 {
    demo.wait_for_stderr("publisher pid ", 30);
    let err = demo.err();
    let at = err.find("publisher pid ").unwrap() + "publisher pid ".len();
    err[at..]
        .split(|c: char| !c.is_ascii_digit())
        .next()
        .unwrap()
        .parse()
        .unwrap()
}

/// One undisturbed run: the estimates every disturbed run must reproduce byte for byte
/// (seed 0; `--backpressure block`, so no slot can be lost).
fn reference_estimates(steps: &str) -> String {
    let dir = scratch("sig-ref");
    let p = prefix("sig-ref");
    let mut run = runner(&dir, "runner", &p, &["--steps", steps]);
    let mut publ = publisher(
        &dir,
        "pub",
        &p,
        &["--rate", "0", "--steps", steps, "--backpressure", "block"],
    );
    assert!(publ.wait(60).success(), "{}", publ.err());
    assert!(run.wait(60).success(), "{}", run.err());
    let csv = std::fs::read_to_string(dir.join("runner.csv")).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    csv
}

/// Sends SIGCONT to every process of `procs` still running, every 2 ms, until all have exited;
/// their exit statuses and the number of signals sent.
fn sigcont_storm(procs: &mut [&mut Proc]) -> (Vec<ExitStatus>, u64) {
    let start = Instant::now();
    let mut status: Vec<Option<ExitStatus>> = vec![None; procs.len()];
    let mut sent = 0;
    while status.iter().any(Option::is_none) {
        assert!(start.elapsed() < Duration::from_secs(60), "no end");
        for (p, s) in procs.iter_mut().zip(status.iter_mut()) {
            if s.is_some() {
                continue;
            }
            // Reaped here, so no signal ever goes to a recycled pid.
            match p.child.as_mut().unwrap().try_wait().unwrap() {
                Some(st) => {
                    *s = Some(st);
                    p.child = None;
                }
                None => {
                    p.signal(libc::SIGCONT);
                    sent += 1;
                }
            }
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    (status.into_iter().map(Option::unwrap).collect(), sent)
}

#[test]
fn sigcont_to_publisher_and_runner_changes_nothing_in_any_wait_mode() {
    let steps = "400";
    let reference = reference_estimates(steps);
    assert_eq!(
        reference.lines().count(),
        401,
        "header + one row per instant"
    );
    // Paced (every wait of the publisher is a pacing sleep) and, last, a publisher blocked on
    // a full 4-slot queue behind a slow runner (its waits are inside `send`).
    let mut cases: Vec<(&str, Vec<&str>, Vec<&str>)> = MODES
        .iter()
        .map(|m| {
            (
                *m,
                vec!["--wait", *m, "--steps", steps],
                vec!["--rate", "400", "--steps", steps, "--backpressure", "block"],
            )
        })
        .collect();
    cases.push((
        "block, publisher blocked",
        vec![
            "--wait",
            "block",
            "--steps",
            steps,
            "--buffer",
            "4",
            "--debug-slow-us",
            "2000",
        ],
        vec!["--rate", "0", "--steps", steps],
    ));
    for (what, run_args, pub_args) in cases {
        let dir = scratch("sigcont");
        let p = prefix("sigcont");
        let mut run = runner(&dir, "runner", &p, &run_args);
        let mut publ = publisher(&dir, "pub", &p, &pub_args);
        let (st, sent) = sigcont_storm(&mut [&mut run, &mut publ]);
        assert!(st[0].success(), "{what}: runner {}\n{}", st[0], run.err());
        assert!(
            st[1].success(),
            "{what}: publisher {}\n{}",
            st[1],
            publ.err()
        );
        assert!(sent > 100, "{what}: only {sent} SIGCONTs sent");
        no_panic(&run);
        no_panic(&publ);
        assert!(
            publ.err().contains("done after 400 instants"),
            "{}",
            publ.err()
        );
        let r = report(&dir.join("runner.json"));
        assert_eq!(r["ending"], "completed", "{what}: {r}");
        assert_eq!(r["counts"]["received"], 400, "{what}: {r}");
        assert_eq!(r["counts"]["lost_in_ipc"], 0, "{what}: {r}");
        assert_eq!(r["stalls"]["count"], 0, "{what}: {r}");
        let csv = std::fs::read_to_string(dir.join("runner.csv")).unwrap();
        assert!(
            csv == reference,
            "{what}: estimates differ from the undisturbed run"
        );
        eprintln!("{what}: {sent} SIGCONTs, estimates identical");
        let _ = std::fs::remove_dir_all(&dir);
    }
}

#[test]
fn a_publisher_stopped_for_250_ms_is_stalled_not_lost() {
    for mode in MODES {
        let dir = scratch("sigstop");
        let p = prefix("sigstop");
        let mut run = runner(&dir, "runner", &p, &["--wait", mode, "--steps", "300"]);
        let mut publ = publisher(
            &dir,
            "pub",
            &p,
            &["--rate", "200", "--steps", "300", "--backpressure", "block"],
        );
        std::thread::sleep(Duration::from_millis(500));
        publ.signal(libc::SIGSTOP);
        std::thread::sleep(Duration::from_millis(250));
        publ.signal(libc::SIGCONT);
        assert!(publ.wait(30).success(), "{}", publ.err());
        let st = run.wait(30);
        assert!(st.success(), "{mode}: {st}\n{}", run.err());
        no_panic(&run);
        let r = report(&dir.join("runner.json"));
        assert_eq!(r["ending"], "completed", "{mode}: {r}");
        assert_eq!(r["publisher_losses"], 0, "{mode}: {r}");
        assert_eq!(r["counts"]["received"], 300, "{mode}: {r}");
        assert_eq!(r["stalls"]["count"], 1, "{mode}: {r}");
        // The silence spans the stop: about its 250 ms, measured between two receive times,
        // so a runner that took the last slot before the stop late (not scheduled: 242 ms was
        // seen here) measures less; 200 ms leaves room for that. The upper bound is only a
        // sanity check.
        let ms = r["stalls"]["longest_ms"].as_f64().unwrap();
        assert!((200.0..5000.0).contains(&ms), "{mode}: stall of {ms} ms");
        let err = run.err();
        assert!(err.contains("publisher stalled"), "{err}");
        assert!(!err.contains("publisher lost"), "{err}");
        let out = run.out();
        assert!(out.contains("publisher stalled 1 time(s)"), "{out}");
        eprintln!("{mode}: stalled {ms:.1} ms");
        let _ = std::fs::remove_dir_all(&dir);
    }
}

#[test]
fn a_stall_longer_than_the_stall_limit_is_a_loss() {
    let dir = scratch("stall-limit");
    let p = prefix("stall-limit");
    let mut run = runner(
        &dir,
        "runner",
        &p,
        &["--wait", "block", "--stall-limit", "0.5"],
    );
    let publ = publisher(&dir, "pub", &p, &["--rate", "200", "--steps", "100000"]);
    std::thread::sleep(Duration::from_millis(400));
    let t = Instant::now();
    publ.signal(libc::SIGSTOP);
    let (st, _) = exit_of(&mut run);
    let took = t.elapsed();
    publ.signal(libc::SIGCONT);
    let err = run.err();
    assert_eq!(st.code(), Some(3), "{st}\n{err}");
    // Lost after the 0.5 s limit of silence, which began with the last slot before the stop
    // (up to one 5 ms period earlier): not before 0.45 s. The upper bound is only a sanity
    // check.
    assert!(took >= Duration::from_millis(450), "lost after {took:?}");
    assert!(took < Duration::from_secs(3), "lost after {took:?}");
    assert!(err.contains("publisher stalled"), "{err}");
    assert!(
        err.contains("alive but silent longer than --stall-limit 0.5 s"),
        "{err}"
    );
    let r = report(&dir.join("runner.json"));
    assert_eq!(r["ending"], "publisher_lost", "{r}");
    assert_eq!(r["publisher_losses"], 1, "{r}");
    assert_eq!(r["stalls"]["count"], 1, "{r}");
    no_panic(&run);
    drop(publ);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn sigint_sigterm_and_sighup_stop_run_in_every_wait_mode_also_mid_catch_up() {
    for mode in MODES {
        // Paced, and mid catch-up: a runner 2 ms per slot behind a full 4096-slot queue.
        let cases: [(&str, i32, Vec<&str>, Vec<&str>); 4] = [
            ("SIGINT", libc::SIGINT, vec![], vec!["--rate", "200"]),
            ("SIGTERM", libc::SIGTERM, vec![], vec!["--rate", "200"]),
            // A closed terminal: the report is written as for the others.
            ("SIGHUP", libc::SIGHUP, vec![], vec!["--rate", "200"]),
            (
                "SIGTERM mid catch-up",
                libc::SIGTERM,
                vec!["--buffer", "4096", "--debug-slow-us", "2000"],
                vec!["--rate", "0"],
            ),
        ];
        for (what, sig, run_extra, pub_extra) in cases {
            let dir = scratch("sigstoprun");
            let p = prefix("sigstoprun");
            let mut run_args = vec!["--wait", mode, "--steps", "100000"];
            run_args.extend(run_extra);
            let mut run = runner(&dir, "runner", &p, &run_args);
            let mut pub_args = vec!["--steps", "100000"];
            pub_args.extend(pub_extra);
            let _publ = publisher(&dir, "pub", &p, &pub_args);
            std::thread::sleep(Duration::from_millis(600));
            run.signal(sig);
            let (st, took) = exit_of(&mut run);
            assert_eq!(st.code(), Some(130), "{mode} {what}: {st}\n{}", run.err());
            assert!(
                took < Duration::from_secs(1),
                "{mode} {what}: took {took:?}"
            );
            no_panic(&run);
            let r = report(&dir.join("runner.json"));
            assert_eq!(r["ending"], "interrupted", "{mode} {what}: {r}");
            assert!(r["counts"]["received"].as_u64().unwrap() > 0, "{r}");
            assert!(dir.join("runner.csv").exists());
            assert!(run.out().contains("ended: Interrupted"), "{}", run.out());
            eprintln!("{mode} {what}: exited after {took:?}");
            let _ = std::fs::remove_dir_all(&dir);
        }
    }
}

fn demo(dir: &Path, name: &str, extra: &[&str]) -> Proc {
    let out = dir.join(name);
    let p = prefix(name);
    let mut args = vec![
        "demo",
        "--scenario",
        S,
        "--quiet",
        "--prefix",
        &p,
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    Proc::start(dir, name, &args)
}

#[test]
fn sigint_and_sigterm_stop_demo_and_its_child_within_a_second() {
    for (what, sig) in [("SIGINT", libc::SIGINT), ("SIGTERM", libc::SIGTERM)] {
        for mode in MODES {
            let dir = scratch("sigdemo");
            let mut d = demo(
                &dir,
                "demo",
                &["--steps", "100000", "--rate", "200", "--wait", mode],
            );
            let child = child_pid(&d);
            std::thread::sleep(Duration::from_millis(800));
            assert!(!ended(child), "the child ended early\n{}", d.err());
            d.signal(sig);
            let (st, took) = exit_of(&mut d);
            assert_eq!(st.code(), Some(130), "{what} {mode}: {st}\n{}", d.err());
            assert!(
                took < Duration::from_secs(1),
                "{what} {mode}: took {took:?}"
            );
            // The demo waited for its child: it is gone, not even a zombie.
            assert!(ended(child), "{what} {mode}: child {child} still running");
            no_panic(&d);
            let r = report(&dir.join("demo").join("report.json"));
            assert_eq!(r["ending"], "interrupted", "{r}");
            for f in [
                "estimates.csv",
                "slots.csv",
                "latency.csv",
                "trajectories.svg",
            ] {
                assert!(dir.join("demo").join(f).exists(), "{f} missing");
            }
            assert!(d.out().contains("ended: Interrupted"), "{}", d.out());
            eprintln!("demo {what} {mode}: exited after {took:?}");
            let _ = std::fs::remove_dir_all(&dir);
        }
    }
}

#[test]
fn a_sigkilled_demo_leaves_no_publisher_running() {
    let dir = scratch("killdemo");
    let mut d = demo(&dir, "demo", &["--steps", "100000", "--rate", "200"]);
    let child = child_pid(&d);
    std::thread::sleep(Duration::from_millis(800));
    assert!(!ended(child), "the child ended early\n{}", d.err());
    d.signal(libc::SIGKILL);
    let _ = exit_of(&mut d);
    let t = Instant::now();
    while !ended(child) {
        assert!(
            t.elapsed() < Duration::from_secs(2),
            "the publisher {child} still runs 2 s after its demo was killed"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    eprintln!("child gone {:?} after the demo's SIGKILL", t.elapsed());
    drop(d);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_dead_child_is_noticed_at_once_and_named() {
    let dir = scratch("deadchild");
    // A child that is no publisher: the demo fails within 1 s (from its start), exit code 2.
    let false_exe = ["/bin/false", "/usr/bin/false"]
        .into_iter()
        .find(|p| Path::new(p).exists())
        .expect("false(1)");
    let t = Instant::now();
    let mut d = demo(&dir, "false", &["--channel-sim", false_exe]);
    let (st, _) = exit_of(&mut d);
    let took = t.elapsed();
    let err = d.err();
    assert_eq!(st.code(), Some(2), "{st}\n{err}");
    assert!(took < Duration::from_secs(1), "took {took:?}\n{err}");
    assert!(err.contains("exited with exit status: 1"), "{err}");
    let errors: Vec<&str> = err.lines().filter(|l| l.contains("error")).collect();
    assert_eq!(errors.len(), 1, "one error line:\n{err}");
    no_panic(&d);
    eprintln!(
        "--channel-sim {false_exe}: failed after {took:?}: {}",
        errors[0]
    );

    // A child that crashes mid-stream: the run ends as lost (exit 3) with its summary, the
    // line names the signal, and it comes at once, not at the 100 ms data deadline's leisure
    // nor after a connect timeout.
    let mut d = demo(&dir, "crash", &["--steps", "100000", "--rate", "200"]);
    let child = child_pid(&d);
    std::thread::sleep(Duration::from_millis(800));
    // SAFETY: kill(2) on the demo's child, which is running (checked just before).
    assert!(!ended(child));
    #[allow(unsafe_code)]
    let rc = unsafe { libc::kill(child as i32, libc::SIGKILL) };
    assert_eq!(rc, 0);
    let (st, took) = exit_of(&mut d);
    let err = d.err();
    assert_eq!(st.code(), Some(3), "{st}\n{err}");
    assert!(took < Duration::from_secs(1), "took {took:?}\n{err}");
    assert!(err.contains("exited with signal: 9"), "{err}");
    no_panic(&d);
    let r = report(&dir.join("crash").join("report.json"));
    assert_eq!(r["ending"], "publisher_lost", "{r}");
    assert!(r["counts"]["received"].as_u64().unwrap() > 0, "{r}");
    eprintln!("crashed child noticed: demo exited {took:?} after the SIGKILL");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The uid this test runs as (`/proc/self` belongs to it).
fn my_uid() -> u32 {
    use std::os::unix::fs::MetadataExt;
    std::fs::metadata("/proc/self").unwrap().uid()
}

/// `pipeline-node args` as user `nobody` in `cwd`.
fn as_nobody(cwd: &Path, name: &str, args: &[&str]) -> std::io::Result<Proc> {
    use std::os::unix::process::CommandExt;
    let (stdout, stderr) = (
        cwd.join(format!("{name}.out")),
        cwd.join(format!("{name}.err")),
    );
    let child = std::process::Command::new(node_exe())
        .args(args)
        .current_dir(cwd)
        .uid(NOBODY)
        .gid(NOBODY)
        .env("IOX2_LOG_LEVEL", "Error")
        .stdin(std::process::Stdio::null())
        .stdout(std::fs::File::create(&stdout)?)
        .stderr(std::fs::File::create(&stderr)?)
        .spawn()?;
    Ok(Proc {
        child: Some(child),
        stderr,
        stdout,
        name: name.to_string(),
    })
}

const NOBODY: u32 = 65534;

#[test]
fn another_user_gets_one_line_and_runs_with_its_own_iceoryx2_root() {
    if my_uid() != 0 {
        skip_log::skipped(
            "another_user_gets_one_line_and_runs_with_its_own_iceoryx2_root",
            "needs root to start processes as another user",
        );
        return;
    }
    // The default iceoryx2 root, created by (and belonging to) root.
    common::cleanup_dead_nodes();
    let dir = scratch("otheruser");
    std::os::unix::fs::chown(&dir, Some(NOBODY), Some(NOBODY)).unwrap();
    let p = prefix("otheruser");
    let mut probe = match as_nobody(&dir, "probe", &["stream-header", "--scenario", S]) {
        Ok(pr) => pr,
        Err(e) => {
            skip_log::skipped(
                "another_user_gets_one_line_and_runs_with_its_own_iceoryx2_root",
                &format!("cannot start the test binary as nobody ({e})"),
            );
            return;
        }
    };
    if !probe.wait(30).success() {
        skip_log::skipped(
            "another_user_gets_one_line_and_runs_with_its_own_iceoryx2_root",
            &format!("the test binary does not run as nobody: {}", probe.err()),
        );
        return;
    }

    let mut denied = as_nobody(
        &dir,
        "denied",
        &[
            "run",
            "--scenario",
            S,
            "--prefix",
            &p,
            "--connect-timeout",
            "1",
        ],
    )
    .unwrap();
    let st = denied.wait(30);
    let err = denied.err();
    assert_eq!(st.code(), Some(2), "{st}\n{err}");
    assert_eq!(err.trim().lines().count(), 1, "one line:\n{err}");
    assert!(err.contains("belongs to uid 0"), "{err}");
    assert!(err.contains("docs/security.md"), "{err}");
    assert!(!err.contains("InternalError"), "{err}");
    no_panic(&denied);
    // The bridge's sides set up their node through the same code (estpipe-process): the same
    // one line, exit 2 (it was an internal error, exit 1), before any zenoh session opens.
    let mut bridge = as_nobody(
        &dir,
        "denied-bridge",
        &[
            "bridge",
            "--side",
            "sensor",
            "--prefix",
            &p,
            "--key",
            "estpipe-t/otheruser",
        ],
    )
    .unwrap();
    let st = bridge.wait(30);
    let err = bridge.err();
    assert_eq!(st.code(), Some(2), "{st}\n{err}");
    assert_eq!(err.trim().lines().count(), 1, "one line:\n{err}");
    assert!(err.contains("belongs to uid 0"), "{err}");
    no_panic(&bridge);

    // The remedy the line names: an iceoryx2 root and prefix of this user's own.
    let cfg = dir.join("config");
    std::fs::create_dir_all(&cfg).unwrap();
    let root = dir.join("iox2-root");
    std::fs::write(
        cfg.join("iceoryx2.toml"),
        format!(
            "[global]\nroot-path = \"{}/\"\nprefix = \"iox2_t{}_\"\n",
            root.display(),
            std::process::id()
        ),
    )
    .unwrap();
    for d in [&cfg, &cfg.join("iceoryx2.toml")] {
        std::os::unix::fs::chown(d, Some(NOBODY), Some(NOBODY)).unwrap();
    }
    let json = dir.join("own.json");
    let mut run = as_nobody(
        &dir,
        "own-run",
        &[
            "run",
            "--scenario",
            S,
            "--prefix",
            &p,
            "--steps",
            "200",
            "--json",
            json.to_str().unwrap(),
        ],
    )
    .unwrap();
    run.wait_for_stderr("waiting for channel-sim", 30);
    let mut publ = as_nobody(
        &dir,
        "own-pub",
        &[
            "channel-sim",
            "--scenario",
            S,
            "--prefix",
            &p,
            "--steps",
            "200",
            "--rate",
            "1000",
        ],
    )
    .unwrap();
    assert!(publ.wait(60).success(), "{}", publ.err());
    assert!(run.wait(60).success(), "{}", run.err());
    let r = report(&json);
    assert_eq!(r["ending"], "completed", "{r}");
    assert_eq!(r["counts"]["received"], 200, "{r}");
    // The pipeline lived in nobody's own root.
    use std::os::unix::fs::MetadataExt;
    assert_eq!(std::fs::metadata(&root).unwrap().uid(), NOBODY);
    let _ = std::fs::remove_dir_all(&dir);
}
