//! Sensor nodes in the loop (docs/sensor-node.md): the node firmware on QEMU's Cortex-M4F
//! (`estimator-core/firmware`, binary `sensor-node`) decides every instant from the raw
//! samples the gateway (`channel-sim --sensor-node`) feeds it over its UART, and the runner
//! estimates from the nodes' packets.
//!
//! What must hold, each against an independent run of the simulated channel (`channel-sim`
//! without nodes, same scenario and seed):
//! - every node decision equals channel-sim's (delivery, flags, the measurement's bits), for
//!   2000 instants of seed 003's token bucket and 2000 × 3 of seed 004's triggered nodes;
//! - the runner's estimates are the channel-sim-fed run's, bit for bit (the CSV prints the
//!   shortest text that reads back to the same `f64`);
//! - corrupt, truncated, overlong and merged frames injected on the node's line are counted
//!   and skipped by the gateway, a corrupt sample by the node, the sample is sent again, and
//!   the run goes on to the same estimates;
//! - `ipc-runner demo --sensor-node qemu` runs the whole loop with one command.
//!
//! Needs qemu-system-arm and the thumbv7em-none-eabihf target: skipped with one line where
//! absent, unless `REQUIRE_QEMU=1` (CI), which makes it fail. With `SENSOR_NODE_PLUGIN` set
//! (by `.ci/firmware`: the instruction-count plugin's argument with `{name}` for the node),
//! the clean runs' nodes are counted.

#[path = "pipeline_common.rs"]
mod common;
#[path = "firmware_qemu/qemu.rs"]
#[allow(dead_code)] // run_qemu: the estimator binaries' runner, not used here
mod qemu;
#[path = "skip_log.rs"]
mod skip_log;

use common::{prefix, scratch, Proc};
use std::io::{Read, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The firmware, built once (the build is a no-op when `.ci/firmware` built it).
fn firmware() -> Option<PathBuf> {
    if let Some(why) = qemu::missing_tools() {
        assert!(!qemu::require_qemu(), "REQUIRE_QEMU=1 but {why}");
        skip_log::skipped(
            &skip_log::current_test("sensor_node_qemu"),
            &format!("{why} (set REQUIRE_QEMU=1 to fail)"),
        );
        return None;
    }
    static ELF: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    Some(
        ELF.get_or_init(|| qemu::build_firmware().join("sensor-node"))
            .clone(),
    )
}

/// One node on QEMU, its UART on a unix socket QEMU listens on. Killed on drop, and by the
/// kernel if this test process dies first.
struct Node {
    child: Option<Child>,
    sock: PathBuf,
}

impl Node {
    fn start(dir: &Path, elf: &Path, name: &str, count: bool) -> Self {
        let sock = dir.join(format!("{name}.sock"));
        let mut cmd = Command::new("qemu-system-arm");
        cmd.args(["-machine", "mps2-an386", "-cpu", "cortex-m4"])
            .args(["-display", "none", "-monitor", "none"])
            .args(["-semihosting-config", "enable=on,target=native"])
            .arg("-chardev")
            .arg(format!(
                "socket,id=line,path={},server=on,wait=on",
                sock.display()
            ))
            .args(["-serial", "chardev:line", "-kernel"])
            .arg(elf)
            .stdin(Stdio::null())
            .stdout(std::fs::File::create(dir.join(format!("{name}.qemu.out"))).unwrap())
            .stderr(std::fs::File::create(dir.join(format!("{name}.qemu.err"))).unwrap());
        if count {
            if let Ok(t) = std::env::var("SENSOR_NODE_PLUGIN") {
                cmd.arg("-plugin").arg(t.replace("{name}", name));
            }
        }
        // SAFETY: prctl(2) in the child before exec: SIGKILL when this thread's process goes.
        #[allow(unsafe_code)]
        unsafe {
            use std::os::unix::process::CommandExt;
            cmd.pre_exec(|| {
                libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL);
                Ok(())
            });
        }
        let child = cmd.spawn().expect("start qemu-system-arm");
        Self {
            child: Some(child),
            sock,
        }
    }

    fn line(&self) -> String {
        format!("unix:{}", self.sock.display())
    }

    /// Waits for QEMU to end by itself (the node exits after `Finish`): its status.
    fn wait(&mut self, secs: u64) -> i32 {
        let mut c = self.child.take().unwrap();
        let start = Instant::now();
        loop {
            if let Some(s) = c.try_wait().unwrap() {
                return s.code().unwrap_or(-1);
            }
            if start.elapsed() > Duration::from_secs(secs) {
                let _ = c.kill();
                let _ = c.wait();
                panic!("QEMU did not exit within {secs} s after Finish");
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}

impl Drop for Node {
    fn drop(&mut self) {
        if let Some(c) = self.child.as_mut() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// The runner on `p`: every estimator of the scenario, estimates to `csv`.
fn runner(dir: &Path, name: &str, p: &str, scenario: &str, seed: u64, steps: u32) -> Proc {
    let csv = dir.join(format!("{name}.csv"));
    let run = Proc::start(
        dir,
        name,
        &[
            "run",
            "--scenario",
            scenario,
            "--seed",
            &seed.to_string(),
            "--steps",
            &steps.to_string(),
            "--prefix",
            p,
            "--wait",
            "block",
            "--buffer",
            "4096",
            "--estimates-csv",
            csv.to_str().unwrap(),
        ],
    );
    run.wait_for_stderr("waiting for channel-sim", 60);
    run
}

/// The publisher on `p`, with `lines` as its sensor nodes (none: the simulated channel).
fn publisher(
    dir: &Path,
    name: &str,
    p: &str,
    scenario: &str,
    seed: u64,
    steps: u32,
    lines: &[String],
) -> Proc {
    let (seed, steps) = (seed.to_string(), steps.to_string());
    let mut args: Vec<&str> = vec![
        "channel-sim",
        "--scenario",
        scenario,
        "--seed",
        &seed,
        "--steps",
        &steps,
        "--rate",
        "0",
        "--prefix",
        p,
        "--node-timeout",
        "0.5",
    ];
    for l in lines {
        args.extend(["--sensor-node", l]);
    }
    Proc::start(dir, name, &args)
}

/// The estimates of the simulated channel's run: the reference.
fn reference(dir: &Path, scenario: &str, seed: u64, steps: u32) -> String {
    let p = prefix("sn-ref");
    let mut run = runner(dir, "ref", &p, scenario, seed, steps);
    let mut publ = publisher(dir, "ref-pub", &p, scenario, seed, steps, &[]);
    assert!(run.wait(120).success(), "reference runner: {}", run.err());
    assert!(
        publ.wait(60).success(),
        "reference publisher: {}",
        publ.err()
    );
    std::fs::read_to_string(dir.join("ref.csv")).unwrap()
}

/// The gateway's counters, from its report line.
#[derive(Debug, Default)]
struct Counts {
    equal: u64,
    compared: u64,
    forwarded: u64,
    corrupt: u64,
    stale: u64,
    timeouts: u64,
    resent: u64,
    refused: u64,
    /// Per node: (frames, bad frames, decisions, sent, repeated, stack peak).
    nodes: Vec<[u64; 6]>,
}

fn numbers(s: &str) -> Vec<u64> {
    s.split(|c: char| !c.is_ascii_digit())
        .filter(|w| !w.is_empty())
        .map(|w| w.parse().unwrap())
        .collect()
}

fn counts(stderr: &str) -> Counts {
    let line = stderr
        .lines()
        .find(|l| l.contains("decisions equal to channel-sim's"))
        .unwrap_or_else(|| panic!("no node report in:\n{stderr}"));
    let n = numbers(line.split("channel-sim's:").nth(1).unwrap());
    // equal, compared, differ, forwarded, sent, corrupt, stale, timeouts, resent, refused
    assert_eq!(n.len(), 10, "{line}");
    let nodes = stderr
        .lines()
        .filter_map(|l| l.split("channel-sim: node ").nth(1))
        .map(|l| {
            let v = numbers(l);
            // node, frames, bad, decisions, sent, repeated, refused, stack
            assert_eq!(v.len(), 8, "{l}");
            [v[1], v[2], v[3], v[4], v[5], v[7]]
        })
        .collect();
    Counts {
        equal: n[0],
        compared: n[1],
        forwarded: n[3],
        corrupt: n[5],
        stale: n[6],
        timeouts: n[7],
        resent: n[8],
        refused: n[9],
        nodes,
    }
}

/// Puts a proxy in front of a node's socket (in the scenario's directory): the proxy's socket.
type Proxy = dyn Fn(&Path, &Path) -> PathBuf;

/// The scenario's loop with its nodes on QEMU (through `proxy` for node 0 when given):
/// the gateway's counts and the estimates.
fn node_loop(
    dir: &Path,
    elf: &Path,
    scenario: &str,
    seed: u64,
    steps: u32,
    nodes: usize,
    proxy: Option<&Proxy>,
) -> (Counts, String) {
    let p = prefix("sn-loop");
    let mut run = runner(dir, "loop", &p, scenario, seed, steps);
    let mut qemus: Vec<Node> = (0..nodes)
        .map(|m| Node::start(dir, elf, &format!("{scenario}-{m}"), proxy.is_none()))
        .collect();
    let mut lines: Vec<String> = qemus.iter().map(Node::line).collect();
    if let Some(proxy) = proxy {
        lines[0] = format!("unix:{}", proxy(dir, &qemus[0].sock).display());
    }
    let mut publ = publisher(dir, "loop-pub", &p, scenario, seed, steps, &lines);
    let ok = publ.wait(300).success();
    assert!(ok, "gateway: {}", publ.err());
    assert!(run.wait(120).success(), "runner: {}", run.err());
    for q in &mut qemus {
        assert_eq!(q.wait(30), 0, "the node's exit status");
    }
    let c = counts(&publ.err());
    println!("{}", publ.err());
    (c, std::fs::read_to_string(dir.join("loop.csv")).unwrap())
}

/// The estimate columns of an estimates CSV (the truth's left out: it is evaluation only,
/// and the runner may miss an instant's truth when its truth subscriber comes late).
fn estimates(csv: &str) -> Vec<Vec<&str>> {
    let mut lines = csv.lines();
    let head: Vec<&str> = lines.next().unwrap_or_default().split(',').collect();
    let keep: Vec<usize> = (0..head.len())
        .filter(|&i| !head[i].starts_with("truth_"))
        .collect();
    std::iter::once(head.clone())
        .chain(lines.map(|l| l.split(',').collect()))
        .map(|row: Vec<&str>| {
            keep.iter()
                .map(|&i| row.get(i).copied().unwrap_or(""))
                .collect()
        })
        .collect()
}

/// Every node's decision equal to channel-sim's, forwarded, and the estimates identical.
fn assert_same(c: &Counts, est: &str, reference: &str, decisions: u64) {
    assert_eq!((c.compared, c.equal), (decisions, decisions), "{c:?}");
    assert_eq!(c.refused, 0, "{c:?}");
    let (a, b) = (estimates(est), estimates(reference));
    assert_eq!(a.len(), b.len());
    assert!(a[0].len() > 2, "no estimator columns: {:?}", a[0]);
    for (i, (a, b)) in a.iter().zip(&b).enumerate() {
        assert_eq!(a, b, "estimates differ at line {i}");
    }
}

#[test]
fn seed003_node_decides_as_channel_sim_and_the_estimates_are_bit_identical() {
    let Some(elf) = firmware() else { return };
    let dir = scratch("sn003");
    let steps = 2000;
    let want = reference(&dir, "nn-token-bucket", 3, steps);
    let (c, est) = node_loop(&dir, &elf, "nn-token-bucket", 3, steps, 1, None);
    // k = 0 (y₀, decided by the node and compared, not published) and k = 1..=2000.
    assert_same(&c, &est, &want, u64::from(steps) + 1);
    assert_eq!(c.forwarded, u64::from(steps) + 1);
    assert_eq!((c.corrupt, c.stale, c.timeouts, c.resent), (0, 0, 0, 0));
    let [frames, bad, decided, sent, repeats, stack] = c.nodes[0];
    // Configure + 2001 samples + Finish; seed 003's bucket sends 2 of every 3 instants from
    // k = 6 on, 6 before: 6 + 2/3 of 1995 = 1336.
    assert_eq!((frames, bad, decided, repeats), (2003, 0, 2001, 0));
    assert_eq!(sent, 6 + 1995 / 3 * 2);
    assert!(stack > 0 && stack < 4096, "stack peak {stack} B");
}

#[test]
fn seed004_three_nodes_decide_as_channel_sim_and_the_estimates_are_bit_identical() {
    let Some(elf) = firmware() else { return };
    let dir = scratch("sn004");
    let steps = 2000;
    let want = reference(&dir, "tobit-fusion", 4, steps);
    let (c, est) = node_loop(&dir, &elf, "tobit-fusion", 4, steps, 3, None);
    assert_same(&c, &est, &want, 3 * u64::from(steps));
    assert_eq!((c.corrupt, c.stale, c.timeouts, c.resent), (0, 0, 0, 0));
    assert_eq!(c.nodes.len(), 3);
    let sent: u64 = c.nodes.iter().map(|n| n[3]).sum();
    // The shared bucket (ξ₀ = 10, g = 5, c = 3, L = 3) lets at most 5/3 nodes' worth of
    // packets through per instant on average, plus the initial level.
    assert!(
        sent > 0 && sent <= (10 + 5 * u64::from(steps)) / 3,
        "{sent}"
    );
    for n in &c.nodes {
        assert_eq!((n[0], n[1], n[2], n[4]), (2002, 0, 2000, 0), "{n:?}");
    }
}

/// What the proxy did to the node's frames.
const FLIP: usize = 10;
const TRUNCATE: usize = 20;
const GARBAGE: usize = 30;
const MERGE: usize = 40;
/// The gateway's frame (counted the same way) that reaches the node with a bit flipped:
/// well after the node-side injections and their retransmissions, so a fresh sample.
const INPUT_FLIP: usize = 100;

/// Flips a bit of a frame's middle byte, never to a zero (that would split the frame).
fn flip(frame: &mut [u8]) {
    let i = frame.len() / 2;
    frame[i] ^= if frame[i] == 0x04 { 0x08 } else { 0x04 };
}

/// Copies frames from `from` to `to`, `change(index, frame, delimiter)` on each non-empty one
/// (counted from 1), until either side closes.
fn frames(
    mut from: UnixStream,
    mut to: UnixStream,
    change: impl Fn(usize, &mut Vec<u8>, &mut Vec<u8>),
) {
    let mut frame = Vec::new();
    let mut index = 0;
    let mut buf = [0u8; 512];
    while let Ok(n) = from.read(&mut buf) {
        if n == 0 {
            return;
        }
        for &b in &buf[..n] {
            if b != 0 {
                frame.push(b);
                continue;
            }
            if frame.is_empty() {
                if to.write_all(&[0]).is_err() {
                    return;
                }
                continue;
            }
            index += 1;
            let mut out = std::mem::take(&mut frame);
            let mut end = vec![0u8];
            change(index, &mut out, &mut end);
            out.extend(end);
            if to.write_all(&out).is_err() {
                return;
            }
        }
    }
}

/// A proxy on node 0's line. Of the node's frames (counted from 1, empty ones not counted)
/// number FLIP gets a bit flipped, TRUNCATE loses its second half, GARBAGE is preceded by 600
/// bytes without a delimiter, MERGE loses its delimiter (it runs into the node's next frame):
/// four corrupt frames, as the gateway must count them. Of the gateway's frames, number
/// INPUT_FLIP gets a bit flipped: one corrupt frame, as the node must count it.
fn corrupting_proxy(dir: &Path, qemu_sock: &Path) -> PathBuf {
    let path = dir.join("proxy.sock");
    let listener = UnixListener::bind(&path).unwrap();
    let qemu_sock = qemu_sock.to_path_buf();
    std::thread::spawn(move || {
        let Ok((gateway, _)) = listener.accept() else {
            return;
        };
        let give_up = Instant::now() + Duration::from_secs(30);
        let node = loop {
            match UnixStream::connect(&qemu_sock) {
                Ok(s) => break s,
                Err(_) if Instant::now() < give_up => std::thread::sleep(Duration::from_millis(20)),
                Err(_) => return,
            }
        };
        let (g_in, n_out) = (gateway.try_clone().unwrap(), node.try_clone().unwrap());
        std::thread::spawn(move || {
            frames(g_in, n_out, |i, f, _| {
                if i == INPUT_FLIP {
                    flip(f);
                }
            })
        });
        frames(node, gateway, |i, f, end| match i {
            FLIP => flip(f),
            TRUNCATE => f.truncate(f.len() / 2),
            GARBAGE => {
                let mut g = vec![0x5a; 600];
                g.push(0);
                g.append(f);
                *f = g;
            }
            MERGE => end.clear(),
            _ => {}
        });
    });
    path
}

#[test]
fn corrupt_and_truncated_frames_are_counted_skipped_and_the_run_goes_on() {
    let Some(elf) = firmware() else { return };
    let dir = scratch("sncorrupt");
    let steps = 300;
    let want = reference(&dir, "nn-token-bucket", 5, steps);
    let (c, est) = node_loop(
        &dir,
        &elf,
        "nn-token-bucket",
        5,
        steps,
        1,
        Some(&corrupting_proxy),
    );
    // Never forwarded: the nodes' answers to the samples sent again are, so every instant
    // is there and the estimates are the reference's.
    assert_same(&c, &est, &want, u64::from(steps) + 1);
    assert_eq!(c.forwarded, u64::from(steps) + 1);
    assert_eq!(c.corrupt, 4, "{c:?}");
    // Two waits to the deadline: the merged frame has no end until the node's next frame, and
    // the node skips the corrupt sample without an answer.
    assert_eq!(c.timeouts, 2, "{c:?}");
    // The node counted the corrupt sample; every sample sent again after one of the node's
    // corrupt frames was answered again without a second decision; the one sent again after
    // the corrupt sample was the node's first (a fresh decision).
    let [_, bad, decided, _, repeats, _] = c.nodes[0];
    assert_eq!((bad, decided), (1, u64::from(steps) + 1));
    assert_eq!(repeats + 1, c.resent, "{c:?}");
    assert!(c.stale <= c.resent, "{c:?}");
}

#[test]
fn demo_with_sensor_nodes_runs_the_whole_loop() {
    let Some(elf) = firmware() else { return };
    let dir = scratch("sndemo");
    let out = dir.join("out");
    let mut demo = Proc::start(
        &dir,
        "demo",
        &[
            "demo",
            "--scenario",
            "tobit-fusion",
            "--steps",
            "200",
            "--rate",
            "0",
            "--quiet",
            "--sensor-node",
            "qemu",
            "--node-firmware",
            elf.to_str().unwrap(),
            "--prefix",
            &prefix("sndemo"),
            "--out",
            out.to_str().unwrap(),
        ],
    );
    let status = demo.wait(180);
    let (o, e) = (demo.out(), demo.err());
    assert!(status.success(), "demo: {status}\n{e}\n{o}");
    let c = counts(&e);
    assert_eq!((c.compared, c.equal, c.corrupt), (600, 600, 0), "{e}");
    assert_eq!(c.nodes.len(), 3, "{e}");
    assert!(o.contains("fused"), "the usual summary: {o}");
    assert!(out.join("estimates.csv").is_file());
}

/// Exit code and stderr of `pipeline-node <args>` (bounded).
fn refused(dir: &Path, name: &str, args: &[&str]) -> (Option<i32>, String) {
    let mut p = Proc::start(dir, name, args);
    let code = p.wait(60).code();
    let err = p.err();
    assert!(!err.contains("panicked"), "{name}: {err}");
    (code, err)
}

#[test]
fn bad_sensor_node_flags_get_one_line_without_qemu() {
    let dir = scratch("snflags");
    let p = prefix("snflags");
    let base = [
        "channel-sim",
        "--quiet",
        "--prefix",
        &p,
        "--connect-timeout",
        "1",
    ];
    let cases: &[(&[&str], i32, &str)] = &[
        (
            &[
                "--scenario",
                "nn-token-bucket",
                "--sensor-node",
                "/dev/ttyUSB0",
            ],
            2,
            "--sensor-node",
        ),
        (
            &["--scenario", "nn-token-bucket", "--sensor-node", "unix:"],
            2,
            "--sensor-node",
        ),
        (
            &["--scenario", "occlusion", "--sensor-node", "unix:/x"],
            2,
            "stage occlusion",
        ),
        (
            &["--scenario", "tobit-fusion", "--sensor-node", "unix:/x"],
            2,
            "3 node(s), 1",
        ),
        (
            &[
                "--scenario",
                "nn-token-bucket",
                "--sensor-node",
                "unix:/x",
                "--node",
                "0",
            ],
            2,
            "--node",
        ),
        (
            &[
                "--scenario",
                "nn-token-bucket",
                "--sensor-node",
                "unix:/x",
                "--node-timeout",
                "0",
            ],
            2,
            "--node-timeout",
        ),
        (
            &[
                "--scenario",
                "nn-token-bucket",
                "--sensor-node",
                "unix:/x",
                "--node-timeout",
                "nan",
            ],
            2,
            "--node-timeout",
        ),
        (
            &[
                "--scenario",
                "nn-token-bucket",
                "--sensor-node",
                "unix:/x",
                "--node-timeout",
                "inf",
            ],
            2,
            "--node-timeout",
        ),
        // Nobody on the line: said after --connect-timeout, exit 1.
        (
            &[
                "--scenario",
                "nn-token-bucket",
                "--sensor-node",
                "unix:/nonexistent/n.sock",
            ],
            1,
            "cannot connect",
        ),
    ];
    for (i, (args, want, needle)) in cases.iter().enumerate() {
        let all = [&base[..], args].concat();
        let (code, err) = refused(&dir, &format!("case{i}"), &all);
        assert_eq!(code, Some(*want), "{args:?}: {err}");
        let lines: Vec<&str> = err.lines().collect();
        assert_eq!(lines.len(), 1, "{args:?}: not one line: {err}");
        assert!(
            lines[0].contains(needle),
            "{args:?}: {needle:?} missing: {err}"
        );
    }
    let out = dir.join("out");
    let (code, err) = refused(
        &dir,
        "demo",
        &[
            "demo",
            "--scenario",
            "nn-token-bucket",
            "--sensor-node",
            "qemu",
            "--node-firmware",
            "/nonexistent/sensor-node",
            "--prefix",
            &prefix("snrefused"),
            "--out",
            out.to_str().unwrap(),
        ],
    );
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("--node-firmware") && err.lines().count() == 1,
        "{err}"
    );
}
