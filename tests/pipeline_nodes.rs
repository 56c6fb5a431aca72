//! One publisher per sensor node (wire version 3, `docs/wire.md`, Stream rules): separate
//! `channel-sim --node N` processes started in a shuffled order, and one publisher that sends
//! every instant's slots in reversed node order, give estimates bit-identical to one ordered
//! publisher of the same scenario and seed (the `--estimates-csv` files are compared byte for
//! byte, truth columns included).

#[path = "pipeline_common.rs"]
mod common;

use common::{prefix, report, scratch, Proc};
use std::path::{Path, PathBuf};

/// Three sensor nodes.
const S: &str = "tobit-fusion";
const STEPS: u32 = 300;
const NODES: u64 = 3;

fn runner(dir: &Path, name: &str, p: &str) -> (Proc, PathBuf, PathBuf) {
    let json = dir.join(format!("{name}.json"));
    let csv = dir.join(format!("{name}.csv"));
    let steps = STEPS.to_string();
    let run = Proc::start(
        dir,
        name,
        &[
            "run",
            "--scenario",
            S,
            "--prefix",
            p,
            "--steps",
            &steps,
            "--buffer",
            "4096",
            "--json",
            json.to_str().unwrap(),
            "--estimates-csv",
            csv.to_str().unwrap(),
            "--connect-timeout",
            "60",
        ],
    );
    run.wait_for_stderr("waiting for channel-sim", 30);
    (run, json, csv)
}

fn channel_sim(dir: &Path, name: &str, p: &str, node: Option<u8>) -> Proc {
    let steps = STEPS.to_string();
    let n = node.map(|n| n.to_string());
    let mut args = vec![
        "channel-sim",
        "--scenario",
        S,
        "--prefix",
        p,
        "--rate",
        "0",
        "--steps",
        &steps,
        "--quiet",
    ];
    if let Some(n) = &n {
        args.extend_from_slice(&["--node", n]);
    }
    Proc::start(dir, name, &args)
}

/// Waits for the runner and its publishers; checks that the run saw every slot of every node
/// and nothing else.
fn finish(run: &mut Proc, pubs: &mut [Proc], json: &Path) {
    let st = run.wait(120);
    assert!(st.success(), "{st}\n{}", run.err());
    for p in pubs.iter_mut() {
        let st = p.wait(60);
        assert!(st.success(), "{}: {st}\n{}", p.name, p.err());
        assert!(!p.err().contains("panicked"), "{}", p.err());
    }
    let r = report(json);
    let c = &r["counts"];
    assert_eq!(r["ending"], "completed", "{r}");
    assert_eq!(c["instants"], u64::from(STEPS), "{r}");
    assert_eq!(c["received"], u64::from(STEPS) * NODES, "{r}");
    assert_eq!(c["markers"], NODES, "{r}");
    for lost in [
        "lost_in_ipc",
        "lost_deadline",
        "lost_overrun",
        "lost_after_end",
        "late",
    ] {
        assert_eq!(c[lost], 0, "{lost}: {r}");
    }
    let skipped: u64 = c["skipped"]
        .as_object()
        .unwrap()
        .values()
        .map(|v| v.as_u64().unwrap())
        .sum();
    assert_eq!(skipped, 0, "{r}");
    assert_eq!(r["truth_missing"], 0, "{r}");
}

#[test]
fn per_node_processes_and_reversed_node_order_match_one_ordered_publisher() {
    let dir = scratch("nodes");

    // The reference: one publisher, every instant's slots in node order.
    let p = prefix("nodes-ref");
    let (mut run, json, reference) = runner(&dir, "ref", &p);
    let mut pubs = vec![channel_sim(&dir, "pub-all", &p, None)];
    finish(&mut run, &mut pubs, &json);
    let want = std::fs::read_to_string(&reference).unwrap();
    assert_eq!(want.lines().count(), STEPS as usize + 1);

    // One process per node, started in a shuffled order (node 0, which publishes the truth,
    // last).
    let p = prefix("nodes-split");
    let (mut run, json, split) = runner(&dir, "split", &p);
    let mut pubs = Vec::new();
    for n in [2u8, 1, 0] {
        pubs.push(channel_sim(&dir, &format!("pub-node{n}"), &p, Some(n)));
        std::thread::sleep(std::time::Duration::from_millis(30));
    }
    finish(&mut run, &mut pubs, &json);
    assert!(
        std::fs::read_to_string(&split).unwrap() == want,
        "per-node processes: estimates differ from the ordered publisher's"
    );

    // One publisher sending node 2, 1, 0 at every instant.
    let p = prefix("nodes-rev");
    let (mut run, json, rev) = runner(&dir, "rev", &p);
    let steps = STEPS.to_string();
    let mut pubs = vec![Proc::start_program(
        &dir,
        "rogue",
        Path::new(env!("CARGO_BIN_EXE_rogue-publisher")),
        &[
            "--prefix",
            &p,
            "--scenario",
            S,
            "--simulate",
            "--steps",
            &steps,
            "--reverse-nodes",
        ],
    )];
    finish(&mut run, &mut pubs, &json);
    assert!(
        std::fs::read_to_string(&rev).unwrap() == want,
        "reversed node order: estimates differ from the ordered publisher's"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_node_out_of_range_is_refused_with_one_line() {
    let dir = scratch("node-range");
    let p = prefix("node-range");
    let mut publ = Proc::start(
        &dir,
        "pub",
        &[
            "channel-sim",
            "--scenario",
            S,
            "--prefix",
            &p,
            "--node",
            "3",
        ],
    );
    let st = publ.wait(30);
    assert_eq!(st.code(), Some(2), "{}", publ.err());
    let err = publ.err();
    assert!(
        err.contains("--node 3") && err.contains("3 node(s)"),
        "{err}"
    );
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_missing_node_process_is_handed_on_as_lost_when_the_others_stop() {
    // Nodes 0 and 1 at 200 Hz; node 2's process never comes. With no END from node 2 the
    // stream never completes: the run ends when the slots stop (publisher lost), and every
    // pending instant is handed on without node 2, counted apart from IPC losses. (The
    // deadline is long: the two processes' clocks start apart, and a short one would count
    // node 1's slots as late.)
    let dir = scratch("nodes-deadline");
    let p = prefix("nodes-deadline");
    let json = dir.join("runner.json");
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
            "40",
            "--instant-deadline-ms",
            "5000",
            "--json",
            json.to_str().unwrap(),
        ],
    );
    run.wait_for_stderr("waiting for channel-sim", 30);
    let mut pubs: Vec<Proc> = [0u8, 1]
        .iter()
        .map(|n| {
            let n = n.to_string();
            Proc::start(
                &dir,
                &format!("pub-node{n}"),
                &[
                    "channel-sim",
                    "--scenario",
                    S,
                    "--prefix",
                    &p,
                    "--rate",
                    "200",
                    "--steps",
                    "40",
                    "--node",
                    &n,
                    "--quiet",
                ],
            )
        })
        .collect();
    let st = run.wait(60);
    for p in &mut pubs {
        assert!(p.wait(60).success(), "{}", p.err());
    }
    assert_eq!(
        st.code(),
        Some(ipc_runner::run::EXIT_PUBLISHER_LOST),
        "{}",
        run.err()
    );
    let r = report(&json);
    let c = &r["counts"];
    assert_eq!(c["instants"], 40, "{r}");
    assert_eq!(c["received"], 80, "{r}");
    assert_eq!(c["lost_deadline"], 40, "{r}");
    assert_eq!(c["markers"], 2, "{r}");
    for other in ["lost_in_ipc", "lost_overrun", "late"] {
        assert_eq!(c[other], 0, "{other}: {r}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
