//! The check every foreign client's end-to-end test makes (Python, C, the docs' own clients):
//! a runner fed through the client ended complete, and its estimates and those the client's
//! subscriber printed equal `ipc-runner replay` of the same slot log bit for bit.
//!
//! Included by path next to `pipeline_common.rs` (`mod common`).

#![allow(dead_code)]

use super::common::{self, Proc};
use std::collections::BTreeMap;
use std::path::Path;

/// `(k, estimator column) → value bits` of a CSV with a `k` column and `<est>_<j>` columns.
pub fn estimate_bits(path: &Path, names: &[String]) -> BTreeMap<(u32, String), u64> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let head: Vec<&str> = lines.next().unwrap().split(',').collect();
    let kcol = head.iter().position(|h| *h == "k").unwrap();
    let mut out = BTreeMap::new();
    for l in lines {
        let cells: Vec<&str> = l.split(',').collect();
        let k: u32 = cells[kcol].parse().unwrap();
        for (c, h) in head.iter().enumerate() {
            if names.iter().any(|n| h.starts_with(&format!("{n}_"))) {
                let v: f64 = cells[c].parse().unwrap();
                out.insert((k, h.to_string()), v.to_bits());
            }
        }
    }
    out
}

/// The last instant of a slot log.
pub fn last_instant(slots: &Path) -> u32 {
    let text = std::fs::read_to_string(slots).unwrap();
    text.lines()
        .skip(1)
        .filter_map(|l| l.split(',').next()?.parse().ok())
        .max()
        .unwrap()
}

/// The runner's report `json` says the run completed with `instants` instants and nothing lost
/// in the IPC; its estimates (`est_csv`) and the subscriber's rows (`sub_out`: `k,estimator,
/// status,x_0..`, every value printed exactly) equal a replay of `slots` under `scenario`, bit
/// for bit. `who` names the client in the messages. Returns the estimators' names.
#[allow(clippy::too_many_arguments)]
pub fn equal_to_replay(
    dir: &Path,
    name: &str,
    who: &str,
    json: &Path,
    est_csv: &Path,
    slots: &Path,
    scenario: &[&str],
    instants: u32,
    sub_out: &str,
) -> Vec<String> {
    let r = common::report(json);
    assert_eq!(r["ending"], "completed", "{r}");
    assert_eq!(r["counts"]["lost_in_ipc"], 0, "{r}");
    assert_eq!(r["counts"]["instants"], instants, "{r}");
    let names: Vec<String> = r["estimators"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["name"].as_str().unwrap().to_string())
        .collect();

    let replay_csv = dir.join("replay.csv");
    let mut replay_args = vec![
        "replay",
        "--input",
        slots.to_str().unwrap(),
        "--output",
        replay_csv.to_str().unwrap(),
    ];
    replay_args.extend_from_slice(scenario);
    let mut replay = Proc::start(dir, "replay", &replay_args);
    assert!(replay.wait(60).success(), "{}", replay.err());

    let want = estimate_bits(&replay_csv, &names);
    assert!(!want.is_empty());
    let live = estimate_bits(est_csv, &names);
    assert_eq!(
        live, want,
        "{name}: the runner's estimates differ from the replay's"
    );

    let mut seen = BTreeMap::new();
    for l in sub_out.lines() {
        let c: Vec<&str> = l.split(',').collect();
        let k: u32 = c[0].parse().unwrap();
        let nx = (0..)
            .take_while(|j| want.contains_key(&(k, format!("{}_{j}", c[1]))))
            .count();
        for j in 0..nx {
            let v: f64 = c[3 + j].parse().unwrap();
            seen.insert((k, format!("{}_{j}", c[1])), v.to_bits());
        }
    }
    // Every instant of every estimator, bit for bit.
    assert_eq!(
        seen, want,
        "{name}: the {who} subscriber's estimates differ from the replay's"
    );
    names
}

/// A slot log of the `linear` preset, 2000 instants, recorded by a runner fed by channel-sim
/// as fast as it goes, in a scratch directory named after `tag`: `(directory, log)`.
pub fn record_linear_log(tag: &str) -> (std::path::PathBuf, std::path::PathBuf) {
    let dir = common::scratch(tag);
    let p = common::prefix(tag);
    let log = dir.join("linear-slots.csv");
    let mut run = Proc::start(
        &dir,
        "record",
        &[
            "run",
            "--scenario",
            "linear",
            "--prefix",
            &p,
            "--steps",
            "2000",
            "--slots-csv",
            log.to_str().unwrap(),
        ],
    );
    run.wait_for_stderr("waiting for channel-sim", 30);
    let mut publ = common::start_channel_sim(&dir, &p, "linear", 2000, 0);
    assert!(publ.wait(60).success(), "{}", publ.err());
    assert!(run.wait(60).success(), "{}", run.err());
    (dir, log)
}
