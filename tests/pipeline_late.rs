//! Late slots over real processes (docs/pipeline.md, "Late packets"): seed 004's three nodes
//! as three `channel-sim --node N` processes paced at 25 Hz, node 2 started 60 ms after the
//! others, into `ipc-runner run --instant-deadline-ms 5 --lag 16` (a lag of 640 ms: room for a
//! loaded machine's process start-up). Every instant is handed on
//! at its deadline without node 2's slot, which arrives a few instants later:
//!
//! * nothing that arrived within the lag is lost: every slot the deadline gave up is folded in
//!   (`late_folded` = `lost_deadline`, `late` = 0);
//! * the slot log (with its `late_after` column) replays with `--lag 16` to the live estimates
//!   bit for bit, instant by instant;
//! * once every late slot is in, the estimators hold what the on-time stream gives: the replay's
//!   final estimates equal those of the same log with every slot on time, bit for bit; without
//!   `--lag` they do not.

#[path = "pipeline_common.rs"]
mod common;

use common::{prefix, report, scratch, Proc};
use std::path::Path;

const S: &str = "tobit-fusion";
const STEPS: u32 = 200;

fn channel_sim(dir: &Path, p: &str, node: u8) -> Proc {
    let (steps, n) = (STEPS.to_string(), node.to_string());
    Proc::start(
        dir,
        &format!("pub-node{node}"),
        &[
            "channel-sim",
            "--scenario",
            S,
            "--prefix",
            p,
            "--rate",
            "25",
            "--steps",
            &steps,
            "--node",
            &n,
            "--quiet",
        ],
    )
}

/// The log with its `late_after` column emptied: every slot on time.
fn on_time(log: &Path, out: &Path) -> usize {
    let s = std::fs::read_to_string(log).unwrap();
    let mut lines = s.lines();
    let head = lines.next().unwrap();
    let col = head
        .split(',')
        .position(|c| c == "late_after")
        .expect("a late_after column");
    let mut late = 0;
    let mut w = format!("{head}\n");
    for l in lines {
        let mut f: Vec<&str> = l.split(',').collect();
        late += usize::from(f[col] != "0");
        f[col] = "0";
        w.push_str(&f.join(","));
        w.push('\n');
    }
    std::fs::write(out, w).unwrap();
    late
}

/// `replay` of `log` with `extra` flags: its stdout and its `--output` CSV.
fn replay(dir: &Path, name: &str, log: &Path, extra: &[&str]) -> (String, std::path::PathBuf) {
    let out = dir.join(format!("{name}.csv"));
    let mut args = vec![
        "replay",
        "--input",
        log.to_str().unwrap(),
        "--scenario",
        S,
        "--output",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let mut p = Proc::start(dir, name, &args);
    assert!(p.wait(120).success(), "{name}: {}", p.err());
    (p.out(), out)
}

/// The `final estimate` lines of a replay's summary.
fn finals(said: &str) -> Vec<&str> {
    said.lines()
        .filter(|l| l.contains("final estimate"))
        .collect()
}

#[test]
fn late_slots_within_the_lag_are_folded_in_and_replay_bit_for_bit() {
    let dir = scratch("late-slots");
    let p = prefix("late-slots");
    let (json, csv, log) = (
        dir.join("run.json"),
        dir.join("run.csv"),
        dir.join("slots.csv"),
    );
    let steps = STEPS.to_string();
    let mut run = Proc::start(
        &dir,
        "runner",
        &[
            "run",
            "--scenario",
            S,
            "--prefix",
            &p,
            "--steps",
            &steps,
            "--instant-deadline-ms",
            "5",
            "--lag",
            "16",
            "--json",
            json.to_str().unwrap(),
            "--estimates-csv",
            csv.to_str().unwrap(),
            "--slots-csv",
            log.to_str().unwrap(),
            "--connect-timeout",
            "60",
        ],
    );
    run.wait_for_stderr("waiting for channel-sim", 30);
    let mut pubs = vec![channel_sim(&dir, &p, 0), channel_sim(&dir, &p, 1)];
    // One and a half sampling periods behind the others (and whatever starting a process adds): its
    // slots miss their instants' 5 ms deadline and come a few instants later.
    std::thread::sleep(std::time::Duration::from_millis(60));
    pubs.push(channel_sim(&dir, &p, 2));
    for q in &mut pubs {
        assert!(q.wait(60).success(), "{}", q.err());
    }
    let st = run.wait(60);
    assert!(st.success(), "{}", run.err());

    let r = report(&json);
    let c = &r["counts"];
    let get = |k: &str| c[k].as_u64().unwrap_or_else(|| panic!("{k}: {r}"));
    assert_eq!(get("instants"), u64::from(STEPS), "{r}");
    // Node 2's slots miss their deadline: nearly all of them (the first instants may wait
    // for it while the others start).
    assert!(get("late_folded") > u64::from(STEPS) * 9 / 10, "{r}");
    assert_eq!(get("late"), 0, "nothing arrived beyond the lag: {r}");
    assert_eq!(get("late_folded"), get("lost_deadline"), "{r}");
    assert_eq!(
        get("received") + get("late_folded"),
        3 * u64::from(STEPS),
        "{r}"
    );
    // Every estimator was offered each of them and folded each in: a late slot of node 2
    // always brings what its instant was missing, within the lag.
    for e in r["estimators"].as_array().unwrap() {
        let l = &e["late"];
        let n = |k: &str| l[k].as_u64().unwrap_or_else(|| panic!("{k}: {e}"));
        assert_eq!(n("folded"), get("late_folded"), "{e}");
        assert_eq!(n("unchanged") + n("too_old") + n("refused"), 0, "{e}");
    }

    // The log replays to the live estimates, instant by instant, bit for bit.
    let (said, replayed) = replay(&dir, "replay-lag", &log, &["--lag", "16"]);
    let (lh, live) = common::csv(&csv);
    let (rh, again) = common::csv(&replayed);
    assert_eq!(live.len(), again.len());
    let mut compared = 0;
    for (j, name) in rh.iter().enumerate().skip(1) {
        let i = lh
            .iter()
            .position(|h| h == name)
            .unwrap_or_else(|| panic!("{name}"));
        for (a, b) in live.iter().zip(&again) {
            assert_eq!(a[i].to_bits(), b[j].to_bits(), "{name}");
            compared += 1;
        }
    }
    assert!(compared > 1000);
    // Every late slot in, the estimators hold the on-time stream's estimates.
    let ok_log = dir.join("on-time.csv");
    let late = on_time(&log, &ok_log);
    assert_eq!(late as u64, get("late_folded"));
    let (on, _) = replay(&dir, "replay-on-time", &ok_log, &["--lag", "16"]);
    let (lost, _) = replay(&dir, "replay-no-lag", &log, &[]);
    assert!(
        said.contains(&format!("{late} slot(s) arrived late")),
        "{said}"
    );
    assert_eq!(finals(&said), finals(&on), "{said}\n{on}");
    assert_ne!(finals(&lost), finals(&on), "{lost}");
    let _ = std::fs::remove_dir_all(&dir);
}
